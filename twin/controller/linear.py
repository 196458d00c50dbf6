"""The linear model of one axis as the position loop sees it: drive reference (V) → table
position (m).

``W0(p) = num(p) / den(p)`` is the closed speed loop of the drive followed by the free
integrator of the mechanism (speed → position). The DCU (``twin.controller.dcu``) and the gain
rules of the position regulator (``twin.controller.regulator``) work on this model and on its
pulse transfer function: zero-order hold on the DAC output plus ``delay_ticks`` periods of
computation delay (seed 000, Fig. 10)::

    G(z) = z^-d · Z{ (1 - e^(-pT)) / p · W0(p) } = z^-d · b'(z^-1) / ((1 - z^-1) · q(z^-1))

The free integrator is kept as the exact factor ``(1 - z^-1)``; ``q`` has the poles
``exp(p_i·T)`` of the speed loop, ``b`` comes from the exact ZOH impulse response (matrix
exponential), so no coefficient is obtained by cancellation of nearly equal numbers.

``position_gain`` is the P-gain rule of the position loop on this model (phase margin of the
sampled loop, capped by a gain margin).

Polynomials in ``p`` are numpy order (highest power first); polynomials in ``z^-1`` are
ascending (index k holds the coefficient of ``z^-k``), the convention of
``scipy.signal.lfilter``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import scipy.linalg

from twin.errors import ConfigError

__all__ = ["LinearAxisModel", "position_gain", "power_series_ratio"]



def _canonical(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                          np.ndarray, np.ndarray]:
    """State space (A, B, C, D) of num(p)/den(p) (numpy order, deg num ≤ deg den) in the
    controller canonical form, the one ``scipy.signal.tf2ss`` returns (importing
    ``scipy.signal`` costs every process a second at start)."""
    den = np.asarray(den, dtype=float)
    num = np.asarray(num, dtype=float)
    num, den = num / den[0], den / den[0]
    m = den.size - 1
    num = np.concatenate([np.zeros(m + 1 - num.size), num])
    d = num[0]
    a = np.zeros((m, m))
    a[0, :] = -den[1:]
    a[1:, :-1] = np.eye(m - 1)
    b = np.zeros((m, 1))
    b[0, 0] = 1.0
    c = (num[1:] - d * den[1:])[None, :]
    return a, b, c, np.array([[d]])

def power_series_ratio(num: Sequence[float], den: Sequence[float], count: int) -> np.ndarray:
    """First Taylor coefficients of ``num(x) / den(x)`` at ``x = 0`` (series division).

    Parameters
    ----------
    num, den : sequence of float
        Ascending coefficients (index k holds the coefficient of ``x**k``); ``den[0] != 0``.
    count : int
        Number of coefficients wanted.

    Returns
    -------
    ndarray, shape (count,)
        ``c`` with ``num / den = c[0] + c[1]·x + … + O(x**count)``.
    """
    n = np.zeros(count)
    a = np.asarray(num, dtype=float)[:count]
    n[: a.size] = a
    d = np.asarray(den, dtype=float)
    if d.size == 0 or d[0] == 0.0:
        raise ConfigError("den", "series division needs den[0] != 0")
    out = np.zeros(count)
    for k in range(count):
        acc = n[k]
        for j in range(1, min(k, d.size - 1) + 1):
            acc -= d[j] * out[k - j]
        out[k] = acc / d[0]
    return out


def _poly(values: Sequence[float], name: str) -> np.ndarray:
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    if arr.ndim != 1 or arr.size == 0:
        raise ConfigError(name, f"must be a 1-D sequence of coefficients, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ConfigError(name, f"must be finite, got {arr.tolist()}")
    nz = np.flatnonzero(arr)
    if nz.size == 0:
        raise ConfigError(name, "must not be identically zero")
    return arr[nz[0] :]


class LinearAxisModel:
    """Continuous transfer function ``W0(p)`` of one axis, reference (V) → position (m).

    Parameters
    ----------
    num, den : sequence of float
        Numerator and denominator coefficients in ``p``, highest power first. ``den`` must
        contain exactly one free integrator (``den[-1] == 0``, ``den[-2] != 0``), the other
        poles must be strictly stable, ``W0`` strictly proper and its velocity gain nonzero.

    Raises
    ------
    ConfigError
        Naming ``num`` or ``den`` when a condition above does not hold.

    Examples
    --------
    >>> m = LinearAxisModel.servo(1.0 / 600.0, 0.02)   # K_H/(p(Tp+1))
    >>> round(m.velocity_gain * 600.0, 12)
    1.0
    """

    __slots__ = ("_den", "_num")

    def __init__(self, num: Sequence[float], den: Sequence[float]):
        n = _poly(num, "num")
        d = _poly(den, "den")
        if d.size < 2 or d[-1] != 0.0:
            raise ConfigError("den", "must contain a free integrator: den[-1] == 0 "
                              f"(reference → position), got {d.tolist()}")
        if d[-2] == 0.0:
            raise ConfigError("den", "must contain exactly one free integrator; den[-2] == 0")
        if n.size >= d.size:
            raise ConfigError("num", f"W0 must be strictly proper: deg num = {n.size - 1} "
                              f">= deg den = {d.size - 1}")
        if n[-1] == 0.0:
            raise ConfigError("num", "num(0) == 0: the velocity gain K_H would be zero")
        poles = np.roots(d[:-1])
        if np.any(poles.real >= 0.0):
            raise ConfigError("den", "poles other than the free integrator must be strictly "
                              f"stable, got {np.round(poles, 6).tolist()}")
        lead = d[0]
        self._num = n / lead
        self._den = d / lead
        self._num.flags.writeable = False
        self._den.flags.writeable = False

    # ------------------------------------------------------------------ constructors
    @classmethod
    def servo(cls, velocity_gain: float, time_constant: float) -> LinearAxisModel:
        """First-order servo ``K_H / (p·(T·p + 1))``.

        Parameters
        ----------
        velocity_gain : float
            ``K_H`` (m/s per V), nonzero.
        time_constant : float
            ``T`` of the closed speed loop (s), ≥ 0 (0 gives the pure integrator ``K_H/p``).
        """
        _check_param("velocity_gain", velocity_gain, nonzero=True)
        _check_param("time_constant", time_constant, lower=0.0)
        return cls([velocity_gain], [time_constant, 1.0, 0.0])

    @classmethod
    def servo2(cls, velocity_gain: float, time_constant: float, tau: float,
               xi: float) -> LinearAxisModel:
        """Seed 001's reduced axis model ``K_H / (p·(T·p + 1)·(τ²·p² + 2·ξ·τ·p + 1))``.

        Parameters
        ----------
        velocity_gain : float
            ``K_H`` (m/s per V), nonzero.
        time_constant : float
            ``T``, closed servo-drive time constant (s), ≥ 0.
        tau : float
            ``τ = 1/ω`` of the elastic mechanics (s), ≥ 0.
        xi : float
            Damping ratio ``ξ`` of the mechanics (1), > 0.
        """
        _check_param("velocity_gain", velocity_gain, nonzero=True)
        _check_param("time_constant", time_constant, lower=0.0)
        _check_param("tau", tau, lower=0.0)
        _check_param("xi", xi, lower=0.0, strict=True)
        den = np.polymul(np.polymul([time_constant, 1.0], [tau * tau, 2.0 * xi * tau, 1.0]),
                         [1.0, 0.0])
        return cls([velocity_gain], den)

    # ------------------------------------------------------------------ properties
    @property
    def num(self) -> np.ndarray:
        """Numerator in ``p`` (highest power first), normalised so that ``den[0] == 1``."""
        return self._num

    @property
    def den(self) -> np.ndarray:
        """Denominator in ``p`` (highest power first), ``den[0] == 1``, ``den[-1] == 0``."""
        return self._den

    @property
    def velocity_gain(self) -> float:
        """``K_H = lim p→0 p·W0(p)`` (m/s per V)."""
        return float(self._num[-1] / self._den[-2])

    @property
    def order(self) -> int:
        """Order of ``W0`` (number of poles, the integrator included)."""
        return self._den.size - 1

    def __repr__(self) -> str:
        return f"LinearAxisModel(num={self._num.tolist()}, den={self._den.tolist()})"

    # ------------------------------------------------------------------ discretisation
    def discrete_increments(self, period: float, *,
                            delay_ticks: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Pulse transfer function of the position increment per tick, ``(1 - z^-1)·G(z)``.

        Parameters
        ----------
        period : float
            Sampling period ``T`` (s).
        delay_ticks : int
            Computation delay ``d`` (periods) between sampling and the DAC update.

        Returns
        -------
        b, q : ndarray
            Ascending coefficients in ``z^-1`` with ``G(z) = b / ((1 - z^-1)·q)``;
            ``q[0] == 1`` and ``b(1)/q(1) == K_H·T``.
        """
        _check_param("period", period, lower=0.0, strict=True)
        if isinstance(delay_ticks, bool) or not isinstance(delay_ticks, int | np.integer) \
                or delay_ticks < 0:
            raise ConfigError("delay_ticks", f"must be an integer >= 0, got {delay_ticks!r}")
        vden = self._den[:-1]                       # reference → velocity: num / vden
        m = vden.size - 1
        poles = np.roots(vden)
        q = np.real(np.poly(np.exp(poles * period))) if m else np.ones(1)
        f = np.zeros(m + 2)                         # increments after a one-tick unit pulse
        if m == 0:
            f[1] = self._num[-1] / vden[0] * period
        else:
            # exact ZOH of [x; u; s]' = [[A, B, 0], [0, 0, 0], [C, D, 0]]·[x; u; s], where
            # x is the speed-loop state, u the held reference and s the position in the tick
            a, bb, c, dd = _canonical(self._num, vden)
            big = np.zeros((m + 2, m + 2))
            big[:m, :m] = a
            big[:m, m] = bb[:, 0]
            big[m + 1, :m] = c[0]
            big[m + 1, m] = dd[0, 0]
            e = scipy.linalg.expm(big * period)
            phi, gam, cs = e[:m, :m], e[:m, m], e[m + 1, :m]
            f[1] = e[m + 1, m]
            x = gam
            for k in range(2, m + 2):
                f[k] = cs @ x
                x = phi @ x
        b = np.convolve(q, f)[: m + 2]
        return np.concatenate([np.zeros(int(delay_ticks)), b]), q

    def discrete(self, period: float, *,
                 delay_ticks: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """Pulse transfer function ``G(z)`` with zero-order hold and computation delay.

        Parameters
        ----------
        period : float
            Sampling period ``T`` (s).
        delay_ticks : int
            Computation delay (periods); 1: the output computed from the sample at tick i
            reaches the drive at tick i + 1.

        Returns
        -------
        numz, denz : ndarray
            Coefficients in ascending powers of ``z^-1``, ``denz[0] == 1``, padded to equal
            length, so ``(numz, denz, period)`` is also a valid ``scipy.signal.dlti``
            (in descending powers of ``z``) and ``scipy.signal.lfilter(numz, denz, u)``
            gives the sampled position (m) for DAC volts ``u``.
        """
        b, q = self.discrete_increments(period, delay_ticks=delay_ticks)
        den = np.convolve([1.0, -1.0], q)
        size = max(b.size, den.size)
        return np.pad(b, (0, size - b.size)), np.pad(den, (0, size - den.size))

    def frequency_response(self, omega: np.ndarray | float, *, period: float | None = None,
                           delay_ticks: int = 1) -> np.ndarray:
        """Complex frequency response of ``W0(jω)`` or, with ``period``, of ``G(e^(jωT))``.

        Parameters
        ----------
        omega : array_like
            Angular frequencies (rad/s), > 0.
        period : float, optional
            Sampling period (s); None for the continuous ``W0``.
        delay_ticks : int
            Computation delay (periods) of the discrete loop.

        Returns
        -------
        ndarray, complex, shape of ``omega``
            Gain (m/V).
        """
        w = np.asarray(omega, dtype=float)
        if period is None:
            s = 1j * w
            return np.polyval(self._num, s) / np.polyval(self._den, s)
        b, q = self.discrete_increments(period, delay_ticks=delay_ticks)
        zi = np.exp(-1j * w * period)
        poly = np.polynomial.polynomial.polyval
        return poly(zi, b) / ((1.0 - zi) * poly(zi, q))

    def inverse_series(self, count: int) -> np.ndarray:
        """Taylor coefficients of ``1 / W0(p)`` in powers of ``p`` (starting at ``p¹``).

        Returns
        -------
        ndarray, shape (count,)
            ``s`` with ``1/W0(p) = s[0]·p + s[1]·p² + …``; ``s[0] = 1/K_H`` (V·s/m),
            ``s[k]`` in V·s^(k+1)/m.
        """
        return power_series_ratio(self._den[-2::-1], self._num[::-1], count)


def position_gain(model: LinearAxisModel, period: float, *,
                  phase_margin: float = math.radians(70.0), gain_margin: float = 2.0,
                  delay_ticks: int = 1) -> float:
    """P gain of the position loop around the speed loop, by a phase-margin rule.

    The rule: the largest ``kp`` for which the sampled loop ``kp·G(z)`` (ZOH and
    ``delay_ticks`` of computation delay) has ``phase_margin`` at its first gain crossover,
    capped so that the gain margin is at least ``gain_margin``. 70° keeps the reference
    step response within about 1 % overshoot for first-order servos (≈ critical damping
    without the sluggishness of exactly 76°); the cap matters only for lightly damped
    mechanical resonances.

    Parameters
    ----------
    model : LinearAxisModel
        The axis.
    period : float
        Loop period (s).
    phase_margin : float
        Phase margin (rad), in (0, π/2).
    gain_margin : float
        Minimum gain margin (1), > 1.
    delay_ticks : int
        Computation delay (periods).

    Returns
    -------
    float
        ``kp`` (V/m).
    """
    if not 0.0 < phase_margin < math.pi / 2:
        raise ConfigError("phase_margin", f"must be in (0, π/2) rad, got {phase_margin!r}")
    if not gain_margin > 1.0:
        raise ConfigError("gain_margin", f"must be > 1, got {gain_margin!r}")

    def response(w: float | np.ndarray) -> np.ndarray:
        """``G(e^(jωT))`` (m/V)."""
        return model.frequency_response(w, period=period, delay_ticks=delay_ticks)

    grid = np.logspace(-5.0, math.log10(math.pi), 4000) / period
    phase = np.unwrap(np.angle(response(grid)))

    def crossing(target: float) -> list[float]:
        """Frequencies (rad/s) where the unwrapped phase crosses ``target`` downwards."""
        idx = np.flatnonzero((phase[:-1] > target) & (phase[1:] <= target))
        return [_refine(i, target) for i in idx]

    def _refine(i: int, target: float) -> float:
        """The crossing inside grid step i: the phase continued from grid[i] (so the wrap
        of the angle at ±π cannot split the bracket); a step over which the phase turns by
        π or more (a notch of the response) keeps the grid point."""
        r0 = complex(response(grid[i]))

        def offset(w: float) -> float:
            return float(phase[i] + np.angle(complex(response(w)) / r0) - target)

        if offset(grid[i + 1]) > 0.0:
            return float(grid[i + 1])
        from scipy.optimize import brentq  # here: half a second of every process' start

        return brentq(offset, grid[i], grid[i + 1])

    candidates = []
    pm_cross = crossing(-math.pi + phase_margin)
    if pm_cross:
        candidates.append(1.0 / abs(response(pm_cross[0])))
    branches = np.arange(1, int(-phase.min() / (2 * math.pi)) + 2)
    gm_gains = [abs(response(w)) for t in branches for w in crossing(math.pi - 2 * math.pi * t)]
    nyquist = complex(response(math.pi / period))
    if nyquist.real < 0.0 and abs(nyquist.imag) <= 1e-9 * abs(nyquist):
        gm_gains.append(abs(nyquist))
    if gm_gains:
        candidates.append(1.0 / (gain_margin * max(gm_gains)))
    if not candidates:
        raise ConfigError("model", "the sampled loop has no phase or gain crossover below "
                          "the Nyquist frequency; cannot apply the margin rule")
    return float(min(candidates))


def _check_param(name: str, value: float, *, lower: float | None = None,
                 strict: bool = False, nonzero: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating):
        raise ConfigError(name, f"must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ConfigError(name, f"must be finite, got {value}")
    if nonzero and value == 0.0:
        raise ConfigError(name, "must be nonzero")
    if lower is not None and (value < lower or (strict and value == lower)):
        raise ConfigError(name, f"must be {'>' if strict else '>='} {lower}, got {value}")
