"""MAVLink 2 signing state kept between runs, so a signed packet recorded in
one run (from the wire, or from its ``.tlog``) is a replay in every later run.

For each key the file holds the highest signature timestamp seen (accepted
from a ground station or sent by a vehicle) and each stream's last accepted
timestamp (stream: link id, system, component; the ``MAX_STREAMS`` most
recent are kept). A run starts its ``SignatureChecker`` from them: a stream
it has seen must go on from where it stopped, and a new stream must not be
more than a minute behind the newest timestamp (the specification's rule).
Vehicles sign from the same point on, so their own timestamps never go back
either, as ArduPilot keeps its signing timestamp across reboots.

The file is ``<folder>/<key id>.json``; the folder is
``$COSIM_CACHE_DIR/signing`` (default ``~/.cache/cosim/signing``) unless the
run names another (``MavlinkConfig.signing_state_dir``). The key id is a
one-way hash of the key: the file never holds the key or its passphrase.
Writers merge (the maximum of every timestamp) under an exclusive lock and
replace the file atomically, so several links of one run, or runs sharing a
key, agree. An unreadable file is reported and treated as empty.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Any

from cosim.mavlink.adapter import Stream

log = logging.getLogger(__name__)

#: streams remembered per key (the most recent)
MAX_STREAMS = 1024


def default_folder() -> Path:
    """Where signing state is kept unless a run says otherwise."""
    cache = os.environ.get("COSIM_CACHE_DIR") or str(Path.home() / ".cache" / "cosim")
    return Path(cache) / "signing"


def key_id(key: bytes) -> str:
    """A one-way name for a key (its state file's name)."""
    return hashlib.sha256(b"cosim signing state\0" + key).hexdigest()[:16]


class SigningState:
    """The replay-protection state of one key on disk (see the module docstring)."""

    def __init__(self, key: bytes, folder: str | Path | None = None) -> None:
        self.folder = Path(folder) if folder is not None else default_folder()
        self.path = self.folder / f"{key_id(key)}.json"

    def load(self) -> tuple[int, dict[Stream, int]]:
        """(highest timestamp, last timestamp of each stream); empty if none yet."""
        return self._read()

    def save(self, timestamp: int, streams: dict[Stream, int]) -> None:
        """Merge ``timestamp`` and ``streams`` into the file (the maximum of
        each); ``OSError`` naming the file if it cannot be written."""
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            with open(self.path.with_suffix(".lock"), "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                old_ts, old = self._read()
                merged = dict(old)
                for s, t in streams.items():
                    merged[s] = max(t, merged.get(s, 0))
                keep = sorted(merged.items(), key=lambda kv: kv[1], reverse=True)[:MAX_STREAMS]
                doc = {"version": 1, "timestamp": max(old_ts, int(timestamp),
                                                      *(t for _, t in keep)),
                       "streams": [[*s, t] for s, t in keep]}
                tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
                tmp.write_text(json.dumps(doc))
                os.replace(tmp, self.path)
        except OSError as e:
            raise OSError(e.errno, f"cannot write the MAVLink signing state {self.path}: "
                                   f"{e.strerror or e}") from e

    def _read(self) -> tuple[int, dict[Stream, int]]:
        try:
            doc: Any = json.loads(self.path.read_text())
            streams = {(int(a), int(b), int(c)): int(t) for a, b, c, t in doc["streams"]}
            return int(doc["timestamp"]), streams
        except FileNotFoundError:
            return 0, {}
        except (OSError, ValueError, TypeError, KeyError) as e:
            log.warning("mavlink signing: cannot read %s (%s); starting from the wall clock",
                        self.path, e)
            return 0, {}
