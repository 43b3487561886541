"""The MAVLink options of a run (``MavlinkConfig``: the link's URL, stream
rates, which vehicles, bounds on the work done for the network, signing,
lockstep with an outside controller) and the signing key they name
(``load_signing_key``). The config holds where the key is, never the key."""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cosim.errors import ConfigError
from cosim.mavlink import adapter as mav
from cosim.mavlink.link import DEFAULT_URL
from cosim.mavlink.scenario import mavlink_rows

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MavlinkConfig:
    """The MAVLink options of a run.

    ``rates_hz`` overrides ``DEFAULT_RATES_HZ`` per message (0 = off);
    ``max_datagrams_per_exchange`` bounds the work one exchange does for the
    network, ``max_peers`` the addresses answered.

    MAVLink 2 signing is on when a key source is named, either
    ``signing_key_file`` (a file holding the passphrase) or
    ``signing_key_env`` (the name of an environment variable holding it),
    never both. The passphrase is what MAVProxy's ``signing key PASSPHRASE``
    takes (one word, ASCII; surrounding whitespace such as the file's final
    newline is ignored); the key is its SHA-256, as MAVProxy derives it. The
    config holds where the key is, never the key, so scenario text cannot
    carry it. ``signing_link_id`` (0..255) is the link id in outgoing
    signatures. What signing changes: ``cosim.mavlink.inbox`` (what is
    received) and ``cosim.mavlink.endpoint`` (what is sent).

    ``url=None``: no socket; vehicles talk only to in-process clients
    (``MavlinkEndpoint.inject`` and ``subscribe``). ``lockstep_sysid``: an
    outside controller with this system id is kept in lockstep with the
    simulation (``cosim.mavlink.lockstep``), silent for at most
    ``lockstep_timeout_s``.
    """

    url: str | None = DEFAULT_URL  # None: in-process only (no socket)
    rates_hz: Mapping[str, float] = field(default_factory=dict)
    #: the state rows of the vehicles on MAVLink (None: every vehicle)
    rows: tuple[int, ...] | None = None
    max_peers: int = 16
    max_datagrams_per_exchange: int = 1000
    signing_key_file: str | Path | None = None
    signing_key_env: str | None = None
    signing_link_id: int = 0
    #: where the signing timestamps are shared with other runs using the key
    #: (None: the cache folder, ``cosim.mavlink.signing.default_folder()``)
    signing_state_dir: str | Path | None = None
    #: lockstep with an outside controller of this system id (``cosim.mavlink.lockstep``)
    lockstep_sysid: int | None = None
    lockstep_timeout_s: float = 30.0

    @classmethod
    def of_scenario(cls, section: Mapping[str, Any] | None,
                    ids: Sequence[str]) -> MavlinkConfig | None:
        """The config a scenario's ``mavlink:`` section asks for (None: no
        section); ``ids``: the scenario's vehicle ids, for its ``vehicles``
        patterns."""
        if section is None:
            return None
        return cls(url=section["url"], rates_hz=dict(section["rates_hz"]),
                   rows=mavlink_rows(section, ids))

    @property
    def signing(self) -> bool:
        """Whether MAVLink 2 signing is on (a key source is named)."""
        return self.signing_key_file is not None or self.signing_key_env is not None


def load_signing_key(config: MavlinkConfig) -> bytes | None:
    """The 32-byte signing key from the config's key source (None: signing
    off); ConfigError naming where it looked if it is missing or unusable."""
    problems: list[str] = []
    if not 0 <= config.signing_link_id <= 255:
        problems.append(f"mavlink signing: link id must be 0..255, got "
                        f"{config.signing_link_id!r}")
    if config.signing_key_file is not None and config.signing_key_env is not None:
        problems.append("mavlink signing: give the key in a file or an environment variable, "
                        f"not both (file {str(config.signing_key_file)!r}, "
                        f"variable {config.signing_key_env!r})")
    if problems or not config.signing:
        if problems:
            raise ConfigError(problems)
        return None
    if config.signing_key_file is not None:
        where = f"key file {str(config.signing_key_file)!r}"
        try:
            passphrase = Path(config.signing_key_file).read_text(encoding="ascii").strip()
        except UnicodeDecodeError:
            raise ConfigError(f"mavlink signing: {where} is not ASCII text (MAVProxy's "
                              "'signing key' takes an ASCII passphrase)") from None
        except OSError as e:
            raise ConfigError(f"mavlink signing: cannot read {where}: "
                              f"{e.strerror or e}") from None
        _warn_if_open(Path(config.signing_key_file))
    else:
        name = str(config.signing_key_env)
        where = f"environment variable {name!r}"
        if not name:
            raise ConfigError("mavlink signing: the key's environment variable name is empty")
        value = os.environ.get(name)
        if value is None:
            raise ConfigError(f"mavlink signing: {where} is not set")
        passphrase = value.strip()
    if not passphrase:
        raise ConfigError(f"mavlink signing: {where} holds an empty passphrase")
    if any(c.isspace() for c in passphrase):
        raise ConfigError(f"mavlink signing: the passphrase in {where} contains whitespace; "
                          "it must be one word, as MAVProxy's 'signing key' takes it")
    try:
        return mav.signing_key(passphrase)
    except UnicodeEncodeError:
        raise ConfigError(f"mavlink signing: the passphrase in {where} is not ASCII "
                          "(MAVProxy's 'signing key' takes an ASCII passphrase)") from None


#: key files already warned about, with their mode (each is said once a process)
_warned_open: set[tuple[str, int]] = set()


def _warn_if_open(path: Path) -> None:
    """Warn, as ssh does, when other users may read or change the key file
    (any group or other permission bit); the run goes on, keyed."""
    if os.name != "posix":  # no Unix modes to judge
        return
    try:
        mode = path.stat().st_mode & 0o777
    except OSError:
        return
    if mode & 0o077 and (str(path), mode) not in _warned_open:
        _warned_open.add((str(path), mode))
        log.warning("mavlink signing: key file %s has mode %04o: other users of this machine "
                    "can read or change the passphrase and so command every vehicle; "
                    "make it yours only: chmod 600 %s", path, mode, path)
