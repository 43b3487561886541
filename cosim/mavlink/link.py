"""One non-blocking UDP socket carrying every vehicle's MAVLink traffic.

URLs follow pymavlink:

- ``udpout:HOST:PORT`` (default ``udpout:127.0.0.1:14550``, where ground
  stations listen): send to HOST:PORT from an ephemeral local port, and also
  answer whoever talks to us.
- ``udpin:HOST:PORT`` (``udp:`` is an alias): listen on HOST:PORT and answer
  whoever talks to us.

The socket binds to loopback unless the user names another address: for
``udpin`` the named HOST is the bind address; for ``udpout`` to a remote
host, the local address the OS routes to that host (never all interfaces).

There is no thread: ``poll()`` is called once per exchange and returns the
datagrams waiting, at most ``max_datagrams`` of them, so a flood cannot stall
the simulation (the rest wait in the kernel buffer or are dropped by it).

Peers (``PeerTable``): the addresses telemetry goes to. The ``udpout``
target always is one; any other address becomes one when it sends a valid
MAVLink packet (with signing on, a correctly signed one: the endpoint only
reports those), up to ``max_peers``. A peer quiet for ``PEER_TIMEOUT_S``
expires. When the table is full, a newcomer takes the place of the peer
quiet longest among those that are not live, and is refused if every peer
is live; live means heard within ``PEER_LIVE_S`` after sending at least
two packets (a ground station's heartbeats), so a flood of one-packet
senders, even from ever new addresses, never displaces a station, and a
station arriving during such a flood gets in at its second packet (packet
counts of recent senders are remembered, ``RECENT_SENDERS`` of them).
Answers to a message (acknowledgements, parameters, mission items) also go
to the address it came from, peer or not.

The receive buffer is enlarged (``RCVBUF_BYTES``, as far as the OS allows)
so a burst between two exchanges is not lost; what the kernel drops anyway
when it is full (a flood) is counted as ``kernel_dropped`` (Linux, from
``/proc/net/udp``): a ground station's command lost that way is retried by
the station, as over any lossy link.
"""

from __future__ import annotations

import errno
import ipaddress
import logging
import os
import socket
import time
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

from cosim.errors import ConfigError
from cosim.mavlink.errors import LinkError

log = logging.getLogger(__name__)

DEFAULT_URL = "udpout:127.0.0.1:14550"
Address = tuple[str, int]
_MODES = {"udpout": "udpout", "udpin": "udpin", "udp": "udpin"}
#: receive buffer asked for (Linux caps it at net.core.rmem_max)
RCVBUF_BYTES = 4 << 20
#: telemetry packets are packed into datagrams up to this size (below the
#: common 1500-byte Ethernet MTU, so nothing is fragmented on a real network)
MAX_DATAGRAM_BYTES = 1400
#: a peer quiet this long (wall clock) expires; ground stations heartbeat at 1 Hz
PEER_TIMEOUT_S = 10.0
#: a peer heard within this long, after two packets or more, cannot be displaced
PEER_LIVE_S = 3.0
#: senders whose packet counts are remembered (so a station's second packet
#: makes it live even if a flood pushed it out of the table meanwhile)
RECENT_SENDERS = 8192


@dataclass
class _Peer:
    last_s: float
    packets: int
    permanent: bool = False


class PeerTable:
    """The addresses telemetry goes to (see the module docstring)."""

    def __init__(self, max_peers: int, counts: Counter[str],
                 clock: Callable[[], float] = time.monotonic,
                 timeout_s: float = PEER_TIMEOUT_S, live_s: float = PEER_LIVE_S) -> None:
        self.max_peers = max_peers
        self.counts = counts
        self.clock = clock
        self.timeout_s = timeout_s
        self.live_s = live_s
        self._peers: dict[Address, _Peer] = {}
        self._recent: OrderedDict[Address, int] = OrderedDict()  # sender -> packets

    @property
    def addresses(self) -> list[Address]:
        return list(self._peers)

    def add_permanent(self, addr: Address) -> None:
        self._peers[addr] = _Peer(self.clock(), 2, permanent=True)

    def expire(self) -> None:
        """Drop peers quiet for longer than ``timeout_s``."""
        now = self.clock()
        for addr in [a for a, p in self._peers.items()
                     if not p.permanent and now - p.last_s > self.timeout_s]:
            del self._peers[addr]
            self.counts["peers_expired"] += 1
            log.info("mavlink: peer %s:%d expired", *addr)

    def _live(self, p: _Peer, now: float) -> bool:
        return p.permanent or (p.packets >= 2 and now - p.last_s <= self.live_s)

    def seen(self, addr: Address, packets: int = 1) -> None:
        """``addr`` sent ``packets`` valid packets just now."""
        now = self.clock()
        count = self._recent.pop(addr, 0) + packets
        self._recent[addr] = count
        if len(self._recent) > RECENT_SENDERS:
            self._recent.popitem(last=False)
        peer = self._peers.get(addr)
        if peer is not None:
            peer.last_s, peer.packets = now, max(peer.packets, count)
            return
        self.expire()
        if len(self._peers) >= self.max_peers:
            idle = [(p.last_s, a) for a, p in self._peers.items() if not self._live(p, now)]
            if not idle:
                self.counts["peers_refused"] += 1
                return
            del self._peers[min(idle)[1]]
            self.counts["peers_displaced"] += 1
        self._peers[addr] = _Peer(now, count)
        log.info("mavlink: new peer %s:%d", *addr)


@dataclass(frozen=True)
class LinkUrl:
    mode: str  # "udpout" or "udpin"
    host: str
    port: int

    @classmethod
    def parse(cls, url: str) -> LinkUrl:
        """Parse ``udpout:HOST:PORT`` / ``udpin:HOST:PORT``; ConfigError otherwise."""
        usage = (f"mavlink URL {url!r}: expected udpout:HOST:PORT (send to a ground station) "
                 f"or udpin:HOST:PORT (listen), e.g. {DEFAULT_URL}")
        parts = url.strip().split(":")
        if len(parts) != 3 or parts[0].lower() not in _MODES or not parts[1]:
            raise ConfigError(usage)
        try:
            port = int(parts[2])
        except ValueError:
            raise ConfigError(f"{usage}; port {parts[2]!r} is not a number") from None
        mode = _MODES[parts[0].lower()]
        if not 0 <= port <= 65535 or (mode == "udpout" and port == 0):
            raise ConfigError(f"{usage}; port {port} out of range")
        return cls(mode, parts[1], port)

    def __str__(self) -> str:
        return f"{self.mode}:{self.host}:{self.port}"


def _resolve(host: str) -> str:
    try:
        return str(socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_DGRAM)[0][4][0])
    except socket.gaierror as e:
        raise ConfigError(f"mavlink: cannot resolve host {host!r}: {e}") from None


def _route_source(ip: str) -> str:
    """The local address the OS would send from to reach ``ip``."""
    if ipaddress.ip_address(ip).is_loopback:
        return "127.0.0.1"
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.connect((ip, 9))  # UDP connect sends nothing; it only picks a route
        return str(probe.getsockname()[0])
    except OSError as e:
        raise LinkError(f"mavlink: no route to {ip}: {e}") from None
    finally:
        probe.close()


class UdpLink:
    """The shared MAVLink socket (see the module docstring)."""

    def __init__(self, url: str | LinkUrl = DEFAULT_URL, max_peers: int = 16,
                 max_datagrams: int = 1000, clock: Callable[[], float] = time.monotonic
                 ) -> None:
        self.url = url if isinstance(url, LinkUrl) else LinkUrl.parse(url)
        if max_peers < 1 or max_datagrams < 1:
            raise ValueError(f"max_peers and max_datagrams must be >= 1, got {max_peers}, "
                             f"{max_datagrams}")
        self.max_peers = max_peers
        self.max_datagrams = max_datagrams
        self.counts: Counter[str] = Counter({k: 0 for k in (
            "datagrams_in", "datagrams_out", "bytes_in", "bytes_out", "send_errors",
            "recv_errors", "poll_capped", "peers_refused", "peers_expired", "peers_displaced",
            "kernel_dropped")})
        ip = _resolve(self.url.host)
        self.table = PeerTable(max_peers, self.counts, clock)
        if self.url.mode == "udpout":
            bind: Address = (_route_source(ip), 0)
            self.table.add_permanent((ip, self.url.port))
        else:
            bind = (ip, self.url.port)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setblocking(False)
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF_BYTES)
            except OSError:  # keep the default buffer
                pass
            sock.bind(bind)
        except OSError as e:
            sock.close()
            hint = " (another program or simulation uses it; pick another port)" \
                if e.errno == errno.EADDRINUSE else ""
            raise LinkError(f"mavlink {self.url}: cannot bind {bind[0]}:{bind[1]}: "
                            f"{e.strerror or e}{hint}") from None
        self._sock: socket.socket | None = sock
        self.local_address: Address = sock.getsockname()
        log.info("mavlink %s on %s:%d", self.url, *self.local_address)

    @property
    def closed(self) -> bool:
        return self._sock is None

    @property
    def peers(self) -> list[Address]:
        """The addresses telemetry goes to now."""
        return self.table.addresses

    @property
    def loopback(self) -> bool:
        """Whether the socket is bound to a loopback address (reachable from
        this machine only)."""
        return ipaddress.ip_address(self.local_address[0]).is_loopback

    def _socket(self) -> socket.socket:
        if self._sock is None:
            raise LinkError(f"mavlink {self.url}: the link is closed")
        return self._sock

    def poll(self) -> list[tuple[bytes, Address]]:
        """The datagrams waiting now (at most ``max_datagrams``); never blocks."""
        sock = self._socket()
        out: list[tuple[bytes, Address]] = []
        for _ in range(self.max_datagrams):
            try:
                data, addr = sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # e.g. ICMP errors surfacing on some platforms
                self.counts["recv_errors"] += 1
                continue
            out.append((data, (str(addr[0]), int(addr[1]))))
            self.counts["bytes_in"] += len(data)
        else:
            self.counts["poll_capped"] += 1
        self.counts["datagrams_in"] += len(out)
        self.table.expire()
        return out

    def wait_readable(self, timeout_s: float) -> bool:
        """Block until a datagram is waiting (True) or ``timeout_s`` passes (False)."""
        import select

        r, _, _ = select.select([self._socket()], [], [], max(0.0, timeout_s))
        return bool(r)

    def remember(self, addr: Address, packets: int = 1) -> None:
        """``addr`` sent ``packets`` valid MAVLink packets (``PeerTable.seen``)."""
        self.table.seen(addr, packets)

    def send(self, packet: bytes, also: Address | None = None) -> None:
        """Send one packet to every peer, and to ``also`` (the sender of the
        message it answers) if that is not a peer; errors are counted, never
        raised."""
        sock = self._socket()
        peers = self.table.addresses
        if also is not None and also not in peers:
            peers.append(also)
        for addr in peers:
            try:
                sock.sendto(packet, addr)
                self.counts["datagrams_out"] += 1
                self.counts["bytes_out"] += len(packet)
            except OSError:  # buffer full, unreachable: UDP is lossy anyway
                self.counts["send_errors"] += 1

    def update_kernel_drops(self) -> None:
        """Refresh ``counts["kernel_dropped"]``: datagrams the OS dropped because
        the receive buffer was full (Linux; elsewhere it stays 0)."""
        if self._sock is None:
            return
        try:
            inode = str(os.fstat(self._sock.fileno()).st_ino)
            with open("/proc/net/udp") as f:
                for line in f:
                    cols = line.split()
                    if len(cols) > 12 and cols[9] == inode:
                        self.counts["kernel_dropped"] = int(cols[-1])
                        return
        except (OSError, ValueError):
            pass

    def send_packets(self, blob: bytes, lengths: list[int]) -> None:
        """Send consecutive packets (``blob``, each ``lengths[i]`` long), several
        per datagram up to ``MAX_DATAGRAM_BYTES`` (ground stations parse every
        packet of a datagram), never splitting a packet."""
        start = end = 0
        for n in lengths:
            if end - start + n > MAX_DATAGRAM_BYTES and end > start:
                self.send(blob[start:end])
                start = end
            end += n
        if end > start:
            self.send(blob[start:end])

    def close(self) -> None:
        """Close the socket (safe to call twice)."""
        if self._sock is not None:
            self.update_kernel_drops()
            self._sock.close()
            self._sock = None


class NullLink:
    """No socket: in-process MAVLink only (``MavlinkConfig(url=None)``); what
    vehicles send reaches only the endpoint's subscribers and the tlogs."""

    url = None
    local_address: Address = ("", 0)
    loopback = True

    def __init__(self) -> None:
        self.peers: list[Address] = []
        self.counts: Counter[str] = Counter()
        self._closed = False

    @property
    def closed(self) -> bool:
        return self._closed

    def poll(self) -> list[tuple[bytes, Address]]:
        return []

    def wait_readable(self, timeout_s: float) -> bool:
        return False

    def remember(self, addr: Address, packets: int = 1) -> None:
        pass

    def send(self, packet: bytes, also: Address | None = None) -> None:
        pass

    def send_packets(self, blob: bytes, lengths: list[int]) -> None:
        pass

    def update_kernel_drops(self) -> None:
        pass

    def close(self) -> None:
        self._closed = True
