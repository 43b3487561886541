"""The one place that knows how to reach JSBSim: model search path, quiet
console, building an FDM for a named model.

It owns JSBSim's process-wide logger (``jsbsim.set_logger``), which every
process that builds FDMs must install (``quiet_jsbsim``), and the aircraft
catalog. It does not step, trim or schedule anything.
"""

from __future__ import annotations

import logging
import os
import re
import threading
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import jsbsim

from cosim.errors import JSBSimError, ModelNotFound

log = logging.getLogger(__name__)

#: the project's own aircraft (``aircraft/`` beside the package in a checkout)
PROJECT_AIRCRAFT_DIR = Path(__file__).resolve().parent.parent / "aircraft"
JSBSIM_ROOT = Path(jsbsim.get_default_root_dir())

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
        if text and self._log.isEnabledFor(self._level):
            self._log.log(self._level, "%s%s", self._where, text)


_quiet = threading.local()


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

    @property
    def xml_path(self) -> Path:
        return Path(self.aircraft_dir) / self.name / f"{self.name}.xml"


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
                found[sub.name] = ModelInfo(sub.name, str(folder), source, _description(xml))
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
    close = [n for n in names if n.lower() == name.lower()]
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ModelNotFound(f"unknown aircraft model {name!r}{hint}; available: {', '.join(names)}")


def new_fdm(model: ModelInfo, dt_s: float) -> jsbsim.FGFDMExec:
    """Build a quiet FGFDMExec with ``model`` loaded and its time step set."""
    quiet_jsbsim()
    fdm = jsbsim.FGFDMExec(str(JSBSIM_ROOT))
    fdm.set_debug_level(0)
    fdm.disable_output()
    if model.source == "jsbsim":
        ok = fdm.load_model(model.name)
    else:
        ok = fdm.load_model_with_paths(
            model.name, model.aircraft_dir, str(JSBSIM_ROOT / "engine"),
            str(JSBSIM_ROOT / "systems"))
    if not ok:
        raise JSBSimError(f"JSBSim could not load model {model.name!r} from {model.xml_path}")
    fdm.set_dt(dt_s)
    return fdm


def has_property(fdm: jsbsim.FGFDMExec, name: str) -> bool:
    """True if ``name`` exists in ``fdm`` (JSBSim silently creates misspelled ones on write)."""
    return bool(fdm.get_property_manager().hasNode(name))
