"""MAVLink 2 signing state shared by every link of a run and by every run
using the same key, so a signed packet accepted anywhere (from the wire, or
read from a ``.tlog``) is a replay everywhere else: on another link of the
run, in a run going on at the same time, in every later run.

For each key a file holds the highest signature timestamp seen (accepted
from a ground station or sent by a vehicle), each stream's last accepted
timestamp (stream: link id, system, component; the ``MAX_STREAMS`` most
recent are kept) and the streams the vehicles sign with (with their last
saved timestamps). ``SharedSigning`` is one key's state in a process:

- a received packet whose signature is correct is judged first against
  what the process knows (``SignatureChecker.admit``: a vehicle's own
  stream, a replay, a stream more than a minute behind); one that would be
  accepted is judged again under the file's exclusive lock, after merging
  the file (what other runs accepted meanwhile), and the file is rewritten
  with it before the lock is released. One lock and one write per batch of
  packets (an exchange's datagrams), none when nothing new arrives; the file
  is read only when another process wrote it since (a token in the lock
  file says so): tens of microseconds per packet accepted, with 240 vehicles;
- the vehicles' own timestamps, which advance with every packet they send,
  are saved at most once a second (``save_sent``) and at close: a later
  run signs from above them, as ArduPilot keeps its signing timestamp
  across reboots;
- a packet on a vehicle stream (of this run or of another run using the
  key: our own packet sent back) is never accepted (``SIG_OWN``).

The links of a run share one ``SharedSigning`` (``MavlinkLinks`` makes it),
so what one accepts the others know without reading the file; runs share
the file. If the file cannot be written when a run starts, the run stops
with ``SigningStateError`` (replay protection needs it); if it fails later,
the run goes on with what the process knows, said once in the log.

The file is ``<folder>/<key id>.json``; the folder is
``signing/`` in the cache folder (``cosim.core.cache``: ``$COSIM_CACHE_DIR``,
else ``$XDG_CACHE_HOME/cosim``, else ``~/.cache/cosim``) unless the
run names another (``MavlinkConfig.signing_state_dir``). The key id is a
one-way hash of the key: the file never holds the key or its passphrase.
Readers and writers hold the lock (``<key id>.lock``). An unreadable file
(or one over ``MAX_FILE_BYTES``) is reported and treated as empty: the
one-minute window for new streams still refuses anything older.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import logging
import os
import threading
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

from cosim.core.cache import cache_folder
from cosim.mavlink import adapter as mav
from cosim.mavlink.adapter import Stream
from cosim.mavlink.errors import MavlinkError

log = logging.getLogger(__name__)

#: streams remembered per key (the most recent), and vehicle streams
MAX_STREAMS = 1024
#: a state file larger than this is not read (it holds about 70 kB at most)
MAX_FILE_BYTES = 1 << 20
#: the lock file's token (see ``SigningState``)
TOKEN_BYTES = 16


class SigningStateError(MavlinkError):
    """The signing state cannot be kept (its folder is not writable)."""


def default_folder() -> Path:
    """Where signing state is kept unless a run says otherwise: ``signing/`` in
    the cache folder (``cosim.core.cache``)."""
    return cache_folder("signing")


def key_id(key: bytes) -> str:
    """A one-way name for a key (its state file's name)."""
    return hashlib.sha256(b"cosim signing state\0" + key).hexdigest()[:16]


class StateDoc(NamedTuple):
    """What the file holds."""

    timestamp: int
    streams: dict[Stream, int]
    vehicles: dict[Stream, int]


def _merged(a: Mapping[Stream, int], b: Mapping[Stream, int]) -> dict[Stream, int]:
    """The maximum of each stream's timestamp, the ``MAX_STREAMS`` most recent."""
    out = dict(a)
    for s, t in b.items():
        out[s] = max(t, out.get(s, 0))
    if len(out) > MAX_STREAMS:
        out = dict(sorted(out.items(), key=lambda kv: kv[1], reverse=True)[:MAX_STREAMS])
    return out


def _rows(streams: Mapping[Stream, int]) -> list[list[int]]:
    return [[*s, t] for s, t in streams.items()]


def _streams(rows: Any) -> dict[Stream, int]:
    return {(int(a), int(b), int(c)): int(t) for a, b, c, t in rows}


class SigningState:
    """The replay-protection file of one key (see the module docstring), and
    its lock file, which also holds a token that every write changes: a
    process that finds the token it wrote or read last knows the file as it
    is without reading it."""

    def __init__(self, key: bytes, folder: str | Path | None = None) -> None:
        self.folder = Path(folder) if folder is not None else default_folder()
        self.path = self.folder / f"{key_id(key)}.json"
        self.lock_path = self.path.with_suffix(".lock")

    @contextmanager
    def locked(self) -> Iterator[int]:
        """Hold the exclusive lock (between processes); yields the lock file's
        descriptor, for ``token`` and ``new_token``."""
        self.folder.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            yield fd
        finally:
            os.close(fd)  # releases the lock

    @staticmethod
    def token(fd: int) -> bytes:
        """The token of the file's last write (empty: unknown, read the file)."""
        return os.pread(fd, TOKEN_BYTES, 0)

    @staticmethod
    def new_token(fd: int) -> bytes:
        """A new token, written before the file (a crash between leaves
        readers reading the file, never trusting a stale copy)."""
        token = os.urandom(TOKEN_BYTES)
        os.pwrite(fd, token, 0)
        return token

    def read(self) -> StateDoc:
        """What the file holds (empty if there is none yet or it is unreadable)."""
        try:
            with open(self.path, "rb") as f:
                data = f.read(MAX_FILE_BYTES + 1)
            if len(data) > MAX_FILE_BYTES:
                raise ValueError(f"larger than {MAX_FILE_BYTES} bytes")
            doc: Any = json.loads(data)
            return StateDoc(int(doc["timestamp"]), _streams(doc["streams"]),
                            _streams(doc.get("vehicles", [])))
        except FileNotFoundError:
            return StateDoc(0, {}, {})
        except (OSError, ValueError, TypeError, KeyError) as e:
            log.warning("mavlink signing: cannot read %s (%s); starting from the wall clock",
                        self.path, e)
            return StateDoc(0, {}, {})

    def write(self, timestamp: int, streams: Mapping[Stream, int], vehicles_json: str) -> None:
        """Rewrite the file in place (the caller holds the lock, as every
        reader does: a rename costs a millisecond on some file systems, for
        every packet accepted). A write cut short by a crash leaves a file
        that does not parse: read as empty, which still refuses every packet
        more than a minute old. ``vehicles_json``: the vehicle streams as
        ``_rows`` in JSON (kept encoded by the caller: they change once a
        second, the streams with every packet)."""
        top = max(timestamp, *streams.values(), 0)
        rows = json.dumps(_rows(streams), separators=(",", ":"))
        data = (f'{{"version":1,"timestamp":{top},"streams":{rows},'
                f'"vehicles":{vehicles_json}}}').encode()
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT, 0o644)
        try:
            os.pwrite(fd, data, 0)
            os.ftruncate(fd, len(data))
        finally:
            os.close(fd)


class SharedSigning:
    """One key's replay protection in this process, kept in step with the
    file (see the module docstring). Safe to use from several threads."""

    def __init__(self, key: bytes, folder: str | Path | None = None) -> None:
        self.state = SigningState(key, folder)
        self.checker = mav.SignatureChecker(key)
        self._lock = threading.Lock()
        self._sent: dict[Stream, int] = {}  # the vehicles' timestamps, saved or not
        self._vehicles: dict[Stream, int] = {}  # every run's, as last read or written
        self._vehicles_json: str | None = None  # ``_vehicles`` encoded (None: to do)
        self._unsaved = True  # something the file does not hold yet
        self._token: bytes | None = None  # the file's token as last read or written
        self._failing = False  # the file could not be written (said once)
        try:
            with self._lock:
                self._sync([])
        except OSError as e:
            raise SigningStateError(
                f"mavlink signing: cannot write the signing state {self.state.path} "
                f"({e.strerror or e}); replay protection keeps it between runs: make "
                f"the folder writable or set COSIM_CACHE_DIR to one that is") from None

    def add_own(self, streams: Iterable[Stream]) -> int:
        """Streams this process's vehicles sign with (never accepted from the
        network; other runs using the key learn them at once); the timestamp
        they start from."""
        with self._lock:
            now = self.checker.local_timestamp()
            for s in streams:
                self.checker.own.add(s)
                self._sent[s] = max(self._sent.get(s, 0), now)
            self._unsaved = True
            self._try_sync()
            return now

    def authenticate(self, raws: Sequence[bytes]) -> list[str]:
        """The verdict on each received packet (``SignatureChecker`` verdicts),
        in order; those accepted are remembered here and in the file."""
        chk = self.checker
        checked = [chk.verify(raw) for raw in raws]
        verdicts = [v for v, _, _ in checked]
        with self._lock:
            todo = [i for i, (v, s, t) in enumerate(checked) if v == mav.SIG_OK]
            for i in todo:  # what this process knows is final unless it says ok
                verdicts[i] = chk.admit(checked[i][1], checked[i][2], remember=False)
            todo = [i for i in todo if verdicts[i] == mav.SIG_OK]
            if todo:
                judged = self._try_sync([checked[i][1:] for i in todo])
                if judged is None:  # the file failed: what this process knows
                    judged = [chk.admit(*checked[i][1:]) for i in todo]
                for i, v in zip(todo, judged):
                    verdicts[i] = v
        return verdicts

    def save_sent(self, sent: Mapping[Stream, int]) -> None:
        """The vehicles' latest signature timestamps, written to the file if
        they moved (the caller batches: once a second and at close)."""
        with self._lock:
            for s, t in sent.items():
                if t > self._sent.get(s, 0):
                    self._sent[s] = t
                    self._unsaved = True
            self.checker.timestamp = max(self.checker.timestamp, *sent.values(), 0)
            if self._unsaved:
                self._try_sync()

    def _try_sync(self, admit: Sequence[tuple[Stream, int]] = ()) -> list[str] | None:
        """``_sync``, or None if the file failed (said once, the run goes on)."""
        try:
            return self._sync(admit)
        except OSError as e:
            self._report(e)
            return None

    def _sync(self, admit: Sequence[tuple[Stream, int]]) -> list[str]:
        """Under the file's lock: merge the file if another process wrote it,
        admit ``admit`` in order, write back if anything changed; their
        verdicts (the caller holds ``_lock``)."""
        chk, state = self.checker, self.state
        with state.locked() as fd:
            token = state.token(fd)
            if token != self._token:
                doc = state.read()
                chk.merge(doc.timestamp, doc.streams)
                chk.own.update(doc.vehicles)
                self._vehicles = _merged(doc.vehicles, self._sent)
                self._vehicles_json = None
                self._token = token
            verdicts = [chk.admit(s, t) for s, t in admit]
            if mav.SIG_OK in verdicts or self._unsaved:
                if self._unsaved:
                    self._vehicles = _merged(self._vehicles, self._sent)
                    self._vehicles_json = None
                if self._vehicles_json is None:
                    self._vehicles_json = json.dumps(_rows(self._vehicles),
                                                     separators=(",", ":"))
                if len(chk.last_timestamp) > MAX_STREAMS:  # memory bounded as the file is
                    chk.last_timestamp = _merged({}, chk.last_timestamp)
                self._token = state.new_token(fd)
                state.write(chk.timestamp, chk.last_timestamp, self._vehicles_json)
                self._unsaved = False
        if self._failing:
            self._failing = False
            log.warning("mavlink signing: %s is written again", state.path)
        return verdicts

    def _report(self, e: OSError) -> None:
        if not self._failing:
            self._failing = True
            log.error("mavlink signing: cannot update %s (%s); replays of packets "
                      "accepted by other runs using this key are not refused until it "
                      "can be written again", self.state.path, e.strerror or e)

    def close(self) -> None:
        """Write what is not yet written (safe to call twice)."""
        self.save_sent({})
