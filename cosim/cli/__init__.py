"""The ``cosim`` command: one module a subcommand (``run``, ``validate``,
``models``, ``plot``, ``export``, ``recover``, ``replay``, ``visibility``, ``trials``,
``bench``) and the subcommands scenario sections bring (``sweep``,
``search-plan``, ``swarm``: ``cosim.core.section.CliCommand``).

``main(argv) -> int``: exit 0 ok, 1 runtime failure, 2 usage or config
error, 130 stopped by Ctrl-C (after a clean stop with everything flushed).
Only this package configures logging handlers.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Sequence

from cosim import __version__
from cosim.cli import (
    bench,
    export,
    models,
    plot,
    recover,
    replay,
    run,
    trials,
    validate,
    visibility,
)
from cosim.cli.common import (
    EXIT_FAIL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    Parser,
    UsageError,
)
from cosim.core import memory
from cosim.core.section import CliCommand, scenario_sections
from cosim.errors import ConfigError, CosimError

__all__ = ["EXIT_FAIL", "EXIT_INTERRUPTED", "EXIT_OK", "EXIT_USAGE", "main"]

#: the CLI's own commands (``cosim --help`` lists them and the sections' by rank)
OWN = (run.COMMAND, validate.COMMAND, models.COMMAND, plot.COMMAND, export.COMMAND,
       recover.COMMAND, replay.COMMAND, visibility.COMMAND, trials.COMMAND, bench.COMMAND)


def commands() -> dict[str, CliCommand]:
    """Every subcommand by name, the CLI's own and each section's, in the
    order of their ranks (a section's command whose name is taken is left
    out with a warning)."""
    out = {c.name: c for c in OWN}
    for key, section in scenario_sections().items():
        for c in section.commands:
            if c.name in out:
                logging.getLogger("cosim").warning(
                    "section %r brings a command %r, which exists: ignored", key, c.name)
                continue
            out[c.name] = c
    return {c.name: c for c in sorted(out.values(), key=lambda c: c.rank)}


def build_parser(cmds: dict[str, CliCommand]) -> Parser:
    p = Parser(prog="cosim", description="Lockstep co-simulation of UAV swarms on JSBSim.")
    p.add_argument("--version", action="version", version=f"cosim {__version__}")
    p.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    p.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    sub = p.add_subparsers(dest="cmd", metavar="COMMAND", parser_class=Parser)
    for c in cmds.values():
        c.add_arguments(sub.add_parser(c.name, help=c.help, epilog=c.epilog or None))
    return p


def setup_logging(verbose: int, quiet: bool) -> None:
    level = logging.WARNING if quiet else (logging.DEBUG if verbose >= 2 else logging.INFO)
    h = logging.StreamHandler(sys.stderr)
    h.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s",
                                     "%H:%M:%S"))
    root = logging.getLogger()
    root.handlers[:] = [h]
    root.setLevel(level)
    if verbose < 3:
        logging.getLogger("cosim.jsbsim").setLevel(logging.WARNING)


def main(argv: Sequence[str] | None = None) -> int:
    cmds = commands()
    parser = build_parser(cmds)
    try:
        a = parser.parse_args(list(argv) if argv is not None else None)
    except UsageError as e:
        print(e, file=sys.stderr)
        return EXIT_USAGE
    except SystemExit as e:  # --help, --version
        return int(e.code or 0)
    if a.cmd is None:
        parser.print_help()
        return EXIT_USAGE
    if argv is None and cmds[a.cmd].flies_aircraft:
        memory.reexec_driver()  # once, with the physics allocator's settings
    setup_logging(a.verbose, a.quiet)
    try:
        return cmds[a.cmd].run(a)
    except ConfigError as e:
        print(e, file=sys.stderr)
        return EXIT_USAGE
    except CosimError as e:
        print(f"cosim {a.cmd}: {e}", file=sys.stderr)
        return EXIT_FAIL
    except KeyboardInterrupt:
        print("cosim: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAIL
    except OSError as e:  # a file that cannot be written, a full disk, ...
        print(f"cosim {a.cmd}: {e}", file=sys.stderr)
        return EXIT_FAIL
    except ValueError as e:  # a bad value that got past the parser
        print(f"cosim {a.cmd}: {e}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
