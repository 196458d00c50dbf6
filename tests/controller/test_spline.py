"""Natural cubic spline: both solvers against scipy's CubicSpline and a dense linear solve."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.interpolate import CubicSpline

from twin.controller.spline import (
    METHODS,
    natural_cubic,
    solve_blocks4,
    solve_tridiagonal,
)

# sizes covering every remainder of the blocks-of-five layout and two recursion levels
SIZES = [2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 25, 26, 27, 28, 29, 30, 131, 1000]


def random_data(n: int, seed: int, *, columns: int | None = None):
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.uniform(0.05, 3.0, n)) - 7.0
    y = rng.normal(size=n if columns is None else (n, columns))
    return x, y


def dense(x: np.ndarray) -> np.ndarray:
    """Points between and on the knots, plus a little extrapolation at both ends."""
    span = x[-1] - x[0]
    inner = np.interp(np.linspace(0, x.size - 1, 20 * x.size), np.arange(x.size), x)
    return np.concatenate(([x[0] - 0.1 * span], inner, x, [x[-1] + 0.1 * span]))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("columns", [None, 2])
def test_matches_scipy_natural_spline_values_and_derivatives(method, n, columns):
    x, y = random_data(n, seed=n, columns=columns)
    ours = natural_cubic(x, y, method=method)
    ref = CubicSpline(x, y, bc_type="natural")
    xq = dense(x)
    for nu in range(4):
        expected = ref(xq, nu)
        scale = 1.0 + np.abs(expected).max()
        np.testing.assert_allclose(ours(xq, nu), expected, rtol=0, atol=1e-10 * scale,
                                   err_msg=f"derivative {nu}")


@pytest.mark.parametrize("n", SIZES)
def test_methods_give_the_same_coefficients(n):
    x, y = random_data(n, seed=100 + n, columns=2)
    a = natural_cubic(x, y, method="tridiagonal")
    b = natural_cubic(x, y, method="blocks4")
    for name in "abcd":
        ref = getattr(a, name)
        np.testing.assert_allclose(getattr(b, name), ref, rtol=0,
                                   atol=1e-12 * (1.0 + np.abs(ref).max()), err_msg=name)


@given(
    st.integers(min_value=2, max_value=60),
    st.floats(min_value=1e-4, max_value=1e4),
    st.integers(min_value=0, max_value=2**31),
)
def test_blocks4_matches_scipy_for_uneven_spacing(n, scale, seed):
    rng = np.random.default_rng(seed)
    x = scale * np.cumsum(rng.uniform(1e-3, 1.0, n) ** 3 + 1e-6)
    y = rng.normal(size=n) * scale
    ours = natural_cubic(x, y, method="blocks4")
    ref = CubicSpline(x, y, bc_type="natural")
    xq = dense(x)[1:-1]  # no extrapolation: it amplifies rounding by (distance/h)³
    for nu in range(4):
        # the natural size of the nu-th derivative of data varying over the finest spacing
        expected = ref(xq, nu)
        scale = max(np.abs(y).max() / np.diff(x).min() ** nu, np.abs(expected).max())
        np.testing.assert_allclose(ours(xq, nu), expected, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("method", METHODS)
def test_interpolates_is_c2_and_natural_at_both_ends(method):
    x, y = random_data(57, seed=3)
    sp = natural_cubic(x, y, method=method)
    np.testing.assert_allclose(sp(x), y, rtol=0, atol=1e-12)
    h = np.diff(x)
    # value, slope and curvature of piece k at its right end equal those of piece k+1 at x_{k+1}
    left = [sp.a + h * (sp.b + h * (sp.c + h * sp.d)),
            sp.b + h * (2 * sp.c + 3 * h * sp.d),
            2 * sp.c + 6 * h * sp.d]
    right = [sp.a, sp.b, 2 * sp.c]
    for order, (lv, rv) in enumerate(zip(left, right, strict=True)):
        scale = 1.0 + np.abs(rv).max()
        np.testing.assert_allclose(lv[:-1], rv[1:], rtol=0, atol=1e-12 * scale,
                                   err_msg=f"derivative {order} jumps at a knot")
    np.testing.assert_allclose(left[0][-1], y[-1], rtol=0, atol=1e-12)
    curvature_scale = np.abs(sp(x, 2)).max()
    assert abs(sp(x[0], 2)) <= 1e-12 * curvature_scale
    assert abs(sp(x[-1], 2)) <= 1e-12 * curvature_scale


@pytest.mark.parametrize("method", METHODS)
def test_two_points_give_the_straight_line(method):
    sp = natural_cubic([1.0, 3.0], [2.0, 6.0], method=method)
    np.testing.assert_array_equal(sp.c, [0.0])
    np.testing.assert_array_equal(sp.d, [0.0])
    xq = np.linspace(0.0, 4.0, 9)
    np.testing.assert_allclose(sp(xq), 2.0 * xq, rtol=1e-15)
    np.testing.assert_allclose(sp(xq, 1), 2.0)


@pytest.mark.parametrize("solver", [solve_tridiagonal, solve_blocks4])
@pytest.mark.parametrize("n", range(1, 40))
def test_tridiagonal_solvers_against_dense_solve(solver, n):
    rng = np.random.default_rng(n)
    sub, sup = rng.normal(size=n - 1), rng.normal(size=n - 1)  # not symmetric
    diag = np.abs(np.r_[sub, 0.0]) + np.abs(np.r_[0.0, sup]) + rng.uniform(0.5, 2.0, n)
    rhs = rng.normal(size=(n, 3))
    dense_matrix = np.diag(diag) + np.diag(sub, -1) + np.diag(sup, 1)
    expected = np.linalg.solve(dense_matrix, rhs)
    np.testing.assert_allclose(solver(sub, diag, sup, rhs), expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(solver(sub, diag, sup, rhs[:, 0]), expected[:, 0], rtol=0,
                               atol=1e-12)


def test_blocks4_handles_a_large_system_exactly():
    n = 100_003
    rng = np.random.default_rng(5)
    off = rng.uniform(0.1, 1.0, n - 1)
    diag = 2.0 * (np.r_[off, 0.5] + np.r_[0.5, off])
    rhs = rng.normal(size=n)
    sol = solve_blocks4(off, diag, off, rhs)
    residual = diag * sol
    residual[1:] += off * sol[:-1]
    residual[:-1] += off * sol[1:]
    np.testing.assert_allclose(residual, rhs, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sol, solve_tridiagonal(off, diag, off, rhs), rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    ("x", "y", "kwargs", "message"),
    [
        ([0.0, 1.0, 2.0, 3.0, 1.0, 5.0], [0.0] * 6, {},
         r"x must be strictly increasing: x\[4\] = 1\.0 ≤ x\[3\] = 3\.0"),
        ([0.0, 1.0, 1.0], [0.0] * 3, {}, r"x\[2\] = 1\.0 ≤ x\[1\] = 1\.0"),
        ([0.0], [0.0], {}, r"at least 2 points, got 1"),
        ([0.0, np.nan, 2.0], [0.0] * 3, {}, r"x\[1\] is not finite"),
        ([0.0, 1.0, 2.0], [0.0, 1.0, np.inf], {}, r"y\[2\] is not finite"),
        ([0.0, 1.0, 2.0], [0.0, 1.0], {}, r"y must have shape \(3,\) or \(3, m\), got \(2,\)"),
        ([[0.0, 1.0]], [0.0, 1.0], {}, r"x must be one-dimensional"),
        ([0.0, 1.0], [0.0, 1.0], {"method": "sweep"}, r"method must be one of"),
    ],
)
def test_invalid_input_is_named(x, y, kwargs, message):
    with pytest.raises(ValueError, match=message):
        natural_cubic(x, y, **kwargs)


def test_derivative_order_is_checked():
    sp = natural_cubic([0.0, 1.0, 2.0], [0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="nu must be 0, 1, 2 or 3, got 4"):
        sp(0.5, nu=4)


def test_coefficients_are_read_only():
    sp = natural_cubic([0.0, 1.0, 2.0], [0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match="read-only"):
        sp.c[0] = 1.0
