"""``RunningSummary``: fed in blocks of any size, it gives what the single metrics give on
the whole record, in memory that does not grow with the record."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.controller.geometry import Arc, Line
from twin.controller.metrics import (
    contour_error,
    coordinate_error,
    cycle_time,
    overshoot,
    settling_travel,
    velocity_error,
)
from twin.controller.summary import RunningSummary

T = 0.005


def two_moves(rng: np.random.Generator, dwell: int, rest: int):
    """A line, a dwell of ``dwell`` samples, an arc, then ``rest`` samples at rest; the table
    lags, overshoots the end and wanders (noise) while at rest."""
    line = Line((0.0, 0.0), (0.01, 0.0))
    arc = Arc((0.01, 0.0), (0.02, 0.0), (0.015, 0.0), ccw=True)
    n1, n2 = 400, 600
    s1 = np.linspace(0.0, 1.0, n1)
    p1 = np.stack([0.01 * s1, np.zeros(n1)], axis=1)
    phi = np.linspace(math.pi, 0.0, n2)
    p2 = np.stack([0.015 + 0.005 * np.cos(phi), 0.005 * np.sin(phi)], axis=1)
    ref = np.concatenate([p1, np.repeat(p1[-1:], dwell, 0), p2, np.repeat(p2[-1:], rest, 0)])
    ref_vel = np.zeros_like(ref)
    ref_vel[:n1 - 1] = np.diff(p1, axis=0) / T
    ref_vel[n1 + dwell:n1 + dwell + n2 - 1] = np.diff(p2, axis=0) / T
    act = ref + rng.normal(0.0, 2e-6, ref.shape)
    act[-rest:] += np.array([3e-6, 0.0]) * np.exp(-np.arange(rest) / 50.0)[:, None]
    act_vel = ref_vel + rng.normal(0.0, 1e-5, ref.shape)
    t = np.arange(len(ref)) * T
    return t, ref, ref_vel, act, act_vel, [line, arc]


def reference(t, ref, ref_vel, act, act_vel, path):
    coord = coordinate_error(ref, act)
    vel = velocity_error(ref_vel, act_vel)
    contour = contour_error(path, act)
    moving = np.any(ref_vel != 0.0, axis=1)
    idx = np.flatnonzero(moving)
    t_end = t[min(idx[-1] + 1, len(t) - 1)] if idx.size else t[0]
    try:
        travel = settling_travel(t, act, t_end)
    except ValueError:
        travel = math.nan
    return {
        "max_coordinate_error": np.abs(coord).max(axis=0),
        "rms_coordinate_error": np.sqrt(np.mean(coord**2, axis=0)),
        "max_vector_error": np.hypot(*coord.T).max(),
        "max_contour_error": contour.max(),
        "rms_contour_error": np.sqrt(np.mean(contour**2)),
        "max_velocity_error": np.abs(vel).max(axis=0),
        "rms_velocity_error": np.sqrt(np.mean(vel**2, axis=0)),
        "cycle_time": cycle_time(t, moving),
        "settling_travel": travel,
        "overshoot": overshoot(t, act, path[-1].end, path[-1].end_tangent, after=t_end),
    }


def fed(data, sizes, block):
    t, ref, ref_vel, act, act_vel, path = data
    running = RunningSummary(path, block=block)
    i = 0
    for size in sizes:
        j = min(i + size, len(t))
        running.feed(t[i:j], ref[i:j], ref_vel[i:j], act[i:j], act_vel[i:j])
        i = j
    assert i == len(t)
    return running.result()


def check(m, want):
    for name, value in want.items():
        got = np.asarray(getattr(m, name), dtype=float)
        np.testing.assert_allclose(got, value, rtol=1e-12, atol=0.0, err_msg=name)


@pytest.mark.parametrize("seed", range(6))
def test_blocks_of_any_size_give_the_whole_record_metrics(seed):
    rng = np.random.default_rng(seed)
    data = two_moves(rng, dwell=int(rng.integers(0, 300)), rest=int(rng.integers(1, 900)))
    n = len(data[0])
    cuts = np.sort(rng.choice(np.arange(1, n), size=int(rng.integers(1, 40)), replace=False))
    sizes = np.diff(np.concatenate(([0], cuts, [n])))
    m = fed(data, sizes, block=int(rng.integers(1, 500)))   # tails compacted many times
    assert m.samples == n
    check(m, reference(*data))


def test_a_long_rest_is_kept_as_its_hull_with_the_same_settling_travel():
    data = two_moves(np.random.default_rng(9), dwell=0, rest=20_000)
    running = RunningSummary(data[-1], block=256)
    for i in range(0, len(data[0]), 100):
        running.feed(*(a[i:i + 100] for a in data[:-1]))
        assert running._tail_n <= 2 * 256 + 100        # bounded whatever the rest's length
    check(running.result(), reference(*data))


@pytest.mark.parametrize("case", ["moving to the end", "nothing moves", "one sample"])
def test_edge_cases_agree(case):
    t, ref, ref_vel, act, act_vel, path = two_moves(np.random.default_rng(3), 10, 50)
    if case == "moving to the end":
        keep = slice(0, 300)
    elif case == "nothing moves":
        keep = slice(len(t) - 40, len(t))
    else:
        keep = slice(len(t) - 1, len(t))
    data = (*(a[keep] for a in (t, ref, ref_vel, act, act_vel)), path)
    m = fed(data, [7] * (len(data[0]) // 7 + 1), block=5)
    want = reference(*data)
    check(m, {k: v for k, v in want.items() if k != "settling_travel"})
    if math.isnan(want["settling_travel"]):
        assert math.isnan(m.settling_travel)
    else:
        assert m.settling_travel == pytest.approx(want["settling_travel"], rel=1e-12)


def test_a_diverged_sample_makes_the_maxima_nan():
    data = list(two_moves(np.random.default_rng(4), 0, 100))
    data[3] = data[3].copy()
    data[3][-30] = np.nan
    m = fed(data, [64] * 40, block=64)
    assert math.isnan(m.max_contour_error) and math.isnan(m.settling_travel)


@pytest.mark.parametrize("seed", range(4))
def test_the_run_summary_derives_velocity_across_feeds_like_numpy(seed):
    """Behind real I/O the velocity is the derivative of the measured position; fed in
    pieces (down to one sample), it is numpy's gradient of the whole record."""
    from twin.controller.summary import summarize
    from twin.session.record import RunSummary

    rng = np.random.default_rng(seed)
    t, ref, ref_vel, act, _, path = two_moves(rng, dwell=50, rest=200)
    t = t + rng.uniform(0.0, 0.3 * T, len(t))        # uneven ticks, as a paced loop gives
    rec = {"t": t, "ref_position": ref, "ref_velocity": ref_vel, "position": act}
    running = RunSummary(path)
    cuts = np.sort(rng.choice(np.arange(1, len(t)), size=60, replace=False))
    for a, b in zip(np.concatenate(([0], cuts)), np.concatenate((cuts, [len(t)])),
                    strict=True):
        running.feed({k: v[a:b] for k, v in rec.items()})
    got = running.result()
    want = summarize(t, ref, ref_vel, act, np.gradient(act, t, axis=0), path).to_report()
    assert got["max_velocity_error_um_s"]["x"] == pytest.approx(
        want["max_velocity_error_x_mm_per_min"] / 60_000 * 1e6, rel=1e-9)
    assert got["max_velocity_error_um_s"]["y"] == pytest.approx(
        want["max_velocity_error_y_mm_per_min"] / 60_000 * 1e6, rel=1e-9)
    assert got["max_contour_error_um"] == want["max_contour_error_um"]
    assert got["cycle_time_s"] == want["cycle_time_s"]
