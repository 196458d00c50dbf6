"""The look-ahead window's speed passes, compiled: the planner's inner loop in one numba call
per block.

The planner (`twin.controller.planner`) keeps its window's blocks as Python objects for
their geometry, and their speeds here, in one float array used as a ring: one row per block,
the columns below. `append` adds a block and runs the backward pass (each block's entry
speed raised as far as the blocks after it can still brake: `reach` from the newest block
back, stopping at the first block that does not change); `commit` takes the oldest block out
and runs the forward pass from its successor when that one's start was lowered (the forward
envelope `fw`: how fast the blocks before it allow it to start).

The speeds are those of `twin.controller.reach`, computed by the same compiled functions
(`reach.floor_of` and `reach.reach_of` on the laws' closed forms,
`twin.controller.profiles.closed_forms`): one implementation for the compiled window and
the Python callers.
``tests/controller/test_window.py`` checks the rows' floor and reach against
`twin.controller.reach` and whole plans against the Python passes (`PythonWindow`, kept as
the reference of the passes).
"""

from __future__ import annotations

from collections.abc import Callable

import numba
import numpy as np

from twin.controller.profiles import Limits, max_end_speed
from twin.controller.profiles.laws import law_code
from twin.controller.reach import floor_of, reach_function, reach_of
from twin.controller.reach import reach_floor as python_reach_floor

__all__ = ["COLUMNS", "PythonWindow", "Window"]

LEN, FW, ENTRY, VMAX, ACC, JERK, U1, F1, U2, F2 = range(10)
COLUMNS = ("length", "fw", "entry", "v_max", "acc", "jerk", "u1", "f1", "u2", "f2")
"""One window row: length (m), forward envelope and entry speed (m/s), the block's
tangential limits (m/s, m/s², m/s³) and its reach floor (`twin.controller.reach`)."""

@numba.njit(cache=True)
def _floor(w: np.ndarray, s: int, kind: int, ka: float, kj: float) -> None:
    """`twin.controller.reach.reach_floor` of row ``s``, into its U1…F2 columns."""
    w[s, U1], w[s, F1], w[s, U2], w[s, F2] = floor_of(kind, ka, kj, w[s, LEN], w[s, VMAX],
                                                      w[s, ACC], w[s, JERK])


@numba.njit(cache=True, inline="always")
def _reach(w: np.ndarray, s: int, v: float, kind: int, ka: float, kj: float) -> float:
    """`twin.controller.reach.reach_function(law)` of row ``s`` from speed ``v``."""
    return reach_of(kind, ka, kj, v, w[s, LEN], w[s, VMAX], w[s, ACC], w[s, JERK],
                    w[s, U1], w[s, F1], w[s, U2], w[s, F2])


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


KIND, KA, KJ, HEAD, COUNT = range(5)
"""The window's state vector: its law's code (`law_code`), its first row and its number of
blocks; the compiled entry points read it, so a call passes few arguments (each costs the
dispatch ~0.04 us)."""


@numba.njit(cache=True)
def _push(w: np.ndarray, st: np.ndarray, length: float, v_max: float, acc: float,
          jerk: float, emax: float, linked: bool, commit: bool) -> tuple[float, float]:
    """`_append`, then `_commit` when ``commit`` (else (-1, -1)), on the state ``st``."""
    head, n, kind, ka, kj = int(st[HEAD]), int(st[COUNT]), int(st[KIND]), st[KA], st[KJ]
    _append(w, head, n, kind, ka, kj, length, v_max, acc, jerk, emax, linked)
    if not commit:
        st[COUNT] = n + 1
        return -1.0, -1.0
    st[HEAD] = (head + 1) % w.shape[0]
    return _commit(w, head, n + 1, kind, ka, kj)


@numba.njit(cache=True)
def _pop(w: np.ndarray, st: np.ndarray) -> tuple[float, float]:
    """`_commit` on the state ``st``."""
    head, n = int(st[HEAD]), int(st[COUNT])
    st[HEAD], st[COUNT] = (head + 1) % w.shape[0], n - 1
    return _commit(w, head, n, int(st[KIND]), st[KA], st[KJ])


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
        self._w = np.zeros((size + 1, len(COLUMNS)))
        self._st = np.array([*law_code(law), 0.0, 0.0])
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def append(self, length: float, limits: Limits, emax: float, linked: bool,
               commit: bool = False) -> tuple[float, float] | None:
        """Add a block of ``length`` (m) and tangential ``limits``; ``emax`` caps its start
        (m/s: its node's cap, 0 at an exact stop), and, when ``linked``, so does how fast
        the block before it can end. Runs the backward pass. ``commit``: then `commit`
        (one compiled call), returning what it returns."""
        if not length >= 0.0:
            max_end_speed(self._law, 0.0, length, limits)       # raises, naming it
        ends = _push(self._w, self._st, length, limits.max_velocity, limits.max_acceleration,
                     limits.max_jerk, emax, linked, commit)
        if commit:
            return ends
        self._n += 1
        return None

    def commit(self) -> tuple[float, float]:
        """Take out the oldest block: (its entry speed, its end speed) (m/s), the end
        speed being its successor's entry (0 with none); runs the forward pass."""
        self._n -= 1
        return _pop(self._w, self._st)

    def rows(self) -> np.ndarray:
        """The window's rows, oldest first (a copy; see `COLUMNS`)."""
        size, head = self._w.shape[0], int(self._st[HEAD])
        return self._w[[(head + k) % size for k in range(self._n)]].copy()


class PythonWindow:
    """The same passes in plain Python on `twin.controller.reach` (the reference)."""

    def __init__(self, law: str, size: int):
        self._law = law
        self._reach: Callable = reach_function(law)
        self._rows: list[list] = []

    def __len__(self) -> int:
        return len(self._rows)

    def append(self, length: float, limits: Limits, emax: float, linked: bool,
               commit: bool = False) -> tuple[float, float] | None:
        self._append(length, limits, emax, linked)
        return self.commit() if commit else None

    def _append(self, length: float, limits: Limits, emax: float, linked: bool) -> None:
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
