"""A camera's downlink (cosim.renderer.datalink): the bit rate, frame rate,
key frames and latency it is given, and the ground truth measured on the
frames it delivers."""

from __future__ import annotations

import csv
import textwrap
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from cosim.core.camera import DatalinkSpec
from cosim.errors import ConfigError
from cosim.renderer.datalink import Downlink
from cosim.renderer.truth import _pixels, delivered
from cosim.scenario import parse_scenario
from tests.renderer.test_sensor import SCENARIO as SENSOR_SCENARIO

av = pytest.importorskip("av")

W, H = 640, 480


def _link(kbps: float, rate_hz: float = 15.0, gop: int = 15, latency_ms: float = 0.0
          ) -> DatalinkSpec:
    return DatalinkSpec(codec="h264", bitrate_kbps=kbps, rate_hz=rate_hz, every=1, gop=gop,
                        latency_ms=latency_ms)


def _scene(n: int, seed: int = 1) -> list[np.ndarray]:
    """``n`` frames (BGRA) of a textured ground moving 3 px a frame, with a
    6 x 6 px grey target at the centre (its id image: ``_ids``)."""
    rng = np.random.default_rng(seed)
    base = cv2.resize(rng.integers(40, 215, (90, 120, 3), np.uint8), (2 * W, 2 * H),
                      interpolation=cv2.INTER_CUBIC)
    frames = []
    for i in range(n):
        img = cv2.cvtColor(np.ascontiguousarray(base[2 * i:2 * i + H, 3 * i:3 * i + W]),
                           cv2.COLOR_BGR2BGRA)
        img[237:243, 317:323, :3] = 235
        frames.append(img)
    return frames


def _ids() -> np.ndarray:
    ids = np.zeros((H, W), np.uint16)
    ids[237:243, 317:323] = 1
    return ids


def _row() -> dict[str, Any]:
    return {"in_view": 1, "bbox_x0_px": 317.0, "bbox_y0_px": 237.0, "bbox_x1_px": 322.0,
            "bbox_y1_px": 242.0, "pixels_on_target": 36, "contrast": None}


@pytest.mark.parametrize("kbps", [300.0, 1000.0])
def test_the_stream_holds_its_bit_rate(tmp_path: Path, kbps: float) -> None:
    """Over 4 s at 15 frames a second the file's video takes the bit rate asked
    for within 12 % (x264's default, quality-driven rate gives far more)."""
    path = tmp_path / "v.mp4"
    link = Downlink(str(path), _link(kbps), W, H)
    for img in _scene(60):
        link.send(img)
    info = link.close()
    with av.open(str(path)) as c:
        packets = [p for p in c.demux(c.streams.video[0]) if p.size]
        keys = [i for i, p in enumerate(packets) if p.is_keyframe]
    got_kbps = sum(p.size for p in packets) * 8 / 4.0 / 1000
    assert got_kbps == pytest.approx(kbps, rel=0.12), got_kbps
    assert info["delivered_kbps"] == pytest.approx(got_kbps, rel=0.01)
    assert info["delivered_frames"] == len(packets) == 60
    assert keys == [0, 15, 30, 45]  # a key frame every gop frames, no others


def test_a_small_target_fades_at_a_low_bit_rate_and_keeps_at_a_high_one(tmp_path: Path
                                                                       ) -> None:
    """The delivered contrast and pixels of a 6 x 6 px target: at 30 kbit/s the
    encoder smears it into the ground; at 20 Mbit/s it is as rendered."""
    frames = _scene(16)
    ids = _ids()
    row = _row()
    clean = dict(row)
    _pixels(clean, frames[-1], ids, 1, 317.0, 237.0, 322.0, 242.0)
    assert clean["pixels_on_target"] == 36 and clean["contrast"] > 0.5
    out = {}
    for kbps in (30.0, 20000.0):
        link = Downlink(str(tmp_path / f"{kbps}.mp4"), _link(kbps), W, H)
        for img in frames:
            link.send(img)
        got = link.latest()
        link.close()
        out[kbps] = delivered([clean], frames[-1], got, ids)[0]
    n_hi, c_hi = out[20000.0]
    n_lo, c_lo = out[30.0]
    assert c_hi == pytest.approx(clean["contrast"], rel=0.05)
    assert n_hi == 36
    assert c_lo is not None and abs(c_lo - clean["contrast"]) > 0.25 * clean["contrast"]
    assert n_lo < 36


def test_frames_decode_as_a_receiver_decoding_every_packet_would(tmp_path: Path) -> None:
    """Decoding waits until a frame is looked at (the packets since the last
    decoded one or key frame, then): each frame looked at equals the file's
    frame decoded in order, whatever was skipped before it, across key frames."""
    path = tmp_path / "v.mp4"
    link = Downlink(str(path), _link(200.0, gop=5), W, H)
    assert not link.latest().any()  # black before anything is sent
    looked: dict[int, np.ndarray] = {}
    for i, img in enumerate(_scene(14)):
        link.send(img)
        if i in (0, 3, 4, 8, 13):  # 8 after 5 and 6 skipped past the key frame at 5
            looked[i] = link.latest().copy()
    link.close()
    with av.open(str(path)) as c:
        every = [cv2.cvtColor(f.to_ndarray(format="yuv420p"), cv2.COLOR_YUV2BGRA_I420)
                 for f in c.decode(c.streams.video[0])]
    assert len(every) == 14
    for i, img in looked.items():
        assert np.array_equal(img, every[i]), i
    assert not np.array_equal(looked[3], looked[4])


def test_delivered_is_contrasts_formula_on_the_delivered_pixels() -> None:
    """The delivered frame equal to the sent one gives the clean measures."""
    img = _scene(1)[0]
    row = _row()
    _pixels(row, img, _ids(), 1, 317.0, 237.0, 322.0, 242.0)
    n, c = delivered([row, {"in_view": 0, "pixels_on_target": 0}], img, img.copy(), _ids())[0:2]
    assert n == (36, row["contrast"])
    assert c == (0, None)


#: the sensor tests' scenario with a 10 Hz camera and a ``datalink:`` instead (line 11)
SCENARIO = SENSOR_SCENARIO.replace("      sensor: %s\n", "      rate_hz: 10\n      datalink: %s\n")


def test_datalink_keys_parse() -> None:
    scn = parse_scenario(SCENARIO % "{bitrate_kbps: 500, rate_hz: 5, keyframe_s: 2, "
                                    "latency_ms: 150}", "s.yaml", check_properties=False)
    assert scn.sections["cameras"].views[0].datalink == DatalinkSpec(
        codec="h264", bitrate_kbps=500.0, rate_hz=5.0, every=2, gop=10, latency_ms=150.0)
    scn = parse_scenario(SCENARIO % "{}", "s.yaml", check_properties=False)
    assert scn.sections["cameras"].views[0].datalink == DatalinkSpec(
        codec="h264", bitrate_kbps=1000.0, rate_hz=10.0, every=1, gop=10, latency_ms=0.0)
    plain = parse_scenario(SCENARIO.replace("      datalink: %s\n", ""), "s.yaml",
                           check_properties=False)
    assert plain.sections["cameras"].views[0].datalink is None


@pytest.mark.parametrize("link, message", [
    ("{bitrate_kbps: 5}", r"s.yaml:11: cameras.views\[0\].datalink.bitrate_kbps: must be >= 10, "
                          r"got 5"),
    ("{bitrate_kbps: 200000}", r"s.yaml:11: cameras.views\[0\].datalink.bitrate_kbps: must be "
                               r"<= 100000"),
    ("{latency_ms: -1}", r"s.yaml:11: cameras.views\[0\].datalink.latency_ms: must be >= 0"),
    ("{latency_ms: 20000}", r"s.yaml:11: cameras.views\[0\].datalink.latency_ms: must be "
                            r"<= 10000"),
    ("{rate_hz: 4}", r"s.yaml:11: cameras.views\[0\].datalink.rate_hz: 4 must divide the "
                     r"camera's rate_hz 10"),
    ("{rate_hz: 20}", r"s.yaml:11: cameras.views\[0\].datalink.rate_hz: must be <= 10"),
    ("{keyframe_s: 100}", r"s.yaml:11: cameras.views\[0\].datalink.keyframe_s: must be <= 60"),
    ("{codec: vp9}", r"s.yaml:11: cameras.views\[0\].datalink.codec: expected one of: h264; "
                     r"got .vp9."),
    ("{fec: true}", r"s.yaml:11: cameras.views\[0\].datalink.fec: unknown key 'fec'"),
    ("300", r"s.yaml:11: cameras.views\[0\].datalink: expected a mapping"),
    ("{}\n      width_px: 161", r"s.yaml:11: cameras.views\[0\].datalink: a datalink's H.264 "
                               r"\(4:2:0\) needs an even frame size; the camera's is 161x480"),
])
def test_bad_datalink_keys_are_refused_with_their_place(link: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_scenario(SCENARIO % link, "s.yaml", check_properties=False)


def test_a_run_writes_the_delivered_video_and_ground_truth(tmp_path: Path) -> None:
    """A 30 Hz camera delivered at 10 Hz with 250 ms latency: the video holds
    every third frame at 10 Hz; those frames' ground truth gains the delivered
    time (render time + latency) and measures, the others' stay empty."""
    from tests.renderer.test_renderer import _fly

    more = textwrap.indent("- {name: link, vehicles: u1, mount: nadir, vfov_deg: 40, "
                           "width_px: 160, height_px: 120, rate_hz: 30, datalink: "
                           "{bitrate_kbps: 200, rate_hz: 10, latency_ms: 250}}\n", "    ")
    summary, out = _fly(tmp_path, "link", rate=30.0, dur=2.0, more=more)
    st = summary["streams"][1]
    assert st["frames"] == 60 and st["delivered_frames"] == 20
    assert st["datalink"] == {"codec": "h264", "bitrate_kbps": 200.0, "rate_hz": 10.0,
                              "keyframe_every": 10, "latency_ms": 250.0}
    with av.open(str(out / "cameras/u1_link.mp4")) as c:
        v = c.streams.video[0]
        assert float(v.average_rate) == pytest.approx(10.0)
        assert sum(1 for _ in c.decode(v)) == 20
    with open(out / "cameras/u1_link.gt.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["target"] == "truck1"]
    assert len(rows) == 60
    for r in rows:
        if int(r["frame"]) % 3:
            assert r["delivered_time_s"] == r["delivered_contrast"] == ""
            continue
        assert float(r["delivered_time_s"]) == pytest.approx(float(r["time_s"]) + 0.25)
        assert r["delivered_pixels_on_target"] != ""
        if r["contrast"]:
            assert r["delivered_contrast"] != ""
    with open(out / "cameras/u1_belly.gt.csv") as f:  # the plain camera: as before
        assert "delivered_contrast" not in f.readline()


def test_the_operator_sees_the_delivered_frames(tmp_path: Path) -> None:
    """The thumbnail the operator view and the --video taps get is the frame as
    delivered (held between deliveries), not the render."""
    from cosim.renderer.frame import WorldSpec
    from cosim.renderer.outputs import Stream
    from cosim.renderer.render_pool import RenderWorker

    repo = Path(__file__).resolve().parents[2]
    path = repo / "scenarios/cameras/flyover.yaml"
    text = path.read_text().replace("rate_hz: 10}", "rate_hz: 10, datalink: {bitrate_kbps: 30, "
                                                    "rate_hz: 5}}")
    scn = parse_scenario(text, str(path), check_properties=False)
    cam = scn.sections["cameras"].views[0]
    o = scn.origin
    ws = WorldSpec(o.lat_deg, o.lon_deg, o.ground_alt_m, scn.seed, 120.0, scn.world.ground,
                   scn.world.targets)
    (tmp_path / "cameras").mkdir()
    s = Stream(0, "uav1", 0, cam, "cameras/b.mp4", "cameras/b.gt.csv", (160, 120))
    w = RenderWorker(ws, [s], tmp_path, "mp4v", False)
    thumbs, renders = [], []
    for i in range(3):
        la, lo = (float(v) for v in o.frame.place(-20.0 + 5 * i, 0.0, o.ground_alt_m + 100))
        pose6 = (la, lo, o.ground_alt_m + 100, 0.0, 0.0, 0.0)
        thumb, _ = w.render(0, i, i * 12, pose6)
        assert thumb is not None
        thumbs.append(thumb)
        renders.append(w.frames[0].copy())
    w.close()

    def small(img: np.ndarray) -> np.ndarray:
        return cv2.cvtColor(cv2.resize(img, (160, 120), interpolation=cv2.INTER_AREA),
                            cv2.COLOR_BGRA2BGR)

    assert not np.array_equal(thumbs[0], small(renders[0]))  # 30 kbit/s: far from the render
    assert np.array_equal(thumbs[1], thumbs[0])  # frame 1 is not delivered: held
    assert not np.array_equal(thumbs[2], thumbs[0])
    with av.open(str(tmp_path / "cameras/b.mp4")) as c:
        got = [f.to_ndarray(format="bgr24") for f in c.decode(c.streams.video[0])]
    assert len(got) == 2
    # the file's second frame (FFmpeg's colour conversion: a level or two from OpenCV's),
    # not the render
    d_file = np.abs(small(cv2.cvtColor(got[1], cv2.COLOR_BGR2BGRA)).astype(int) - thumbs[2])
    d_render = np.abs(small(renders[2]).astype(int) - thumbs[2])
    assert d_file.max() <= 4 and d_file.mean() < 2 < d_render.mean(), (d_file.mean(),
                                                                         d_render.mean())


def _link_run(tmp_path: Path, name: str, workers: int) -> tuple[bytes, bytes]:
    """The delivered video and ground truth of a datalink camera beside a plain one."""
    from tests.renderer.test_renderer import _fly

    more = textwrap.indent("- {name: link, vehicles: u1, mount: nadir, vfov_deg: 40, "
                           "width_px: 160, height_px: 120, rate_hz: 10, datalink: "
                           "{bitrate_kbps: 100, rate_hz: 5, latency_ms: 80}}\n", "    ")
    _, out = _fly(tmp_path, name, rate=10.0, dur=1.0, more=more, workers=workers)
    return ((out / "cameras/u1_link.mp4").read_bytes(),
            (out / "cameras/u1_link.gt.csv").read_bytes())


@pytest.mark.integration
def test_delivered_frames_are_the_same_for_any_render_worker_count(tmp_path: Path) -> None:
    assert _link_run(tmp_path, "w0", 0) == _link_run(tmp_path, "w2", 2)
