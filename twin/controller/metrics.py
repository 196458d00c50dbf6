"""Error metrics of a run: what seed 000's rig plotted and seed 001 optimised.

Coordinate error (``reference − actual`` per axis), contour error (shortest distance to the
programmed path, exact for lines, arcs and splines: each segment answers its own exact
distance; bounding boxes prune the search, 10⁶ samples on 10³ segments take well under a
second), vector error, velocity error, the seed 001 corner error, settling travel and
overshoot after the motion, cycle time and productivity (path length / time, seed 001).

Everything is SI (m, s, m/s), positions are arrays ``(n, 2)`` with columns x, y;
``twin.controller.summary`` gathers them into one ``RunMetrics`` and converts to µm and
mm/min in one place.

Typical use (a run gives ``path`` and the record's positions and segment numbers)::

    >>> import numpy as np
    >>> from twin.controller.geometry import Line
    >>> path = [Line((0.0, 0.0), (0.01, 0.0))]
    >>> contour_error(path, np.array([[0.005, 2e-6], [0.01, -1e-6]])).tolist()   # m
    [2e-06, 1e-06]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.controller.geometry import Line, Segment

__all__ = [
    "CornerError",
    "OscillationMeter",
    "contour_error",
    "coordinate_error",
    "corner_error",
    "cycle_time",
    "oscillation",
    "overshoot",
    "productivity",
    "settling_travel",
    "vector_error",
    "velocity_error",
]


def _xy(name: str, value, n: int | None = None) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must have shape (n, 2), got {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise ValueError(f"{name} must have {n} rows like the other inputs, got {arr.shape[0]}")
    return arr


def _times(t, n: int) -> np.ndarray:
    arr = np.asarray(t, dtype=float)
    if arr.shape != (n,):
        raise ValueError(f"t must have shape ({n},), got {arr.shape}")
    return arr


def _unit(name: str, value) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    norm = float(np.hypot(*arr)) if arr.shape == (2,) else 0.0
    if not (norm > 0.0 and math.isfinite(norm)):
        raise ValueError(f"{name} must be a finite non-zero vector of shape (2,), got {value!r}")
    return arr / norm


# ------------------------------------------------------------------ pointwise errors
def coordinate_error(ref, actual) -> np.ndarray:
    """Coordinate error per axis, ``ref − actual``.

    Parameters
    ----------
    ref, actual : array_like, shape (n, 2)
        Reference and actual position (m).

    Returns
    -------
    ndarray, shape (n, 2)
        Error (m).
    """
    ref = _xy("ref", ref)
    return ref - _xy("actual", actual, ref.shape[0])


def vector_error(ref, actual) -> np.ndarray:
    """Vector error ``|ref − actual|`` (m), shape (n,); inputs (n, 2) (m)."""
    return np.hypot(*coordinate_error(ref, actual).T)


def velocity_error(ref_velocity, velocity) -> np.ndarray:
    """Velocity error per axis ``ref_velocity − velocity`` (m/s), shape (n, 2)."""
    ref = _xy("ref_velocity", ref_velocity)
    return ref - _xy("velocity", velocity, ref.shape[0])


# --------------------------------------------------------------------- contour error
def contour_error(path: Sequence[Segment], actual, *, hint=None, window: int = 1
                  ) -> np.ndarray:
    """Distance from each actual point to the programmed path.

    Parameters
    ----------
    path : sequence of Segment
        The programmed path (lines, arcs, splines), in order.
    actual : array_like, shape (n, 2)
        Actual positions (m).
    hint : array_like of int, shape (n,), optional
        Index of the active segment per sample (values outside ``[0, len(path))`` are
        clipped). Then only segments ``hint − window … hint + window`` are searched:
        the exact distance whenever the nearest point of the path lies on one of them,
        which holds unless the path comes back within the error distance of itself.
        Without it the whole path is searched, exactly.
    window : int
        Segments searched on each side of the hint (≥ 0).

    Returns
    -------
    ndarray, shape (n,)
        Contour error (m), ≥ 0.

    Notes
    -----
    Without a hint each segment is tried only on the samples inside its bounding box grown
    by a search radius (found from coordinate-sorted samples, x or y, whichever strip holds
    fewer) whose box distance does not exceed their best distance so far; samples whose
    best distance is within the radius are final (a nearer segment would have been tried),
    the others are searched again with four times the radius.
    """
    segments = list(path)
    if not segments:
        raise ValueError("path must hold at least one segment")
    pts = _xy("actual", actual)
    n = pts.shape[0]
    best = np.full(n, np.inf)
    if n == 0:
        return best
    if hint is not None:
        if isinstance(window, bool) or not isinstance(window, int | np.integer) or window < 0:
            raise ValueError(f"window must be an integer >= 0, got {window!r}")
        hint = np.asarray(hint)
        if hint.shape != (n,) or not np.issubdtype(hint.dtype, np.integer):
            raise ValueError(f"hint must be an integer array of shape ({n},), got "
                             f"{hint.dtype} {hint.shape}")
        _search_window(segments, pts, best, hint, int(window))
        return best
    _search_all(segments, pts, best)
    return best


def _search_window(segments: list[Segment], pts: np.ndarray, best: np.ndarray,
                   hint: np.ndarray, window: int) -> None:
    m = len(segments)
    hint = np.clip(hint, 0, m - 1)
    order = np.argsort(hint, kind="stable")
    first = np.searchsorted(hint[order], np.arange(m + 1))  # samples of segment j: [j, j+1)
    for j, seg in enumerate(segments):
        idx = order[first[max(j - window, 0)]:first[min(j + window, m - 1) + 1]]
        if idx.size:
            best[idx] = np.minimum(best[idx], seg.distance(pts[idx]))


def _search_all(segments: list[Segment], pts: np.ndarray, best: np.ndarray) -> None:
    boxes = np.array([np.concatenate(seg.bounding_box()) for seg in segments])  # (m, 4)
    lower, upper = boxes[:, :2], boxes[:, 2:]
    radius = max(1e-4 * float(np.hypot(*(upper.max(axis=0) - lower.min(axis=0)))), 1e-12)
    finite = np.isfinite(pts).all(axis=1)
    best[~finite] = np.nan
    todo = np.flatnonzero(finite)
    while todo.size:
        sub, sub_best = pts[todo], best[todo]
        by_x, by_y = np.argsort(sub[:, 0]), np.argsort(sub[:, 1])
        xs, ys = sub[by_x, 0], sub[by_y, 1]
        x0, y0 = (np.searchsorted(v, lower[:, k] - radius, side="left")
                  for k, v in enumerate((xs, ys)))
        x1, y1 = (np.searchsorted(v, upper[:, k] + radius, side="right")
                  for k, v in enumerate((xs, ys)))
        for j, seg in enumerate(segments):
            narrow_x = x1[j] - x0[j] <= y1[j] - y0[j]
            cand = by_x[x0[j]:x1[j]] if narrow_x else by_y[y0[j]:y1[j]]
            if not cand.size:
                continue
            p = sub[cand]
            gap = np.maximum(np.maximum(lower[j] - p, p - upper[j]), 0.0)  # to the box (m)
            cand = cand[np.hypot(*gap.T) <= np.minimum(sub_best[cand], radius)]
            if cand.size:
                sub_best[cand] = np.minimum(sub_best[cand], seg.distance(sub[cand]))
        best[todo] = sub_best
        todo = todo[sub_best > radius]
        radius *= 4.0


# ---------------------------------------------------------------------- corner error
@dataclass(frozen=True)
class CornerError:
    """Seed 001 contour error at a corner B between segments AB and BC.

    Attributes
    ----------
    delta_max : float
        ``max(delta_path_max, delta_node)`` (m).
    delta_path_max : float
        ``max_n min(dist(T_n, AB), dist(T_n, BC))`` (m).
    delta_node : float
        ``min_n |B − T_n|``, how close the tool came to the corner (m).
    index : int
        Sample at which ``delta_max`` is attained.
    """

    delta_max: float
    delta_path_max: float
    delta_node: float
    index: int


def corner_error(a, b, c, points) -> CornerError:
    """Seed 001 maximum contour error of a trajectory around the corner A-B-C.

    Parameters
    ----------
    a, b, c : array_like, shape (2,)
        Corner points (m): the path runs A → B → C.
    points : array_like, shape (n, 2)
        Trajectory samples T_n (m), n ≥ 1.

    Returns
    -------
    CornerError
        ``δ_n = min(dist(T_n, AB), dist(T_n, BC))``, ``δ_B = min_n |B − T_n|``,
        ``δ_max = max(max_n δ_n, δ_B)`` and the sample where ``δ_max`` is attained.
    """
    pts = _xy("points", points)
    if pts.shape[0] == 0:
        raise ValueError("points must hold at least one sample")
    first, second = Line(a, b), Line(b, c)
    along = np.minimum(first.distance(pts), second.distance(pts))
    to_node = np.hypot(*(pts - second.start).T)
    i_path, i_node = int(np.argmax(along)), int(np.argmin(to_node))
    path_max, node = float(along[i_path]), float(to_node[i_node])
    if path_max >= node:
        return CornerError(path_max, path_max, node, i_path)
    return CornerError(node, path_max, node, i_node)


# -------------------------------------------------------------- after-motion metrics
def settling_travel(t, position, t_end: float, *, target=None) -> float:
    """How far the table still travelled after the commanded motion ended: the peak distance
    of the position from its final (or target) value after ``t_end``.

    With a type-1 position loop this is mostly the lag the loop was still catching up (a
    P loop ends a cruise at V about V/K_v behind), plus any ringing; the elastic oscillation
    itself is measured on the screw deflection (``oscillation``).

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times (s).
    position : array_like, shape (n, 2)
        Actual position (m).
    t_end : float
        End of the commanded motion (s); samples with ``t > t_end`` are examined.
    target : array_like, shape (2,), optional
        Rest position (m). Default: the last sample.

    Returns
    -------
    float
        ``max |position − target|`` over the samples after ``t_end`` (m).

    Raises
    ------
    ValueError
        If no sample lies after ``t_end`` (record past the end of the motion).
    """
    pos = _xy("position", position)
    times = _times(t, pos.shape[0])
    after = times > t_end
    if not after.any():
        raise ValueError(f"no sample after t_end = {t_end} s: record past the end of the "
                         "motion to measure the settling travel")
    rest = pos[-1] if target is None else np.asarray(target, dtype=float)
    return float(np.hypot(*(pos[after] - rest).T).max())


def overshoot(t, position, target, direction, *, after: float | None = None) -> float:
    """Largest travel past ``target`` along ``direction`` (m), 0 if it never passes.

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times (s).
    position : array_like, shape (n, 2)
        Actual position (m).
    target : array_like, shape (2,)
        Target point (m).
    direction : array_like, shape (2,)
        Direction of the approach (any length, not zero).
    after : float, optional
        Only samples with ``t >= after`` count (s), e.g. once the reference has arrived, so
        that a path passing the target's level earlier is not mistaken for an overshoot.
    """
    pos = _xy("position", position)
    times = _times(t, pos.shape[0])
    if after is not None:
        pos = pos[times >= after]
    if pos.shape[0] == 0:
        return 0.0
    past = (pos - np.asarray(target, dtype=float)) @ _unit("direction", direction)
    return max(float(past.max()), 0.0)


def cycle_time(t, moving) -> float:
    """Time from the first moving sample to the sample after the last one (s).

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times (s), increasing.
    moving : array_like of bool, shape (n,)
        True where the machine is in motion (e.g. the reference velocity is not zero).

    Returns
    -------
    float
        ``t[last + 1] − t[first]`` (``t[-1] − t[first]`` if the motion lasts to the end);
        0 when nothing moves. With period T, k moving samples in a row give k·T.
    """
    moving = np.asarray(moving, dtype=bool)
    if moving.ndim != 1:
        raise ValueError(f"moving must have shape (n,), got {moving.shape}")
    times = _times(t, moving.shape[0])
    idx = np.flatnonzero(moving)
    if idx.size == 0:
        return 0.0
    stop = min(int(idx[-1]) + 1, times.size - 1)
    return float(times[stop] - times[idx[0]])


def productivity(path_length: float, duration: float) -> float:
    """Seed 001 productivity index: path length over program time (m/s).

    Parameters
    ----------
    path_length : float
        Length of the programmed path (m), ≥ 0.
    duration : float
        Program time (s), > 0.
    """
    if not (math.isfinite(path_length) and path_length >= 0.0):
        raise ValueError(f"path_length must be finite and >= 0 (m), got {path_length!r}")
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration must be finite and > 0 (s), got {duration!r}")
    return path_length / duration



class OscillationMeter:
    """The largest oscillating part of sampled signals, fed in blocks of any size.

    The oscillating part of a signal is its deviation from a centred moving average over a
    window (an odd number of samples): over one period of an oscillation the average removes
    it, and a ramp or a slow drift passes the average unchanged. Fed block by block, the
    meter gives exactly what :func:`oscillation` gives on the whole record (the record's ends,
    half a window each, are left out), keeping only one window of samples per channel.

    Parameters
    ----------
    windows : sequence of int
        Window of each channel (samples; made odd).
    """

    def __init__(self, windows: Sequence[int]):
        self.windows = [max(1, int(w)) | 1 for w in windows]
        self._carry = [np.zeros(0) for _ in self.windows]
        self.peak = 0.0
        """float: the largest oscillating part so far (signal units)."""

    def feed(self, block: np.ndarray) -> None:
        """Add samples, shape (n, channels)."""
        block = np.asarray(block, dtype=float).reshape(-1, len(self.windows))
        for k, w in enumerate(self.windows):
            data = np.concatenate((self._carry[k], block[:, k]))
            if len(data) >= w:
                # moving sum by a running total: O(n) whatever the window (a belt mode of
                # 63 ms is 251 samples of 0.25 ms); the block is short, so the sum is exact
                # to a few ulps of the deflection
                total = np.concatenate(([0.0], np.cumsum(data)))
                smooth = (total[w:] - total[:-w]) / w
                lo = w // 2
                dev = np.abs(data[lo:lo + smooth.size] - smooth)
                if dev.size:
                    self.peak = max(self.peak, float(dev.max()))
            self._carry[k] = data[-(w - 1):] if w > 1 else data[:0]


def oscillation(samples, windows: Sequence[int]) -> float:
    """``max_k max_i |s_k(i) − mean_window_k(s_k)(i)|`` of samples (n, channels), the
    centred moving average over ``windows[k]`` samples (odd); the record's ends (half a
    window) are left out. See :class:`OscillationMeter`."""
    meter = OscillationMeter(windows)
    meter.feed(samples)
    return meter.peak
