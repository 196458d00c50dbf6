"""The step-interpolator study (seeds 002 and 003): the seeds' claims on the product's
implementations, lines in every quadrant and full circles."""

from __future__ import annotations

import math

from twin.analysis.studies.seed002_steps import run_study


def test_the_seeds_bounds_hold_on_every_line_and_circle():
    r = run_study(quick=True)
    assert r["example"]["of"] == r["example"]["seed"] == "XYXYXXYX"
    lines, circles = r["lines"], r["circles"]
    assert lines["of"]["lines"] == (2 * 12 + 1) ** 2 - 1
    assert all(v["exact_end"] for v in lines.values())
    assert lines["of"]["max_deviation"] < 1.0                     # seed 003: under a step
    assert lines["of_extrapolated"]["max_deviation"] <= math.sqrt(0.5) + 1e-12
    assert lines["of_extrapolated"]["mean_deviation"] < lines["of"]["mean_deviation"]
    assert circles["of"]["max_deviation"] <= 1.0 + 1e-12
    assert circles["of_extrapolated"]["max_deviation"] <= math.sqrt(0.5) + 1e-12
    assert circles["of_extrapolated"]["steps_are_8r"]
    # unit steps only from the OF methods; the DDA pulses both axes in one clock at times
    assert lines["of"]["diagonal_share"] == lines["of_extrapolated"]["diagonal_share"] == 0
    assert lines["of"]["steps_per_move"] == 1.0 > lines["dda"]["steps_per_move"]
    assert lines["dda_preloaded"]["max_deviation"] < lines["dda"]["max_deviation"]
