"""Position regulator of the axes: PID + FF1/FF2/FF3 feed-forward + DCU, saturation, DAC.

Per axis and per tick (seed 004's extended-interface regulator plus seed 000's DCU)::

    e   = x_ref - x
    u   = kp·e + ki·T·Σe + kd·(e - e_prev)/T                  (P, I, D)
        + ff1·v_ref + ff2·a_ref + ff3·j_ref                   (FF, LinuxCNC pid names)
        + α1·∇x_ref + α2·∇²x_ref + α3·∇³x_ref                 (DCU, ∇ = 1 - z^-1)
    out = dac(clamp(u, ±output_limit))

Anti-windup is **conditional integration** (clamping): the integral is not advanced in a tick
where the output saturates and the error would drive it further into saturation; it keeps
integrating whenever the error pulls the output back. No extra tuning constant is needed.

A controller saturates each axis at its DAC's full scale and leaves the quantisation to
the DAC itself, the machine's (``loop_defaults.loop_gains``: ``dac_bits`` None). With
``dac_bits`` set, the regulator quantises as such a DAC would, for studies of the
regulator alone: a bipolar ``dac_bits`` converter spanning ±``output_limit``;
``lsb = 2·output_limit / 2**dac_bits`` (12 bit, ±10 V: 20 V/4096 = 4.8828 mV); the code is
``c = floor(u/lsb + 1/2)`` clamped to ``-2**(bits-1) … 2**(bits-1) - 1`` and the output is
``c·lsb`` volts (offset-binary word ``c + 2**(bits-1)``), so +10 V comes out as 9.99512 V.

``update`` is the cyclic path, compiled (numba, :func:`_regulate`) over float64 arrays of
the gains and the state; ``update_reference`` is the same arithmetic in plain Python, kept as
the reference the compiled path is tested against bit for bit. Neither raises for expected
conditions: a following error beyond the limit, or a non-finite input, zeroes the outputs
and latches ``FOLLOWING_ERROR`` (``INVALID_INPUT``) until ``reset``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import IntEnum

import numba
import numpy as np

from twin.controller.gains import RegulatorGains
from twin.errors import ConfigError

__all__ = ["TERMS", "PositionRegulator", "RegulatorStatus"]

TERMS = ("p", "i", "d", "ff", "dcu")
"""Column names of ``PositionRegulator.terms`` (V)."""

_NDARRAY = np.ndarray


class RegulatorStatus(IntEnum):
    """Result of one ``PositionRegulator.update``."""

    OK = 0
    """Regulating within the output range."""
    SATURATED = 1
    """At least one axis' output is clamped at ±output_limit (integration held)."""
    FOLLOWING_ERROR = 2
    """|x_ref - x| exceeded the limit on some axis: outputs zero, latched until reset."""
    INVALID_INPUT = 3
    """A non-finite reference or position: outputs zero, latched until reset."""


def _per_axis(gains: RegulatorGains, name: str, n: int) -> list[float]:
    value = getattr(gains, name)
    if isinstance(value, tuple):
        if len(value) != n:
            raise ConfigError(name, f"has {len(value)} values, the regulator has {n} axes")
        return list(value)
    return [value] * n


# gain columns of the compiled path
_KP, _KI_T, _KD_T, _FF1, _FF2, _FF3, _FEL, _A1, _A2, _A3, _LIM, _LSB = range(12)
# state columns: integral (V), previous error (m), reference history x(k-1..k-3) (m)
_INT, _EPREV, _H1, _H2, _H3 = range(5)


@numba.njit(cache=True)
def _regulate(par, st, x_ref, v_ref, a_ref, j_ref, x_act, out, err, terms, code_min,
              code_max):
    """One tick of every axis (the arithmetic of ``update_reference``, in the same order);
    returns the ``RegulatorStatus`` code (a trip returns at once; the caller zeroes the
    outputs and latches it until ``reset``, which clears the state)."""
    n = par.shape[0]
    status = 0
    for k in range(n):
        xr = x_ref[k]
        e = xr - x_act[k]
        err[k] = e
        if not abs(e) <= par[k, _FEL]:
            return 2 if e - e == 0.0 else 3
        p = par[k, _KP] * e
        i_old = st[k, _INT]
        i = i_old + par[k, _KI_T] * e
        d = par[k, _KD_T] * (e - st[k, _EPREV])
        ff = par[k, _FF1] * v_ref[k] + par[k, _FF2] * a_ref[k] + par[k, _FF3] * j_ref[k]
        x1, x2 = st[k, _H1], st[k, _H2]
        d1 = xr - x1
        d1p = x1 - x2
        d2 = d1 - d1p
        dcu = (par[k, _A1] * d1 + par[k, _A2] * d2
               + par[k, _A3] * (d2 - d1p + (x2 - st[k, _H3])))
        u = p + i + d + ff + dcu
        if u - u != 0.0:                       # NaN or inf from a feed-forward input
            return 3
        limit = par[k, _LIM]
        lsb = par[k, _LSB]
        if u > limit or u < -limit:
            if (u > 0.0) == (e > 0.0):         # conditional integration: hold
                u += i_old - i
                i = i_old
            if u > limit:
                u = limit
                status = 1
            elif u < -limit:
                u = -limit
                status = 1
        if lsb:
            c = math.floor(u / lsb + 0.5)
            u = lsb * (code_max if c > code_max else code_min if c < code_min else c)
        out[k] = u
        terms[k, 0] = p
        terms[k, 1] = i
        terms[k, 2] = d
        terms[k, 3] = ff
        terms[k, 4] = dcu
        st[k, _INT] = i
        st[k, _EPREV] = e
        st[k, _H3] = x2
        st[k, _H2] = x1
        st[k, _H1] = xr
    return status


class PositionRegulator:
    """The position regulator of ``n_axes`` axes.

    Parameters
    ----------
    gains : RegulatorGains
        Gains and limits.
    period : float
        Loop period ``T`` (s).
    n_axes : int
        Number of axes.

    Attributes
    ----------
    output : ndarray, shape (n_axes,)
        DAC output of the last update (V), saturated and quantised.
    error : ndarray, shape (n_axes,)
        ``x_ref - x`` of the last update (m).
    terms : ndarray, shape (n_axes, 5)
        P, I, D, FF and DCU contributions of the last update (V), columns ``TERMS``;
        their sum is the output before saturation and quantisation.
    status : RegulatorStatus
        Status of the last update.
    """

    def __init__(self, gains: RegulatorGains, period: float, *, n_axes: int = 2):
        if not (isinstance(period, int | float) and math.isfinite(period) and period > 0.0):
            raise ConfigError("period", f"must be a finite number > 0 (s), got {period!r}")
        if isinstance(n_axes, bool) or not isinstance(n_axes, int) or n_axes < 1:
            raise ConfigError("n_axes", f"must be an integer >= 1, got {n_axes!r}")
        self.gains = gains
        self.period = float(period)
        self.n_axes = n_axes
        n = n_axes
        self._axes = range(n)
        alpha = np.broadcast_to(np.asarray(gains.dcu_alpha, dtype=float), (n, 3)) \
            if np.ndim(gains.dcu_alpha) == 1 or len(gains.dcu_alpha) == n else None
        if alpha is None:
            raise ConfigError("dcu_alpha", f"has {len(gains.dcu_alpha)} rows, the regulator "
                              f"has {n} axes")
        par = np.zeros((n, 12))
        par[:, _KP] = _per_axis(gains, "kp", n)
        par[:, _KI_T] = [k * period for k in _per_axis(gains, "ki", n)]
        par[:, _KD_T] = [k / period for k in _per_axis(gains, "kd", n)]
        par[:, _FF1] = _per_axis(gains, "ff1", n)
        par[:, _FF2] = _per_axis(gains, "ff2", n)
        par[:, _FF3] = _per_axis(gains, "ff3", n)
        par[:, _FEL] = _per_axis(gains, "following_error_limit", n)
        par[:, _A1:_A3 + 1] = alpha
        par[:, _LIM] = _per_axis(gains, "output_limit", n)
        if gains.dac_bits is not None:
            par[:, _LSB] = 2.0 * par[:, _LIM] / 2**gains.dac_bits
        self._par = par
        self._st = np.zeros((n, 5))
        half = 0 if gains.dac_bits is None else 2 ** (gains.dac_bits - 1)
        self._code_min, self._code_max = -half, half - 1
        self.output = np.zeros(n)
        self.error = np.zeros(n)
        self.terms = np.zeros((n, len(TERMS)))
        # one update here, at rest: the compiled update is loaded (or compiled) now, not in
        # the first tick of a paced loop, which would miss its deadline (and a real I/O
        # module's watchdog would trip)
        zero = np.zeros(n)
        self.reset(zero)
        self.update(zero, zero, zero, zero, zero)
        self.reset(zero)

    @property
    def tripped(self) -> bool:
        """True while a following-error or invalid-input trip is latched."""
        return self._latched != RegulatorStatus.OK

    def reset(self, position: Sequence[float] | np.ndarray) -> None:
        """Start regulating at rest at ``position`` (m): clear the integral, the derivative
        and DCU history (the reference is taken as standing at ``position``) and the trip."""
        pos = [float(p) for p in position]
        if len(pos) != self.n_axes or not all(map(math.isfinite, pos)):
            raise ConfigError("position", f"must be {self.n_axes} finite numbers (m), "
                              f"got {position!r}")
        self._st[:] = 0.0
        self._st[:, _H1] = self._st[:, _H2] = self._st[:, _H3] = pos
        self._latched = RegulatorStatus.OK
        self.status = RegulatorStatus.OK
        self.output[:] = 0.0
        self.error[:] = 0.0
        self.terms[:] = 0.0

    def update(self, x_ref, v_ref, a_ref, j_ref, x_actual) -> RegulatorStatus:
        """One regulation tick (compiled: :func:`_regulate`).

        Parameters
        ----------
        x_ref, v_ref, a_ref, j_ref : sequence of float, length n_axes
            Position (m), velocity (m/s), acceleration (m/s²) and jerk (m/s³) references
            (float64 arrays on the cyclic path; anything else is converted).
        x_actual : sequence of float, length n_axes
            Measured position (m).

        Returns
        -------
        RegulatorStatus
            Also stored in ``status``; ``output``, ``error`` and ``terms`` are written.
        """
        if type(x_ref) is not _NDARRAY or type(x_actual) is not _NDARRAY \
                or type(v_ref) is not _NDARRAY or type(a_ref) is not _NDARRAY \
                or type(j_ref) is not _NDARRAY:
            x_ref, v_ref, a_ref, j_ref, x_actual = (
                np.asarray(v, dtype=np.float64) for v in (x_ref, v_ref, a_ref, j_ref,
                                                          x_actual))
        if self._latched:   # tripped: the error is still shown (inf − inf is NaN, quietly)
            with np.errstate(invalid="ignore", over="ignore"):
                np.subtract(x_ref, x_actual, out=self.error)
            return self._latched
        code = _regulate(self._par, self._st, x_ref, v_ref, a_ref, j_ref, x_actual,
                         self.output, self.error, self.terms, self._code_min,
                         self._code_max)
        if code >= RegulatorStatus.FOLLOWING_ERROR:
            return self._trip(_STATUS[code])
        self.status = _STATUS[code]
        return self.status

    def update_reference(self, x_ref, v_ref, a_ref, j_ref, x_actual) -> RegulatorStatus:
        """``update`` in plain Python float arithmetic (the reference the compiled path is
        tested against, operation for operation; same state, same results)."""
        x_ref, v_ref, a_ref, j_ref, x_actual = (
            [float(v) for v in seq] for seq in (x_ref, v_ref, a_ref, j_ref, x_actual))
        err = self.error
        if self._latched:
            for k in self._axes:
                err[k] = x_ref[k] - x_actual[k]
            return self._latched
        par, st = self._par.tolist(), self._st.tolist()
        status = RegulatorStatus.OK
        for k in self._axes:
            g, s = par[k], st[k]
            xr = x_ref[k]
            e = xr - x_actual[k]
            err[k] = e
            if not abs(e) <= g[_FEL]:
                return self._trip(RegulatorStatus.FOLLOWING_ERROR if e - e == 0.0
                                  else RegulatorStatus.INVALID_INPUT)
            p = g[_KP] * e
            i_old = s[_INT]
            i = i_old + g[_KI_T] * e
            d = g[_KD_T] * (e - s[_EPREV])
            ff = g[_FF1] * v_ref[k] + g[_FF2] * a_ref[k] + g[_FF3] * j_ref[k]
            x1, x2 = s[_H1], s[_H2]
            d1 = xr - x1
            d1p = x1 - x2
            d2 = d1 - d1p
            dcu = g[_A1] * d1 + g[_A2] * d2 + g[_A3] * (d2 - d1p + (x2 - s[_H3]))
            u = p + i + d + ff + dcu
            if u - u != 0.0:                       # NaN or inf from a feed-forward input
                return self._trip(RegulatorStatus.INVALID_INPUT)
            limit, lsb = g[_LIM], g[_LSB]
            if u > limit or u < -limit:
                if (u > 0.0) == (e > 0.0):         # conditional integration: hold
                    u += i_old - i
                    i = i_old
                if u > limit:
                    u = limit
                    status = RegulatorStatus.SATURATED
                elif u < -limit:
                    u = -limit
                    status = RegulatorStatus.SATURATED
            if lsb:
                c = math.floor(u / lsb + 0.5)
                u = lsb * (self._code_max if c > self._code_max else
                           self._code_min if c < self._code_min else c)
            self.output[k] = u
            self.terms[k] = (p, i, d, ff, dcu)
            self._st[k] = (i, e, xr, x1, x2)
        self.status = status
        return status

    def _trip(self, status: RegulatorStatus) -> RegulatorStatus:
        self._latched = status
        self.status = status
        self.output[:] = 0.0
        self.terms[:] = 0.0
        return status


_STATUS = tuple(RegulatorStatus)
