"""Seeds 002 and 003: the step (pulse) interpolators of stepper-drive controllers.

Seed 003 gives the classic evaluation-function ("OF") interpolator, its worked example
(x_e = 5, y_e = 3) and its bound: the error never exceeds one step. Seed 002 proposes the
extrapolated OF, which takes the sign of F half a step ahead, and says it keeps the
staircase closer to the ideal curve at little extra computation. The digital differential
analyser (DDA) is the other unit-increment family the seeds name.

This study runs the product's implementations (``twin.controller.steps``) on every line
to the end points of a square grid (all four quadrants) and on full circles of every
radius up to a limit, and measures what the seeds claim: the largest and the mean normal
distance of the visited grid nodes from the ideal line or circle (in steps), the number of
steps, and whether the staircase ends exactly on the end point. On every axis-parallel
unit edge the distance is largest at an end (``steps``' docstring), so the nodes give the
deviation of the whole staircase. Integer arithmetic only: no machine is involved.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from twin.controller.steps import (
    dda_linear,
    of_arc,
    of_arc_extrapolated,
    of_linear,
    of_linear_extrapolated,
    path_nodes,
)

__all__ = ["LINE_METHODS", "circle_figures", "line_figures", "run_study"]

LINE_METHODS: dict[str, Callable[[int, int], list[tuple[int, int]]]] = {
    "of": of_linear, "of_extrapolated": of_linear_extrapolated,
    "dda": lambda xe, ye: dda_linear(xe, ye), "dda_preloaded":
    lambda xe, ye: dda_linear(xe, ye, preload=True)}
"""The line interpolators compared, by name."""

CIRCLE_METHODS = {"of": of_arc, "of_extrapolated": of_arc_extrapolated}
"""The circle interpolators compared, by name."""

SEED_EXAMPLE = "XYXYXXYX"
"""Seed 003's worked example: the classic OF's steps to (5, 3)."""


def _letters(steps: Sequence[tuple[int, int]]) -> str:
    return "".join("X" if dy == 0 else "Y" if dx == 0 else "D" for dx, dy in steps)


def line_figures(method: Callable[[int, int], list[tuple[int, int]]], reach: int
                 ) -> dict[str, float]:
    """Every line from (0, 0) to (xe, ye), |xe|, |ye| ≤ ``reach`` steps, not both 0.

    Returns
    -------
    dict
        ``max_deviation`` and ``mean_deviation`` (step) of the nodes from the line,
        ``steps_per_move`` (mean of steps / (|xe| + |ye|): 1 for unit steps, below 1 when
        diagonal steps come), ``diagonal_share`` (of all steps), ``exact_end`` (every move
        ends on its end point) and ``lines``.
    """
    worst, total, nodes_seen, steps_ratio, diagonal, steps_all = 0.0, 0.0, 0, 0.0, 0, 0
    exact = True
    lines = 0
    for xe in range(-reach, reach + 1):
        for ye in range(-reach, reach + 1):
            if xe == 0 and ye == 0:
                continue
            steps = method(xe, ye)
            nodes = path_nodes(steps)
            exact &= tuple(nodes[-1]) == (xe, ye)
            d = np.abs(xe * nodes[:, 1] - ye * nodes[:, 0]) / math.hypot(xe, ye)
            worst = max(worst, float(d.max()))
            total += float(d.sum())
            nodes_seen += len(d)
            steps_ratio += len(steps) / (abs(xe) + abs(ye))
            diagonal += sum(1 for dx, dy in steps if dx and dy)
            steps_all += len(steps)
            lines += 1
    return {"max_deviation": worst, "mean_deviation": total / nodes_seen,
            "steps_per_move": steps_ratio / lines, "diagonal_share": diagonal / steps_all,
            "exact_end": bool(exact), "lines": lines}


def circle_figures(method: Callable[..., list[tuple[int, int]]], radii: Sequence[int]
                   ) -> dict[str, Any]:
    """Full counter-clockwise circles from (R, 0) about the origin, one per radius.

    Returns
    -------
    dict
        ``max_deviation`` and ``mean_deviation`` (step) of the nodes' radius from R,
        ``steps_over_8r``: whether every circle took exactly 8·R steps (the count of a
        4-connected staircase that crosses each axis at ±R), and ``circles``.
    """
    worst, total, seen = 0.0, 0.0, 0
    eight_r = True
    for r in radii:
        steps = method(r, 0, r, 0, ccw=True)
        nodes = path_nodes(steps, start=(r, 0))
        d = np.abs(np.hypot(nodes[:, 0], nodes[:, 1]) - r)
        worst = max(worst, float(d.max()))
        total += float(d.sum())
        seen += len(d)
        eight_r &= len(steps) == 8 * r
    return {"max_deviation": worst, "mean_deviation": total / seen,
            "steps_are_8r": bool(eight_r), "circles": len(radii)}


def run_study(*, quick: bool = False) -> dict[str, Any]:
    """Lines to every node of a ±40-step square (±12 quick) and circles of radius 2 … 60
    (2 … 20 quick).

    Returns
    -------
    dict
        JSON-ready: ``example`` (the classic and extrapolated steps to (5, 3) and the
        seed's), ``lines`` and ``circles`` per method, and the bounds the seeds and the
        module state.
    """
    t0 = time.perf_counter()
    reach, r_max = (12, 20) if quick else (40, 60)
    radii = list(range(2, r_max + 1))        # a unit-step arc needs R ≥ √2
    return {
        "study": "seed002_steps",
        "title": "Seeds 002 and 003: step interpolators, classic and extrapolated OF, DDA",
        "example": {"of": _letters(of_linear(5, 3)),
                    "of_extrapolated": _letters(of_linear_extrapolated(5, 3)),
                    "seed": SEED_EXAMPLE},
        "reach_steps": reach, "max_radius_steps": r_max,
        "lines": {name: line_figures(fn, reach) for name, fn in LINE_METHODS.items()},
        "circles": {name: circle_figures(fn, radii) for name, fn in CIRCLE_METHODS.items()},
        "bounds": {"of_line": 1.0, "of_extrapolated_line": math.sqrt(0.5),
                   "of_circle": 1.0, "of_extrapolated_circle": math.sqrt(0.5)},
        "quick": quick, "wall_time_s": time.perf_counter() - t0}
