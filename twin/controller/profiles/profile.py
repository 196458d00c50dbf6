"""A planned 1-D move: a chain of segments evaluated at any time, scalar or vectorised."""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, field

import numpy as np

from twin.controller.profiles.laws import Shape

__all__ = ["Blend", "BlendPart", "Polynomial", "Profile", "Segment", "constant_jerk"]


def constant_jerk(tau, s0, v0, a0, j):
    """State after ``tau`` (s) of constant jerk ``j`` (m/s³) from (s0, v0, a0).

    Works on floats and ndarrays alike. Returns (s, v, a): m, m/s, m/s².
    """
    return (s0 + tau * (v0 + tau * (0.5 * a0 + tau * (j / 6.0))),
            v0 + tau * (a0 + 0.5 * j * tau),
            a0 + j * tau)


@dataclass(frozen=True, slots=True)
class Segment:
    """One piece of a move, on local time τ ∈ [0, duration].

    Attributes
    ----------
    start : float
        Time of the piece's start within the move (s).
    duration : float
        Length of the piece (s), > 0.
    s0 : float
        Path position at its start (m).
    v0 : float
        Path speed at its start (m/s).
    """

    start: float
    duration: float
    s0: float
    v0: float

    def at(self, tau: float) -> tuple[float, float, float, float]:
        """(s, v, a, j) at local time ``tau`` (s): m, m/s, m/s², m/s³."""
        raise NotImplementedError

    def sample(self, tau: np.ndarray) -> tuple[np.ndarray, ...]:
        """Vectorised `at`: four arrays shaped like ``tau``."""
        raise NotImplementedError

    def end(self) -> tuple[float, float, float]:
        """(s, v, a) at the end of the piece."""
        s, v, a, _ = self.at(self.duration)
        return s, v, a


@dataclass(frozen=True, slots=True)
class Polynomial(Segment):
    """Constant jerk: a cruise (a0 = j = 0), a trapezoid ramp (j = 0), an S-curve phase.

    Attributes
    ----------
    a0 : float
        Acceleration at the start (m/s²).
    j : float
        Jerk (m/s³).
    """

    a0: float
    j: float

    def at(self, tau: float) -> tuple[float, float, float, float]:
        s, v, a = constant_jerk(tau, self.s0, self.v0, self.a0, self.j)
        return s, v, a, self.j

    def sample(self, tau: np.ndarray) -> tuple[np.ndarray, ...]:
        s, v, a = constant_jerk(tau, self.s0, self.v0, self.a0, self.j)
        return s, v, a, np.full_like(tau, self.j)

    def speed_range(self) -> tuple[float, float]:
        """Lowest and highest speed on the piece (m/s): at its ends or where a crosses 0."""
        v0, a0, j, T = self.v0, self.a0, self.j, self.duration
        v1 = v0 + T * (a0 + 0.5 * j * T)
        lo, hi = (v0, v1) if v0 <= v1 else (v1, v0)
        if j != 0.0 and 0.0 < -a0 / j < T:
            turn = v0 - 0.5 * a0 * a0 / j
            lo, hi = min(lo, turn), max(hi, turn)
        return lo, hi


@dataclass(frozen=True, slots=True)
class Blend(Segment):
    """One speed change of a shape law: v = v0 + dv·φ(τ/duration).

    Attributes
    ----------
    dv : float
        Signed speed change v1 − v0 (m/s).
    shape : Shape
        The normalised change φ.
    """

    dv: float
    shape: Shape

    def _eval(self, tau, xp):
        T, dv, shape = self.duration, self.dv, self.shape
        u = tau / T
        return (self.s0 + T * (self.v0 * u + dv * shape.integral(u, xp)),
                self.v0 + dv * shape.velocity(u, xp),
                dv / T * shape.acceleration(u, xp),
                dv / (T * T) * shape.jerk(u, xp))

    def at(self, tau: float) -> tuple[float, float, float, float]:
        return self._eval(tau, math)

    def sample(self, tau: np.ndarray) -> tuple[np.ndarray, ...]:
        return self._eval(tau, np)

    def end(self) -> tuple[float, float, float]:
        T, dv = self.duration, self.dv
        return (self.s0 + T * (self.v0 + 0.5 * dv), self.v0 + dv,
                dv / T * self.shape.acceleration(1.0))


@dataclass(frozen=True, slots=True)
class BlendPart(Segment):
    """A part of one speed change of a shape law: the change's time window
    ``[offset, offset + duration]`` of its full span (what one block gets of a change that
    the planner spread over several blocks).

    The whole change is ``v = base + dv·φ(u)`` for ``u = t/span ∈ [0, 1]``; this part starts
    at ``u0 = offset/span`` with path position ``s0`` and speed ``v0`` (= base + dv·φ(u0)).

    Attributes
    ----------
    dv : float
        Signed speed change of the whole change (m/s).
    shape : Shape
        The normalised change φ.
    base : float
        Speed at the start of the whole change (m/s).
    span : float
        Duration of the whole change (s).
    offset : float
        Time of this part's start within the whole change (s).
    """

    dv: float
    shape: Shape
    base: float
    span: float
    offset: float

    def _eval(self, tau, xp):
        T, dv, shape, base = self.span, self.dv, self.shape, self.base
        u0 = self.offset / T
        u = (tau + self.offset) / T
        return (self.s0 + T * (base * (u - u0)
                               + dv * (shape.integral(u, xp) - shape.integral(u0, xp))),
                base + dv * shape.velocity(u, xp),
                dv / T * shape.acceleration(u, xp),
                dv / (T * T) * shape.jerk(u, xp))

    def at(self, tau: float) -> tuple[float, float, float, float]:
        return self._eval(tau, math)

    def sample(self, tau: np.ndarray) -> tuple[np.ndarray, ...]:
        return self._eval(tau, np)


def _part(seg: Segment, a: float, b: float, start: float, s_base: float) -> Segment:
    """The piece ``seg`` on its local times [a, b], starting at ``start`` of a new profile
    whose path position is measured from ``s_base``."""
    s, v, acc, _ = seg.at(a)
    if type(seg) is Polynomial:
        return Polynomial(start, b - a, s - s_base, v, acc, seg.j)
    if type(seg) is Blend:
        return BlendPart(start, b - a, s - s_base, v, seg.dv, seg.shape, seg.v0, seg.duration, a)
    if type(seg) is BlendPart:
        return BlendPart(start, b - a, s - s_base, v, seg.dv, seg.shape, seg.base, seg.span,
                         seg.offset + a)
    raise TypeError(f"cannot cut a {type(seg).__name__}")


@dataclass(frozen=True, slots=True)
class Profile:
    """A planned 1-D move along the path: from ``v_start`` to ``v_end`` over ``distance``.

    Evaluate it with `at` (one time, the controller tick's fast path) or `sample` (many).
    Times are clipped to ``[0, duration]``; from ``duration`` on the move holds its end
    state: ``s = distance``, ``v = v_end``, ``a = j = 0``.

    Attributes
    ----------
    law : str
        The acceleration law that planned it.
    distance : float
        Path length (m).
    v_start, v_end : float
        Speeds at the ends (m/s).
    v_peak : float
        Highest speed of the move (m/s): the cruise speed, or the top of an accelerate-brake
        move without cruise.
    segments : tuple of Segment
        The pieces, in time order, back to back from t = 0.
    duration : float
        Length of the move (s).
    """

    law: str
    distance: float
    v_start: float
    v_end: float
    v_peak: float
    segments: tuple[Segment, ...]
    duration: float = field(init=False)
    _starts: tuple[float, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        segments = self.segments
        last = segments[-1] if segments else None
        # the slots' own setters (the frozen class's __setattr__ is not called): one
        # profile per block the interpolator reaches
        _set_duration(self, last.start + last.duration if last else 0.0)
        _set_starts(self, tuple([seg.start for seg in segments]))

    def at(self, t: float) -> tuple[float, float, float, float]:
        """Path state at time ``t`` (s).

        Returns
        -------
        s, v, a, j : float
            Position (m), speed (m/s), acceleration (m/s²) and jerk (m/s³).
        """
        if t < 0.0:
            t = 0.0
        if t >= self.duration:
            return self.distance, self.v_end, 0.0, 0.0
        seg = self.segments[bisect_right(self._starts, t) - 1]
        return seg.at(t - seg.start)

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Path state at many times: the vectorised `at`.

        Parameters
        ----------
        t : array_like
            Times (s), any shape.

        Returns
        -------
        s, v, a, j : ndarray
            Shaped like ``t``: position (m), speed (m/s), acceleration (m/s²), jerk (m/s³).
        """
        t = np.asarray(t, dtype=np.float64)
        out = [np.zeros_like(t) for _ in range(4)]
        out[0].fill(self.distance)
        out[1].fill(self.v_end)
        moving = t < self.duration
        if self.segments and moving.any():
            tm = np.maximum(t[moving], 0.0)
            index = np.searchsorted(self._starts, tm, side="right") - 1
            parts = [np.empty_like(tm) for _ in range(4)]
            for k, seg in enumerate(self.segments):
                mask = index == k
                if mask.any():
                    for part, values in zip(parts, seg.sample(tm[mask] - seg.start),
                                            strict=True):
                        part[mask] = values
            for whole, part in zip(out, parts, strict=True):
                whole[moving] = part
        return out[0], out[1], out[2], out[3]

    def time_at(self, distance: float) -> float:
        """The time (s) at which the move has covered ``distance`` (m, clipped to
        ``[0, self.distance]``): where s(t) = d, found by Newton steps on the piece that
        holds it, kept inside the piece's bracket (s is non-decreasing: the speed is
        ≥ 0), to a few ulps of the time."""
        segments = self.segments
        if not segments or distance <= 0.0:
            return 0.0
        if distance >= self.distance:
            return self.duration
        k = 0
        while k + 1 < len(segments) and segments[k + 1].s0 <= distance:
            k += 1
        seg = segments[k]
        lo, hi = 0.0, seg.duration
        s1 = seg.end()[0]
        t = (distance - seg.s0) / (s1 - seg.s0) * hi if s1 > seg.s0 else 0.0
        for _ in range(100):
            s, v, _, _ = seg.at(t)
            f = s - distance
            if f > 0.0:
                hi = t
            else:
                lo = t
            nt = t - f / v if v > 0.0 else -1.0
            if not lo <= nt <= hi:
                nt = 0.5 * (lo + hi)
            if abs(nt - t) <= 4.0 * math.ulp(seg.duration) or hi - lo <= 4.0 * math.ulp(hi):
                t = nt
                break
            t = nt
        return seg.start + t

    def slice(self, t0: float, t1: float) -> Profile:
        """The move between its times ``t0`` and ``t1`` (s) as a move of its own: from
        t = 0, s = 0, speeds and accelerations as they are there (not zero: a change may
        run on across the cut)."""
        t0 = min(max(t0, 0.0), self.duration)
        t1 = min(max(t1, t0), self.duration)
        s_base, v_start, _, _ = self.at(t0) if t0 < self.duration else (
            self.distance, self.v_end, 0.0, 0.0)
        pieces: list[Segment] = []
        for seg in self.segments:
            a = max(t0, seg.start) - seg.start
            b = min(t1, seg.start + seg.duration) - seg.start
            if b > a:
                pieces.append(_part(seg, a, b, max(t0, seg.start) - t0, s_base))
        if pieces:
            s_end, v_end, _ = pieces[-1].end()
        else:
            s_end, v_end = 0.0, v_start
        peak = max((max(p.at(0.0)[1], p.end()[1]) for p in pieces), default=v_start)
        return Profile(self.law, s_end, v_start, v_end, peak, tuple(pieces))


_set_duration, _set_starts = (Profile.__dict__[name].__set__ for name in ("duration", "_starts"))
