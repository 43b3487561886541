"""The one place that knows how to reach JSBSim: model search path, quiet
console, building an FDM for a named model.

It owns JSBSim's process-wide logger (``jsbsim.set_logger``), which every
process that builds FDMs must install (``quiet_jsbsim``), and the aircraft
catalog. It does not step, trim or schedule anything. What only the
catalog and the autopilot wrapper need (yaml, difflib, hashlib, shutil,
tempfile) is imported where it is used: a physics worker, which reaches
JSBSim through this module, starts without them.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import jsbsim

from cosim.core.cache import cache_folder
from cosim.errors import JSBSimError, ModelNotFound

log = logging.getLogger(__name__)

#: the project's own aircraft (``aircraft/`` beside the package in a checkout)
PROJECT_AIRCRAFT_DIR = Path(__file__).resolve().parents[2] / "aircraft"
JSBSIM_ROOT = Path(jsbsim.get_default_root_dir())
#: shared JSBSim systems (the cosim autopilot) and profiles of bundled models
SYSTEMS_DIR = PROJECT_AIRCRAFT_DIR / "systems"
PROFILES_DIR = PROJECT_AIRCRAFT_DIR / "profiles"
AUTOPILOT_SYSTEM = "cosim_autopilot"

_LEVELS = {
    0: logging.DEBUG,  # BULK
    1: logging.DEBUG,  # DEBUG
    2: logging.DEBUG,  # INFO: JSBSim's chatter at load time
    3: logging.WARNING,
    4: logging.ERROR,
    5: logging.CRITICAL,
    6: logging.DEBUG,  # STDOUT (the banner)
}


class _LoggingBridge(jsbsim.FGLogger):
    """Routes JSBSim's console output into ``logging`` (logger ``cosim.jsbsim``)."""

    def __init__(self) -> None:
        super().__init__()
        self._level = logging.DEBUG
        self._parts: list[str] = []
        self._where = ""
        self._log = logging.getLogger("cosim.jsbsim")

    def set_level(self, level: object) -> None:
        self._level = _LEVELS.get(int(level), logging.DEBUG)  # type: ignore[call-overload]
        self._parts = []
        self._where = ""

    def file_location(self, filename: str, line: int) -> None:
        self._where = f"{filename}:{line}: "

    def message(self, message: str) -> None:
        self._parts.append(message)

    def format(self, format: object) -> None:  # noqa: A002 - JSBSim's signature
        pass

    def flush(self) -> None:
        text = "".join(self._parts).strip()
        self._parts = []
        if not text:
            return
        held = getattr(_quiet, "held", None)
        if held is not None and self._level >= logging.WARNING:
            held.append((self._level, f"{self._where}{text}"))
        elif self._log.isEnabledFor(self._level):
            self._log.log(self._level, "%s%s", self._where, text)


_quiet = threading.local()


@contextlib.contextmanager
def held_messages() -> Iterator[list[tuple[int, str]]]:
    """JSBSim's warnings and errors in this thread held back in the list
    yielded ((level, text), in order), for a caller that reports them as part
    of its own error (a trim that fails says why once, in its message, rather
    than JSBSim printing it for every vehicle). The caller logs what it does
    not report (``release``)."""
    outer = getattr(_quiet, "held", None)
    held: list[tuple[int, str]] = []
    _quiet.held = held
    try:
        yield held
    finally:
        _quiet.held = outer


def release(held: list[tuple[int, str]]) -> None:
    """Log messages ``held_messages`` held back, as JSBSim would have."""
    bridge_log = logging.getLogger("cosim.jsbsim")
    for level, text in held:
        bridge_log.log(level, "%s", text)


def quiet_jsbsim() -> None:
    """Install the logging bridge for this thread (JSBSim's logger is per thread)."""
    if not getattr(_quiet, "done", False):
        bridge = _LoggingBridge()
        jsbsim.set_logger(bridge)
        _quiet.bridge = bridge  # keep it alive
        _quiet.done = True


@dataclass(frozen=True)
class ModelInfo:
    """One usable aircraft model."""

    name: str
    aircraft_dir: str  # the folder that holds <name>/<name>.xml
    source: str  # "cosim", "jsbsim" or "user"
    description: str = ""
    #: cosim profile (``aircraft/<name>/cosim.yaml`` or ``aircraft/profiles/<name>.yaml``):
    #: its vehicle class, autopilot (native | attach), clmax, alpha_stall_deg, airspeed
    #: envelope, JSBSim properties to set after loading
    profile: dict[str, Any] = field(default_factory=dict, compare=False, hash=False)

    @property
    def xml_path(self) -> Path:
        return Path(self.aircraft_dir) / self.name / f"{self.name}.xml"


def _load_profile(name: str, aircraft_dir: Path) -> dict[str, Any]:
    import yaml

    for p in (aircraft_dir / name / "cosim.yaml", PROFILES_DIR / f"{name}.yaml"):
        if p.is_file():
            data = yaml.safe_load(p.read_text()) or {}
            if not isinstance(data, dict):
                raise JSBSimError(f"{p}: a cosim profile must be a mapping")
            return data
    return {}


def aircraft_search_path(extra: tuple[str, ...] = ()) -> list[tuple[Path, str]]:
    """Folders searched for models, first match wins: the scenario's own, then
    ``$COSIM_AIRCRAFT_PATH`` (os.pathsep separated), the project's
    ``aircraft/``, JSBSim's bundled aircraft."""
    dirs: list[tuple[Path, str]] = [(Path(p), "user") for p in extra]
    env = os.environ.get("COSIM_AIRCRAFT_PATH", "")
    dirs += [(Path(p), "user") for p in env.split(os.pathsep) if p]
    dirs.append((PROJECT_AIRCRAFT_DIR, "cosim"))
    dirs.append((JSBSIM_ROOT / "aircraft", "jsbsim"))
    return dirs


_DESC = re.compile(r"<description>\s*(.*?)\s*</description>", re.S)


def _description(xml: Path) -> str:
    try:
        head = xml.read_text(errors="replace")[:8000]
    except OSError:
        return ""
    m = _DESC.search(head)
    return " ".join(m.group(1).split())[:100] if m else ""


@lru_cache(maxsize=8)
def _catalog(extra: tuple[str, ...]) -> dict[str, ModelInfo]:
    found: dict[str, ModelInfo] = {}
    for folder, source in aircraft_search_path(extra):
        if not folder.is_dir():
            continue
        for sub in sorted(folder.iterdir()):
            xml = sub / f"{sub.name}.xml"
            if sub.name not in found and xml.is_file():
                found[sub.name] = ModelInfo(sub.name, str(folder), source, _description(xml),
                                            _load_profile(sub.name, folder))
    return found


def list_models(extra: tuple[str, ...] = ()) -> list[ModelInfo]:
    """Every model on the search path, sorted by name."""
    return sorted(_catalog(tuple(extra)).values(), key=lambda m: m.name.lower())


def find_model(name: str, extra: tuple[str, ...] = ()) -> ModelInfo:
    """The model called ``name``; ``ModelNotFound`` listing the available ones otherwise."""
    cat = _catalog(tuple(extra))
    if name in cat:
        return cat[name]
    names = sorted(cat, key=str.lower)
    lower = {n.lower(): n for n in names}
    close = [n for n in names if n.lower() == name.lower()]
    if not close:  # the nearest spellings, best first (ties in name order)
        import difflib

        scored = sorted((-difflib.SequenceMatcher(None, name.lower(), k).ratio(), v)
                        for k, v in lower.items())
        close = [v for score, v in scored[:3] if -score >= 0.75]
    hint = f" (did you mean {' or '.join(repr(c) for c in close)}?)" if close else ""
    raise ModelNotFound(f"unknown aircraft model {name!r}{hint}; available: {', '.join(names)}")


def wrapper_root(model: ModelInfo) -> Path:
    """An aircraft folder holding ``model`` with the cosim autopilot attached.

    The model's own files are symlinked, its XML is copied with one
    ``<system file="cosim_autopilot"/>`` line added, and the autopilot file is
    placed in the wrapper's ``Systems/`` (which JSBSim searches first). Built
    once per content hash in the cache folder (``cosim.core.cache``:
    ``wrapped/``), atomically, so concurrent workers agree.
    """
    import hashlib
    import shutil
    import tempfile

    src = Path(model.aircraft_dir) / model.name
    xml = (src / f"{model.name}.xml").read_text()
    ap = (SYSTEMS_DIR / f"{AUTOPILOT_SYSTEM}.xml").read_text()
    key = hashlib.sha256((str(src) + "\0" + xml + "\0" + ap).encode()).hexdigest()[:16]
    root = cache_folder("wrapped", f"{model.name}-{key}")
    if (root / model.name / f"{model.name}.xml").is_file():
        return root
    root.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{model.name}-", dir=root.parent))
    try:
        dst = tmp / model.name
        dst.mkdir()
        for entry in src.iterdir():
            if entry.name in (f"{model.name}.xml", "Systems"):
                continue
            (dst / entry.name).symlink_to(entry.resolve())
        systems = dst / "Systems"
        systems.mkdir()
        if (src / "Systems").is_dir():
            for entry in (src / "Systems").iterdir():
                (systems / entry.name).symlink_to(entry.resolve())
        shutil.copyfile(SYSTEMS_DIR / f"{AUTOPILOT_SYSTEM}.xml",
                        systems / f"{AUTOPILOT_SYSTEM}.xml")
        end = xml.rfind("</fdm_config>")
        if end < 0:
            raise JSBSimError(f"{src}: no </fdm_config> in {model.name}.xml")
        patched = (xml[:end] + f'  <system file="{AUTOPILOT_SYSTEM}"/>  <!-- added by cosim -->\n'
                   + xml[end:])
        (dst / f"{model.name}.xml").write_text(patched)
        try:
            os.rename(tmp, root)
        except OSError:  # another process won the race: use its copy
            if not (root / model.name / f"{model.name}.xml").is_file():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return root


def new_fdm(model: ModelInfo, dt_s: float) -> jsbsim.FGFDMExec:
    """Build a quiet FGFDMExec with ``model`` loaded (with the cosim autopilot
    when its profile asks for it), its profile applied and its time step set."""
    quiet_jsbsim()
    fdm = jsbsim.FGFDMExec(str(JSBSIM_ROOT))
    fdm.set_debug_level(0)
    fdm.disable_output()
    attach = model.profile.get("autopilot") == "attach"
    try:
        if model.source == "jsbsim" and not attach:
            ok = fdm.load_model(model.name)
        else:
            aircraft = wrapper_root(model) if attach else Path(model.aircraft_dir)
            systems = JSBSIM_ROOT / "systems" if model.source == "jsbsim" else SYSTEMS_DIR
            ok = fdm.load_model_with_paths(model.name, str(aircraft),
                                           str(JSBSIM_ROOT / "engine"), str(systems))
    except jsbsim.BaseError as e:  # e.g. an XML parse error
        raise JSBSimError(f"JSBSim could not load model {model.name!r} from "
                          f"{model.xml_path}: {' '.join(str(e).split())}") from None
    if not ok:
        raise JSBSimError(f"JSBSim could not load model {model.name!r} from {model.xml_path}")
    fdm.set_dt(dt_s)
    prof = model.profile
    if "clmax" in prof:
        fdm["cosim/ap/clmax"] = float(prof["clmax"])
    if "alpha_stall_deg" in prof:
        fdm["cosim/ap/alpha-stall-deg"] = float(prof["alpha_stall_deg"])
        fdm["cosim/ap/alpha-recover-deg"] = float(prof["alpha_stall_deg"]) - 2.0
    for prop, value in (prof.get("properties") or {}).items():
        if not has_property(fdm, prop):
            raise JSBSimError(f"profile of {model.name!r} sets {prop!r}, which the model lacks")
        if not is_writable(fdm, prop):
            raise JSBSimError(f"profile of {model.name!r} sets {prop!r}, which is read-only")
        fdm[prop] = float(value)
    return fdm


def has_property(fdm: jsbsim.FGFDMExec, name: str) -> bool:
    """True if ``name`` exists in ``fdm`` (JSBSim silently creates misspelled ones on write)."""
    return bool(fdm.get_property_manager().hasNode(name))


def is_writable(fdm: jsbsim.FGFDMExec, name: str) -> bool:
    """True if the existing property ``name`` accepts writes (JSBSim silently
    ignores writes to read-only ones)."""
    node = fdm.get_property_manager().get_node(name)
    return node is not None and bool(node.get_attribute(jsbsim.Attribute.WRITE))
