"""Two Ray nodes in two network namespaces joined by a veth pair, ``tc netem``
delaying the packets leaving each end (a LAN's 0.2 ms each way): the ray
backend's calls to the other node's agent cross a real network stack (two
kernels' TCP, a link, a queue) instead of the loopback. The tests of
``tests/fdm_pool/test_ray_netns.py`` and ``benchmarks/ray_efficiency.py
--netns`` use it.

The driver's node (the head) is in namespace ``a`` with no CPU, so it steps
no vehicle itself; the other node in namespace ``b`` has the CPUs, so every
vehicle is behind an agent there: what a remote machine costs. The driver
runs in ``a`` (``command`` prefixes a command with ``ip netns exec``).

Needs root and iproute2 (``ip``, ``tc``): ``unavailable()`` says why not.
Addresses only inside the two namespaces made here (a private /30). Names
carry this process's id, so two runs at once do not collide; the
namespaces of an earlier run whose process is gone (it crashed) are removed
first, with whatever still runs in them. Everything is removed on ``stop``,
whatever happened before. A kernel without netem (``CONFIG_NET_SCH_NETEM``,
as on the 2-core test machine) gets a TUN device in each namespace instead
of the veth pair, and a relay process between them holding each packet
``delay_ms`` before passing it on (``link`` says which; the relay's own
time comes on top, as ``connect_ms`` measures; its MTU is 64 KiB, the
segments a NIC's TCP offloads hand the kernel, so the relay handles a few
packets a Ray call, not hundreds).

    python -m tests.ray_netns relay NS_A NS_B DEV_A DEV_B DELAY_MS   # the relay

The relay runs at the lowest real-time priority (a link does not wait for a
core; on a loaded machine it would), and SIGUSR2 / SIGUSR1 turn its delay
off and on again (``set_delay``, as ``tc qdisc change`` does for netem).
"""

from __future__ import annotations

import ctypes
import fcntl
import heapq
import itertools
import os
import re
import select
import shutil
import signal
import struct
import subprocess
import sys
import time

from tests.ray_cluster import LocalRayCluster

#: every namespace made here is named PREFIX<pid>-<n><a|b>
PREFIX = "cosimray"
_SEQ = itertools.count()


def _tool(name: str) -> str | None:
    return shutil.which(name) or next(
        (p for p in (f"/usr/sbin/{name}", f"/sbin/{name}") if os.access(p, os.X_OK)), None)


def unavailable() -> str | None:
    """Why namespaces cannot be made here (not root, no ``ip`` or ``tc``), or None."""
    if sys.platform != "linux":
        return "network namespaces are Linux's"
    if os.geteuid() != 0:
        return "making network namespaces needs root"
    missing = [t for t in ("ip", "tc") if _tool(t) is None]
    if missing:
        return f"{' and '.join(missing)} not found (iproute2: apt-get install iproute2)"
    return None


def _run(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    tool = _tool(args[0]) or args[0]
    r = subprocess.run([tool, *args[1:]], capture_output=True, text=True, timeout=30)
    if check and r.returncode:
        raise RuntimeError(f"{' '.join(args)}: {r.stderr.strip() or r.stdout.strip()}")
    return r


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove(ns: str) -> None:
    """Kill what runs in ``ns`` and delete it (its veth end goes with it)."""
    for line in _run("ip", "netns", "pids", ns, check=False).stdout.split():
        try:
            os.kill(int(line), signal.SIGKILL)
        except (ValueError, ProcessLookupError):
            pass
    _run("ip", "netns", "del", ns, check=False)


def remove_stale() -> list[str]:
    """Remove the namespaces of earlier runs whose process is gone; their names."""
    gone = []
    for line in _run("ip", "netns", "list", check=False).stdout.splitlines():
        m = re.match(rf"({PREFIX}(\d+)-\d+[ab])\b", line)
        if m and not _alive(int(m.group(2))):
            _remove(m.group(1))
            gone.append(m.group(1))
    return gone


class NetnsPair:
    """Namespaces ``a`` and ``b`` joined by a veth pair, addresses ``ips`` (a
    /30), each end's packets delayed ``delay_ms`` by netem (by the relay
    where the kernel has no netem, or when told: ``relay``)."""

    def __init__(self, delay_ms: float = 0.2, relay: bool = False) -> None:
        pid, k = os.getpid(), next(_SEQ)
        self.ns = (f"{PREFIX}{pid}-{k}a", f"{PREFIX}{pid}-{k}b")
        self.dev = (f"crv{pid % 10**7}{k % 10}a", f"crv{pid % 10**7}{k % 10}b")  # <= 15 chars
        x = (pid * 7 + k) % 64 * 4  # a /30 of 10.231.<0..255>.<x>
        net = f"10.231.{pid % 256}"
        self.ips = (f"{net}.{x + 1}", f"{net}.{x + 2}")
        self.delay_ms = float(delay_ms)
        #: "veth" (netem delays each end) or "tun" (a relay process delays)
        self.link = "veth"
        self._use_relay = relay  # the relay even where netem is (to measure it)
        self._relay: subprocess.Popen[str] | None = None

    def command(self, side: int, *argv: str) -> list[str]:
        """``argv`` run in namespace ``a`` (0) or ``b`` (1)."""
        return [_tool("ip") or "ip", "netns", "exec", self.ns[side], *argv]

    def start(self) -> NetnsPair:
        why = unavailable()
        if why:
            raise RuntimeError(why)
        remove_stale()
        try:
            for ns in self.ns:
                _run("ip", "netns", "add", ns)
                _run("ip", "-n", ns, "link", "set", "lo", "up")
            _run("ip", "link", "add", self.dev[0], "netns", self.ns[0], "type", "veth",
                 "peer", "name", self.dev[1], "netns", self.ns[1])
            if self._use_relay or (self.delay_ms > 0 and not self._netem()):  # a relay instead
                _run("ip", "-n", self.ns[0], "link", "del", self.dev[0])
                self._start_relay()
            for ns, dev, ip in zip(self.ns, self.dev, self.ips):
                _run("ip", "-n", ns, "addr", "add", f"{ip}/30", "dev", dev)
                _run("ip", "-n", ns, "link", "set", dev, "up")
        except BaseException:
            self.stop()
            raise
        return self

    def _netem(self) -> bool:
        """netem's delay on each end; False where the kernel has no netem."""
        for ns, dev in zip(self.ns, self.dev):
            r = _run("tc", "-n", ns, "qdisc", "add", "dev", dev, "root", "netem", "delay",
                     f"{self.delay_ms:g}ms", check=False)
            if r.returncode:
                if "unknown" in r.stderr.lower():  # the kernel was built without it
                    return False
                raise RuntimeError(f"tc netem on {dev} in {ns}: {r.stderr.strip()}")
        return True

    def _start_relay(self) -> None:
        self.link = "tun"
        self._relay = subprocess.Popen(
            [sys.executable, "-m", "tests.ray_netns", "relay", *self.ns, *self.dev,
             f"{self.delay_ms:g}"], stdout=subprocess.PIPE, text=True,
            cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        assert self._relay.stdout is not None
        if self._relay.stdout.readline().strip() != "ready":
            raise RuntimeError(f"the delay relay did not start (exit {self._relay.wait(10)})")
        for ns, dev in zip(self.ns, self.dev):
            _run("ip", "-n", ns, "link", "set", dev, "mtu", str(_TUN_MTU))

    def connect_ms(self, tries: int = 20) -> float:
        """The median time of a TCP connection attempt from ``a`` to a port of
        ``b`` where nothing listens (a SYN out, a RST back: one round trip)."""
        code = ("import socket,statistics,time\nt=[]\n"
                f"for _ in range({tries}):\n"
                "    s=socket.socket();t0=time.perf_counter()\n"
                f"    try: s.connect(({self.ips[1]!r},9))\n"
                "    except ConnectionRefusedError: t.append(time.perf_counter()-t0)\n"
                "    s.close()\n"
                "print(statistics.median(t)*1e3)")
        r = subprocess.run(self.command(0, sys.executable, "-c", code), capture_output=True,
                           text=True, timeout=60)
        if r.returncode:
            raise RuntimeError(f"the round trip from {self.ns[0]} to {self.ns[1]}: {r.stderr}")
        return float(r.stdout.strip())

    def describe(self) -> dict[str, object]:
        """What ``set_delay`` needs, as JSON (for a driver in another process)."""
        return {"ns": self.ns, "dev": self.dev, "link": self.link, "delay_ms": self.delay_ms,
                "relay_pid": None if self._relay is None else self._relay.pid}

    def stop(self) -> None:
        if self._relay is not None:  # its TUN devices go with it
            self._relay.kill()
            self._relay.wait(10)
        for ns in self.ns:
            _remove(ns)


def set_delay(link: dict[str, object], on: bool) -> None:
    """The link ``NetnsPair.describe`` describes delays by its ``delay_ms``
    (``on``) or not at all, from now on."""
    pid = link["relay_pid"]
    if isinstance(pid, int):
        os.kill(pid, signal.SIGUSR1 if on else signal.SIGUSR2)
        return
    ms = float(link["delay_ms"]) if on else 0.0  # type: ignore[arg-type]
    for ns, dev in zip(link["ns"], link["dev"]):  # type: ignore[call-overload]
        _run("tc", "-n", ns, "qdisc", "change", "dev", dev, "root", "netem", "delay", f"{ms:g}ms")


class NetnsRayCluster(LocalRayCluster):
    """A Ray cluster across a ``NetnsPair``: the head in ``a`` with no CPU,
    one node in ``b`` with ``cpus``."""

    def __init__(self, pair: NetnsPair, cpus: int = 2) -> None:
        super().__init__(nodes=2, cpus_per_node=cpus)
        self.pair = pair
        self.address = f"{pair.ips[0]}:{self.port}"

    def _where(self, node: int) -> tuple[list[str], str, int]:
        side = min(node, 1)
        return self.pair.command(side), self.pair.ips[side], 0 if side == 0 else self.cpus

    def driver_env(self) -> dict[str, str]:
        """The environment of a driver joining this cluster from ``a``."""
        return {**self.env, "RAY_ADDRESS": self.address}


_TUN_MTU = 65535
_CLONE_NEWNET = 0x40000000
_TUNSETIFF = 0x400454CA
_IFF_TUN, _IFF_NO_PI = 0x0001, 0x1000
_PR_SET_TIMERSLACK = 29
_SPIN_S = 100e-6


def _tun(ns: str, dev: str) -> int:
    """A TUN device ``dev`` made in namespace ``ns`` (by entering it); its fd."""
    libc = ctypes.CDLL(None, use_errno=True)
    with open(f"/run/netns/{ns}") as f:
        if libc.setns(f.fileno(), _CLONE_NEWNET) != 0:
            raise OSError(ctypes.get_errno(), f"setns {ns}")
    fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
    fcntl.ioctl(fd, _TUNSETIFF, struct.pack("16sH22x", dev.encode(), _IFF_TUN | _IFF_NO_PI))
    return fd


def relay(ns_a: str, ns_b: str, dev_a: str, dev_b: str, delay_ms: float) -> None:
    """Pass each packet between the TUN devices of two namespaces ``delay_ms``
    after it came (one thread, a deadline heap per the whole link)."""
    fds = (_tun(ns_a, dev_a), _tun(ns_b, dev_b))
    other = {fds[0]: fds[1], fds[1]: fds[0]}
    delay_s = [delay_ms / 1e3]
    signal.signal(signal.SIGUSR1, lambda *_: delay_s.__setitem__(0, delay_ms / 1e3))
    signal.signal(signal.SIGUSR2, lambda *_: delay_s.__setitem__(0, 0.0))
    due: list[tuple[float, int, int, bytes]] = []  # (when, order, to fd, packet)
    order = itertools.count()
    ctypes.CDLL(None).prctl(_PR_SET_TIMERSLACK, 1)  # woken on time, not 50 us late
    try:  # a link is not a process that waits for a core: first when a packet is due
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except OSError:
        pass
    print("ready", flush=True)
    while True:
        # woken a little early, then spinning to the packet's time: a wake-up
        # is late by up to ~0.1 ms on a loaded machine
        wait_s = max(0.0, due[0][0] - time.perf_counter() - _SPIN_S) if due else None
        ready, _, _ = select.select(fds, (), (), wait_s)
        while not ready and due and time.perf_counter() < due[0][0]:
            pass
        now = time.perf_counter()
        for fd in ready:
            while True:
                try:
                    packet = os.read(fd, _TUN_MTU + 64)
                except BlockingIOError:
                    break
                heapq.heappush(due, (now + delay_s[0], next(order), other[fd], packet))
        now = time.perf_counter()
        while due and due[0][0] <= now:
            _, _, fd, packet = heapq.heappop(due)
            try:
                os.write(fd, packet)
            except OSError:  # the other end's queue full or gone: dropped, as a link does
                pass


if __name__ == "__main__" and sys.argv[1:2] == ["relay"]:
    _ns_a, _ns_b, _dev_a, _dev_b, _delay = sys.argv[2:7]
    relay(_ns_a, _ns_b, _dev_a, _dev_b, float(_delay))
