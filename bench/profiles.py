"""Benchmark: cost of the acceleration laws where the controller pays for them.

``at_us``: one ``Profile.at(t)`` per law (what a controller tick pays), on the Tomsk rig's
accelerate-cruise-brake move of 10 mm, at 20 000 times spread over the move; best of
``--repeat``. ``sample_points_per_s``: ``Profile.sample`` on 100 000 times at once.
``plan_move_us``: planning that move (the jerk-limited law calls ruckig). ``closed_forms``:
calls per second of ``min_distance`` and ``max_end_speed`` (what the look-ahead planner calls
per block), and ``planner_pairs_per_s``, one of each per block, the rate that bounds a
planner built on them. ``jerk_limited``: over 2000 random moves of random limits (end
speeds 0, at the cap or between; distances 1e-8 to 10 times longer than one speed change,
or 1 µm to 1 m between equal speeds),
the share that ruckig planned and the share left to the closed-form fallback (ruckig errs on
some moves a hair longer than one speed change).

Prints one JSON object. Usage: ``python bench/profiles.py [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

from twin.controller.profiles import LAWS, Limits, max_end_speed, min_distance, plan_move
from twin.controller.profiles.scurve import ruckig_segments

TOMSK = Limits(max_velocity=0.015, max_acceleration=0.2, max_jerk=5.0)
DISTANCE = 0.01


def _best(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _move(law: str):
    return plan_move(law, DISTANCE, v_start=0.0, v_end=0.0, v_max=0.015, limits=TOMSK)


def _at_us(law: str, repeat: int) -> float:
    move = _move(law)
    times = np.linspace(0.0, move.duration, 20_000).tolist()
    at = move.at

    def run():
        for t in times:
            at(t)
    return _best(run, repeat) / len(times) * 1e6


def _sample_points_per_s(law: str, repeat: int) -> float:
    move = _move(law)
    times = np.linspace(0.0, move.duration, 100_000)
    return times.size / _best(lambda: move.sample(times), repeat)


def _plan_us(law: str, repeat: int) -> float:
    n = 200
    return _best(lambda: [_move(law) for _ in range(n)], repeat) / n * 1e6


def _closed_forms(law: str, repeat: int) -> dict[str, float]:
    rng = np.random.default_rng(1)
    speeds = rng.uniform(0.0, 0.015, 10_000).tolist()
    lengths = rng.uniform(1e-5, 5e-3, 10_000).tolist()
    pairs = list(zip(speeds, lengths, strict=True))

    def distances():
        for v, _ in pairs:
            min_distance(law, v, 0.0, TOMSK)

    def ends():
        for v, d in pairs:
            max_end_speed(law, v, d, TOMSK)

    def both():
        for v, d in pairs:
            max_end_speed(law, v, d, TOMSK)
            min_distance(law, v, 0.0, TOMSK)

    n = len(pairs)
    return {"min_distance_per_s": n / _best(distances, repeat),
            "max_end_speed_per_s": n / _best(ends, repeat),
            "planner_pairs_per_s": n / _best(both, repeat)}


def _ruckig_share(cases: int = 2000) -> dict[str, float]:
    rng = np.random.default_rng(3)
    solved = 0
    for _ in range(cases):
        lim = Limits(10 ** rng.uniform(-3, 0), 10 ** rng.uniform(-1.3, 1),
                     10 ** rng.uniform(0, 3))
        vs, ve = (rng.choice([0.0, lim.max_velocity, rng.uniform(0.0, lim.max_velocity)])
                  for _ in range(2))
        d = min_distance("jerk-limited", vs, ve, lim) * (1 + 10 ** rng.uniform(-8, 1))
        if d == 0.0:                      # equal speeds: any length
            d = 10 ** rng.uniform(-6, 0)
        solved += ruckig_segments(d, vs, ve, lim.max_velocity, lim) is not None
    return {"cases": cases, "ruckig_share": round(solved / cases, 4),
            "closed_form_fallback_share": round(1 - solved / cases, 4)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    r = args.repeat
    print(json.dumps({
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "move": {"distance": DISTANCE, "limits": [TOMSK.max_velocity, TOMSK.max_acceleration,
                                                  TOMSK.max_jerk]},
        "at_us": {law: round(_at_us(law, r), 3) for law in LAWS},
        "sample_points_per_s": {law: round(_sample_points_per_s(law, r)) for law in LAWS},
        "plan_move_us": {law: round(_plan_us(law, r), 1) for law in LAWS},
        "closed_forms": {law: {k: round(v) for k, v in _closed_forms(law, r).items()}
                         for law in LAWS},
        "jerk_limited": _ruckig_share(),
    }, indent=1))


if __name__ == "__main__":
    main()
