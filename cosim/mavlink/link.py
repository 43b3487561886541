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
Peers are remembered (up to ``max_peers``) once they send a valid MAVLink
packet; every outgoing packet goes to every peer.

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
from collections import Counter
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
                 max_datagrams: int = 1000) -> None:
        self.url = url if isinstance(url, LinkUrl) else LinkUrl.parse(url)
        if max_peers < 1 or max_datagrams < 1:
            raise ValueError(f"max_peers and max_datagrams must be >= 1, got {max_peers}, "
                             f"{max_datagrams}")
        self.max_peers = max_peers
        self.max_datagrams = max_datagrams
        self.counts: Counter[str] = Counter({k: 0 for k in (
            "datagrams_in", "datagrams_out", "bytes_in", "bytes_out", "send_errors",
            "recv_errors", "poll_capped", "peers_refused", "kernel_dropped")})
        ip = _resolve(self.url.host)
        self.peers: list[Address] = []
        if self.url.mode == "udpout":
            bind: Address = (_route_source(ip), 0)
            self.peers.append((ip, self.url.port))
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
        return out

    def wait_readable(self, timeout_s: float) -> bool:
        """Block until a datagram is waiting (True) or ``timeout_s`` passes (False)."""
        import select

        r, _, _ = select.select([self._socket()], [], [], max(0.0, timeout_s))
        return bool(r)

    def remember(self, addr: Address) -> None:
        """Answer ``addr`` from now on (it sent a valid MAVLink packet)."""
        if addr in self.peers:
            return
        if len(self.peers) >= self.max_peers:
            self.counts["peers_refused"] += 1
            return
        self.peers.append(addr)
        log.info("mavlink: new peer %s:%d", *addr)

    def send(self, packet: bytes) -> None:
        """Send one packet to every peer (errors are counted, never raised)."""
        sock = self._socket()
        for addr in self.peers:
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

    def remember(self, addr: Address) -> None:
        pass

    def send(self, packet: bytes) -> None:
        pass

    def send_packets(self, blob: bytes, lengths: list[int]) -> None:
        pass

    def update_kernel_drops(self) -> None:
        pass

    def close(self) -> None:
        self._closed = True
