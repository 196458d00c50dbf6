"""Seed 001, chapter 4: a laser-cutting job with stops at every node against look-ahead.

Seed 001 cut an industrial job (32 471.6 mm of cut, 5 304.6 mm of idle travel, 50 mm/s max
cutting speed, 500 mm/s rapids, 800 mm/s² contour acceleration) in 1196 s with the classic
controller that stops at every node and in 830 s with its speed assignment (ratio 0.69).

Here the job is a generated nest of the same size (``twin.analysis.studies.nest``) on ``laser_belt``
(whose contour limits are the seed's), run through the full controller three times at the
same contour tolerance (the machine's 50 µm):

1. ``planner = "stop"`` — the classic controller;
2. ``planner = "lookahead"`` — the product's planner with its default corner model;
3. ``lookahead`` with the corner model calibrated on the twin: the constant c of
   ``SeedCornerModel`` that makes its prediction exact for a 90° corner on this machine
   (measured like the corner study, at 50 mm/s), instead of the first-order-lag default.

The cycle time is the program time (first to last commanded motion), the seed's "cutting
time"; the contour error is the largest distance of the table's true path from the program
(``twin.analysis.compare.true_contour_error``); the run summary's figure, measured on the motor
encoders as the controller sees the table, is kept as ``summary_max_contour_error_um``.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from twin.analysis.compare import true_contour_error
from twin.analysis.studies.common import gcode_program, run_items
from twin.analysis.studies.nest import nest
from twin.analysis.studies.seed001_corner import calibrated_model
from twin.session.run import RunSpec

__all__ = ["SEED", "run_study"]

MACHINE = "laser_belt"
SEED = {"cut_length_mm": 32471.6, "idle_length_mm": 5304.6, "stop_time_s": 1196.0,
        "lookahead_time_s": 830.0, "ratio": 830.0 / 1196.0,
        "mean_speed_stop_mm_per_s": 27.0, "mean_speed_lookahead_mm_per_s": 39.0}
"""Seed 001's job and its two cutting times."""

_QUICK_NEST = {"cols": 2, "rows": 1, "width": 300.0, "height": 150.0}


def _job_run(gcode: str, planner: str, **options: Any) -> dict[str, Any]:
    result = run_items(RunSpec(machine=MACHINE, planner=planner, max_time=4000.0),
                       gcode_program(gcode), **options)
    s = result.summary
    contour = true_contour_error(result)
    return {"status": s["status"], "cycle_time_s": s["cycle_time_s"],
            "max_contour_error_um": float(contour.max()) * 1e6,
            "rms_contour_error_um": float(np.sqrt(np.mean(contour**2))) * 1e6,
            "summary_max_contour_error_um": s["max_contour_error_um"],
            "path_length_mm": s["path_length_mm"], "wall_time_s": s["wall_time_s"]}


def run_study(*, quick: bool = False) -> dict[str, Any]:
    """The job three ways (``quick``: a 2-part nest instead of 24 parts).

    Returns
    -------
    dict
        JSON-ready: the nest's totals, the three runs, the ratios lookahead/stop and the
        seed's figures.
    """
    t0 = time.perf_counter()
    job = nest(**_QUICK_NEST) if quick else nest()
    model, measured = calibrated_model(MACHINE, 0.05)
    runs = {"stop": _job_run(job.gcode, "stop"),
            "lookahead": _job_run(job.gcode, "lookahead"),
            "lookahead_calibrated": _job_run(job.gcode, "lookahead", corner_model=model)}
    stop = runs["stop"]["cycle_time_s"]
    for r in runs.values():
        r["ratio_to_stop"] = r["cycle_time_s"] / stop if stop > 0 else math.nan
        r["mean_cut_speed_mm_per_s"] = job.cut_length / r["cycle_time_s"]
    return {
        "study": "seed001_laser",
        "title": "Seed 001 laser job: stop at every node vs look-ahead, same tolerance",
        "machine": MACHINE,
        "nest": {"cut_length_mm": job.cut_length, "idle_length_mm": job.idle_length,
                 "parts": job.parts, "contours": job.contours, "blocks": job.blocks},
        "contour_tolerance_um": 50.0,
        "calibration": {"measured_relative_error_ms": measured * 1e3,
                        "calibration": model.calibration},
        "runs": runs,
        "seed": SEED,
        "quick": quick,
        "wall_time_s": time.perf_counter() - t0,
    }
