"""``cosim models``: the usable aircraft models (which take commands), their
JSBSim properties, or the vehicle classes."""

from __future__ import annotations

import argparse
import logging

from cosim.cli.common import EXIT_FAIL, EXIT_OK, EXIT_USAGE
from cosim.core.section import CliCommand
from cosim.errors import CosimError

log = logging.getLogger("cosim")
#: refusals listed for each model by --check (--model lists all)
_SHOWN = 5


def rigid_problems(m: object) -> list[str]:
    """What the rigid-body compiler refuses in a model's files (file:line: element)."""
    from cosim.rigid.aircraft import problems
    from cosim.vehicles.fixed_wing_rigid import model_files

    xml, systems, engines = model_files(m.aircraft_dir, m.name, m.source,  # type: ignore[attr-defined]
                                        getattr(m, "profile", None))
    try:
        return [str(e) for e in problems(xml, systems, engines)]
    except CosimError as e:  # a file it cannot even read
        return [str(e)]

def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--check", action="store_true",
                   help="load each model to prove it works, and compile it for the rigid-body "
                        "tier (class fixed_wing_rigid), listing what the compiler refuses")
    p.add_argument("--model", metavar="MODEL",
                   help="with --check: only MODEL, with every refusal listed")
    p.add_argument("--properties", metavar="MODEL",
                   help="list the JSBSim properties of MODEL")
    p.add_argument("--classes", action="store_true",
                   help="list the vehicle classes instead (cosim's and installed packages')")


def run(a: argparse.Namespace) -> int:
    from cosim.vehicles.jsb import find_model, list_models, new_fdm

    if a.properties:
        fdm = new_fdm(find_model(a.properties), 1 / 120)
        print(fdm.query_property_catalog(""))
        return EXIT_OK
    if a.classes:
        from cosim.vehicles import vehicle_classes

        for name, cls in vehicle_classes().items():
            print(f"{name:12s} {cls.model_kind:8s} {type(cls).__module__:28s} {cls.description}")
        return EXIT_OK
    from cosim.vehicles import DEFAULT_CLASS, vehicle_classes
    from cosim.vehicles.jsb import held_messages

    classes = vehicle_classes()
    failed: list[str] = []
    refused: list[str] = []
    models = list_models()
    if a.model:
        if not a.check:
            log.error("cosim models: --model goes with --check")
            return EXIT_USAGE
        models = [find_model(a.model)]
    print(f"{'check   RIGID   ' if a.check else ''}{'MODEL':18s} {'SOURCE':7s} {'CLASS':12s} "
          f"{'COMMANDS':8s} DESCRIPTION")
    for m in models:
        status = ""
        if a.check:  # JSBSim's own messages are held: a failure says its first error
            with held_messages() as said:
                try:
                    new_fdm(m, 1 / 120)
                    status = "ok      "
                except CosimError as e:
                    status = "FAILED  "
                    errors = [t for level, t in said if level >= logging.ERROR]
                    failed.append(f"{m.name}: {(errors or [str(e)])[0].splitlines()[0]}")
            for _level, text in said:
                log.debug("%s: %s", m.name, text)
            found = rigid_problems(m)
            status += f"{'yes' if not found else f'no ({len(found)})':8s}"
            shown = found if a.model else found[:_SHOWN]
            refused += [f"{m.name}: {p}" for p in shown]
            if len(found) > len(shown):
                refused.append(f"{m.name}: ... and {len(found) - len(shown)} more "
                               f"(cosim models --check --model {m.name} lists them all)")
        name = str((m.profile or {}).get("class", DEFAULT_CLASS))
        commands = "yes" if name in classes and classes[name].commandable else "no"
        print(f"{status}{m.name:18s} {m.source:7s} {name:12s} {commands:8s} {m.description}")
    print("COMMANDS yes: the model has a cosim profile (aircraft/profiles/, "
          "aircraft/<model>/cosim.yaml) that makes it a vehicle class taking command:, "
          "MAVLink commands, missions and the swarm; no: it flies open-loop, worked by set: "
          "only (JSBSim properties).")
    if a.check:
        print(f"{len(models) - len(failed)} of {len(models)} models load"
              + "".join(f"\n  {f}" for f in failed))
        print("RIGID yes: the rigid-body tier (class fixed_wing_rigid) compiles the model's "
              "files; no (N): N elements it does not support, each named by file, line and "
              "element:" if refused else "RIGID yes: the rigid-body tier compiles every model")
        for r in refused:
            print(f"  {r}")
    return EXIT_FAIL if failed else EXIT_OK


COMMAND = CliCommand(
    "models",
    "list usable aircraft models",
    add_arguments, run, rank=30)
