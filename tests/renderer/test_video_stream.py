"""Camera video to a ground station: what `cosim run --video` sends over RTP
and MPEG-TS decodes (PyAV, as ffplay or QGroundControl would) to the
camera's frames, to IPv4 and IPv6 addresses; the vehicle answers
VIDEO_STREAM_INFORMATION with the stream; remote addresses, unknown
vehicles and cameras are refused; a stream that fails or sends nothing
fails the run."""

from __future__ import annotations

import io
import json
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import av
import pytest

from cosim.cli import main
from cosim.errors import ConfigError
from cosim.renderer.stream import VideoParticipant, VideoTarget, parse_target, sdp
from cosim.sync.participants import ParticipantFailed

REPO = Path(__file__).resolve().parent.parent.parent
FLYOVER = REPO / "scenarios" / "cameras" / "flyover.yaml"


def _port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _sim(tmp_path: Path, video: str, seconds: float = 3.0,
         extra: Sequence[str] = ()) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cosim", "-q", "run", str(FLYOVER), "--out",
                           str(tmp_path / "run"), "--duration-s", str(seconds),
                           "--no-progress", "--video", video, *extra],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.integration
def test_rtp_decodes_to_the_cameras_frames(tmp_path: Path) -> None:
    port = _port()
    (tmp_path / "rx.sdp").write_text(sdp(VideoTarget(1, None, "127.0.0.1", port, "rtp"), "rx"))
    frames: list[tuple[int, int]] = []

    def receive() -> None:
        # FFmpeg's timeout is per read: long enough for the run's start on a busy
        # machine (a 3 s one had ended the receiver before the first packet)
        c = av.open(str(tmp_path / "rx.sdp"), format="sdp", options={
            "protocol_whitelist": "file,udp,rtp", "timeout": "60000000"})
        try:
            frames.extend((f.width, f.height) for f in c.decode(video=0))
        except av.error.FFmpegError:
            pass  # no more packets: the stream ended
    rx = threading.Thread(target=receive, daemon=True)
    rx.start()
    time.sleep(1.0)  # listening before the first packet
    r = _sim(tmp_path, f"1=udp://127.0.0.1:{port}")
    assert r.returncode == 0, r.stderr
    deadline, seen = time.monotonic() + 15, -1
    while time.monotonic() < deadline and len(frames) != seen:  # until no frame comes
        seen = len(frames)
        time.sleep(1.0)
    assert 25 <= len(frames) <= 31 and set(frames) == {(640, 480)}  # 3 s at 10 Hz
    assert (tmp_path / "run" / "video_1_belly.sdp").read_text() == \
        sdp(VideoTarget(1, None, "127.0.0.1", port, "rtp"), "cosim uav1/belly")


@pytest.mark.parametrize("family, host", [(socket.AF_INET, "127.0.0.1"),
                                          (socket.AF_INET6, "::1")], ids=["ipv4", "ipv6"])
@pytest.mark.integration
def test_mpegts_decodes_too(tmp_path: Path, family: socket.AddressFamily, host: str) -> None:
    sock = socket.socket(family, socket.SOCK_DGRAM)
    sock.bind((host, 0))
    port = sock.getsockname()[1]
    netloc = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    sock.settimeout(60.0)  # the first datagram: after the run has started
    data = bytearray()

    def receive() -> None:
        try:
            while True:
                data.extend(sock.recv(65535))
                sock.settimeout(3.0)  # then: the stream's end
        except OSError:
            pass
    rx = threading.Thread(target=receive, daemon=True)
    rx.start()
    r = _sim(tmp_path, f"1:belly=udp://{netloc}?format=mpegts", seconds=2.0)
    assert r.returncode == 0, r.stderr
    rx.join(65)
    sock.close()
    frames = [(f.width, f.height) for f in av.open(io.BytesIO(bytes(data)),
                                                   format="mpegts").decode(video=0)]
    assert 15 <= len(frames) <= 21 and set(frames) == {(640, 480)}
    stream = json.loads((tmp_path / "run" / "summary.json").read_text())["video"]["uav1/belly"]
    assert stream["uri"] == f"udp://{netloc}" and stream["frames_sent"] == len(frames)


def test_an_ipv6_destination_is_written_in_brackets() -> None:
    t = parse_target("1=udp://[::1]:15600")
    assert (t.host, t.port, t.uri) == ("::1", 15600, "udp://[::1]:15600")
    assert "c=IN IP6 ::1\n" in sdp(t, "x") and "IP4" not in sdp(t, "x")
    with pytest.raises(ConfigError, match="not a loopback address"):
        parse_target("1=udp://[2001:db8::7]:5600")


@pytest.mark.integration
def test_a_stream_that_fails_fails_the_run(tmp_path: Path) -> None:
    """Sending to the broadcast address without permission: FFmpeg cannot
    send a frame (nothing leaves the machine); the run says which stream
    and exits 1 instead of claiming success."""
    r = _sim(tmp_path, "1=udp://255.255.255.255:5600",
             seconds=1.0, extra=["--video-allow-remote"])
    assert r.returncode == 1, r.stderr
    assert re.search(r"cosim run: video uav1/belly to udp://255.255.255.255:5600 stopped "
                     r"after 0 frame\(s\): PermissionError", r.stderr), r.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["video"]["uav1/belly"]["frames_sent"] == 0


def test_a_stream_that_sent_no_frame_in_a_completed_run_is_a_failure(tmp_path: Path) -> None:
    from types import SimpleNamespace

    from cosim.scenario import load_scenario

    port = _port()
    video = VideoParticipant([parse_target(f"1=udp://127.0.0.1:{port}")],
                             load_scenario(str(FLYOVER)))
    video.start(SimpleNamespace(out_dir=tmp_path, mavlink=None))
    with pytest.raises(ParticipantFailed,
                       match=rf"video uav1/belly to udp://127.0.0.1:{port} sent no frame"):
        video.finish(10, "completed")
    video.start(SimpleNamespace(out_dir=tmp_path, mavlink=None))
    section = video.finish(0, "interrupted")  # stopped early: no failure
    assert section is not None and section["uav1/belly"]["frames_sent"] == 0


@pytest.mark.parametrize("text, message", [
    ("1=udp://192.0.2.7:5600", "not a loopback address"),
    ("1=tcp://127.0.0.1:5600", "expected udp://HOST:PORT"),
    ("1=udp://127.0.0.1:5600?format=webm", "format must be one of"),
    ("uav1=udp://127.0.0.1:5600", "expected SYSID"),
])
def test_bad_video_options_are_refused(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_target(text)
    assert parse_target("1=udp://192.0.2.7:5600", allow_remote=True).host == "192.0.2.7"


def test_unknown_vehicle_or_camera_is_a_usage_error(tmp_path: Path, capsys) -> None:
    assert main(["run", str(FLYOVER), "--out", str(tmp_path / "a"),
                 "--video", "7=udp://127.0.0.1:5600"]) == 2
    assert "no vehicle has system id 7" in capsys.readouterr().err
    assert main(["run", str(FLYOVER), "--out", str(tmp_path / "b"),
                 "--video", "1:nose=udp://127.0.0.1:5600"]) == 2
    assert "has no camera 'nose'; it has belly" in capsys.readouterr().err
