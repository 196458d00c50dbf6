"""Seed 001 on laser_belt, short versions: the corner study and the laser job."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from twin.analysis.studies import seed001_corner, seed001_laser
from twin.analysis.studies.nest import nest
from twin.controller.gcode import parse
from twin.controller.planner import segment_of

CI = bool(os.environ.get("CI"))


@pytest.fixture(scope="module")
def corner():
    return seed001_corner.run_study(quick=True)


def test_corner_error_is_linear_in_the_node_speed(corner):
    for variant in ("twin", "frictionless"):
        assert corner[variant]["linear_in_speed"]["r2"] > 0.98


def test_without_friction_corner_error_is_proportional_to_sin_alpha(corner):
    fit = corner["frictionless"]["linear_in_sine"]
    assert fit["r2"] > 0.98
    assert fit["intercept_share"] < 0.05
    # with friction an offset remains (belt stretch of the axis starting from rest)
    assert corner["twin"]["linear_in_sine"]["intercept_share"] > fit["intercept_share"]


def test_seed_relation_fit_recovers_f2_from_exact_data():
    pts = [{"sine": s, "damping": xi, "relative_error_ms": 3.0 * s * (abs(xi - 0.25) + 0.25)}
           for s in (0.2, 0.5, 1.0) for xi in (0.1, 0.4, 0.9)]
    fit = seed001_corner.fit_seed_relation(pts)
    assert fit["f2_ms"] == pytest.approx(3.0, rel=1e-12)
    assert fit["mean_error_pct"] == pytest.approx(0.0, abs=1e-9)


def test_product_corner_model_is_on_the_safe_side(corner):
    # the first-order-lag calibration predicts larger errors than the twin's corners
    model = corner["corner_model"]
    assert model["f2_ms"] > corner["twin"]["seed_relation_fit"]["f2_ms"]
    assert model["fitted_calibration"] < model["calibration"]


def test_default_nest_has_the_seed_jobs_cut_length_and_fits_the_table():
    job = nest()
    assert job.cut_length == pytest.approx(32471.6, rel=0.02)
    assert job.idle_length == pytest.approx(5304.6, rel=0.3)
    moves = [i for i in parse(job.gcode, start=(0.010, 0.010)) if hasattr(i, "end")]
    ends = np.array([m.end for m in moves])
    assert ends[:, 0].min() > 0.003 and ends[:, 0].max() < 1.247      # inside the switches
    assert ends[:, 1].min() > 0.003 and ends[:, 1].max() < 0.797
    # the program as the controller reads it has the lengths the generator counted
    cut = sum(segment_of(m).length for m in moves if m.kind != "rapid")
    idle = sum(math.dist(m.start, m.end) for m in moves if m.kind == "rapid")
    assert cut * 1e3 == pytest.approx(job.cut_length, rel=1e-4)
    assert idle * 1e3 == pytest.approx(job.idle_length, rel=1e-4)


def test_short_laser_job_lookahead_is_not_slower_than_stop():
    r = seed001_laser.run_study(quick=True)
    runs = r["runs"]
    for run in runs.values():
        assert run["status"] == "FINISHED"
    assert runs["lookahead"]["cycle_time_s"] <= runs["stop"]["cycle_time_s"]
    assert runs["lookahead_calibrated"]["cycle_time_s"] <= runs["lookahead"]["cycle_time_s"]
    # at least the pure cutting time at 50 mm/s
    assert runs["stop"]["cycle_time_s"] > r["nest"]["cut_length_mm"] / 50.0


@pytest.mark.parametrize("seed", range(3) if CI else range(12))
def test_random_nests_are_programs_of_their_parts(seed):
    """``random_nest`` (the class of seed 001's job with random grids, kinds and sizes) is
    reproducible; each part's lines hold whole contours (every M3 closed by an M5) and the
    parts follow one another; an unknown kind is refused."""
    from twin.analysis.studies.nest import KINDS, Part, layout, random_nest

    job, parts = random_nest(seed)
    again, _ = random_nest(seed)
    assert again.gcode == job.gcode and len(job.part_lines) == len(parts) >= 2
    lines = job.gcode.splitlines()
    assert all(p.kind in KINDS and 0.0 <= p.size <= 1.0 for p in parts)
    previous = 0
    for first, last in job.part_lines:
        assert first > previous and last >= first
        body = lines[first - 1:last]
        assert body.count("M3") == body.count("M5")
        previous = last
    assert lines.count("M3") == job.contours
    with pytest.raises(ValueError, match="unknown part kind"):
        layout([Part("gear", 0.0, 0.0, 100.0, 100.0, 0.5)])
