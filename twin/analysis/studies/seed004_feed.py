"""Seed 004: feed stability of the interpolator/regulator interface.

The traditional interface hands the regulator only integer positions; the regulator's speed
is the backward difference ``V(i) = X(i) − X(i−1)`` (counts per tick), which alternates
between the floor and the ceiling of the feed per tick ``F_T = F·k/(60·f)``. Seed 004 (1 kHz,
k = 1000 counts/mm): relative feed error +500 %/−100 % at F = 10 mm/min, ±1 % at 5000.
The extended interface sends float64 velocity alongside the position.

This study runs the twin's own ``Interpolator`` both ways (``mode="traditional"`` rounds the
position to counts and differences it; ``"extended"`` is the product's float channel) on a
straight X move planned by the product's planner, with the seed's rate and resolution, and
measures the speed error over the cruise: ``(V(i) − F_T)/F_T``. It is a property of the
interface, not of the machine, so no plant is involved.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from twin.controller.geometry import Line
from twin.controller.interpolator import Interpolator, InterpolatorStatus
from twin.controller.planner import MotionBlock, Planner
from twin.controller.profiles import Limits

__all__ = ["FEEDS_MM_PER_MIN", "SEED", "feed_errors", "run_study"]

FEEDS_MM_PER_MIN = (10.0, 100.0, 1000.0, 5000.0)
RATE = 1000.0                 # Hz, seed 004
COUNTS_PER_METRE = 1.0e6      # 1000 counts/mm, seed 004
SEED = {"10": {"max_pct": 500.0, "min_pct": -100.0},
        "5000": {"max_pct": 1.0, "min_pct": -1.0}}
"""Seed 004's relative feed errors of the traditional interface (%)."""

_LIMITS = Limits(max_velocity=0.2, max_acceleration=0.5, max_jerk=10.0)
_CRUISE = 2.0                 # s of cruise measured


def _references(feed: float, mode: str) -> dict[str, np.ndarray]:
    """Tick-by-tick X references of one straight move at ``feed`` (m/s)."""
    planner = Planner(_LIMITS, [_LIMITS, _LIMITS], rapid_velocity=0.2, tolerance=1e-5,
                      law="parabolic")
    length = feed * (_CRUISE + 4.0 * feed / _LIMITS.max_acceleration) + 1e-4
    blocks = planner.plan([MotionBlock(Line((0.0, 0.0), (length, 0.0)), feed)])
    interp = Interpolator(blocks, period=1.0 / RATE, start=(0.0, 0.0), mode=mode,
                          counts_per_metre=(COUNTS_PER_METRE, COUNTS_PER_METRE))
    rows = []
    while interp.update() < InterpolatorStatus.FINISHED:
        ref = interp.reference
        rows.append((ref.position[0], ref.velocity[0], ref.acceleration[0], ref.jerk[0]))
    return dict(zip(("position", "velocity", "acceleration", "jerk"), np.array(rows).T,
                    strict=True))


def feed_errors(feed_mm_per_min: float) -> dict[str, float]:
    """Relative speed errors of both interfaces over the cruise at one feed.

    Returns
    -------
    dict
        ``feed_per_tick_counts`` (F_T), traditional ``max_pct``/``min_pct`` of
        ``(V(i) − F_T)/F_T``, its acceleration and jerk spikes in the cruise (m/s², m/s³),
        the float channel's largest ``|V(i) − F|/F`` (1), and ``first_speed_tick``: ticks
        from the start until the differenced speed is first non-zero.
    """
    feed = feed_mm_per_min / 60e3
    ext = _references(feed, "extended")
    trad = _references(feed, "traditional")
    n = min(len(ext["velocity"]), len(trad["velocity"]))
    cruise = np.flatnonzero(np.abs(ext["velocity"][:n] - feed) <= 1e-9 * feed)
    cruise = cruise[1:]                  # the first cruise tick still differences a ramp
    f_t = feed * COUNTS_PER_METRE / RATE
    v_counts = trad["velocity"][cruise] * COUNTS_PER_METRE / RATE
    rel = (v_counts - f_t) / f_t
    moving = np.flatnonzero(trad["velocity"] != 0.0)
    return {
        "feed_mm_per_min": feed_mm_per_min,
        "feed_per_tick_counts": f_t,
        "cruise_ticks": int(cruise.size),
        "max_pct": float(rel.max()) * 100.0,
        "min_pct": float(rel.min()) * 100.0,
        "acceleration_spike": float(np.abs(trad["acceleration"][cruise]).max()),
        "jerk_spike": float(np.abs(trad["jerk"][cruise]).max()),
        "float_channel_max_rel": float(np.abs(ext["velocity"][cruise] - feed).max() / feed),
        "first_speed_tick": int(moving[0]) + 1 if moving.size else -1,
    }


def run_study(*, quick: bool = False) -> dict[str, Any]:
    """All four feeds (the study takes about a second; ``quick`` changes nothing).

    Returns
    -------
    dict
        JSON-ready: ``rows`` per feed, the ``seed`` figures, rate and resolution.
    """
    t0 = time.perf_counter()
    rows = {f"{f:g}": feed_errors(f) for f in FEEDS_MM_PER_MIN}
    return {"study": "seed004_feed",
            "title": "Seed 004: feed stability, integer differences vs float velocity channel",
            "rate_hz": RATE, "counts_per_mm": COUNTS_PER_METRE * 1e-3, "law": "parabolic",
            "rows": rows, "seed": SEED, "quick": quick,
            "wall_time_s": time.perf_counter() - t0}
