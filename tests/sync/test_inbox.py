"""The command inbox and replay: an operator's commands submitted from another
thread while a run goes are applied at an exchange and logged; a run with
them equals the same scenario with the same commands as schedule items at
the same ticks; an inbox without commands changes nothing; ``replay_run``
reproduces a run's states and video from its log, and tells a tampered log;
bad commands, logs and folders are refused saying what and where."""

from __future__ import annotations

import json
import random
import re
import shutil
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cosim.cli import main
from cosim.errors import ConfigError
from cosim.logs import read_states
from cosim.scenario import parse_scenario
from cosim.sync import Run
from cosim.sync import inbox as inbox_mod
from cosim.sync import replay as replay_mod
from cosim.sync.inbox import MAX_PENDING, CommandInbox
from cosim.sync.replay import read_commands, replay_run
from tests.helpers import same_states

HZ, K = 120, 4  # physics ticks a second, ticks an exchange
BODY = """\
schema_version: 1
origin: {lat_deg: 37.4150, lon_deg: -122.0480, ground_alt_m: 10}
rates: {physics_hz: 120, control_hz: 30, log_hz: 10}
duration_s: DURATION
seed: 7
vehicles:
  - {id: uav1, model: uav700, init: {north_m: -300, east_m: 0, alt_agl_m: 100,
     heading_deg: 0, airspeed_kt: 100}}
  - {id: uav2, model: uav700, init: {north_m: -300, east_m: 300, alt_agl_m: 100,
     heading_deg: 0, airspeed_kt: 100}}
schedule:
  - {at_s: 0, vehicles: uav2, command: {alt_agl_m: 120}}
SCHEDULE
ground: {texture: procedural}
targets:
  - {id: truck1, kind: truck, north_m: 0, east_m: 0, heading_deg: 20}
cameras:
  render_workers: 0
  views:
    - {name: belly, vehicles: uav1, mount: nadir, vfov_deg: 40, width_px: 160,
       height_px: 120, rate_hz: 10}
"""
#: what the operator sends, and at which exchange (at or after) the thread sends it
COMMANDS: list[tuple[int, str, dict[str, Any]]] = [(24, "uav1", {"heading_deg": 60}),
            (60, "uav2", {"goto": {"north_m": 200, "east_m": 0}}),
            (96, "uav1", {"alt_agl_m": 140, "airspeed_kt": 90})]


def _scenario(folder: Path, duration_s: float = 1.5, schedule: str = "") -> Any:
    text = BODY.replace("DURATION", f"{duration_s:g}").replace("SCHEDULE\n", schedule)
    return parse_scenario(text, str(folder / "s.yaml"))


class Probe:
    """A participant that tells the last exchange it saw (its ``on_exchange``
    runs after the inbox's ``before_step`` of that tick) and calls ``at(tick)``."""

    name = "probe"

    def __init__(self, at: Callable[[int], None] | None = None) -> None:
        self.tick = -1
        self.at = at
        self.cond = threading.Condition()

    def start(self, ctx: Any) -> None:
        pass

    def on_exchange(self, tick: int, states: np.ndarray) -> None:
        with self.cond:
            self.tick = tick
            self.cond.notify_all()
        if self.at is not None:
            self.at(tick)

    def finish(self, tick: int, reason: str) -> None:
        return None

    def after_run(self, out_dir: Path) -> None:
        pass

    def wait_for(self, tick: int) -> int:
        with self.cond:
            assert self.cond.wait_for(lambda: self.tick >= tick, timeout=60)
            return self.tick


def _log(run: Path) -> list[dict[str, Any]]:
    return [json.loads(x) for x in (run / "commands.jsonl").read_text().splitlines()]


@pytest.fixture(scope="module")
def operated(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A run paced at real time whose operator, in another thread, sends
    ``COMMANDS``: for each, the last exchange the probe saw before submitting
    and the last it saw once the command was queued. It is applied after the
    first, and at the latest two exchanges after the second: the exchange
    after it may have taken its commands just before this one came."""
    tmp = tmp_path_factory.mktemp("operated")
    applied: list[dict[str, Any]] = []
    inbox = CommandInbox(on_applied=applied.append)
    probe = Probe()
    bounds: list[tuple[int, int]] = []
    seqs: list[int] = []

    def operator() -> None:
        for at, vehicle, spec in COMMANDS:
            before = probe.wait_for(at)
            seqs.append(inbox.submit(vehicle, spec))
            bounds.append((before, probe.tick))

    thread = threading.Thread(target=operator)
    thread.start()
    res = Run(_scenario(tmp), tmp / "run", backend="inline", realtime=1.0,
              extra_participants=[inbox, probe]).run()
    thread.join(10)
    assert res.stop_reason == "completed", res.error
    return {"run": tmp / "run", "bounds": bounds, "seqs": seqs, "applied": applied,
            "summary": res.summary, "tmp": tmp}


def test_commands_from_another_thread_are_applied_at_the_next_exchange_and_logged(
        operated: dict[str, Any]) -> None:
    log = _log(operated["run"])
    assert operated["seqs"] == [0, 1, 2]
    assert [e["seq"] for e in log] == [0, 1, 2]
    for e, (before, after), (_, vehicle, spec) in zip(log, operated["bounds"], COMMANDS):
        assert e["tick"] % K == 0 and before < e["tick"] <= after + 2 * K, (e, before, after)
        assert e["time_s"] == e["tick"] / HZ
        assert (e["vehicle"], e["command"], e["source"]) == (vehicle, spec, "operator")
    assert operated["applied"] == log  # on_applied heard each entry as logged
    assert operated["summary"]["command_inbox"] == {"commands": 3}
    events = [json.loads(x) for x in (operated["run"] / "events.jsonl").read_text().splitlines()]
    cmds = [e for e in events if e["event"] == "command"]
    assert [(e["tick"], e["vehicle"], e["source"], e["seq"]) for e in cmds] == \
        [(e["tick"], e["vehicle"], "operator", e["seq"]) for e in log]
    assert cmds[0]["label"] == "heading 60"
    # the state log's command column shows each from its tick on
    t = read_states(operated["run"])
    ticks, vehicles = t["tick"].to_numpy(), t["vehicle"].to_pylist()
    labels = t["command"].to_pylist()
    first = min(tk for tk, v, c in zip(ticks, vehicles, labels)
                if v == "uav1" and c == "heading 60")
    assert log[0]["tick"] <= first < log[0]["tick"] + 12  # logged every 12 ticks


def test_a_command_from_another_thread_in_an_unpaced_run_applies_at_the_next_exchange(
        tmp_path: Path) -> None:
    """The run's thread waits inside its exchange at tick 24 while another
    thread submits: the command is applied at 28, the exchange after."""
    inbox = CommandInbox()
    go, done = threading.Event(), threading.Event()

    def in_the_run(tick: int) -> None:
        if tick == 24:
            go.set()
            assert done.wait(30)

    def operator() -> None:
        assert go.wait(60)
        inbox.submit("uav2", {"heading_deg": 45})
        done.set()

    thread = threading.Thread(target=operator)
    thread.start()
    res = Run(_scenario(tmp_path, 0.5), tmp_path / "run", backend="inline",
              extra_participants=[inbox, Probe(in_the_run)]).run()
    thread.join(10)
    assert res.stop_reason == "completed", res.error
    assert [(e["tick"], e["vehicle"]) for e in _log(tmp_path / "run")] == [(28, "uav2")]


def test_the_inbox_run_equals_the_same_commands_as_schedule_items(
        operated: dict[str, Any], tmp_path: Path) -> None:
    """The independent path: the scenario's schedule, at the logged ticks."""
    items = "".join(f"  - {{at_s: {e['tick'] / HZ!r}, vehicles: {e['vehicle']}, "
                    f"command: {json.dumps(e['command'])}}}\n" for e in _log(operated["run"]))
    scn = _scenario(tmp_path, schedule=items)
    assert [i.tick for i in scn.schedule[1:]] == [e["tick"] for e in _log(operated["run"])]
    res = Run(scn, tmp_path / "run", backend="inline").run()
    assert res.stop_reason == "completed", res.error
    assert same_states(read_states(operated["run"]), read_states(tmp_path / "run"))
    video = "cameras/uav1_belly.mp4"
    assert (operated["run"] / video).read_bytes() == (tmp_path / "run" / video).read_bytes()


def test_an_inbox_without_commands_changes_nothing(tmp_path: Path) -> None:
    runs = []
    for name, extra in (("plain", []), ("inbox", [CommandInbox()])):
        res = Run(_scenario(tmp_path, 1.5), tmp_path / name, backend="inline",
                  extra_participants=extra).run()
        assert res.stop_reason == "completed", res.error
        runs.append(tmp_path / name)
    assert same_states(read_states(runs[0]), read_states(runs[1]))
    video = "cameras/uav1_belly.mp4"
    assert (runs[0] / video).read_bytes() == (runs[1] / video).read_bytes()
    assert (runs[1] / "commands.jsonl").read_text() == ""


def test_replay_reproduces_the_states_and_the_video(operated: dict[str, Any],
                                                   tmp_path: Path) -> None:
    res = replay_run(operated["run"], tmp_path / "again")
    assert res.identical, res.differences
    assert res.run.ticks == 180 and res.run.summary["command_inbox"] == {"commands": 3}
    assert res.compared == ["states.parquet: 32 rows, 27 columns",
                            "cameras/uav1_belly.mp4: the same bytes",
                            "cameras/uav1_belly.gt.csv: the same bytes"]
    assert _log(tmp_path / "again") == _log(operated["run"])


def test_a_command_moved_one_exchange_later_replays_different(operated: dict[str, Any],
                                                              tmp_path: Path) -> None:
    run = tmp_path / "tampered"
    shutil.copytree(operated["run"], run)
    log = _log(run)
    log[0]["tick"] += K
    log[0]["time_s"] = log[0]["tick"] / HZ
    (run / "commands.jsonl").write_text("".join(json.dumps(e) + "\n" for e in log))
    res = replay_run(run, tmp_path / "again")
    assert not res.identical
    assert any(d.startswith("states.parquet: ") and "first at tick" in d
               for d in res.differences), res.differences
    assert any(re.fullmatch(r"cameras/uav1_belly\.mp4: frame \d+ differs \(decoded\)", d)
               for d in res.differences), res.differences
    assert "cameras/uav1_belly.gt.csv: the ground truth differs" in res.differences


def test_a_video_of_other_bytes_but_the_same_frames_replays_identical(
        operated: dict[str, Any], tmp_path: Path) -> None:
    """The original's video remuxed with a title: other bytes, the same
    encoded frames, so the same decoded ones."""
    import av

    run = tmp_path / "remuxed"
    shutil.copytree(operated["run"], run)
    video = run / "cameras" / "uav1_belly.mp4"
    with av.open(str(operated["run"] / "cameras" / "uav1_belly.mp4")) as src, \
            av.open(str(video), "w") as dst:
        dst.metadata["title"] = "remuxed"
        stream = dst.add_stream_from_template(src.streams.video[0])
        for packet in src.demux(src.streams.video[0]):
            if packet.dts is not None:
                packet.stream = stream
                dst.mux(packet)
    assert video.read_bytes() != (operated["run"] / "cameras" / "uav1_belly.mp4").read_bytes()
    res = replay_run(run, tmp_path / "again")
    assert res.identical, res.differences
    assert "cameras/uav1_belly.mp4: the same frames (the files' bytes differ)" in res.compared


def test_states_of_the_same_values_in_other_types_replay_different(
        operated: dict[str, Any], tmp_path: Path) -> None:
    """Bit for bit means the types too: the original's ticks as 32-bit
    numbers (the same values) are a difference."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    run = tmp_path / "retyped"
    shutil.copytree(operated["run"], run)
    t = read_states(run)
    t = t.set_column(t.column_names.index("tick"), "tick", t["tick"].cast(pa.int32()))
    shutil.rmtree(run / "states.parquet")
    pq.write_table(t, run / "states.parquet")
    res = replay_run(run, tmp_path / "again")
    assert not res.identical
    assert res.differences == ["states.parquet: tick is int32 in the original, int64 in the "
                               "replay"]


def test_cosim_replay_exit_codes(operated: dict[str, Any], tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(operated["run"]), "--out", str(tmp_path / "a"),
                 "--no-progress"]) == 0
    assert "identical:" in capsys.readouterr().out
    run = tmp_path / "tampered"
    shutil.copytree(operated["run"], run)
    log = _log(run)
    log[2]["command"] = {"alt_agl_m": 100, "airspeed_kt": 90}
    (run / "commands.jsonl").write_text("".join(json.dumps(e) + "\n" for e in log))
    assert main(["replay", str(run), "--out", str(tmp_path / "b"), "--no-progress"]) == 1
    assert "different: states.parquet: " in capsys.readouterr().out
    (run / "commands.jsonl").write_text("{}\n")
    assert main(["replay", str(run), "--out", str(tmp_path / "c")]) == 2
    assert "commands.jsonl:1: expected the keys" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "nowhere")]) == 2
    assert main(["replay", str(run), "--out", str(run)]) == 2
    assert "would overwrite the run it replays" in capsys.readouterr().err


def test_cosim_replay_of_the_current_folder_writes_beside_it(
        operated: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    shutil.copytree(operated["run"], tmp_path / "run")
    monkeypatch.chdir(tmp_path / "run")
    assert main(["replay", ".", "--no-progress"]) == 0, capsys.readouterr().err
    assert (tmp_path / "run-replay" / "states.parquet").exists()


# -- refusals -------------------------------------------------------------------------

MIXED_CLASSES = """\
schema_version: 1
origin: {lat_deg: 37.4150, lon_deg: -122.0480, ground_alt_m: 10}
duration_s: 0.5
vehicles:
  - {id: uav1, model: uav700, init: {north_m: 0, east_m: 0, alt_agl_m: 100,
     heading_deg: 0, airspeed_kt: 100}}
  - {id: f, model: f16, init: {north_m: 5000, alt_msl_m: 3000, airspeed_kt: 400}}
"""


def _mixed_run(folder: Path, inbox: CommandInbox, at: Callable[[int], None]) -> None:
    """``MIXED_CLASSES`` run to its end into ``folder/run`` with ``inbox``, and
    ``at(tick)`` called in the run's thread at every exchange."""
    res = Run(parse_scenario(MIXED_CLASSES, str(folder / "m.yaml")), folder / "run",
              backend="inline", extra_participants=[inbox, Probe(at)]).run()
    assert res.stop_reason == "completed", res.error


def test_bad_submissions_are_refused_saying_what(tmp_path: Path) -> None:
    inbox = CommandInbox()
    with pytest.raises(ConfigError, match=r"the run has not started yet"):
        inbox.submit("uav1", {"heading_deg": 10})
    done: list[int] = []

    def in_the_run(tick: int) -> None:
        """In the run's thread, between two exchanges: nothing is applied in
        between (a failed check here fails the run)."""
        if tick != 8:
            return
        bad: list[tuple[str, dict[str, Any], str]] = [
                ("uav9", {"heading_deg": 10},
                 r"^command for 'uav9': no such vehicle; the run's are uav1, f$"),
                ("uav1", {"headng_deg": 10},
                 r"command for 'uav1': command\.headng_deg: unknown command 'headng_deg'"),
                ("f", {"heading_deg": 10},
                 r"command for 'f': model f16 \(class jsbsim\) takes no commands"),
                ("uav1", {"alt_agl_m": 1},
                 r"command for 'uav1': altitude .* must stay at least \d+ m above it"),
                ("uav1", {"waypoints": [{"north_m": i, "east_m": 0} for i in range(200)]},
                 r"command for 'uav1': the command is \d+ bytes as JSON; at most 4096"),
                ("uav1", {"heading_deg": float("nan")},
                 r"command for 'uav1': not a JSON mapping: Out of range float")]
        for vehicle, spec, message in bad:
            with pytest.raises(ConfigError, match=message):
                inbox.submit(vehicle, spec)
        inbox.submit("f", {"gimbal": {"pitch_deg": -45}})  # for its cameras, as scheduled
        for i in range(MAX_PENDING - 1):
            inbox.submit("uav1", {"heading_deg": i})
        with pytest.raises(ConfigError, match=r"command for 'uav1': 64 commands already wait "
                                              r"for the next exchange"):
            inbox.submit("uav1", {"heading_deg": 99})
        done.append(tick)

    _mixed_run(tmp_path, inbox, in_the_run)
    assert done == [8]
    log = _log(tmp_path / "run")
    assert [(e["seq"], e["tick"]) for e in log] == [(i, 12) for i in range(MAX_PENDING)]
    with pytest.raises(ConfigError, match=r"command for 'uav1': the run is over"):
        inbox.submit("uav1", {"heading_deg": 10})
    with pytest.raises(ConfigError, match=r"replays a logged run; it takes no commands"):
        CommandInbox(replay=[]).submit("uav1", {"heading_deg": 10})


def test_a_run_takes_at_most_max_commands_and_a_source_is_a_name(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(inbox_mod, "MAX_COMMANDS", 2)
    inbox = CommandInbox()
    done: list[int] = []

    def in_the_run(tick: int) -> None:
        if tick in (8, 12):  # one at each of two exchanges, then no more
            inbox.submit("uav1", {"heading_deg": tick})
        if tick == 16:
            with pytest.raises(ConfigError, match=r"command for 'uav1': the run has taken 2 "
                                                  r"commands, as many as a replay of it can "
                                                  r"read; it takes no more"):
                inbox.submit("uav1", {"heading_deg": 16})
            done.append(tick)

    _mixed_run(tmp_path, inbox, in_the_run)
    assert done == [16] and [e["tick"] for e in _log(tmp_path / "run")] == [12, 16]
    for source in ("", "x" * 65, None):
        with pytest.raises(ConfigError, match=r"command inbox: source .*: expected a name of "
                                              r"1 to 64 characters"):
            CommandInbox(source=source)  # type: ignore[arg-type]


def test_a_run_stopped_early_replays_to_the_tick_it_stopped_at(tmp_path: Path) -> None:
    """As the live console's experimenter stops a trial: the replay runs the
    same ticks, no further, and is identical."""
    inbox = CommandInbox()
    runs: list[Run] = []

    def in_the_run(tick: int) -> None:
        if tick == 40:
            inbox.submit("uav1", {"heading_deg": 60})
        if tick == 100:
            runs[0].stop()

    runs.append(Run(_scenario(tmp_path), tmp_path / "run", backend="inline",
                    extra_participants=[inbox, Probe(in_the_run)]))
    res = runs[0].run()
    assert (res.stop_reason, res.ticks) == ("interrupted", 104)
    again = replay_run(tmp_path / "run", tmp_path / "again")
    assert again.identical, again.differences
    assert (again.run.stop_reason, again.run.ticks) == ("completed", 104)
    assert read_states(tmp_path / "again")["tick"].to_pylist()[-1] == 104


GOOD = {"seq": 0, "tick": 8, "time_s": 8 / HZ, "vehicle": "uav1",
        "command": {"heading_deg": 10}, "source": "operator"}


@pytest.mark.parametrize("lines,message", [
    (["{not json"], r"commands\.jsonl:1: not JSON"),
    (["[1]"], r"commands\.jsonl:1: expected a logged command \(a JSON object"),
    ([{**GOOD, "extra": 1}], r"commands\.jsonl:1: expected the keys .*; unknown 'extra'"),
    ([{k: v for k, v in GOOD.items() if k != "tick"}], r":1: expected the keys .*; missing tick"),
    ([GOOD, GOOD], r"commands\.jsonl:2: seq is 0; expected 1"),
    ([{**GOOD, "tick": 6}], r":1: tick 6 is not an exchange of the run \(every 4 ticks\)"),
    ([{**GOOD, "tick": -4}], r":1: tick is -4; expected a whole number 0 to"),
    ([{**GOOD, "tick": 240}], r":1: tick 240 is at or after the tick the run stopped at"),
    ([GOOD, {**GOOD, "seq": 1, "tick": 4}], r":2: tick 4 is before the previous command's"),
    ([{**GOOD, "vehicle": "uav9"}], r":1: vehicle 'uav9' is not a vehicle of the run \(uav1"),
    ([{**GOOD, "time_s": "soon"}], r":1: time_s is 'soon'; expected a number"),
    ([{**GOOD, "source": ""}], r":1: source is ''; expected a name"),
    ([{**GOOD, "command": {"heading_deg": 900}}], r":1: command\.heading_deg: must be"),
    (['{"seq": 0' + " " * 9000 + "}"], r":1: a line of more than 8192 bytes"),
])
def test_bad_command_logs_are_refused_with_file_and_line(tmp_path: Path, lines: list[Any],
                                                         message: str) -> None:
    p = tmp_path / "commands.jsonl"
    p.write_text("".join((x if isinstance(x, str) else json.dumps(x)) + "\n" for x in lines))
    with pytest.raises(ConfigError, match=message):
        read_commands(p, ["uav1", "uav2"], K, 240)


def test_a_cut_last_line_and_too_many_lines_are_refused(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    p = tmp_path / "commands.jsonl"
    p.write_text(json.dumps(GOOD) + "\n" + json.dumps({**GOOD, "seq": 1})[:20])
    with pytest.raises(ConfigError, match=r"commands\.jsonl:2: the last line is cut short"):
        read_commands(p)
    assert replay_mod.MAX_COMMAND_LINES == inbox_mod.MAX_COMMANDS  # every log replays
    monkeypatch.setattr(replay_mod, "MAX_COMMAND_LINES", 3)
    p.write_text("".join(json.dumps({**GOOD, "seq": i}) + "\n" for i in range(4)))
    with pytest.raises(ConfigError, match=r"commands\.jsonl:4: more than 3 commands"):
        read_commands(p)
    p.write_text("".join(json.dumps({**GOOD, "seq": i}) + "\n" for i in range(3)))
    assert [e["seq"] for e in read_commands(p)] == [0, 1, 2]


JSON_VALUES: list[Any] = [None, True, -1, 0, 2 ** 70, 1e308, -0.0, "", "x" * 70, "uav1", [],
                          [1, 2], {}, {"heading_deg": 10}, {"goto": {"north_m": "n"}},
                          {"goto": None}, {"waypoints": [[]]}, {"loiter": {"radius_m": -1}},
                          {"gimbal": {"look_at": 3}}, {"camera": {"interval_s": []}}]


def test_fuzzed_command_logs_are_read_or_refused_naming_the_file(tmp_path: Path) -> None:
    """2000 seeded logs of one to three good lines, each with up to three
    fields set to random JSON values, a line cut, doubled or made of bytes that are
    not UTF-8: each is read, every entry then as it should be, or refused
    with a ConfigError naming the file (never another exception)."""
    rng = random.Random(30)
    p = tmp_path / "commands.jsonl"
    read = refused = 0
    for _ in range(2000):
        lines: list[bytes] = []
        for seq in range(rng.randint(1, 3)):
            e: dict[str, Any] = {**GOOD, "seq": seq, "tick": 8 * (seq + 1)}
            for key in rng.sample([*GOOD, "extra"], rng.choice((0, 0, 0, 1, 2, 3))):
                e[key] = rng.choice(JSON_VALUES)
            lines.append(json.dumps(e).encode())
        kind = rng.randrange(4)
        if kind == 1:
            lines[-1] = lines[-1][:rng.randrange(len(lines[-1]))]
        elif kind == 2:
            lines.append(lines[-1])
        elif kind == 3:
            lines[0] = lines[0].replace(b'"uav1"', b'"uav\xff1"')
        p.write_bytes(b"".join(x + b"\n" for x in lines))
        try:
            entries = read_commands(p, ["uav1", "uav2"], K, 240)
        except ConfigError as e:
            assert str(p) in str(e), e
            refused += 1
            continue
        read += 1
        for i, x in enumerate(entries):
            assert x["seq"] == i and x["tick"] % K == 0 and x["vehicle"] in ("uav1", "uav2")
    assert read > 100 and refused > 1000, (read, refused)


def test_fuzzed_submissions_are_taken_and_flown_or_refused(tmp_path: Path) -> None:
    """600 seeded specs of one or two commands of the vocabulary with random
    values, 60 at each of ten exchanges: each is refused with a ConfigError
    or taken, and the run flies every one it took to the end."""
    from cosim.guidance.commands import COMMAND_KEYS

    rng = random.Random(30)
    good: dict[str, Any] = {
        "heading_deg": 90, "alt_msl_m": 300, "alt_agl_m": 150, "airspeed_kt": 90,
        "airspeed_mps": 45, "throttle": 0.5, "bank_limit_deg": 30, "stall_protection": True,
        "goto": {"north_m": 100, "east_m": 50}, "waypoints": [{"north_m": 0, "east_m": 0}],
        "loiter": {"radius_m": 400}, "takeoff_agl_m": 50, "land": True,
        "velocity": {"north_mps": 1, "east_mps": 0}, "gimbal": {"pitch_deg": -30},
        "camera": {"shoot": True}}
    assert set(good) == set(COMMAND_KEYS)
    inbox = CommandInbox()
    taken: list[int] = []
    refused: list[str] = []

    def in_the_run(tick: int) -> None:
        if not 8 <= tick <= 44:  # ten exchanges
            return
        for _ in range(60):
            spec = {k: good[k] if rng.random() < 0.6 else rng.choice(JSON_VALUES)
                    for k in rng.sample(COMMAND_KEYS, rng.randint(1, 2))}
            try:
                taken.append(inbox.submit(rng.choice(["uav1", "f"]), spec))
            except ConfigError as e:
                refused.append(str(e))

    _mixed_run(tmp_path, inbox, in_the_run)
    assert len(taken) + len(refused) == 600 and len(taken) > 10, (len(taken), len(refused))
    assert [e["seq"] for e in _log(tmp_path / "run")] == taken
    assert all(m.startswith("command for ") for m in refused)


def test_the_limits_are_in_the_readme() -> None:
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert (f"at most {replay_mod.MAX_COMMAND_LINES:,} lines of at most "
            f"{replay_mod.MAX_COMMAND_LINE_BYTES // 1024} KiB each") in readme
    text = " ".join(readme.split())  # the paragraph's words, whatever its line breaks
    for said in (f"more than {inbox_mod.MAX_SPEC_BYTES // 1024} KiB as JSON",
                 f"{inbox_mod.MAX_PENDING} commands already waiting",
                 f"has taken {inbox_mod.MAX_COMMANDS:,} commands"):
        assert said in text, said
