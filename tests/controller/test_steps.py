"""Step interpolators: exact sequences, references and the deviation bounds proven by brute force.

Deviations are measured at the visited nodes; on an axis-parallel unit edge the distance to a
line and the radius take their extremes at the ends (see the module docstring), so the
node deviation is the deviation of the whole staircase.
"""

from __future__ import annotations

import itertools
import math
import random

import numpy as np
import pytest

from twin.controller.steps import (
    dda_linear,
    of_arc,
    of_arc_extrapolated,
    of_linear,
    of_linear_extrapolated,
    path_nodes,
)

HALF_DIAGONAL = math.sqrt(0.5)
EPS = 1e-12
LINE_RANGE = range(-40, 41)
ENDPOINTS = [(xe, ye) for xe in LINE_RANGE for ye in LINE_RANGE]
X, Y = (1, 0), (0, 1)


# ------------------------------------------------------------------------ references
def line_deviation(nodes: np.ndarray, xe: int, ye: int) -> np.ndarray:
    """Normal distance of each node from the line (0, 0)-(xe, ye) (step)."""
    norm = math.hypot(xe, ye)
    if norm == 0:
        return np.zeros(len(nodes))
    return np.abs(xe * nodes[:, 1] - ye * nodes[:, 0]) / norm


def reference_of_linear(xe: int, ye: int) -> list[tuple[int, int]]:
    """Seed 003's rule with F evaluated from the node itself, not updated incrementally."""
    a, b, sx, sy = abs(xe), abs(ye), 1 if xe >= 0 else -1, 1 if ye >= 0 else -1
    x = y = 0
    out = []
    while (x, y) != (a, b):
        f = a * y - b * x
        if y == b or (x < a and f >= 0):
            x, step = x + 1, (sx, 0)
        else:
            y, step = y + 1, (0, sy)
        out.append(step)
    return out


def minimax_deviation(a: int, b: int) -> float:
    """Smallest possible max normal deviation of a monotone unit-step path (0,0) → (a, b).

    Bottleneck dynamic programme over every monotone lattice path (brute force, no use of
    the anti-diagonal argument).
    """
    if a == 0 or b == 0:
        return 0.0
    xs, ys = np.meshgrid(np.arange(a + 1), np.arange(b + 1), indexing="ij")
    dev = np.abs(a * ys - b * xs) / math.hypot(a, b)
    best = np.full((a + 1, b + 1), np.inf)
    for x in range(a + 1):
        for y in range(b + 1):
            before = min(best[x - 1, y] if x else np.inf, best[x, y - 1] if y else np.inf)
            best[x, y] = dev[x, y] if x == y == 0 else max(dev[x, y], before)
    return float(best[a, b])


def quadrant(x: int, y: int, ccw: bool) -> int:
    """Half-open quadrant in the direction of motion, written out from the definition."""
    table = ([(x > 0 and y >= 0), (x <= 0 and y > 0), (x < 0 and y <= 0), (x >= 0 and y < 0)]
             if ccw else
             [(x >= 0 and y > 0), (x < 0 and y >= 0), (x <= 0 and y < 0), (x > 0 and y <= 0)])
    return table.index(True)


def tangent_signs(q: int, ccw: bool) -> tuple[int, int]:
    """Signs of the tangent (−y, x) (ccw) or (y, −x) (cw) inside quadrant q."""
    ccw_signs = [(-1, 1), (-1, -1), (1, -1), (1, 1)][q]
    return ccw_signs if ccw else (-ccw_signs[0], -ccw_signs[1])


def reference_circle(x0: int, y0: int, *, ccw: bool, extrapolated: bool
                     ) -> list[tuple[int, int]]:
    """Full circle by the plain rule: of the two candidates take the one with the smaller
    radius when F (classic: at the node; extrapolated: at the candidates' midpoint) ≥ 0."""
    r2 = x0 * x0 + y0 * y0
    x, y = x0, y0
    out = []
    for _ in range(16 * (math.isqrt(r2) + 2)):
        sx, sy = tangent_signs(quadrant(x, y, ccw), ccw)
        candidates = sorted([(x + sx, y), (x, y + sy)], key=lambda p: p[0] ** 2 + p[1] ** 2)
        if extrapolated:
            inward = (x + sx / 2) ** 2 + (y + sy / 2) ** 2 - r2 > 0  # exact: halves
        else:
            inward = x * x + y * y - r2 >= 0
        nx, ny = candidates[0] if inward else candidates[1]
        out.append((nx - x, ny - y))
        x, y = nx, ny
        if (x, y) == (x0, y0):
            return out
    raise AssertionError("reference walk did not close")


def radial_deviation(steps, start, center=(0, 0)) -> np.ndarray:
    nodes = path_nodes(steps, start=start) - np.asarray(center)
    return np.abs(np.hypot(nodes[:, 0], nodes[:, 1]) - math.hypot(start[0] - center[0],
                                                                  start[1] - center[1]))


def check_unit_steps(steps, start, end) -> None:
    assert all(abs(dx) + abs(dy) == 1 for dx, dy in steps)
    assert tuple(path_nodes(steps, start=start)[-1]) == tuple(end)


# ------------------------------------------------------------------------------ lines
def test_seed_003_worked_example():
    """x_e = 5, y_e = 3: X Y X Y X X Y X with F = −3, 2, −1, 4, 1, −2, 3, 0 after each step."""
    steps = of_linear(5, 3)
    assert steps == [X, Y, X, Y, X, X, Y, X]
    nodes = path_nodes(steps)[1:]
    assert (5 * nodes[:, 1] - 3 * nodes[:, 0]).tolist() == [-3, 2, -1, 4, 1, -2, 3, 0]


def test_extrapolated_worked_example_picks_nearer_node():
    # Seed 002 on the same line: from (2, 1) (F = −1) the nodes (3, 1) and (2, 2) have
    # F = −4 and +4 (a tie); at (1, 0) the classic rule went to (1, 1) (F = +2) like this one.
    assert of_linear_extrapolated(5, 3) == [X, Y, X, X, Y, X, Y, X]


@pytest.mark.parametrize("fn", [of_linear, of_linear_extrapolated])
@pytest.mark.parametrize("xe, ye", [(0, 0), (7, 0), (-7, 0), (0, 4), (0, -4), (-3, 3)])
def test_line_trivial_cases(fn, xe, ye):
    steps = fn(xe, ye)
    assert len(steps) == abs(xe) + abs(ye)
    check_unit_steps(steps, (0, 0), (xe, ye))
    assert line_deviation(path_nodes(steps), xe, ye).max(initial=0) <= HALF_DIAGONAL + EPS


def test_classic_line_matches_direct_evaluation_and_bound():
    """All end points |xe|, |ye| ≤ 40: reference sequence, exact counts, bound max(a,b)/√(a²+b²)."""
    for xe, ye in ENDPOINTS:
        steps = of_linear(xe, ye)
        assert steps == reference_of_linear(xe, ye)
        xs = sum(1 for dx, _ in steps if dx)
        assert (xs, len(steps) - xs) == (abs(xe), abs(ye))
        dev = line_deviation(path_nodes(steps), xe, ye).max()
        if xe and ye:
            assert dev <= max(abs(xe), abs(ye)) / math.hypot(xe, ye) + EPS < 1.0
        else:
            assert dev == 0.0


def test_extrapolated_line_takes_the_nearest_node_of_every_anti_diagonal():
    """On every anti-diagonal |x| + |y| = k the visited node is the nearest to the line."""
    worst = 0.0
    for xe, ye in ENDPOINTS:
        steps = of_linear_extrapolated(xe, ye)
        check_unit_steps(steps, (0, 0), (xe, ye))
        a, b = abs(xe), abs(ye)
        nodes = np.abs(path_nodes(steps))
        for k, (x, y) in enumerate(nodes):
            assert x + y == k
            on_diagonal = [abs(a * (k - i) - b * i) for i in range(max(0, k - b), min(a, k) + 1)]
            assert abs(a * y - b * x) == min(on_diagonal)
        if a and b:
            dev = line_deviation(path_nodes(steps), xe, ye).max()
            assert dev <= (a + b) / (2 * math.hypot(a, b)) + EPS
            worst = max(worst, dev)
    assert worst <= HALF_DIAGONAL + EPS


def test_extrapolated_line_is_minimax_optimal_and_never_worse_than_classic():
    """Its max deviation equals the best over all monotone paths (brute force), any quadrant."""
    for a in range(0, 41, 3):
        for b in range(0, 41):
            optimum = minimax_deviation(a, b)
            for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
                xe, ye = sx * a, sy * b
                ext = line_deviation(path_nodes(of_linear_extrapolated(xe, ye)), xe, ye).max()
                classic = line_deviation(path_nodes(of_linear(xe, ye)), xe, ye).max()
                assert ext == pytest.approx(optimum, abs=EPS)
                assert ext <= classic + EPS


def test_linear_validation():
    with pytest.raises(TypeError, match="xe"):
        of_linear(2.5, 1)
    with pytest.raises(TypeError, match="ye"):
        of_linear_extrapolated(2, True)
    assert of_linear(np.int64(2), np.int32(1)) == of_linear(2, 1)


# -------------------------------------------------------------------------------- DDA
@pytest.mark.parametrize("preload", [False, True])
def test_dda_matches_accumulator_formula_and_bounds(preload):
    """Nodes are floor((k·a + p)/2**bits) per axis for clocks k = 0 … 2**bits."""
    for xe, ye in ENDPOINTS:
        a, b = abs(xe), abs(ye)
        for bits in {None, 7}:
            steps = dda_linear(xe, ye, bits=bits, preload=preload)
            width = bits or max(1, (max(a, b) - 1).bit_length())
            cap = 1 << width
            p = cap // 2 if preload else 0
            expected = [(0, 0)]
            for k in range(1, cap + 1):
                node = ((k * a + p) // cap, (k * b + p) // cap)
                if node != expected[-1]:
                    expected.append(node)
            nodes = path_nodes(steps)
            assert np.abs(nodes).tolist() == [list(e) for e in expected]
            assert tuple(nodes[-1]) == (xe, ye)
            assert all(dx in (0, (xe > 0) - (xe < 0)) and dy in (0, (ye > 0) - (ye < 0))
                       and (dx or dy) for dx, dy in steps)
            if a and b:
                dev = line_deviation(nodes, xe, ye).max()
                bound = (a + b) / 2 if preload else max(a, b)
                assert dev <= bound / math.hypot(a, b) + EPS


def test_dda_emits_diagonal_steps_when_both_axes_overflow():
    steps = dda_linear(4, 4, bits=2)
    assert steps == [(1, 1)] * 4
    assert dda_linear(-3, 2, bits=2) == [(-1, 1), (-1, 0), (-1, 1)]  # x 0,1,2,3; y 0,1,1,2
    assert dda_linear(0, 0) == []


@pytest.mark.parametrize("xe, ye, bits", [(9, 1, 3), (1, -17, 4), (1, 1, 0)])
def test_dda_register_too_narrow(xe, ye, bits):
    with pytest.raises(ValueError, match=f"bits = {bits}"):
        dda_linear(xe, ye, bits=bits)


# ------------------------------------------------------------------------------- arcs
ARC_FUNCS = [(of_arc, False), (of_arc_extrapolated, True)]
SMALL_STARTS = [(x, y) for x in range(-20, 21) for y in range(-20, 21) if x * x + y * y >= 2]
OCTANT_STARTS = [(x, y) for x in range(0, 61) for y in range(0, x + 1)
                 if 2 <= x * x + y * y <= 3600]


@pytest.mark.parametrize("fn, extrapolated", ARC_FUNCS)
def test_full_circles_match_the_plain_rule(fn, extrapolated):
    """Incremental F, quadrant changes and the end condition against a direct evaluation."""
    for start in SMALL_STARTS:
        for ccw in (True, False):
            assert fn(*start, *start, ccw=ccw) == reference_circle(
                *start, ccw=ccw, extrapolated=extrapolated)


@pytest.mark.parametrize("fn, extrapolated", ARC_FUNCS)
def test_full_circle_bounds(fn, extrapolated):
    """Classic |r − R| ≤ 1, extrapolated ≤ √2/2, radius up to 60, every direction."""
    bound = HALF_DIAGONAL if extrapolated else 1.0
    for i, (x0, y0) in enumerate(OCTANT_STARTS):
        turned = ((-y0, x0), (-x0, -y0), (y0, -x0))[i % 3]  # starts in every quadrant
        for start in ((x0, y0), turned):
            for ccw in (True, False):
                steps = fn(*start, *start, ccw=ccw)
                check_unit_steps(steps, start, start)
                assert radial_deviation(steps, start).max() <= bound + EPS


def test_extrapolated_full_circle_step_counts_are_exact():
    """Each axis is crossed at ±round(R): 8·round(R) steps, 4·round(R) on each axis."""
    for x0, y0 in OCTANT_STARTS:
        radius = math.hypot(x0, y0)
        for ccw in (True, False):
            steps = of_arc_extrapolated(x0, y0, x0, y0, ccw=ccw)
            nodes = path_nodes(steps, start=(x0, y0))
            n = round(radius)
            assert len(steps) == 8 * n
            assert sum(1 for dx, _ in steps if dx) == 4 * n
            assert nodes.max(axis=0).tolist() == [n, n]
            assert nodes.min(axis=0).tolist() == [-n, -n]


def test_extrapolated_arc_takes_the_node_nearest_to_the_circle_on_each_diagonal():
    """Every step: of all grid nodes on the line through the two candidates, the chosen one is
    the nearest to where the circle crosses that line (so |r − R| ≤ √2/2)."""
    for x0, y0 in OCTANT_STARTS[::7]:
        r2 = x0 * x0 + y0 * y0
        for ccw in (True, False):
            steps = of_arc_extrapolated(x0, y0, x0, y0, ccw=ccw)
            nodes = path_nodes(steps, start=(x0, y0))
            for (x, y), chosen in itertools.pairwise(nodes):
                sx, sy = tangent_signs(quadrant(int(x), int(y), ccw), ccw)
                c1, d = np.array([x + sx, y]), np.array([-sx, sy])  # c2 = c1 + d
                qa, qb, qc = d @ d, 2 * c1 @ d, c1 @ c1 - r2
                disc = math.sqrt(qb * qb - 4 * qa * qc)
                t = min(((-qb - disc) / (2 * qa), (-qb + disc) / (2 * qa)),
                        key=lambda t: abs(t - 0.5))
                assert (c1 + round(t) * d).tolist() == chosen.tolist()


@pytest.mark.parametrize("fn, extrapolated", ARC_FUNCS)
def test_partial_arcs_are_prefixes_of_the_full_circle(fn, extrapolated):
    for start in SMALL_STARTS[::5]:
        for ccw in (True, False):
            full = fn(*start, *start, ccw=ccw)
            nodes = path_nodes(full, start=start)
            for k in range(1, len(full), 3):
                assert fn(*start, *nodes[k], ccw=ccw) == full[:k]


@pytest.mark.parametrize("fn, extrapolated", ARC_FUNCS)
def test_arcs_to_any_end_within_one_step(fn, extrapolated):
    """End points up to one step off the circle: exact arrival, deviation ≤ max(bound, end's)."""
    rng = random.Random(3)
    bound = HALF_DIAGONAL if extrapolated else 1.0
    grid = np.stack(np.meshgrid(np.arange(-61, 62), np.arange(-61, 62)), axis=-1).reshape(-1, 2)
    grid_radius = np.hypot(grid[:, 0], grid[:, 1])
    for x0, y0 in OCTANT_STARTS[::4]:
        radius = math.hypot(x0, y0)
        ring = grid[(np.abs(grid_radius - radius) <= 1.0) & (grid_radius > 0)].tolist()
        for end in map(tuple, rng.sample(ring, min(6, len(ring)))):
            for ccw in (True, False):
                steps = fn(x0, y0, *end, ccw=ccw)
                check_unit_steps(steps, (x0, y0), end)
                off = abs(math.hypot(*end) - radius)
                assert radial_deviation(steps, (x0, y0)).max() <= max(bound, off) + EPS


@pytest.mark.parametrize("fn, extrapolated", ARC_FUNCS)
def test_clockwise_is_the_mirror_of_counter_clockwise(fn, extrapolated):
    for x0, y0 in SMALL_STARTS[::3]:
        for xe, ye in ((x0, y0), (-y0, x0), (y0, x0)):
            cw = fn(x0, y0, xe, ye, ccw=False)
            ccw = fn(x0, -y0, xe, -ye, ccw=True)
            assert cw == [(dx, -dy) for dx, dy in ccw]


@pytest.mark.parametrize("fn, extrapolated", ARC_FUNCS)
@pytest.mark.parametrize("start, end, ccw, visits, x_sign, y_sign", [
    ((10, 0), (0, 10), True, [], -1, 1),                      # quarter, inside Q1
    ((10, 0), (-10, 0), True, [(0, 10)], 0, 0),               # half, crosses into Q2
    ((10, 0), (0, 10), False, [(0, -10), (-10, 0)], 0, 0),    # three quarters clockwise
    ((7, 7), (7, -7), False, [(10, 0)], 0, -1),               # across the +x axis
    ((-7, -7), (7, 7), True, [(0, -10), (10, 0)], 0, 0),      # half, Q3 through Q4 to Q1
])
def test_arcs_across_quadrant_boundaries(fn, extrapolated, start, end, ccw, visits, x_sign,
                                         y_sign):
    steps = fn(*start, *end, ccw=ccw)
    check_unit_steps(steps, start, end)
    nodes = {tuple(p) for p in path_nodes(steps, start=start).tolist()}
    assert set(visits) <= nodes
    if x_sign:
        assert all(dx in (0, x_sign) for dx, _ in steps)
    if y_sign:
        assert all(dy in (0, y_sign) for _, dy in steps)


@pytest.mark.parametrize("fn, extrapolated", ARC_FUNCS)
def test_centre_offset_only_translates(fn, extrapolated):
    assert fn(15, 7, 12, 15, ccw=True, center=(5, 7)) == fn(10, 0, 7, 8, ccw=True)
    assert fn(-3, -9, -3, -9, ccw=False, center=(-8, -9)) == fn(5, 0, 5, 0, ccw=False)


@pytest.mark.parametrize("fn, extrapolated", ARC_FUNCS)
def test_arc_validation(fn, extrapolated):
    with pytest.raises(ValueError, match=r"end \(13, 0\) is 13\.0000 .* start \(10, 0\) is "
                                         r"10\.0000"):
        fn(10, 0, 13, 0, ccw=True)
    with pytest.raises(ValueError, match=r"start \(6, 5\) is 1 step from the centre \(5, 5\)"):
        fn(6, 5, 5, 6, ccw=True, center=(5, 5))
    with pytest.raises(ValueError, match="centre"):
        fn(1, 1, 0, 0, ccw=True)  # end at the centre: 1.41 steps off the circle
    with pytest.raises(TypeError, match="x0"):
        fn(1.0, 1, 1, 1, ccw=True)
    with pytest.raises(TypeError, match=r"center\[1\]"):
        fn(10, 0, 0, 10, ccw=True, center=(0, 0.5))
