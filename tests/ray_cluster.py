"""A Ray cluster of several nodes on this machine, as a real one is started
(``ray start --head``, then ``ray start --address`` per other node), for the
ray backend's tests: loopback addresses, token authentication on, one CPU
per node, every node's processes in a session of their own so the cluster is
stopped without touching any other Ray on the machine."""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: the nodes' address: loopback (Ray turns 127.0.0.1 itself into the machine's
#: routable address on Linux, but keeps any other address of the loopback net)
NODE_IP = "127.0.0.2"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class LocalRayCluster:
    def __init__(self, nodes: int = 2, cpus_per_node: int = 1) -> None:
        self.nodes = nodes
        self.cpus = cpus_per_node
        self.port = _free_port()
        self.address = f"{NODE_IP}:{self.port}"
        # short: Ray's socket paths must fit in 107 bytes
        self.tmp = Path(tempfile.mkdtemp(prefix="cr", dir="/tmp"))
        self.env = {**os.environ, "RAY_AUTH_MODE": "token",
                    "RAY_AUTH_TOKEN": secrets.token_hex(16), "RAY_USAGE_STATS_ENABLED": "0"}
        self.procs: list[subprocess.Popen[bytes]] = []

    def _where(self, node: int) -> tuple[list[str], str, int]:
        """Node ``node``'s command prefix (what runs its commands where it is),
        address and CPUs: here, on ``NODE_IP``."""
        return [], NODE_IP, self.cpus

    def _ray(self, *args: str) -> subprocess.Popen[bytes]:
        ray = Path(sys.executable).with_name("ray")
        prefix, ip, cpus = self._where(len(self.procs))
        log = open(self.tmp / f"node{len(self.procs)}.log", "wb")  # noqa: SIM115 - kept
        p = subprocess.Popen([*prefix, str(ray), "start", *args, "--node-ip-address", ip,
                              "--num-cpus", str(cpus), "--object-store-memory",
                              str(80 * 1024 * 1024), "--block"], env=self.env, stdout=log,
                             stderr=subprocess.STDOUT, start_new_session=True)
        self.procs.append(p)
        return p

    def start(self, timeout_s: float = 90.0) -> LocalRayCluster:
        self._ray("--head", "--port", str(self.port), "--include-dashboard=false",
                  "--disable-usage-stats", "--temp-dir", str(self.tmp))
        self._wait_for(1, timeout_s)
        for _ in range(self.nodes - 1):
            self._ray("--address", self.address)
        self._wait_for(self.nodes, timeout_s)
        return self

    def live_nodes(self) -> int:
        code = (f"import ray,logging;ray.init(address={self.address!r},"
                "logging_level=logging.ERROR);print(sum(n['Alive'] for n in ray.nodes()))")
        r = subprocess.run([*self._where(0)[0], sys.executable, "-c", code], env=self.env,
                           capture_output=True, text=True, timeout=60)
        return int(r.stdout.strip().splitlines()[-1]) if r.returncode == 0 and r.stdout.strip() \
            else 0

    def _wait_for(self, n: int, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            dead = [p for p in self.procs if p.poll() is not None]
            if dead:
                raise RuntimeError(f"ray start exited: {self.logs()}")
            if self.live_nodes() >= n:
                return
            time.sleep(1.0)
        raise RuntimeError(f"the Ray cluster did not reach {n} nodes: {self.logs()}")

    def logs(self) -> str:
        return "\n".join(f.read_text(errors="replace")[-2000:]
                         for f in sorted(self.tmp.glob("node*.log")))

    def stop(self) -> None:
        for p in reversed(self.procs):  # the head last
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                continue
        for p in self.procs:  # a test cluster has nothing to save: a short grace
            try:
                p.wait(timeout=3)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(timeout=10)
        for p in self.procs:  # whatever the node left in its session
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        shutil.rmtree(self.tmp, ignore_errors=True)
