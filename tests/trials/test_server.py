"""The trial web app, live: uvicorn on 127.0.0.1 (an ephemeral port) in a
thread, driven over HTTP and by a scripted participant in headless Debian
Chromium (/usr/bin/chromium through Playwright; nothing is downloaded)."""

from __future__ import annotations

import contextlib
import hashlib
import http.client
import json
import math
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import uvicorn
from test_store import write_gt, write_video

from cosim.renderer.video import open_video
from cosim.trials.server import make_app, serve, served_in_thread
from cosim.trials.store import Store

W, H, RATE_HZ, FRAMES = 320, 240, 10.0, 20  # each clip: 2 s of 320 x 240 at 10 Hz
HALF_X, HALF_Y = 10, 6  # the target's half size (camera px)
# the participant's display: an 800 x 500 px window, 400 x 250 mm, eye 600 mm away
PROFILE = {"screen_width_px": 800, "screen_height_px": 500, "screen_width_mm": 400.0,
           "screen_height_mm": 250.0, "viewing_distance_mm": 600.0}
SPEEDS = {"c0": 50, "c1": 100, "c2": 200}
HFOV_DEG = 60.0  # the camera the study's clips say they were filmed with
# every clip frame carries its number in its pixels: bit b of it in block b of a row
# below the target's path (bright 170 or dark 20: clear through H.264, and darker than
# the white target the screenshot test looks for)
BITS, BIT_X0, BIT_STEP, BIT_W, BIT_Y0, BIT_Y1 = 5, 16, 60, 48, 196, 236
assert 2 ** BITS >= FRAMES

#: a page script, the test's witness of what each clip showed, apart from the page's
#: own code: every frame the browser reports presented (a requestVideoFrameCallback
#: of its own, which later scripts' wrappers do not touch), with its number read from
#: its pixels and when it was due on screen, until the next clip loads; and every
#: Space pressed while a clip plays, with its time and the frame drawn at that moment
WITNESS = f"""
(() => {{
  const rvfc = HTMLVideoElement.prototype.requestVideoFrameCallback;
  const w = window.witness = {{ frames: [], presses: [] }};
  const c = document.createElement("canvas");
  const g = c.getContext("2d", {{ willReadFrequently: true }});
  const number = (v) => {{  // the frame number in the video's current picture
    c.width = v.videoWidth; c.height = v.videoHeight;
    g.drawImage(v, 0, 0);
    let k = 0;
    for (let b = 0; b < {BITS}; b++) {{
      const x = {BIT_X0} + {BIT_STEP} * b + {BIT_W} / 2, y = ({BIT_Y0} + {BIT_Y1}) / 2;
      if (g.getImageData(x, y, 1, 1).data[1] > 95) k |= 1 << b;
    }}
    return k;
  }};
  const trial = () => Number(document.body.dataset.trial);
  let handle = null;
  const stop = (v) => {{ if (handle !== null) v.cancelVideoFrameCallback(handle); handle = null; }};
  document.addEventListener("loadstart", (e) => stop(e.target), true);
  document.addEventListener("play", (e) => {{
    const v = e.target, t = trial();
    stop(v);
    const log = (now, m) => {{
      w.frames.push({{ trial: t, number: number(v), read_ms: performance.now(),
                      media_time_s: m.mediaTime, due_ms: m.expectedDisplayTime,
                      sent_ms: m.presentationTime, presented: m.presentedFrames }});
      handle = rvfc.call(v, log);
    }};
    handle = rvfc.call(v, log);
  }}, true);
  addEventListener("keydown", (e) => {{
    if (e.code !== "Space" || document.body.dataset.phase !== "playing") return;
    w.presses.push({{ trial: trial(), at_ms: e.timeStamp,
                     drawn: number(document.getElementById("clip")) }});
  }}, true);
}})();
"""


def shown_at_press(witness: dict[str, Any], trial: int) -> dict[str, Any]:
    """What the witness saw of trial ``trial``'s press: ``frames``, the
    numbers the frame on screen at the press may have (the last frame due on
    screen by then: one number, unless the browser reported none of the
    frames it presented in between, then each of them), and ``drawn``, the
    number in the picture drawn when the page handled the key (that frame or
    a later one). The frames' numbers are their media times' and, checked
    here, their pixels'."""
    frames = [f for f in witness["frames"] if f["trial"] == trial]
    (press,) = [p for p in witness["presses"] if p["trial"] == trial]
    # the pixels of each frame read before the next one went to the compositor
    # (a report run late reads a later one) are the frame its media time names
    timely = [f for f, g in zip(frames, frames[1:])
              if f["read_ms"] < g["sent_ms"] and g["presented"] - f["presented"] == 1]
    assert 2 * len(timely) >= len(frames) > 1, frames
    assert all(f["number"] == round(f["media_time_s"] * RATE_HZ) for f in timely), frames
    before = [f for f in frames if f["due_ms"] <= press["at_ms"]]
    assert before, f"the witness saw no frame due on screen by the press: {press}"
    a = before[-1]
    ka = round(a["media_time_s"] * RATE_HZ)
    b = next((f for f in frames if f["due_ms"] > press["at_ms"]), None)  # None: the clip stopped
    if b is None or b["presented"] - a["presented"] == 1:
        numbers = [ka]
    else:
        numbers = list(range(ka, round(b["media_time_s"] * RATE_HZ)))
    return {"frames": numbers, "drawn": press["drawn"]}


def centre(clip: str, k: int) -> tuple[float, float]:
    """Where clip ``clip``'s target is in frame ``k`` (camera px)."""
    step = {"c0": 18.0, "c1": 14.0, "c2": 10.0}[clip]
    return 30.0 + step * k, 80.0


def make_clip(folder: Path, name: str) -> None:
    """An H.264 clip (cosim's own video writer) of a white box crossing a grey
    ground, each frame's number in its pixels, and its ground truth in the
    renderer's columns."""
    sink = open_video(str(folder / f"{name}.mp4"), "h264", RATE_HZ, W, H)
    rows = ["frame,time_s,vehicle,camera,target,in_view,fully_in_view,bbox_x0_px,bbox_y0_px,"
            "bbox_x1_px,bbox_y1_px,center_x_px,center_y_px,eccentricity_px,eccentricity_deg,"
            "angular_size_deg,pixels_on_target,range_m,contrast"]
    for k in range(FRAMES):
        cx, cy = centre(name, k)
        img = np.full((H, W, 3), 90, np.uint8)
        x0, y0, x1, y1 = cx - HALF_X, cy - HALF_Y, cx + HALF_X, cy + HALF_Y
        cv2.rectangle(img, (round(x0), round(y0)), (round(x1), round(y1)), (255, 255, 255), -1)
        for b in range(BITS):
            bx = BIT_X0 + BIT_STEP * b
            img[BIT_Y0:BIT_Y1, bx:bx + BIT_W] = 170 if k >> b & 1 else 20
        sink.write(img)
        iv = int(x0 <= W - 0.5)
        rows.append(f"{k},{k / RATE_HZ:.6f},uav,nadir,truck,{iv},{int(x1 <= W - 0.5)},{x0},{y0},"
                    f"{x1},{y1},{cx},{cy},,,,,,")
    sink.release()
    (folder / f"{name}.gt.csv").write_text("\n".join(rows) + "\n")


@pytest.fixture(scope="module")
def study_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("study")
    for name in SPEEDS:
        make_clip(folder, name)
    (folder / "secret.txt").write_text("not for the browser")
    clips = "".join(f"  - {{id: {n}, video: {n}.mp4, ground_truth: {n}.gt.csv, run: run_{n}, "
                    f"hfov_deg: {HFOV_DEG}, "
                    f"conditions: {{speed_kt: {v}, alt_agl_m: 30, target: truck}}}}\n"
                    for n, v in SPEEDS.items())
    p = folder / "study.yaml"
    p.write_text("name: tiny\nprotocol: disappear\npractice: 1\nbreak_every: 2\norder: shuffle\n"
                 "seed: 7\nclips:\n" + clips)
    return p


class LiveServer:
    def __init__(self, url: str, store: Store, study_path: Path) -> None:
        self.url, self.store, self.study_path = url, store, study_path
        self.host, self.port = url.removeprefix("http://").split(":")

    def request(self, method: str, path: str, body: Any = None,
                headers: dict[str, str] | None = None) -> tuple[int, Any]:
        """One request with ``path`` sent exactly as given (no normalisation);
        ``body`` as JSON, or bytes as they are."""
        c = http.client.HTTPConnection(self.host, int(self.port), timeout=10)
        try:
            data = body if body is None or isinstance(body, bytes) else json.dumps(body).encode()
            c.request(method, path, body=data, headers={"Content-Type": "application/json",
                                                        **(headers or {})})
            r = c.getresponse()
            raw = r.read()
        finally:
            c.close()
        try:
            return r.status, json.loads(raw)
        except ValueError:
            return r.status, raw


@contextlib.contextmanager
def live_server(study_path: Path, **limits: Any) -> Iterator[LiveServer]:
    """The app for ``study_path`` served by uvicorn in a thread on
    127.0.0.1:<ephemeral>, with ``cosim trials serve``'s bounds (``limits``:
    other values of ``uvicorn_settings``'s)."""
    store = Store(study_path.with_suffix(".sqlite"))
    try:
        with served_in_thread(make_app(study_path, store), **limits) as url:
            yield LiveServer(url, store, study_path)
    finally:
        store.close()


@pytest.fixture(scope="module")
def server(study_file: Path) -> Iterator[LiveServer]:
    with live_server(study_file) as s:
        yield s


def expected(clip: str, frame: int, page_px: tuple[int, int] | None = None
             ) -> dict[str, float]:
    """The measures at ``frame`` of ``clip`` on PROFILE (or drawn on a page of
    ``page_px`` device pixels at PROFILE's pixel size), from the clip's own
    geometry."""
    pw, ph = page_px or (PROFILE["screen_width_px"], PROFILE["screen_height_px"])
    scale = min(pw / W, ph / H)
    cx, cy = centre(clip, frame)
    # the image centre (pixel centres at integers) is the page's centre: the fixation mark
    x_mm = (cx - (W - 1) / 2) * scale * PROFILE["screen_width_mm"] / PROFILE["screen_width_px"]
    y_mm = (cy - (H - 1) / 2) * scale * PROFILE["screen_height_mm"] / PROFILE["screen_height_px"]
    d = math.hypot(x_mm, y_mm)
    # seen from the camera: the pixel offset over the pinhole's focal length
    f_px = W / 2 / math.tan(math.radians(HFOV_DEG / 2))
    gap = math.degrees(math.atan(math.hypot(cx - (W - 1) / 2, cy - (H - 1) / 2) / f_px))
    return {"onscreen_distance_mm": d, "camera_gap_deg": gap,
            "eccentricity_deg": math.degrees(math.atan(d / PROFILE["viewing_distance_mm"]))}


# --- the HTTP side -------------------------------------------------------

def _session(server: LiveServer, participant: str) -> dict[str, Any]:
    status, s = server.request("POST", "/api/sessions", {"participant": participant, **PROFILE})
    assert status == 201, s
    return s


def test_videos_only_by_number_from_the_study(server: LiveServer) -> None:
    status, body = server.request("GET", "/video/0", headers={"Range": "bytes=0-9"})
    assert status == 206 and len(body) == 10  # seekable
    for path in ("/video/3", "/video/-1", "/video/..%2fsecret.txt", "/video/../secret.txt",
                 "/static/../secret.txt", "/static/..%2f..%2fserver.py",
                 "/static/%2e%2e/server.py", "/secret.txt", "/study.yaml"):
        status, body = server.request("GET", path)
        assert status == 404, (path, status)
        assert b"not for the browser" not in (body if isinstance(body, bytes) else b"")


def test_foreign_host_refused(server: LiveServer) -> None:
    status, _ = server.request("GET", "/api/study", headers={"Host": "evil.example:80"})
    assert status == 400
    assert server.request("GET", "/api/study")[0] == 200


def test_bad_requests(server: LiveServer) -> None:
    status, body = server.request("POST", "/api/sessions", {"participant": "Jane Doe",
                                                            **PROFILE})
    assert status == 400 and "pseudonym" in body["error"]
    status, body = server.request("POST", "/api/sessions", {**PROFILE, "participant": "p9",
                                                            "viewing_distance_mm": "far"})
    assert status == 400 and "viewing_distance_mm must be a number" in body["error"]
    s = _session(server, "p-bad")
    base = f"/api/sessions/{s['id']}/responses"
    for bad, msg in (({"trial_index": 99, "key": "space"}, "trial_index"),
                     ({"trial_index": 0, "key": "space", "reshown": "yes"},
                      "reshown: expected true, false or null, got 'yes'"),
                     ({"trial_index": 0, "key": "<script>"}, "key"),
                     ({"trial_index": 0, "key": "space", "kind": "recognise"}, "protocol"),
                     ({"trial_index": 0, "key": "space", "media_time_s": 1e9}, "outside"),
                     ({"trial_index": 0, "key": "space", "media_time_s": "NaN"}, "number")):
        status, body = server.request("POST", base, bad)
        assert status == 400 and msg in body["error"], (bad, body)
    assert server.request("GET", "/api/sessions/nope")[0] == 404
    status, body = server.request("POST", base, {"trial_index": 0, "key": "x" * 100000})
    assert status == 413


def test_response_posted_twice_is_stored_once(server: LiveServer) -> None:
    s = _session(server, "p-twice")
    base = f"/api/sessions/{s['id']}/responses"
    body = {"trial_index": 1, "kind": "disappear", "key": "space", "media_time_s": 0.5,
            "reaction_time_ms": 500.0}
    status, first = server.request("POST", base, body)
    assert status == 201 and first["created"] and first["response"]["frame"] == 5
    status, again = server.request("POST", base, {**body, "media_time_s": 0.9})  # a retry
    assert status == 200 and not again["created"] and again["response"] == first["response"]
    assert len(server.store.responses(s["id"])) == 1
    clip = s["trials"][1]["clip_id"]
    assert first["response"]["eccentricity_deg"] == pytest.approx(
        expected(clip, 5)["eccentricity_deg"], rel=1e-12)


def test_serve_refuses_public_address_without_flag(study_file: Path) -> None:
    from cosim.errors import ConfigError

    with pytest.raises(ConfigError, match=r"refusing to listen on 0\.0\.0\.0.*--public"):
        serve(study_file, host="0.0.0.0", port=1)


def asgi(app: Any, method: str, path: str, body: Any = None, host: str = "127.0.0.1:8000",
         client: str = "127.0.0.1") -> tuple[int, Any]:
    """One JSON request straight into the ASGI app (no socket): the ``Host``
    header and the client's address as given."""
    import asyncio

    data = [b"" if body is None else json.dumps(body).encode()]
    sent: list[dict[str, Any]] = []

    async def receive() -> dict[str, Any]:
        if data:
            return {"type": "http.request", "body": data.pop(), "more_body": False}
        return {"type": "http.disconnect"}

    async def send(message: dict[str, Any]) -> None:
        sent.append(message)

    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1",
             "method": method, "scheme": "http", "path": path, "raw_path": path.encode(),
             "root_path": "", "query_string": b"", "client": (client, 50000),
             "server": ("127.0.0.1", 8000),
             "headers": [(b"host", host.encode()), (b"content-type", b"application/json")]}
    asyncio.run(app(scope, receive, send))
    status = next(m["status"] for m in sent if m["type"] == "http.response.start")
    raw = b"".join(m.get("body", b"") for m in sent if m["type"] == "http.response.body")
    try:
        return status, json.loads(raw)
    except ValueError:
        return status, raw


def test_serve_on_another_loopback_address_answers_requests_to_it(
        study_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--host 127.0.0.2`` is this machine: the browser's ``Host: 127.0.0.2:port``
    is answered; another name still is not."""

    ran: dict[str, Any] = {}
    monkeypatch.setattr(uvicorn, "run", lambda app, **kw: ran.update(app=app, **kw))
    serve(study_file, host="127.0.0.2", port=8123, db_url=str(tmp_path / "t.sqlite"))
    app = ran["app"]
    try:
        assert ran["host"] == "127.0.0.2"
        # the HTTP bounds (cosim.trials.limits), as the slow-client test runs them shorter
        assert (ran["http"].request_timeout_s, ran["http"].max_per_client) == (10.0, 32)
        assert (ran["timeout_keep_alive"], ran["limit_concurrency"]) == (5, 200)
        status, body = asgi(app, "GET", "/api/study", host="127.0.0.2:8123", client="127.0.0.2")
        assert status == 200 and body["name"] == "tiny"
        assert asgi(app, "GET", "/api/sessions/nope", host="127.0.0.2:8123")[0] == 404
        assert asgi(app, "GET", "/api/study", host="127.0.0.3:8123")[0] == 400
        assert asgi(app, "GET", "/api/study", host="evil.example:8123")[0] == 400
    finally:
        app.state.trials.store.close()


def small_study(folder: Path, head: str, clips: dict[str, float]) -> Path:
    """A study file of 5-frame clips (id: the target's first x, camera px) below ``head``."""
    for cid, x0 in clips.items():
        write_video(folder / f"{cid}.mp4")
        write_gt(folder / f"{cid}.gt.csv", [(f, x0 + 10 * f, 119.5, 1) for f in range(5)])
    p = folder / "study.yaml"
    p.write_text(head + "clips:\n" + "".join(
        f"  - {{id: {c}, video: {c}.mp4, ground_truth: {c}.gt.csv}}\n" for c in clips))
    return p


@pytest.mark.parametrize("protocol", ["disappear", "recognise", "track"])
def test_reaction_times_outside_0_to_10_minutes_are_refused(tmp_path: Path,
                                                            protocol: str) -> None:
    study = small_study(tmp_path, f"protocol: {protocol}\n", {"a": 150.0})
    with Store(tmp_path / "t.sqlite") as store:
        app = make_app(study, store)
        status, s = asgi(app, "POST", "/api/sessions", {"participant": "p", **PROFILE})
        assert status == 201, s
        body = {"trial_index": 0, "kind": "track-up" if protocol == "track" else protocol,
                "key": "space", "media_time_s": 0.2, "recognised": True}
        path = f"/api/sessions/{s['id']}/responses"
        for rt in (-0.5, -1e6, 600_000.5):
            status, r = asgi(app, "POST", path, {**body, "reaction_time_ms": rt})
            assert status == 400 and r["error"] == (
                f"reaction_time_ms: expected 0..600000 ms (from the clip's start to the "
                f"press), got {rt:g}"), r
        assert asgi(app, "POST", path, {**body, "reaction_time_ms": 0.0})[0] == 201


@pytest.mark.parametrize("protocol, frame", [("disappear", 3), ("track", 2)])
def test_a_response_stores_the_targets_depth_along_the_optical_axis(
        tmp_path: Path, protocol: str, frame: int) -> None:
    """target_depth_m: the ground truth's range_m * cos(eccentricity_deg) at the
    frame measured (a track trial: its still frame, the target nearest the centre)."""
    study = small_study(tmp_path, f"protocol: {protocol}\n", {"a": 139.5})
    write_gt(tmp_path / "a.gt.csv", [(f, 139.5 + 10 * f, 119.5, 1) for f in range(5)],
             range_ecc={f: (f"{40 + 10 * f}", "60") for f in range(5)})
    with Store(tmp_path / "t.sqlite") as store:
        app = make_app(study, store)
        status, s = asgi(app, "POST", "/api/sessions", {"participant": "p", **PROFILE})
        assert status == 201, s
        status, r = asgi(app, "POST", f"/api/sessions/{s['id']}/responses", {
            "trial_index": 0, "kind": "track-left" if protocol == "track" else protocol,
            "key": "space", "media_time_s": 0.3, "reaction_time_ms": 700.0})
        assert status == 201, r
        assert r["response"]["frame"] == frame
        assert r["response"]["target_depth_m"] == pytest.approx((40 + 10 * frame) / 2)
        assert store.responses(s["id"])[0]["target_depth_m"] == r["response"]["target_depth_m"]


def test_page_size_reports_are_checked_and_kept_for_the_experimenter(
        server: LiveServer) -> None:
    s = _session(server, "p-size")
    path = f"/api/sessions/{s['id']}/window"

    def warning() -> Any:
        status, listed = server.request("GET", "/api/sessions")
        (row,) = [x for x in listed if x["id"] == s["id"]]
        return row["window_px"], row["window_warning"]

    assert warning() == (None, None)  # nothing reported yet
    for bad in ({"window_width_px": 3.5, "window_height_px": 400},
                {"window_width_px": 800, "window_height_px": 1e9},
                {"window_width_px": "800", "window_height_px": 500},
                {"window_width_px": 800}):
        status, body = server.request("POST", path, bad)
        assert status == 400 and "window_" in body["error"], (bad, body)
    assert server.request("POST", "/api/sessions/nope/window",
                          {"window_width_px": 800, "window_height_px": 500})[0] == 404
    assert server.request("POST", path, {"window_width_px": 800, "window_height_px": 500},
                          headers={"Origin": "http://evil.example"})[0] == 403
    assert server.request("POST", path, {"window_width_px": 1024, "window_height_px": 500}
                          )[0] == 200
    px, text = warning()
    assert px == [1024, 500] and text.startswith(
        "the participant's page is 1024 x 500 px, not the profile's 800 x 500")
    assert server.request("POST", path, {"window_width_px": 800, "window_height_px": 500}
                          )[0] == 200
    assert warning() == ([800, 500], None)
    # a response says the page's size too: the last word
    status, _ = server.request("POST", f"/api/sessions/{s['id']}/responses", {
        "trial_index": 1, "kind": "disappear", "key": "space", "media_time_s": 0.5,
        "window_width_px": 640, "window_height_px": 500})
    assert status == 201 and warning()[0] == [640, 500]
    # kept in the database: a server started again on it still warns
    with live_server(server.study_path) as again:
        status, listed = again.request("GET", "/api/sessions")
        (row,) = [x for x in listed if x["id"] == s["id"]]
        assert row["window_px"] == [640, 500] and "640 x 500 px" in row["window_warning"]


def test_the_targets_picture_is_cut_from_its_clip(server: LiveServer) -> None:
    """/target/0: the square twice the target's box around it, from the frame
    of the clips where it is largest and wholly in view (clip c0's first, where
    the box is centred at x 30): the white box in the middle of grey ground."""
    s = _session(server, "p-picture")
    assert {(t["target"], t["target_picture"]) for t in s["trials"]} == {("truck", "/target/0")}
    status, png = server.request("GET", "/target/0")
    assert status == 200 and isinstance(png, bytes)
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (4 * HALF_X, 4 * HALF_X, 3)  # twice the box's longer side
    ys, xs = np.nonzero(img.min(axis=2) > 200)
    # the box (21 x 13 px drawn) in the middle: another frame's would be 18 px off
    assert (xs.max() - xs.min() + 1, ys.max() - ys.min() + 1) == (2 * HALF_X + 1, 2 * HALF_Y + 1)
    assert abs(xs.mean() - 19.5) <= 1 and abs(ys.mean() - 19.5) <= 1
    assert abs(float(np.median(img[img.min(axis=2) < 200])) - 90) < 10  # grey ground around
    status, body = server.request("GET", "/target/1")
    assert status == 404 and body["error"] == "no target 1"


def test_a_video_gone_or_made_a_fifo_while_serving_is_refused(tmp_path: Path) -> None:
    """A clip's video replaced by a FIFO (or removed) after the study was read
    is a 409 naming it, not a server error."""
    study = small_study(tmp_path, "protocol: disappear\n", {"a": 150.0})
    with Store(tmp_path / "t.sqlite") as store:
        app = make_app(study, store)
        assert asgi(app, "GET", "/video/0")[0] == 200
        video = tmp_path / "a.mp4"
        video.unlink()
        status, body = asgi(app, "GET", "/video/0")
        assert status == 409 and body["error"] == f"clip 'a': its video {video} is gone: restore it"
        os.mkfifo(video)
        status, body = asgi(app, "GET", "/video/0")
        assert status == 409 and body["error"] == (f"clip 'a': its video {video} is a FIFO, not "
                                                   f"a regular file")


def test_a_session_refuses_clips_gone_or_changed(tmp_path: Path) -> None:
    """Sessions find their clips by id and fingerprint: the study's clips
    reordered is fine; a clip removed, or its ground truth or video changed, is
    a 409 naming the clip and what changed. Older sessions: by id, or number."""
    study = small_study(tmp_path, "protocol: disappear\norder: latin_square\n",
                        {"a": 100.0, "b": 150.0})
    head, a, b = study.read_text().rsplit("\n", 3)[:3]
    db = tmp_path / "t.sqlite"

    def call(method: str, path: str, body: Any = None) -> tuple[int, Any]:
        with Store(db) as store:  # the study read afresh, as a restarted server would
            return asgi(make_app(study, store), method, path, body)

    status, s = call("POST", "/api/sessions", {"participant": "p", **PROFILE})
    assert status == 201
    assert s["trials"][0]["fingerprint"] == {
        "ground_truth_sha256": hashlib.sha256(
            (tmp_path / f"{s['trials'][0]['clip_id']}.gt.csv").read_bytes()).hexdigest(),
        "video_bytes": (tmp_path / "a.mp4").stat().st_size}
    get = f"/api/sessions/{s['id']}"
    study.write_text(f"{head}\n{b}\n{a}\n")  # the clips listed the other way round
    status, again = call("GET", get)
    assert status == 200
    assert [(t["clip_id"], t["video"]) for t in again["trials"]] == [
        (t["clip_id"], {"a": "/video/1", "b": "/video/0"}[t["clip_id"]]) for t in s["trials"]]
    study.write_text(f"{head}\n{a}\n")
    status, body = call("GET", get)
    assert status == 409 and body["error"].startswith(
        f"clip 'b' of this session is no longer in the study {study}")
    study.write_text(f"{head}\n{a}\n{b}\n")
    gt = tmp_path / "b.gt.csv"
    kept = gt.read_bytes()
    gt.write_bytes(kept.replace(b",150.0,", b",151.0,", 1))
    status, body = call("GET", get)
    assert status == 409 and body["error"] == (
        f"clip 'b' of this session changed since the session was created (its ground truth "
        f"{gt} is not the file it was): restore the files, or start a new session")
    response = {"trial_index": 0, "key": "space", "media_time_s": 0.1}
    b_trial = next(t["index"] for t in s["trials"] if t["clip_id"] == "b")
    status, body = call("POST", f"{get}/responses", {**response, "trial_index": b_trial})
    assert status == 409 and "clip 'b'" in body["error"]
    gt.write_bytes(kept)
    video = tmp_path / "b.mp4"
    size = video.stat().st_size
    video.write_bytes(video.read_bytes() + bytes(16))
    status, body = call("GET", get)
    assert status == 409 and f"its video {video} is {size + 16} bytes, not {size}" in body["error"]
    video.write_bytes(video.read_bytes()[:size])
    assert call("GET", get)[0] == 200
    # older sessions: without fingerprints by clip id, without clip ids by number
    with Store(db) as store:
        old = store.create_session(
            participant="old", study="study", protocol="disappear",
            display=PROFILE, order_method="shuffle", seed=0, session_number=9,
            trial_order=[{"index": 0, "practice": False, "clip": 0, "clip_id": "a",
                          "break_before": False},
                         {"index": 1, "practice": False, "clip": 1, "break_before": False}])
    gt.write_bytes(kept.replace(b",150.0,", b",151.0,", 1))  # not known to the old session
    status, body = call("GET", f"/api/sessions/{old['id']}")
    assert status == 200 and [t["video"] for t in body["trials"]] == ["/video/0", "/video/1"]
    study.write_text(f"{head}\n{a}\n")
    status, body = call("GET", f"/api/sessions/{old['id']}")
    assert status == 409 and body["error"].startswith(
        "trial 1 of this session shows clip number 1, which the study")


# --- a scripted participant in Chromium -------------------------------------

#: trial index -> the frame to press at (trial 3: the clip runs out without a press)
PRESSES: dict[int, int] = {0: 5, 1: 8, 2: 10}
RELOAD_AT = (2, 3)  # reload the page while trial 2 shows frame 3


#: the state of the participant page's texts, its target pictures and its label
PAGE_STATE = """(() => {
  const m = document.getElementById("message"), label = document.getElementById("label");
  return {
    phase: document.body.dataset.phase, trial: document.body.dataset.trial,
    text: m.hidden ? null : m.innerText,
    paragraphs: m.hidden ? [] : [...m.querySelectorAll("p")].map((p) => {
      const r = p.getBoundingClientRect();
      return { text: p.innerText, top: r.top, bottom: r.bottom };
    }),
    pictures: m.hidden ? [] : [...m.querySelectorAll("img.target")].map((i) => ({
      src: i.getAttribute("src"), loaded: i.complete && i.naturalWidth > 0,
      natural: [i.naturalWidth, i.naturalHeight], shown_px: i.getBoundingClientRect().width,
      rendering: getComputedStyle(i).imageRendering,
      caption: i.closest("figure").innerText })),
    label: !label || label.hidden ? null : label.innerText,
  };
})()"""
PICTURES_LOADED = ("[...document.querySelectorAll('#message img.target')]"
                   ".every((i) => i.complete && i.naturalWidth > 0)")


@pytest.fixture(scope="module")
def browser_run(server: LiveServer, tmp_path_factory: pytest.TempPathFactory,
                chromium: str) -> dict[str, Any]:
    from playwright.sync_api import sync_playwright

    s = _session(server, "p01")
    assert [t["practice"] for t in s["trials"]] == [True, False, False, False]
    assert [t["break_before"] for t in s["trials"]] == [False, False, False, True]
    shots = tmp_path_factory.mktemp("participant_page")
    run: dict[str, Any] = {"session": s, "phases": [], "console": [], "witness": {},
                           "state": {}, "shots": shots}
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium,
                                     args=["--autoplay-policy=no-user-gesture-required"])
        try:
            page = browser.new_page(viewport={"width": 800, "height": 500},
                                    device_scale_factor=1)
            page.add_init_script(WITNESS)
            page.on("console", lambda m: run["console"].append(m.text))
            page.on("pageerror", lambda e: run["console"].append(str(e)))
            page.set_default_timeout(15_000)

            def wait_phase(p: str) -> None:
                page.wait_for_function(f"document.body.dataset.phase === '{p}'")
                run["phases"].append(p)

            def wait_frame(trial: int, frame: int) -> None:
                page.wait_for_function(
                    f"document.body.dataset.trial === '{trial}' && document.body.dataset.phase"
                    f" === 'playing' && Number(document.body.dataset.frame) >= {frame}",
                    polling=5)
                # a frame is reported as it goes to the compositor, a display refresh
                # (~17 ms) before it is due on screen: press after that
                page.wait_for_timeout(30)

            def press_on_clip() -> None:
                """Space; once the page has taken its frame, the witness's record of it."""
                page.keyboard.press("Space")
                page.wait_for_function("document.body.dataset.phase !== 'playing'")
                w = page.evaluate("window.witness")
                run["witness"][w["presses"][-1]["trial"]] = w

            def keep(name: str) -> None:
                """The page's state and a screenshot of it (``shots/NAME.png``)."""
                page.wait_for_function(PICTURES_LOADED)
                run["state"][name] = page.evaluate(PAGE_STATE)
                page.screenshot(path=str(shots / f"{name}.png"))

            page.goto(f"{server.url}/participant?session={s['id']}")
            wait_phase("begin")
            keep("begin")
            page.keyboard.press("Space")
            wait_phase("waiting")  # not started yet
            assert server.request("POST", f"/api/sessions/{s['id']}/state",
                                  {"state": "running"})[0] == 200
            wait_phase("practice")
            keep("practice")
            page.keyboard.press("Space")
            wait_frame(0, PRESSES[0])
            keep("practice clip")
            press_on_clip()
            wait_phase("practice-over")
            page.keyboard.press("Space")
            wait_frame(1, PRESSES[1])
            keep("clip")
            press_on_clip()
            wait_phase("next")  # the next clip waits for the participant
            keep("next")
            page.wait_for_timeout(1500)  # (the page had started it after 1 s)
            run["state"]["next, 1.5 s later"] = page.evaluate(PAGE_STATE)
            page.keyboard.press("Space")
            wait_frame(*RELOAD_AT)
            # the picture on the screen where the geometry says (letterboxed, centred)
            run["shot"] = (page.screenshot(), int(page.evaluate("document.body.dataset.frame")))
            run["before_reload"] = len(server.store.responses(s["id"]))
            page.reload()
            wait_phase("begin")
            page.keyboard.press("Space")
            page.wait_for_function("document.body.dataset.phase === 'fixation'")
            run["resumed_at"] = page.evaluate("document.body.dataset.trial")
            wait_frame(2, PRESSES[2])
            press_on_clip()
            wait_phase("break")
            page.keyboard.press("Space")
            wait_phase("finished")
        finally:
            browser.close()
    run["responses"] = server.store.responses(s["id"])
    return run


def test_the_instructions_are_lines_of_their_own_with_the_targets_picture(
        browser_run: dict[str, Any]) -> None:
    """Each instruction a paragraph under the last (they had run together:
    "...disappears.Press the space bar"), and the target's picture, loaded
    and enlarged with sharp pixels, between them and the key to press."""
    begin = browser_run["state"]["begin"]
    texts = [p["text"] for p in begin["paragraphs"]]
    assert texts == ["Look at the red cross in the centre of the screen while each clip plays.",
                     "Press the space bar as soon as the target disappears.",
                     "The target looks like this, in the middle of the picture:",
                     "Press the space bar to begin."], begin
    tops = [(p["top"], p["bottom"]) for p in begin["paragraphs"]]
    assert all(b0 <= t1 for (_, b0), (t1, _) in zip(tops, tops[1:])), tops
    assert "disappears.Press" not in begin["text"]
    (picture,) = begin["pictures"]
    assert picture["src"] == "/target/0" and picture["loaded"] and picture["caption"] == "truck"
    assert picture["natural"] == [40, 40] and picture["shown_px"] >= 150  # enlarged
    assert picture["rendering"] == "pixelated"
    assert (browser_run["shots"] / "begin.png").stat().st_size > 0


def test_practice_trials_are_labelled_on_the_page(browser_run: dict[str, Any]) -> None:
    st = browser_run["state"]
    assert st["practice"]["paragraphs"][0]["text"] == "Practice clip 1 of 1"
    assert "First, 1 practice clip to get used to the task: it does not count." in \
        st["practice"]["text"]
    assert (st["practice clip"]["trial"], st["practice clip"]["label"]) == ("0", "Practice")
    assert (st["clip"]["trial"], st["clip"]["label"]) == ("1", None)


def test_the_next_clip_starts_when_the_participant_asks(browser_run: dict[str, Any]) -> None:
    """After a press, a prompt with the next clip's number and target, and no
    clip until the space bar (it had started a second after each press)."""
    st = browser_run["state"]
    nxt = st["next"]
    assert [p["text"] for p in nxt["paragraphs"]] == [
        "Clip 2 of 3", "Press the space bar for the next clip."], nxt
    assert [p["src"] for p in nxt["pictures"]] == ["/target/0"] and nxt["label"] is None
    later = st["next, 1.5 s later"]
    assert (later["phase"], later["text"]) == ("next", nxt["text"])
    assert browser_run["phases"].count("next") == 1


def test_key_presses_give_the_ground_truth_frame(browser_run: dict[str, Any]) -> None:
    rs = browser_run["responses"]
    assert [r["trial_index"] for r in rs] == [0, 1, 2, 3], browser_run["console"]
    trials = browser_run["session"]["trials"]
    for r in rs:
        t = trials[r["trial_index"]]
        assert (r["clip"], bool(r["practice"]), r["participant"]) == (
            t["clip_id"], t["practice"], "p01")
        assert r["condition_speed_kt"] == str(SPEEDS[t["clip_id"]])
        want = PRESSES.get(r["trial_index"])
        if want is None:  # the clip ran out without a press
            assert (r["key"], r["frame"], r["eccentricity_deg"]) == ("none", None, None)
            continue
        assert r["key"] == "space"
        # the frame on screen at the key press, as the witness numbers it from its pixels
        seen = shown_at_press(browser_run["witness"][r["trial_index"]], r["trial_index"])
        assert r["frame"] in seen["frames"] and r["frame"] <= seen["drawn"], (r, seen)
        assert r["frame"] >= want  # (the script pressed once that frame was shown)
        assert r["frame"] == round(r["video_time_s"] * RATE_HZ)
        exp = expected(t["clip_id"], r["frame"])
        assert r["eccentricity_deg"] == pytest.approx(exp["eccentricity_deg"], rel=1e-9)
        assert r["onscreen_distance_mm"] == pytest.approx(exp["onscreen_distance_mm"], rel=1e-9)
        assert r["camera_gap_deg"] == pytest.approx(exp["camera_gap_deg"], rel=1e-9)
        assert r["target_in_view"] is True
        # from the onset to the press: the frame's time (it is due on screen at a display
        # refresh, 60 Hz, and a press can be stamped the moment it is due: within one) and
        # less than a frame (and slack) more
        assert -1000 / 60 < r["reaction_time_ms"] - 1000 * r["video_time_s"] < 150
        for k, v in PROFILE.items():
            assert r[k] == v


def test_reload_resumes_at_the_first_trial_without_a_response(
        browser_run: dict[str, Any], server: LiveServer) -> None:
    assert browser_run["before_reload"] == 2  # trials 0 and 1 answered, 2 on screen
    assert browser_run["resumed_at"] == "2"
    rs = browser_run["responses"]
    assert len({(r["trial_index"], r["kind"]) for r in rs}) == len(rs) == 4
    # trial 2 was playing at the reload and was shown again from its start
    assert {r["trial_index"]: r["reshown"] for r in rs} == {0: False, 1: False, 2: True,
                                                            3: False}
    assert "break" in browser_run["phases"] and browser_run["phases"][-1] == "finished"
    status, s = server.request("GET", f"/api/sessions/{browser_run['session']['id']}")
    assert (s["state"], s["next_trial"], s["answered"]) == ("finished", None, 4)


def test_video_drawn_where_the_measures_assume(browser_run: dict[str, Any]) -> None:
    png, frame = browser_run["shot"]
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert img is not None
    assert img.shape == (PROFILE["screen_height_px"], PROFILE["screen_width_px"])
    ys, xs = np.nonzero(img > 200)  # the white target (the red fixation cross is darker)
    assert len(xs) > 50
    clip = browser_run["session"]["trials"][RELOAD_AT[0]]["clip_id"]
    scale = min(800 / W, 500 / H)
    sx = [400 + (centre(clip, k)[0] - (W - 1) / 2) * scale for k in (frame - 1, frame, frame + 1)]
    sy = 250 + (centre(clip, frame)[1] - (H - 1) / 2) * scale
    assert abs(ys.mean() - sy) < 3
    assert min(sx) - 3 < xs.mean() < max(sx) + 3, (xs.mean(), sx)


@contextlib.contextmanager
def one_clip_study(study_file: Path, name: str, head: str) -> Iterator[
        tuple[LiveServer, dict[str, Any]]]:
    """A study of clip c1 alone beside ``study_file`` (``head``: its first
    lines), served, with one running session."""
    study = study_file.parent / f"{name}.yaml"
    study.write_text(head + "clips:\n"
                     "  - {video: c1.mp4, ground_truth: c1.gt.csv, conditions: {speed_kt: 100}}\n")
    with live_server(study) as server:
        s = _session(server, name)
        server.request("POST", f"/api/sessions/{s['id']}/state", {"state": "running"})
        yield server, s


@contextlib.contextmanager
def participant_page(server: LiveServer, session: dict[str, Any], *scripts: str, chromium: str,
                     size_px: tuple[int, int] = (800, 500)) -> Iterator[Any]:
    """Chromium (the ``chromium`` fixture's) showing ``session``'s participant
    page, ``size_px`` large, at its first screen; ``scripts`` run in it before
    the page's own."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium,
                                     args=["--autoplay-policy=no-user-gesture-required"])
        try:
            page = browser.new_page(viewport={"width": size_px[0], "height": size_px[1]},
                                    device_scale_factor=1)
            for script in scripts:
                page.add_init_script(script)
            page.set_default_timeout(15_000)
            page.goto(f"{server.url}/participant?session={session['id']}")
            page.wait_for_function("document.body.dataset.phase === 'begin'")
            yield page
        finally:
            browser.close()


def test_recognise_protocol(study_file: Path, tmp_path: Path, chromium: str) -> None:
    """Press to start the sub-trial, press on recognising, answer yes. The
    page is narrower than the profile: the participant sees no warning of it,
    the experimenter's session list does, and the measures follow the page."""
    page_px = (700, 500)
    with one_clip_study(study_file, "recognise", "protocol: recognise\norder: latin_square\n"
                        ) as (server, s):
        with participant_page(server, s, WITNESS, chromium=chromium, size_px=page_px) as page:
            page.keyboard.press("Space")
            page.wait_for_function("document.body.dataset.phase === 'start'")
            page.keyboard.press("Space")
            page.wait_for_function("document.body.dataset.phase === 'playing' && "
                                   "Number(document.body.dataset.frame) >= 6", polling=5)
            assert page.is_visible("#arrow") and not page.is_visible("#fixation")
            assert page.inner_text("#status") == "" and page.is_hidden("#message")
            page.wait_for_timeout(30)  # (frame 6 is due on screen ~17 ms after its report)
            page.keyboard.press("Space")
            page.wait_for_function("document.body.dataset.phase === 'answer'")
            seen = shown_at_press(page.evaluate("window.witness"), 0)
            page.keyboard.press("y")
            page.wait_for_function("document.body.dataset.phase === 'finished'")
        (r,) = server.store.responses(s["id"])
        status, listed = server.request("GET", "/api/sessions")
    assert (r["protocol"], r["key"], r["recognised"], r["practice"], r["reshown"]) == (
        "recognise", "y", True, False, False)
    assert r["frame"] in seen["frames"] and 6 <= r["frame"] <= seen["drawn"], (r, seen)
    assert r["eccentricity_deg"] == pytest.approx(
        expected("c1", r["frame"], page_px)["eccentricity_deg"], rel=1e-9)
    (row,) = [x for x in listed if x["id"] == s["id"]]
    assert row["window_px"] == list(page_px)
    assert "page is 700 x 500 px, not the profile's 800 x 500" in row["window_warning"]


#: a page script that has the browser expect every video frame on screen 5 s
#: later than it will be: a press during the clip then comes before its onset
FRAMES_DUE_LATE = """
const rvfc = HTMLVideoElement.prototype.requestVideoFrameCallback;
HTMLVideoElement.prototype.requestVideoFrameCallback = function (cb) {
  return rvfc.call(this, (now, meta) =>
    cb(now, { ...meta, expectedDisplayTime: meta.expectedDisplayTime + 5000 }));
};
"""


def test_a_press_before_the_clips_onset_is_sent_as_0_ms(study_file: Path, chromium: str) -> None:
    """The page takes the clip's onset from when its first frame is expected
    on screen, which is after that frame's callback: a press in between gives
    a negative time, which the page must send as 0 (the server refuses it)."""
    with one_clip_study(study_file, "early", "protocol: disappear\n") as (server, s):
        with participant_page(server, s, FRAMES_DUE_LATE, chromium=chromium) as page:
            page.keyboard.press("Space")
            page.wait_for_function("document.body.dataset.phase === 'playing' && "
                                   "Number(document.body.dataset.frame) >= 2", polling=5)
            page.keyboard.press("Space")
            page.wait_for_function("['finished', 'error'].includes(document.body.dataset.phase)")
            shown = page.inner_text("#message")
        rs = server.store.responses(s["id"])
    assert [(r["key"], r["reaction_time_ms"]) for r in rs] == [("space", 0.0)], shown


def busy_page(frame: int, hold_frames: float, report_next: bool) -> str:
    """A page script that holds the page's main thread, as a loaded machine
    does, from the page's report of frame ``frame`` until ``hold_frames``
    frames after it was due on screen, and then presses Space: a key event
    handled before the page hears of the frames presented meanwhile, which it
    is then told of late (``report_next``) or, the next one, never (the
    browser reports only the latest of the frames presented while a page was
    busy)."""
    return f"""
(() => {{
  const rvfc = HTMLVideoElement.prototype.requestVideoFrameCallback;
  let pressed = false;
  HTMLVideoElement.prototype.requestVideoFrameCallback = function (cb) {{
    const v = this;
    return rvfc.call(v, function report(now, m) {{
      const k = Math.round(m.mediaTime * {RATE_HZ});
      if (pressed && k === {frame + 1} && !{str(report_next).lower()}) {{
        rvfc.call(v, report);
        return;
      }}
      cb(now, m);
      if (k !== {frame} || pressed) return;
      pressed = true;
      const until = m.expectedDisplayTime + {hold_frames} * 1000 / {RATE_HZ};
      while (performance.now() < until);
      dispatchEvent(new KeyboardEvent("keydown", {{ code: "Space", key: " ", cancelable: true }}));
    }});
  }};
}})();
"""


@pytest.mark.parametrize("frame, hold_frames, report_next, on_screen", [
    (5, 1.5, True, 6), (5, 1.5, False, 6), (FRAMES - 1, 0.5, True, FRAMES - 1)],
    ids=["reported late", "not reported", "the last frame"])
def test_a_busy_page_stores_the_frame_on_screen_at_the_press(
        study_file: Path, frame: int, hold_frames: float, report_next: bool,
        on_screen: int, chromium: str) -> None:
    """Frame 6 was on screen at the press, but the page heard of it only after
    the key event (or never): the page had stored frame 5, the last it knew.
    A press on the last frame, which no frame follows, is kept at the end."""
    with one_clip_study(study_file, f"busy{frame}{int(report_next)}", "protocol: disappear\n"
                        ) as (server, s):
        script = busy_page(frame, hold_frames, report_next)
        with participant_page(server, s, WITNESS, script, chromium=chromium) as page:
            page.keyboard.press("Space")  # (the script presses during the clip)
            page.wait_for_function("['finished', 'error'].includes(document.body.dataset.phase)")
            seen = shown_at_press(page.evaluate("window.witness"), 0)
        (r,) = server.store.responses(s["id"])
    assert seen["frames"] == [on_screen], seen  # (the browser kept playing the clip meanwhile)
    assert (r["key"], r["frame"]) == ("space", on_screen), (r, seen)


def test_experimenter_page(server: LiveServer, chromium: str) -> None:
    """Create a session from the form, start it, pause it; the size its
    participant's page reports, with a warning as it is not the profile's;
    no script errors."""
    from playwright.sync_api import sync_playwright

    errors: list[str] = []
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium)
        try:
            page = browser.new_page()
            page.set_default_timeout(10_000)
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(server.url + "/")
            page.wait_for_selector("#study:has-text('protocol disappear, 3 clips')")
            page.fill("input[name=participant]", "p-form")
            for k, v in PROFILE.items():
                page.fill(f"input[name={k}]", str(v))
            page.click("button:has-text('Create session')")
            row = page.locator("#sessions tr", has_text="p-form")
            row.wait_for()
            (sid,) = [x["id"] for x in server.store.sessions() if x["participant"] == "p-form"]
            assert server.request("POST", f"/api/sessions/{sid}/window", {
                "window_width_px": 640, "window_height_px": 400})[0] == 200
            row.locator("button:has-text('Start')").click()
            row.locator("td:has-text('running')").wait_for()
            warning = row.locator(".warning").inner_text()
            row.locator("button:has-text('Pause')").click()
            row.locator("td:has-text('paused')").wait_for()
            link = row.locator("a").get_attribute("href")
        finally:
            browser.close()
    (s,) = [s for s in server.store.sessions() if s["participant"] == "p-form"]
    assert (s["state"], s["trials"], s["answered"]) == ("paused", 4, 0)
    assert link == f"/participant?session={s['id']}"
    assert {k: s[k] for k in PROFILE} == PROFILE
    assert "page is 640 x 400 px, not the profile's 800 x 500" in warning
    assert not errors


def test_pages_elsewhere_cannot_post_and_other_machines_cannot_run_sessions(
        server: LiveServer) -> None:
    import asyncio

    from starlette.requests import Request

    from cosim.trials.server import BadRequest, _experimenter

    body = json.dumps({"participant": "x", **PROFILE})
    c = http.client.HTTPConnection(server.host, int(server.port), timeout=10)
    try:  # a form post from another site's page: text/plain, no preflight
        c.request("POST", "/api/sessions", body=body, headers={"Content-Type": "text/plain"})
        assert c.getresponse().status == 415
    finally:
        c.close()
    status, _ = server.request("POST", "/api/sessions", {"participant": "x", **PROFILE},
                               headers={"Origin": "http://evil.example"})
    assert status == 403
    # the experimenter's routes answer this machine only, --public or not
    calls: list[str] = []

    async def page(request: Request) -> Any:
        calls.append(request.url.path)

    guarded = _experimenter(page)
    scope = {"type": "http", "method": "GET", "path": "/", "headers": [], "query_string": b""}
    with pytest.raises(BadRequest) as e:
        asyncio.run(guarded(Request({**scope, "client": ("192.0.2.7", 50000)})))
    assert e.value.status == 403 and not calls
    asyncio.run(guarded(Request({**scope, "client": ("127.0.0.1", 50000)})))
    assert calls == ["/"]


def test_a_live_sessions_export_is_analysed(server: LiveServer, browser_run: dict[str, Any],
                                            tmp_path: Path) -> None:
    """Live responses (a trial without a press among them, clips whose target
    is not a swept condition) export and analyse without a problem."""
    from cosim.trials.analysis import analyse
    from cosim.trials.store import export_csv

    path = export_csv(server.store, tmp_path / "responses.csv")
    rows = path.read_text().splitlines()
    assert len(rows) > 2 and any(",none," in r for r in rows)  # a trial run out unpressed
    summary = analyse(path, tmp_path / "a", plots=False)
    assert summary["rows"] >= len(browser_run["responses"])


def test_a_page_smaller_than_the_profile_is_measured_as_drawn(server: LiveServer) -> None:
    """The browser says how large the page was: the clip fitted that, so the
    target's place on the screen (and its eccentricity) follow it."""
    s = _session(server, "p-window")
    page = (PROFILE["screen_width_px"] // 2, PROFILE["screen_height_px"])
    status, r = server.request("POST", f"/api/sessions/{s['id']}/responses", {
        "trial_index": 1, "kind": "disappear", "key": "space", "media_time_s": 0.5,
        "reaction_time_ms": 500.0, "window_width_px": page[0], "window_height_px": page[1]})
    assert status == 201, r
    clip = s["trials"][1]["clip_id"]
    want = expected(clip, 5, page)
    assert r["response"]["eccentricity_deg"] == pytest.approx(want["eccentricity_deg"],
                                                               rel=1e-12)
    assert want["eccentricity_deg"] != pytest.approx(expected(clip, 5)["eccentricity_deg"],
                                                     rel=1e-3)  # the profile's would differ
    status, r = server.request("POST", f"/api/sessions/{s['id']}/responses", {
        "trial_index": 2, "kind": "disappear", "key": "space", "media_time_s": 0.5,
        "window_width_px": 3.5, "window_height_px": 400})
    assert status == 400 and "window_width_px" in r["error"]


def test_track_protocol(study_file: Path, chromium: str) -> None:
    """The clip still at the frame where its target is nearest the centre; per
    direction a press starts the dot leaving the target, a press later stops
    it: the stored conspicuity angle is the target's from where the dot was
    then (computed here from the geometry and the stored time), the dot was
    drawn there, and a reload mid-trial resumes at the next direction."""
    from playwright.sync_api import sync_playwright

    from cosim.core.display import angle_between_deg

    with one_clip_study(study_file, "track", "protocol: track\narrow_speed_deg_s: 4\nseed: 3\n"
                        ) as (server, s):
        t0 = s["trials"][0]
        # the still frame: the target nearest the image centre (c1 moves 14 px a frame)
        still = min(range(FRAMES), key=lambda k: abs(centre("c1", k)[0] - (W - 1) / 2))
        assert t0["still_time_s"] == pytest.approx(still / RATE_HZ)
        assert sorted(t0["directions"]) == ["down", "left", "right", "up"]
        drawn: list[tuple[float, float]] = []
        between_ms: list[float] = []  # from the press starting the dot to the one stopping it
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium)
            try:
                page = browser.new_page(viewport={"width": 800, "height": 500},
                                        device_scale_factor=1)
                page.set_default_timeout(15_000)
                # when the page saw each press (a loaded machine delays Playwright's)
                page.add_init_script("window.pressed_ms = []; addEventListener('keydown', e => "
                                     "{ if (e.code === 'Space') pressed_ms.push(e.timeStamp); },"
                                     " true);")
                page.goto(f"{server.url}/participant?session={s['id']}")
                page.wait_for_function("document.body.dataset.phase === 'begin'")
                page.keyboard.press("Space")
                for k in range(4):
                    if k == 2:  # a reload after two directions: the third comes next
                        page.reload()
                        page.wait_for_function("document.body.dataset.phase === 'begin'")
                        page.keyboard.press("Space")
                    page.wait_for_function("document.body.dataset.phase === 'track-start'")
                    assert page.evaluate("document.body.dataset.direction") == \
                        t0["directions"][k]
                    assert page.inner_text("#hint") == ("Clip 1 of 1: press the space bar to "
                                                        "start the dot.")
                    page.keyboard.press("Space")
                    page.wait_for_timeout(400 + 100 * k)
                    box = page.locator("#tracker").bounding_box()
                    assert box is not None
                    drawn.append((box["x"] + box["width"] / 2, box["y"] + box["height"] / 2))
                    page.keyboard.press("Space")
                    start_ms, stop_ms = page.evaluate("pressed_ms.slice(-2)")
                    between_ms.append(stop_ms - start_ms)
                page.wait_for_function("document.body.dataset.phase === 'finished'")
            finally:
                browser.close()
        rs = {r["kind"]: r for r in server.store.responses(s["id"])}
    assert sorted(rs) == ["track-down", "track-left", "track-right", "up"[:0] + "track-up"]
    dirs = {"right": (1, 0), "left": (-1, 0), "up": (0, -1), "down": (0, 1)}
    mm = PROFILE["screen_width_mm"] / PROFILE["screen_width_px"]
    scale = min(PROFILE["screen_width_px"] / W, PROFILE["screen_height_px"] / H)
    cx, cy = centre("c1", still)
    tx, ty = (cx - (W - 1) / 2) * scale * mm, (cy - (H - 1) / 2) * scale * mm  # target, mm
    dist = PROFILE["viewing_distance_mm"]
    for k, name in enumerate(t0["directions"]):
        r = rs[f"track-{name}"]
        # timed from the dot's first frame after the starting press to the stop
        assert between_ms[k] - 300 <= r["reaction_time_ms"] <= between_ms[k] + 20
        assert between_ms[k] >= 400 + 100 * k - 20  # the test waited that long
        off = dist * math.tan(math.radians(4.0 * r["reaction_time_ms"] / 1000))
        dx, dy = dirs[name]
        assert r["onscreen_distance_mm"] == pytest.approx(off, rel=1e-9)
        assert r["eccentricity_deg"] == pytest.approx(
            angle_between_deg((tx + dx * off, ty + dy * off), (tx, ty), dist), rel=1e-9)
        assert r["frame"] == still
        # the dot on the page a little before the press: on its way out along the direction
        px, py = drawn[k]
        ox, oy = PROFILE["screen_width_px"] / 2 + tx / mm, PROFILE["screen_height_px"] / 2 + ty / mm
        along = (px - ox) * dx + (py - oy) * dy
        across = abs((px - ox) * dy - (py - oy) * dx)
        assert 0 < along <= off / mm + 2 and across < 1.5
