"""The regulator's gains: ``RegulatorGains`` (validated, scalar or per axis) and
``default_gains``, the analytic design from the linear axis model the controller believes
in (P by the phase margin, the DCU or its feed-forward form, ``twin.controller.dcu``).

The regulator itself, which runs them, is ``twin.controller.regulator``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from twin.controller.dcu import dcu_as_feedforward, dcu_coefficients
from twin.controller.linear import LinearAxisModel, position_gain
from twin.errors import ConfigError

__all__ = ["Gain", "RegulatorGains", "default_gains"]

Gain = float | tuple[float, ...]
def _gain(name: str, value: object, *, nonnegative: bool = False,
          allow_inf: bool = False) -> Gain:
    """A scalar or per-axis gain as float / tuple of float, validated."""
    arr = np.asarray(value, dtype=float) if not isinstance(value, str) else None
    if arr is None or arr.ndim > 1 or arr.size == 0:
        raise ConfigError(name, f"must be a number or a sequence of numbers, got {value!r}")
    if np.any(np.isnan(arr)) or (not allow_inf and np.any(np.isinf(arr))):
        raise ConfigError(name, f"must be finite, got {value!r}")
    if nonnegative and np.any(arr < 0.0):
        raise ConfigError(name, f"must be >= 0, got {value!r}")
    return float(arr) if arr.ndim == 0 else tuple(float(v) for v in arr)


@dataclass(frozen=True, kw_only=True)
class RegulatorGains:
    """Gains and limits of the position regulator.

    Each gain is one float for all axes or a sequence with one value per axis (stored as
    a tuple).

    Attributes
    ----------
    kp : float or tuple
        Proportional gain (V/m), ≥ 0.
    ki : float or tuple
        Integral gain (V/(m·s)), ≥ 0.
    kd : float or tuple
        Derivative gain (V·s/m), ≥ 0.
    ff1, ff2, ff3 : float or tuple
        Velocity (V·s/m), acceleration (V·s²/m) and jerk (V·s³/m) feed-forward.
    dcu_alpha : tuple, shape (3,) or (n_axes, 3)
        DCU coefficients ``α1, α2, α3`` (V/m); zeros: no DCU.
    output_limit : float or tuple
        Output saturation, ±``output_limit`` (V), > 0: each axis' DAC full scale.
    dac_bits : int or None
        Quantise the output to a ``dac_bits`` converter spanning ±``output_limit`` (bit,
        1 … 32); None: no quantisation. A controller leaves it None: the DAC belongs to
        the machine's I/O, which quantises (the twin's plant, or the I/O module behind the
        driver); the option remains for studies of the regulator alone.
    following_error_limit : float or tuple
        Trip threshold on ``|x_ref - x|`` (m), > 0; ``math.inf`` disables the trip.
    """

    kp: Gain
    ki: Gain = 0.0
    kd: Gain = 0.0
    ff1: Gain = 0.0
    ff2: Gain = 0.0
    ff3: Gain = 0.0
    dcu_alpha: tuple = (0.0, 0.0, 0.0)
    output_limit: Gain = 10.0
    dac_bits: int | None = 12
    following_error_limit: Gain = 2e-3

    def __post_init__(self) -> None:
        put = object.__setattr__
        for name in ("kp", "ki", "kd"):
            put(self, name, _gain(name, getattr(self, name), nonnegative=True))
        for name in ("ff1", "ff2", "ff3"):
            put(self, name, _gain(name, getattr(self, name)))
        alpha = np.asarray(self.dcu_alpha, dtype=float)
        if alpha.shape[-1:] != (3,) or alpha.ndim > 2 or not np.all(np.isfinite(alpha)):
            raise ConfigError("dcu_alpha", "must be 3 finite numbers or one row of 3 per "
                              f"axis, got {self.dcu_alpha!r}")
        put(self, "dcu_alpha", tuple(tuple(float(a) for a in row) for row in alpha)
            if alpha.ndim == 2 else tuple(float(a) for a in alpha))
        limit = _gain("output_limit", self.output_limit)
        if min(limit if isinstance(limit, tuple) else (limit,)) <= 0.0:
            raise ConfigError("output_limit", f"must be > 0 (V), got {self.output_limit!r}")
        put(self, "output_limit", limit)
        bits = self.dac_bits
        if bits is not None and (isinstance(bits, bool) or not isinstance(bits, int)
                                 or not 1 <= bits <= 32):
            raise ConfigError("dac_bits", f"must be an integer 1…32 or None, got {bits!r}")
        fel = _gain("following_error_limit", self.following_error_limit, allow_inf=True)
        if min(fel if isinstance(fel, tuple) else (fel,)) <= 0.0:
            raise ConfigError("following_error_limit", f"must be > 0 (m), got {fel!r}")
        put(self, "following_error_limit", fel)

    @property
    def dac_lsb(self) -> Gain:
        """DAC step (V), per axis like ``output_limit``: ``2·output_limit / 2**dac_bits``;
        0 without quantisation."""
        if self.dac_bits is None:
            return 0.0
        step = 2.0 / 2**self.dac_bits
        limit = self.output_limit
        return tuple(step * v for v in limit) if isinstance(limit, tuple) else step * limit


# --------------------------------------------------------------------------- gain rules
def default_gains(model: LinearAxisModel | Sequence[LinearAxisModel], period: float, *,
                  dcu_order: int = 0, ff: bool = False,
                  phase_margin: float = math.radians(70.0), delay_ticks: int = 1,
                  following_error_limit: float = 2e-3) -> RegulatorGains:
    """Gains from the linear axis model(s): P by ``position_gain``, feed-forward from the DCU.

    ``ki = kd = 0``: the drive's PI speed loop already rejects load torque, and with the
    free integrator a P position loop has no steady error at rest. With ``dcu_order`` k the
    DCU coefficients make ``C0 … Ck`` vanish (``dcu_coefficients``). ``ff=True`` instead
    sets FF1…FF3 to the float-channel equivalent of the order-3 DCU
    (``dcu_as_feedforward``): ``FF1 = 1/K_H`` and FF2, FF3 compensating ZOH and delay.

    Parameters
    ----------
    model : LinearAxisModel or sequence of LinearAxisModel
        One model for all axes, or one per axis.
    period : float
        Loop period (s).
    dcu_order : int
        0 … 3.
    ff : bool
        Use FF1…FF3 instead of the DCU (they are two forms of one feed-forward).
    phase_margin : float
        For ``position_gain`` (rad).
    delay_ticks : int
        Computation delay (periods).
    following_error_limit : float
        Trip threshold (m).
    """
    if ff and dcu_order:
        raise ConfigError("ff", "FF1…FF3 and the DCU are two forms of the same feed-forward; "
                          "choose ff=True or dcu_order > 0, not both")
    models = [model] if isinstance(model, LinearAxisModel) else list(model)
    kp, alphas, ffs = [], [], []
    for m in models:
        kp.append(position_gain(m, period, phase_margin=phase_margin,
                                delay_ticks=delay_ticks))
        alpha = dcu_coefficients(m, period, 3 if ff else dcu_order, delay_ticks=delay_ticks)
        ffs.append(dcu_as_feedforward(alpha, period) if ff else np.zeros(3))
        alphas.append(np.zeros(3) if ff else alpha)
    one = isinstance(model, LinearAxisModel)

    def pack(values: list) -> Gain:
        return float(values[0]) if one else tuple(float(v) for v in values)

    return RegulatorGains(
        kp=pack(kp), ff1=pack([f[0] for f in ffs]), ff2=pack([f[1] for f in ffs]),
        ff3=pack([f[2] for f in ffs]),
        dcu_alpha=tuple(alphas[0]) if one else tuple(tuple(a) for a in alphas),
        following_error_limit=following_error_limit)

