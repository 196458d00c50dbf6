"""The acceleration laws compared on CAM output: a chorded nest and small lettering (issue 30).

Engineers compare the laws on their own part programs, which CAM writes as thousands of
short chords. This study runs each law on ``laser_belt`` through the full controller and the
twin on two such programs:

* ``chorded_nest`` — seed 001's nest of 24 parts with every arc as chords within 0.01 mm
  (`twin.analysis.studies.cam.chorded_nest`);
* ``small_lettering`` — the outlines of "xy-twin 2026" with capitals 5 mm tall, chorded
  within 0.01 mm (`twin.analysis.studies.cam.lettering`).

For each law: the planned cycle time of the whole program (the blocks' profile durations,
`cam.planned_time`), and on the twin, for one part of the nest and the word "xy 26" (the
twin runs much slower than the planner plans), the cycle time (first to last commanded
motion) and the largest distance of the table's true path from the program
(`twin.analysis.compare.true_contour_error`). ``BEFORE`` holds the same figures measured
with this study's code on the planner before issue 30 (main at 985b40a), for the
comparison the issue asks for. And the chord-independence table
(`twin.analysis.studies.circles`): per law and radius, the spread of a circle's planned
cycle time over its G3 arc and its chordings; ``BEFORE_CIRCLES`` holds the spreads of main
at 7ef941c (before the chords were faired, `twin.controller.fair`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from twin.analysis.compare import true_contour_error
from twin.analysis.studies import cam
from twin.analysis.studies.circles import chord_independence
from twin.analysis.studies.common import run_items
from twin.config import load_machine
from twin.controller.gcode import parse
from twin.controller.planner import Planner
from twin.controller.profiles import LAWS
from twin.session.run import RunSpec

__all__ = ["BEFORE", "BEFORE_CIRCLES", "MACHINE", "programs", "run_study"]

MACHINE = "laser_belt"

BEFORE: dict[str, dict[str, Any]] = {
    "chorded_nest": {
        "trapezoid": {"planned_s": 761.625, "twin": {"cycle_time_s": 63.3535,
            "max_contour_error_um": 73.4, "rms_contour_error_um": 34.5}},
        "parabolic": {"planned_s": 852.155, "twin": {"cycle_time_s": 65.5690,
            "max_contour_error_um": 73.1, "rms_contour_error_um": 34.4}},
        "cosine": {"planned_s": 854.068, "twin": {"cycle_time_s": 65.8630,
            "max_contour_error_um": 72.0, "rms_contour_error_um": 34.3}},
        "cubic": {"planned_s": 875.028, "twin": {"cycle_time_s": 67.0705,
            "max_contour_error_um": 75.1, "rms_contour_error_um": 34.2}},
        "jerk-limited": {"planned_s": 831.070, "twin": {"cycle_time_s": 63.7245,
            "max_contour_error_um": 73.8, "rms_contour_error_um": 34.5}},
    },
    "small_lettering": {
        "trapezoid": {"planned_s": 12.793, "twin": {"cycle_time_s": 5.6700,
            "max_contour_error_um": 78.6, "rms_contour_error_um": 30.6}},
        "parabolic": {"planned_s": 21.337, "twin": {"cycle_time_s": 9.2645,
            "max_contour_error_um": 64.2, "rms_contour_error_um": 30.3}},
        "cosine": {"planned_s": 20.855, "twin": {"cycle_time_s": 9.0895,
            "max_contour_error_um": 65.6, "rms_contour_error_um": 30.3}},
        "cubic": {"planned_s": 21.876, "twin": {"cycle_time_s": 9.5550,
            "max_contour_error_um": 62.6, "rms_contour_error_um": 30.1}},
        "jerk-limited": {"planned_s": 19.759, "twin": {"cycle_time_s": 8.5365,
            "max_contour_error_um": 63.5, "rms_contour_error_um": 30.7}},
    },
}
"""``runs`` as `run_study` gives them, measured on main at 985b40a (the planner before
issue 30)."""


BEFORE_CIRCLES: dict[str, dict[str, float]] = {
    "trapezoid": {"r0.5": 0.0895, "r1": 0.0779, "r2": 0.0661, "r5": 0.023, "r10": 0.004,
                  "r20": 0.0012},
    "parabolic": {"r0.5": 0.3436, "r1": 0.2504, "r2": 0.2102, "r5": 0.0643, "r10": 0.0336,
                  "r20": 0.0009},
    "cosine": {"r0.5": 0.3092, "r1": 0.2146, "r2": 0.1819, "r5": 0.0542, "r10": 0.0227,
               "r20": 0.001},
    "cubic": {"r0.5": 0.3129, "r1": 0.2108, "r2": 0.1832, "r5": 0.0551, "r10": 0.022,
              "r20": 0.001},
    "jerk-limited": {"r0.5": 0.2903, "r1": 0.1995, "r2": 0.185, "r5": 0.0522, "r10": 0.0233,
                     "r20": 0.001},
}
"""Per law and radius the spread of ``chord_independence`` on main at 7ef941c (chords not
faired, a contour's end chords planned apart from its curve)."""


def programs(twin: bool, quick: bool = False) -> dict[str, str]:
    """The study's programs by name: whole (``twin`` False) or the twin's short versions;
    ``quick``: the lettering alone, one letter."""
    if quick:
        return {"small_lettering": cam.lettering("x", height=5.0, chord=0.01)}
    nest, text = ((1, 1), "xy 26") if twin else ((6, 4), "xy-twin 2026")
    return {"chorded_nest": cam.chorded_nest(*nest),
            "small_lettering": cam.lettering(text, height=5.0, chord=0.01)}


def _planned(gcode: str, law: str) -> float:
    cfg = load_machine(MACHINE)
    planner = Planner.from_settings(cfg.controller, cfg.axes, law=law, work_zone=None)
    return cam.planned_time(planner.plan(parse(gcode, start=(0.01, 0.01))))


def _run(gcode: str, law: str) -> dict[str, Any]:
    def build(cfg, start):
        return list(parse(gcode, start=tuple(start.tolist())))

    result = run_items(RunSpec(machine=MACHINE, profile=law, planner="lookahead",
                               max_time=4000.0), build)
    contour = true_contour_error(result)
    return {"status": result.summary["status"],
            "cycle_time_s": result.summary["cycle_time_s"],
            "max_contour_error_um": float(contour.max()) * 1e6,
            "rms_contour_error_um": float(np.sqrt(np.mean(contour**2))) * 1e6}


def run_study(*, quick: bool = False) -> dict[str, Any]:
    """Every law on both programs, planned and on the twin (``quick``: the trapezoid and the
    jerk-limited law on one letter).

    Returns
    -------
    dict
        JSON-ready: per program and law the planned cycle time of the whole program and
        the twin's figures on its short version, and ``BEFORE``.
    """
    t0 = time.perf_counter()
    whole, short = programs(False, quick), programs(True, quick)
    runs: dict[str, dict[str, Any]] = {}
    for name in whole:
        runs[name] = {}
        for law in ("trapezoid", "jerk-limited") if quick else LAWS:
            runs[name][law] = {"planned_s": _planned(whole[name], law),
                               "twin": _run(short[name], law)}
    circles = {} if quick else chord_independence(load_machine(MACHINE), LAWS)
    return {"study": "laws_on_cam",
            "title": "The acceleration laws on CAM output: chorded nest, small lettering",
            "machine": MACHINE, "runs": runs, "before": {} if quick else BEFORE,
            "chord_independence": circles,
            "chord_independence_before": {} if quick else BEFORE_CIRCLES,
            "quick": quick, "wall_time_s": time.perf_counter() - t0}
