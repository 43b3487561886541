"""``cosim trials``: serve a study in the browser, export its responses,
analyse them (conspicuity angles, the critical gap, recognition; a live
study's sessions scored; the NASA-TLX and SAGAT answers), replay a live
session's runs from their logged commands."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cosim.cli.common import EXIT_FAIL, EXIT_OK, Parser
from cosim.core.section import CliCommand
from cosim.errors import ConfigError


def add_arguments(p: argparse.ArgumentParser) -> None:
    trs = p.add_subparsers(dest="trials_cmd", metavar="ACTION", parser_class=Parser)
    ts = trs.add_parser("serve", help="serve a study: the experimenter's and the "
                                      "participant's pages")
    ts.add_argument("study", metavar="STUDY.yaml")
    ts.add_argument("--host", default="127.0.0.1",
                    help="address to listen on (default 127.0.0.1: this machine only)")
    ts.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    ts.add_argument("--db", metavar="URL_OR_FILE",
                    help="responses database: a SQLite file or a SQLAlchemy URL (default "
                         "STUDY.sqlite beside the study)")
    ts.add_argument("--public", action="store_true",
                    help="allow listening on an address other machines reach")
    te = trs.add_parser("export", help="the responses as CSV")
    te.add_argument("db", metavar="DB", help="the study's database (file or URL)")
    te.add_argument("--out", metavar="CSV", required=True)
    te.add_argument("--live", metavar="CSV",
                    help="also write a live study's clicks here (the live console's "
                         "reports, as stored), a row per click")
    te.add_argument("--live-commands", metavar="CSV",
                    help="also write a live study's map commands here (go, orbit, look: "
                         "as stored, with the tick each was applied at), a row per command")
    te.add_argument("--instruments", metavar="CSV",
                    help="also write the NASA-TLX and SAGAT answers here, a row per block "
                         "or probe")
    ta = trs.add_parser("analyse", help="conspicuity angles and distances, the critical gap, "
                                        "recognition against altitude, speed and conspicuity; "
                                        "with --study, a live study's sessions scored and the "
                                        "NASA-TLX and SAGAT answers")
    ta.add_argument("responses", metavar="DB_OR_CSV",
                    help="the study's database, or a responses CSV (cosim trials export)")
    ta.add_argument("--out", metavar="DIR", required=True, help="folder for the CSVs and PNGs")
    ta.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    ta.add_argument("--tolerance", type=float, default=0.1, metavar="SHARE",
                    help="how far a critical gap may change and still count as constant, "
                         "as a share of it (default 0.1: 10%%)")
    ta.add_argument("--exclude-reshown", action="store_true",
                    help="leave out trials shown a second time after the page was reloaded")
    ta.add_argument("--study", metavar="STUDY.yaml",
                    help="the study file: needed to score a live study's sessions (from the "
                         "database) and to analyse the NASA-TLX and SAGAT answers")
    ta.add_argument("--runs", metavar="DIR",
                    help="a live study's run folders (default STUDY-live beside the study)")
    tr = trs.add_parser("replay", help="run a live session's trials again from their logged "
                                       "commands and say whether the states and videos come "
                                       "out identical")
    tr.add_argument("db", metavar="DB", help="the study's database (file or URL)")
    tr.add_argument("session", metavar="SESSION", help="the live session's id")
    tr.add_argument("--trial", type=int, metavar="N",
                    help="only this trial (default: every trial of the session that has run)")
    tr.add_argument("--out", metavar="DIR",
                    help="where the replays go, a folder a trial (default "
                         "RUNS/SESSION/replay)")
    tr.add_argument("--runs", metavar="DIR",
                    help="the study's live run folders (default STUDY-live beside the "
                         "database STUDY.sqlite)")


def run(a: argparse.Namespace) -> int:
    if a.trials_cmd == "serve":
        from cosim.trials.server import serve

        if not 0 < a.port < 65536:
            raise ConfigError(f"--port must be 1..65535, got {a.port}")
        serve(a.study, host=a.host, port=a.port, db_url=a.db, public=a.public)
        return EXIT_OK
    if a.trials_cmd == "export":
        from cosim.trials.store import export_csv

        _existing_db(a.db)
        print(export_csv(a.db, a.out))
        if a.instruments:
            print(_export_instruments(a.db, a.instruments))
        if a.live:
            print(_export_live(a.db, a.live))
        if a.live_commands:
            print(_export_live(a.db, a.live_commands, commands=True))
        return EXIT_OK
    if a.trials_cmd == "analyse":
        return _analyse(a)
    if a.trials_cmd == "replay":
        return _replay(a)
    raise ConfigError("cosim trials: give serve, export, analyse or replay "
                      "(cosim trials --help)")


def _replay(a: argparse.Namespace) -> int:
    """``cosim trials replay``: each trial of the session replayed; 0 if every
    one is identical, 1 if any differs."""
    import sys

    from cosim.trials.live_replay import default_runs_dir, replay_session
    from cosim.trials.store import Store

    _existing_db(a.db)
    runs = Path(a.runs) if a.runs else default_runs_dir(a.db)
    if runs is None:
        raise ConfigError(f"{a.db}: a database URL: give the study's live run folders "
                          f"(--runs DIR)")
    if a.runs and not runs.is_dir():
        raise ConfigError(f"--runs {a.runs}: no such folder")
    out = Path(a.out) if a.out else runs / a.session / "replay"
    with Store(a.db) as store:
        results = replay_session(store, a.session, runs, out, a.trial,
                                 progress=sys.stderr.isatty())
    for r in results:
        if r.identical:
            print(f"trial {r.trial_index}: identical ({r.run_dir} replayed into {r.out_dir})")
        else:
            print(f"trial {r.trial_index}: differs ({r.run_dir} replayed into {r.out_dir}):")
            for d in r.differences[:50]:
                print(f"  {d}")
            if len(r.differences) > 50:
                print(f"  ... and {len(r.differences) - 50} more")
    return EXIT_OK if all(r.identical for r in results) else EXIT_FAIL


def _analyse(a: argparse.Namespace) -> int:
    """``cosim trials analyse``: a clip study's responses, a live study's
    sessions scored, and the instruments' answers of either."""
    from cosim.trials.study import load_study

    if a.runs and not a.study:
        raise ConfigError("--runs: give the live study too (--study STUDY.yaml)")
    study = load_study(a.study) if a.study else None
    is_db = Path(a.responses).suffix.lower() != ".csv"
    live = study is not None and study.protocol == "live"
    if live and not is_db:
        raise ConfigError(f"{a.responses}: a live study ({a.study}) is analysed from its "
                          f"database (its sessions, clicks and instruments), not a CSV")
    files: list[str] = []
    if is_db:
        _existing_db(a.responses)
    if not live:
        files += _analyse_clips(a)
    if is_db:
        files += _analyse_db(a, study)
    print(f"outputs in {a.out}/: " + ", ".join(dict.fromkeys(files)))
    return EXIT_OK


def _analyse_db(a: argparse.Namespace, study: Any) -> list[str]:
    """A database's live sessions and instrument answers analysed (both need
    the study); what is there and cannot be analysed without it is refused
    (live sessions) or said (instrument answers)."""
    from cosim.trials.store import Store

    files: list[str] = []
    with Store(a.responses) as store:
        has_live = any(r["protocol"] == "live" for r in store.sessions())
        answers = store.instrument_answers()
        if study is None:
            if has_live:
                raise ConfigError(f"{a.responses}: holds live sessions: give their study "
                                  f"(--study STUDY.yaml) to score them")
            if answers:
                print(f"{len(answers)} NASA-TLX and SAGAT answers not analysed: give the "
                      f"study (--study STUDY.yaml)")
            return files
        if study.protocol == "live":
            files += _analyse_live(a, study, store)
        elif has_live:
            raise ConfigError(f"{a.responses}: holds live sessions but {a.study} is a "
                              f"{study.protocol} study: give the live study they belong to")
        if answers:
            files += _analyse_instruments(a, study, store, answers)
    return files


def _analyse_instruments(a: argparse.Namespace, study: Any, store: Any,
                         answers: list[dict[str, Any]]) -> list[str]:
    """The NASA-TLX and SAGAT answers' tables and figures."""
    from cosim.trials.instrument_analysis import analyse_instruments

    sessions = [store.session(r["id"]) for r in store.sessions()]
    summary = analyse_instruments(study, sessions, answers, a.out)
    print(f"instruments: {summary['tlx_blocks']} NASA-TLX blocks of "
          f"{summary['participants']} participants; SAGAT {summary['sagat_correct']} of "
          f"{summary['sagat_questions']} questions answered correctly" +
          (f" ({summary['sagat_unscored']} probes' answers stored unscored, left out)"
           if summary["sagat_unscored"] else ""))
    return list(summary["files"])


def _analyse_live(a: argparse.Namespace, study: Any, store: Any) -> list[str]:
    """Every run trial of the live study's sessions scored and analysed."""
    from cosim.trials.live_analysis import analyse_live
    from cosim.trials.live_results import scored_sessions

    res = scored_sessions(study, store, Path(a.runs) if a.runs else None)
    summary = analyse_live(res.sessions, a.out)
    rep = summary["reports"]
    print(f"live: {len(res.sessions)} trials scored of {summary['participants']} "
          f"participants: {summary['detected']} of {summary['targets']} targets detected; "
          f"{rep['hit']} hits, {rep['duplicate']} duplicates, {rep['false_alarm']} false "
          f"alarms" + (f"; {len(res.not_run)} trials not run (no run folder)"
                       if res.not_run else ""))
    cmds = summary["commands"]
    if any(cmds.values()):
        print(f"live: {sum(cmds.values())} commands from the map ({cmds['go']} go, "
              f"{cmds['orbit']} orbit, {cmds['look']} look): live_tasking_levels.csv")
    return list(summary["files"])


def _analyse_clips(a: argparse.Namespace) -> list[str]:
    """The clip trials' analysis (``analysis.analyse``) and its print-out."""
    import tempfile

    from cosim.trials.analysis import analyse
    from cosim.trials.figures import MAX_PANELS, shown_first
    from cosim.trials.store import export_csv

    src = Path(a.responses)
    with tempfile.TemporaryDirectory() as tmp:
        if src.suffix.lower() != ".csv":  # a database: its responses first
            _existing_db(a.responses)
            src = export_csv(a.responses, Path(tmp) / "responses.csv")
        summary = analyse(src, a.out, seed=a.seed, exclude_reshown=a.exclude_reshown,
                          tolerance=a.tolerance)
    verdicts: dict[str, list[str]] = {}
    for c in summary.get("critical_gap_check", []):
        verdicts.setdefault(c["fit"], []).append(c["verdict"])
    fits = summary.get("critical_gap", {})
    labels = list(fits)
    order = shown_first([fits[label].get("status", "") for label in labels])
    for i in order[:MAX_PANELS]:  # those with a critical gap first, as in the figure
        fit = fits[labels[i]]
        print(f"critical gap, {labels[i]}: {_gap_summary(fit, verdicts.get(labels[i], []))}")
    if len(order) > MAX_PANELS:
        print(f"critical gap: {len(order) - MAX_PANELS} more of the {len(order)} fits in "
              f"critical_gap.csv (those above have a critical gap first)")
    for which, columns in summary.get("binned_conditions", {}).items():
        for column, bins in columns.items():
            print(f"{column}: {sum(b['values'] for b in bins)} values in the {which} "
                  f"responses, cut into {len(bins)} bins of about equal trials, each "
                  f"analysed at its trials' mean (the bins in analysis.json)")
    model = (summary.get("recognise") or {}).get("logistic") or {}
    for name, c in (model.get("coefficients") or {}).items():
        if name != "intercept":
            print(f"recognition, {name}: {c['estimate']:+.2f} (95% CI {c['ci'][0]:+.2f} "
                  f"to {c['ci'][1]:+.2f}) on the log-odds")
    return [Path(f).name for f in summary.get("files", [])]


def _export_live(db: str, out: str, commands: bool = False) -> Path:
    """A live study's stored clicks (``store.LIVE_EXPORT_COLUMNS``) or, with
    ``commands``, its map commands (``store.LIVE_COMMAND_COLUMNS``) as CSV."""
    from cosim.trials.store import LIVE_COMMAND_COLUMNS, LIVE_EXPORT_COLUMNS, Store, write_csv

    with Store(db) as store:
        rows = store.live_commands() if commands else store.live_reports()
    with Path(out).open("w", newline="") as f:
        write_csv(rows, f, LIVE_COMMAND_COLUMNS if commands else LIVE_EXPORT_COLUMNS)
    return Path(out)


def _export_instruments(db: str, out: str) -> Path:
    """The study's NASA-TLX and SAGAT answers as CSV (``instruments``)."""
    from cosim.trials.instruments import write_instruments_csv
    from cosim.trials.store import Store

    with Store(db) as store:
        rows = store.instrument_answers()
    with Path(out).open("w", newline="") as f:
        write_instruments_csv(rows, f)
    return Path(out)


def _gap_summary(fit: dict[str, Any], verdicts: list[str]) -> str:
    """One line of ``cosim trials analyse``'s print-out for a critical-gap fit."""
    u, sym = fit.get("unit"), "d" if fit.get("unit") == "mm" else "h"
    if fit.get("cg") is None:
        return f"{fit.get('status')} ({fit.get('detail')})"
    lo, hi = fit["cg_ci"]
    where = (f"from {sym}0 = {fit['threshold']:.0f} {u}" if fit["status"] == "plateau" else
             f"constant from the lowest level tested ({fit['threshold']:g} {u}) on")
    counts = {v: verdicts.count(v) for v in ("fails", "inconclusive", "untested")}
    total = verdicts.count("holds") + sum(counts.values())
    others = ", ".join(f"{k} at {n}" for k, n in counts.items() if n)
    people = fit.get("participants") or 0
    return (f"{fit['status']}: CG {fit['cg']:.3g} {u} (95% CI {lo:.3g}-{hi:.3g}, "
            f"{fit.get('interval')}, {people} participant{'' if people == 1 else 's'}), "
            f"{where}; the relation holds at {verdicts.count('holds')} of {total} plateau "
            f"levels" + (f" ({others})" if others else ""))


def _existing_db(db: str) -> None:
    """A database file to read must be there (opening a mistyped path would
    make an empty one; ``Store`` refuses one that is not a regular file)."""
    if "://" not in db and not Path(db).exists():
        raise ConfigError(f"{db}: no such trial database")


COMMAND = CliCommand(
    "trials",
    "conspicuity trials with people: a browser trial runner, its responses, their analysis",
    add_arguments, run, rank=100)
