"""Synthetic NASA-TLX and SAGAT answers from a known model, analysed: for
trying the instruments' analysis (and the README's figures) before any
participant has come.

Twelve participants each do four live trials, at 1, 2, 4 and 9 feeds (in a
rotated order), with the TLX after each (a block a trial) and one SAGAT
probe in each. A participant's six ratings of a block are each
TLX_0 + TLX_PER_FEED * feeds + their own offset (sd 8) + noise (sd 6), on
the form's steps of 5 within 0-100; their pairwise choices are drawn once
per participant. The probe's three questions are answered correctly with
probability (of kind) ``last_target`` 0.92 - 0.06 * feeds, ``count``
0.80 - 0.03 * feeds and ``choice`` 0.7 whatever the feeds. The answers go
to ``cosim.trials.instrument_analysis.analyse_instruments`` as the store
gives them (its rows), with a study of those conditions, probe and TLX.

    python examples/instruments_synthetic.py --out analysis/
"""

from __future__ import annotations

import argparse
import itertools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cosim.trials.instrument_analysis import analyse_instruments
from cosim.trials.instruments import SCALE_KEYS, TlxSetting
from cosim.trials.sagat import Probe, Question

FEEDS = (1, 2, 4, 9)
PARTICIPANTS = 12
TLX_0, TLX_PER_FEED = 25.0, 5.0
#: P(correct) = a + b * feeds, per kind of question
SAGAT = {"last_target": (0.92, -0.06), "count": (0.80, -0.03), "choice": (0.70, 0.0)}


@dataclass(frozen=True)
class Condition:
    """What the analysis reads of a live condition."""

    id: str
    conditions: tuple[tuple[str, str], ...]
    fingerprint: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SyntheticStudy:
    """What the analysis reads of a study file."""

    path: Path
    protocol: str = "live"
    live: tuple[Condition, ...] = tuple(Condition(f"feeds{k}", (("feeds", str(k)),))
                                        for k in FEEDS)
    tlx: TlxSetting = TlxSetting(after="block", weights=True)
    sagat: tuple[Probe, ...] = (Probe(0, 30.0, (
        Question("where", "last_target"),
        Question("north", "count", sector=((0.0, 0.0), (500.0, 0.0), (500.0, 500.0))),
        Question("low", "choice", which="lowest", of="alt_agl_m"))),)


def synthetic(seed: int = 1) -> tuple[SyntheticStudy, list[dict[str, Any]],
                                      list[dict[str, Any]]]:
    """(the study, its sessions, their answers as ``Store.instrument_answers`` rows)."""
    rng = np.random.default_rng(seed)
    study = SyntheticStudy(Path("synthetic.yaml"))
    pairs = list(itertools.combinations(SCALE_KEYS, 2))
    sessions, answers = [], []
    for p in range(PARTICIPANTS):
        order = [FEEDS[(p + j) % len(FEEDS)] for j in range(len(FEEDS))]
        sid, who = f"s{p:02d}", f"p{p:02d}"
        sessions.append({"id": sid, "participant": who, "trial_order": [
            {"index": j, "practice": False, "condition_id": f"feeds{k}", "fingerprint": {},
             "break_before": j > 0} for j, k in enumerate(order)]})
        offset = rng.normal(0.0, 8.0)
        choices = {f"{a}/{b}": (a, b)[int(rng.integers(2))] for a, b in pairs}
        for j, k in enumerate(order):
            mean = TLX_0 + TLX_PER_FEED * k + offset
            ratings = {s: int(np.clip(5 * round((mean + rng.normal(0.0, 6.0)) / 5), 0, 100))
                       for s in SCALE_KEYS}
            answers.append({"session": sid, "participant": who, "instrument": "tlx",
                            "trial_index": j, "item": j,
                            "answer": {"ratings": ratings, "pairs": choices},
                            "scores": None})
            scores = {q.id: {"correct": bool(rng.random() < a + b * k), "error": None,
                             "truth": None}
                      for q, (a, b) in zip(study.sagat[0].questions, SAGAT.values())}
            answers.append({"session": sid, "participant": who, "instrument": "sagat",
                            "trial_index": j, "item": 0, "answer": {}, "scores": scores})
    return study, sessions, answers


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="folder for the tables and figures")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    study, sessions, answers = synthetic(a.seed)
    summary = analyse_instruments(study, sessions, answers, a.out)
    print(f"{summary['tlx_blocks']} TLX blocks, {summary['sagat_questions']} SAGAT questions "
          f"into {a.out}/: {', '.join(summary['files'])}")
    print(f"made with: raw TLX {TLX_0:g} + {TLX_PER_FEED:g} x feeds (+ each participant's "
          f"offset); P(correct) " + ", ".join(f"{k} {x:g} {y:+g} x feeds"
                                               for k, (x, y) in SAGAT.items()))


if __name__ == "__main__":
    main()
