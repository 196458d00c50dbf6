"""Benchmark: natural cubic spline coefficients, the sweep against the blocks-of-four solver.

``natural_cubic_points_per_s`` is points through which a spline is built per second of wall
time (best of ``--repeat``), for both methods of ``twin.controller.spline.natural_cubic``
at n = 1e3 and 1e5 random points. For context it also reports scipy's ``CubicSpline``
(natural) and the sweep written as a plain Python loop (how the seed's sweep would run
uncompiled; n = 1e3 only) and ``blocks4_over_tridiagonal`` (> 1 means blocks4 is faster).

``spline_path`` times what the controller tick pays for a ``SplinePath`` of 1000 points, in
µs per call at a new s each time (one s → u inversion): ``point(s)`` (an ndarray), and
``frame(s)`` (point, tangent, curvature and dκ/ds as floats, what the interpolator needs).

Prints one JSON object. Usage: ``python bench/spline.py [--repeat 7]``.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from functools import partial

import numpy as np
from scipy.interpolate import CubicSpline

from twin.controller.spline import METHODS, natural_cubic
from twin.controller.spline_path import SplinePath

SIZES = (1_000, 100_000)


def _best(fn, repeat: int, number: int) -> float:
    """Best wall time of one call (s)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - t0) / number)
    return best


def _thomas_loop(x: np.ndarray, y: np.ndarray) -> list[float]:
    """Second derivatives of the natural spline by the sweep, one Python step per knot."""
    x, y = x.tolist(), y.tolist()
    n = len(x)
    h = [x[i + 1] - x[i] for i in range(n - 1)]
    c_prime, d_prime = [0.0] * n, [0.0] * n
    for i in range(1, n - 1):
        r = 6.0 * ((y[i + 1] - y[i]) / h[i] - (y[i] - y[i - 1]) / h[i - 1])
        m = 2.0 * (h[i - 1] + h[i]) - h[i - 1] * c_prime[i - 1]
        c_prime[i] = h[i] / m
        d_prime[i] = (r - h[i - 1] * d_prime[i - 1]) / m
    second = [0.0] * n
    for i in range(n - 2, 0, -1):
        second[i] = d_prime[i] - c_prime[i] * second[i + 1]
    return second


def _spline_path_us(repeat: int) -> dict[str, float]:
    rng = np.random.default_rng(1)
    angle = np.cumsum(rng.uniform(-0.5, 0.5, 1000))
    pts = 1e-3 * np.cumsum(np.stack((np.cos(angle), np.sin(angle)), axis=1), axis=0)
    t0 = time.perf_counter()
    path = SplinePath(pts)
    build = time.perf_counter() - t0
    s = np.linspace(0.0, path.length, 20_000).tolist()
    best = {"point": np.inf, "frame": np.inf}
    for i in range(repeat):
        for name in best:
            call = getattr(path, name)
            shifted = [si * (1.0 - 1e-9 * (i + 1)) for si in s]  # never a cache hit
            t0 = time.perf_counter()
            for si in shifted:
                call(si)
            best[name] = min(best[name], (time.perf_counter() - t0) / len(s))
    return {"points": len(pts), "build_ms": 1e3 * build, "point_us": 1e6 * best["point"],
            "frame_us": 1e6 * best["frame"]}


def _rates(x: np.ndarray, y: np.ndarray, repeat: int) -> dict[str, float]:
    """Points per second of each way to build the spline through (x, y)."""
    n = x.size
    number = max(1, 200_000 // n)
    builders = {m: partial(natural_cubic, x, y, method=m) for m in METHODS}
    builders["scipy_cubicspline"] = partial(CubicSpline, x, y, bc_type="natural")
    if n <= 1_000:
        builders["thomas_python_loop"] = partial(_thomas_loop, x, y)
    return {name: n / _best(fn, repeat, number) for name, fn in builders.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    ours = {m: {} for m in METHODS}
    context = {"scipy_cubicspline": {}, "thomas_python_loop": {}}
    for n in SIZES:
        rates = _rates(np.cumsum(rng.uniform(0.1, 1.0, n)), rng.normal(size=n), args.repeat)
        for name, rate in rates.items():
            (ours if name in ours else context)[name][str(n)] = rate
    print(json.dumps({
        "benchmark": "spline",
        "machine": platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "natural_cubic_points_per_s": ours,
        "blocks4_over_tridiagonal": {
            k: ours["blocks4"][k] / ours["tridiagonal"][k] for k in ours["blocks4"]},
        "reference_points_per_s": context,
        "spline_path": _spline_path_us(args.repeat),
    }, indent=2))


if __name__ == "__main__":
    main()
