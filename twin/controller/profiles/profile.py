"""A planned 1-D move: a chain of segments evaluated at any time, scalar or vectorised."""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, field

import numpy as np

from twin.controller.profiles.laws import Shape

__all__ = ["Blend", "Polynomial", "Profile", "Segment", "constant_jerk"]


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
        last = self.segments[-1] if self.segments else None
        object.__setattr__(self, "duration", last.start + last.duration if last else 0.0)
        object.__setattr__(self, "_starts", tuple(seg.start for seg in self.segments))

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
