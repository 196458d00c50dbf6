"""The look-ahead window's speed passes, compiled: the planner's inner loop in one numba call
per block.

The planner (`twin.controller.planner`) keeps its window's blocks as Python objects for
their geometry, and their speeds here, in one float array used as a ring: one row per block,
the columns below. `append` adds a block and runs the backward pass (each block's entry
speed raised as far as the blocks after it can still brake: `reach` from the newest block
back, stopping at the first block that does not change); `commit` takes the oldest block out
and runs the forward pass from its successor when that one's start was lowered (the forward
envelope `fw`: how fast the blocks before it allow it to start).

The speeds are those of `twin.controller.reach` with the closed forms of
`twin.controller.profiles.laws`, written out for numba in the same operations in the same
order (and libm's functions for sqrt, sinh, asinh, cbrt, pow), so the plans are the same
floats as the plain Python path's: ``tests/controller/test_window.py`` checks `reach_floor`
and `reach` against `twin.controller.reach` bit for bit, and whole plans against the Python
passes (`PythonWindow`, kept as the reference).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np

from twin.controller.profiles import SHAPES, Limits, max_end_speed
from twin.controller.profiles.laws import JERK_LIMITED, check_law
from twin.controller.reach import reach_floor as python_reach_floor
from twin.controller.reach import reach_function

__all__ = ["COLUMNS", "PythonWindow", "Window", "law_code"]

LEN, FW, ENTRY, VMAX, ACC, JERK, U1, F1, U2, F2 = range(10)
COLUMNS = ("length", "fw", "entry", "v_max", "acc", "jerk", "u1", "f1", "u2", "f2")
"""One window row: length (m), forward envelope and entry speed (m/s), the block's
tangential limits (m/s, m/s², m/s³) and its reach floor (`twin.controller.reach`)."""

_TRAPEZOID, _SHAPE, _SCURVE = 0, 1, 2


def law_code(law: str) -> tuple[int, float, float]:
    """(kind, k_a, k_j) of a law for the kernels: the trapezoid, a shape law (its peak rate
    and curvature, `twin.controller.profiles.SHAPES`), or the jerk-limited S-curve."""
    check_law(law)
    if law == JERK_LIMITED:
        return _SCURVE, 0.0, 0.0
    if law == "trapezoid":
        return _TRAPEZOID, SHAPES[law].peak_rate, SHAPES[law].peak_curvature
    return _SHAPE, SHAPES[law].peak_rate, SHAPES[law].peak_curvature


# ------------------------------------------------------------------- the laws' closed forms
@numba.njit(cache=True, inline="always")
def _cubic_root(p: float, q: float) -> float:
    if q <= 0.0:
        return 0.0
    scale = (p / 3.0) ** 1.5
    if scale > 1e-100 * q:
        x = 2.0 * math.sqrt(p / 3.0) * math.sinh(math.asinh(0.5 * q / scale) / 3.0)
    else:
        x = np.cbrt(q)
    return x - (x * (x * x + p) - q) / (3.0 * x * x + p)


@numba.njit(cache=True)
def _end_speed(kind: int, ka: float, kj: float, v0: float, d: float, a: float,
               j: float) -> float:
    """`twin.controller.profiles.laws.end_speed_function(law)(v0, d, a, j)`."""
    if kind == _SCURVE:
        dv_star = a * a / j
        if d >= (v0 + 0.5 * dv_star) * 2.0 * a / j:
            b = v0 / a + 0.5 * a / j
            c = v0 * a / j - d
            return v0 - 2.0 * c / (b + math.sqrt(b * b - 2.0 * c / a))
        x = _cubic_root(2.0 * v0, d * math.sqrt(j))
        return v0 + x * x
    if kj != 0.0:
        dv_star = kj * a * a / (ka * ka * j)
        if d < (v0 + 0.5 * dv_star) * ka * dv_star / a:
            x = _cubic_root(2.0 * v0, 2.0 * d * math.sqrt(j / kj))
            return v0 + x * x
    return math.sqrt(v0 * v0 + 2.0 * a * d / ka)


@numba.njit(cache=True, inline="always")
def _capped(kind: int, ka: float, kj: float, v0: float, d: float, cap: float, a: float,
            j: float) -> float:
    """`max_end_speed` for arguments known valid."""
    v = _end_speed(kind, ka, kj, v0, d, a, j)
    return v if v < cap else cap


@numba.njit(cache=True, inline="always")
def _guesses(kind: int, ka: float, kj: float, d: float, a: float,
             j: float) -> tuple[float, float]:
    """`twin.controller.reach._guesses`: the closed-form roots of f(u) = 3u."""
    if kind == _SCURVE:
        return ((j * d * d / 32.0) ** (1.0 / 3.0),
                0.125 * a * (math.sqrt(4.0 * a * a / (j * j) + 16.0 * d / a) - 2.0 * a / j))
    return (j * d * d / (8.0 * kj)) ** (1.0 / 3.0), math.sqrt(a * d / (4.0 * ka))


@numba.njit(cache=True)
def _root_3u(kind: int, ka: float, kj: float, d: float, cap: float, a: float, j: float,
             g1: float, g2: float) -> float:
    """`twin.controller.reach._root_3u`, given the guesses ``g1``, ``g2``."""
    if abs(_capped(kind, ka, kj, g1, d, cap, a, j) - 3.0 * g1) <= 1e-12 * g1:
        return g1
    if abs(_capped(kind, ka, kj, g2, d, cap, a, j) - 3.0 * g2) <= 1e-12 * g2:
        return g2
    lo, hi = 0.0, _capped(kind, ka, kj, 0.0, d, cap, a, j)
    h_lo, h_hi = hi, _capped(kind, ka, kj, hi, d, cap, a, j) - 3.0 * hi
    if h_hi >= 0.0:
        return hi
    side = 0
    for _ in range(100):
        u = (lo * h_hi - hi * h_lo) / (h_hi - h_lo)
        h = _capped(kind, ka, kj, u, d, cap, a, j) - 3.0 * u
        if h == 0.0:
            return u
        if h > 0.0:
            lo, h_lo = u, h
            if side == 1:
                h_hi *= 0.5
            side = 1
        else:
            hi, h_hi = u, h
            if side == -1:
                h_lo *= 0.5
            side = -1
        if hi - lo <= 1e-12 * hi:
            break
    return 0.5 * (lo + hi)


@numba.njit(cache=True)
def _floor(w: np.ndarray, s: int, kind: int, ka: float, kj: float) -> None:
    """`twin.controller.reach.reach_floor` of row ``s``, into its U1…F2 columns."""
    w[s, U1] = w[s, F1] = w[s, U2] = w[s, F2] = 0.0
    if kind == _TRAPEZOID:
        return
    d, cap, a, j = w[s, LEN], w[s, VMAX], w[s, ACC], w[s, JERK]
    g1, g2 = _guesses(kind, ka, kj, d, a, j)
    u2 = a * a / (2.0 * j)
    if 3.0 * min(g1, g2) >= cap and _capped(kind, ka, kj, 0.0, d, cap, a, j) >= cap and (
            kind != _SCURVE or _capped(kind, ka, kj, u2, d, cap, a, j) >= cap):
        return
    u1 = _root_3u(kind, ka, kj, d, cap, a, j, g1, g2)
    w[s, U1] = u1
    w[s, F1] = _capped(kind, ka, kj, u1, d, cap, a, j)
    if kind == _SCURVE:
        w[s, U2] = u2
        w[s, F2] = _capped(kind, ka, kj, u2, d, cap, a, j)


@numba.njit(cache=True, inline="always")
def _reach(w: np.ndarray, s: int, v: float, kind: int, ka: float, kj: float) -> float:
    """`twin.controller.reach.reach_function(law)` of row ``s`` from speed ``v``."""
    cap = w[s, VMAX]
    f = _end_speed(kind, ka, kj, v, w[s, LEN], w[s, ACC], w[s, JERK])
    f = f if f < cap else cap
    if v < w[s, U1] and w[s, F1] < f:
        f = w[s, F1]
    if v < w[s, U2] and w[s, F2] < f:
        f = w[s, F2]
    return f


# --------------------------------------------------------------------------- the passes
@numba.njit(cache=True)
def _append(w: np.ndarray, head: int, n: int, kind: int, ka: float, kj: float,
            length: float, v_max: float, acc: float, jerk: float, emax: float,
            linked: bool) -> None:
    size = w.shape[0]
    s = (head + n) % size
    w[s, LEN], w[s, VMAX], w[s, ACC], w[s, JERK] = length, v_max, acc, jerk
    _floor(w, s, kind, ka, kj)
    if linked:
        p = (s - 1) % size
        reach = _reach(w, p, w[p, FW], kind, ka, kj)
        if reach < emax:
            emax = reach
    w[s, FW] = emax
    w[s, ENTRY] = -1.0
    v = 0.0
    for k in range(n, -1, -1):              # backward pass, newest first
        r = (head + k) % size
        fw = w[r, FW]
        if w[r, ENTRY] == fw:               # at its forward cap (or committed): final
            break
        cand = _reach(w, r, v, kind, ka, kj)
        new = fw if fw < cand else cand
        if new <= w[r, ENTRY]:
            break
        w[r, ENTRY] = v = new


@numba.njit(cache=True)
def _commit(w: np.ndarray, head: int, n: int, kind: int, ka: float,
            kj: float) -> tuple[float, float]:
    size = w.shape[0]
    entry, v_end = w[head, ENTRY], 0.0
    if n > 1:
        prev = (head + 1) % size
        v_end = w[prev, ENTRY]
        if w[prev, FW] > v_end:             # the next block starts at v_end: forward pass
            w[prev, FW] = v_end
            for k in range(2, n):
                r = (head + k) % size
                cand = _reach(w, prev, w[prev, FW], kind, ka, kj)
                if cand >= w[r, FW]:
                    break
                w[r, FW] = cand
                if w[r, ENTRY] > cand:
                    w[r, ENTRY] = cand
                prev = r
    return entry, v_end


class Window:
    """The speeds of a look-ahead window of at most ``size`` blocks (compiled passes).

    Parameters
    ----------
    law : str
        Acceleration law.
    size : int
        Most blocks the window holds at once.
    """

    def __init__(self, law: str, size: int):
        self._law = law
        self._kind, self._ka, self._kj = law_code(law)
        self._w = np.zeros((size + 1, len(COLUMNS)))
        self._head = 0
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def append(self, length: float, limits: Limits, emax: float, linked: bool) -> None:
        """Add a block of ``length`` (m) and tangential ``limits``; ``emax`` caps its start
        (m/s: its node's cap, 0 at an exact stop), and, when ``linked``, so does how fast
        the block before it can end. Runs the backward pass."""
        if not length >= 0.0:
            max_end_speed(self._law, 0.0, length, limits)       # raises, naming it
        _append(self._w, self._head, self._n, self._kind, self._ka, self._kj, length,
                limits.max_velocity, limits.max_acceleration, limits.max_jerk, emax, linked)
        self._n += 1

    def commit(self) -> tuple[float, float]:
        """Take out the oldest block: (its entry speed, its end speed) (m/s), the end
        speed being its successor's entry (0 with none); runs the forward pass."""
        entry, v_end = _commit(self._w, self._head, self._n, self._kind, self._ka, self._kj)
        self._head = (self._head + 1) % self._w.shape[0]
        self._n -= 1
        return entry, v_end

    def rows(self) -> np.ndarray:
        """The window's rows, oldest first (a copy; see `COLUMNS`)."""
        size = self._w.shape[0]
        return self._w[[(self._head + k) % size for k in range(self._n)]].copy()


class PythonWindow:
    """The same passes in plain Python on `twin.controller.reach` (the reference)."""

    def __init__(self, law: str, size: int):
        self._law = law
        self._reach: Callable = reach_function(law)
        self._rows: list[list] = []

    def __len__(self) -> int:
        return len(self._rows)

    def append(self, length: float, limits: Limits, emax: float, linked: bool) -> None:
        floor = python_reach_floor(self._law, length, limits)
        rows = self._rows
        if linked:
            p = rows[-1]
            reach = self._reach(p[FW], p[LEN], p[-1], p[-2])
            if reach < emax:
                emax = reach
        row = [length, emax, -1.0, limits.max_velocity, limits.max_acceleration,
               limits.max_jerk, *floor, floor, limits]
        rows.append(row)
        v = 0.0
        for r in reversed(rows):
            if r[ENTRY] == r[FW]:
                break
            cand = self._reach(v, r[LEN], r[-1], r[-2])
            new = r[FW] if r[FW] < cand else cand
            if new <= r[ENTRY]:
                break
            r[ENTRY] = v = new

    def commit(self) -> tuple[float, float]:
        rows = self._rows
        b = rows.pop(0)
        v_end = 0.0
        if rows:
            v_end = rows[0][ENTRY]
            if rows[0][FW] > v_end:
                rows[0][FW] = v_end
                prev = rows[0]
                for r in rows[1:]:
                    cand = self._reach(prev[FW], prev[LEN], prev[-1], prev[-2])
                    if cand >= r[FW]:
                        break
                    r[FW] = cand
                    if r[ENTRY] > cand:
                        r[ENTRY] = cand
                    prev = r
        return b[ENTRY], v_end

    def rows(self) -> np.ndarray:
        return np.array([r[:10] for r in self._rows], dtype=float).reshape(-1, 10)
