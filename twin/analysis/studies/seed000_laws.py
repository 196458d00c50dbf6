"""Seed 000: the parabolic acceleration law against the trapezoid on the same geometry.

Seed 000 ran its O-A-B-C trajectory (three spline sections with different contour speeds:
accelerate on O-A, faster on A-B, slow down on B-C) and reports that, against the classic
trapezoidal velocity diagram, the parabolic acceleration law lowered "the elastic
oscillations in the mechanics and the speed jumps at the junctions of the
acceleration/deceleration intervals by 12.5 %" (and, in its text, the contour errors by the
same 12.5 %).

The twin runs the same three sections (``library.default_program``'s O-A-B-C) on tomsk_xy
with every law, the look-ahead planner and the machine's limits, and measures with the
definitions of ``twin.analysis.compare``: the elastic oscillation of the screw deflection (sampled
every drive interval), the speed jump at junctions, the largest contour error, and the
cycle time. The table gives each law's figures and the parabolic law's change against the
trapezoid, next to the seed's −12.5 %.
"""

from __future__ import annotations

import time
from typing import Any

from twin.analysis.compare import law_figures
from twin.analysis.studies.common import percent, run_items
from twin.controller.library import default_program
from twin.controller.profiles import LAWS
from twin.session.run import RunSpec

__all__ = ["SEED_CHANGE_PCT", "run_study"]

MACHINE = "tomsk_xy"
SEED_CHANGE_PCT = -12.5
"""Seed 000: parabolic against trapezoid, elastic oscillation and junction speed jumps."""

FIGURES = ("elastic_oscillation_um", "junction_speed_jump_mm_per_s", "max_contour_error_um",
           "rms_contour_error_um", "peak_reference_jerk_m_per_s3", "cycle_time_s")


def _oabc(cfg, start):
    return default_program(cfg, start)[:3]


def law_run(law: str) -> dict[str, float]:
    """The O-A-B-C sections with one law: the figures of ``FIGURES``."""
    spec = RunSpec(machine=MACHINE, profile=law, planner="lookahead")
    result = run_items(spec, _oabc, keep_fine=True)
    figures = {**result.summary, **law_figures(result)}
    return {k: float(figures[k]) for k in FIGURES}


def run_study(*, quick: bool = False) -> dict[str, Any]:
    """Every law (``quick``: trapezoid and parabolic only).

    Returns
    -------
    dict
        JSON-ready: ``laws`` {law: figures}, ``change_pct`` (parabolic against trapezoid,
        per figure) and the seed's change.
    """
    t0 = time.perf_counter()
    laws = ("trapezoid", "parabolic") if quick else LAWS
    rows = {law: law_run(law) for law in laws}
    change = {k: percent(rows["parabolic"][k] - rows["trapezoid"][k], rows["trapezoid"][k])
              for k in FIGURES}
    return {"study": "seed000_laws",
            "title": "Seed 000: parabolic vs trapezoid law on the O-A-B-C spline sections",
            "machine": MACHINE, "planner": "lookahead", "laws": rows,
            "change_pct": change, "seed_change_pct": SEED_CHANGE_PCT, "quick": quick,
            "wall_time_s": time.perf_counter() - t0}
