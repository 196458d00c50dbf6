"""The tuning space: a normalised vector in [-1, 1]^11 ↔ regulator gains and the jerk limit.

Every coordinate is centred on the analytic design, so the zero vector *is* the analytic
baseline (``default_gains(models, period, dcu_order=3)`` and the machine's jerk limit):

=============  =====================================================  ===================
coordinate     physical value                                          range
=============  =====================================================  ===================
``kp_<ax>``    ``kp0 · kp_span^a``  (log scale)                       ``kp0/4 … 4·kp0``
``ki_<ax>``    0 for ``a ≤ 0``; ``kp0·K_v·10^(-3 + 3a)`` for ``a > 0``  ``0, 1e-3 … 1 ·kp0·K_v``
``a1_<ax>``    ``α1⁰ · (1 + 0.1·a)``                                  ±10 %
``a2_<ax>``    ``α2⁰ · (1 + 0.5·a)``                                  ±50 %
``a3_<ax>``    ``α3⁰ · (1 + 1.0·a)``                                  0 … 2·α3⁰
``max_jerk``   ``J0 · jerk_span^a``  (log scale)                      ``J0/4 … 4·J0``
``sf_<ax>``    ``f0 · SHAPER_FREQUENCY_SPAN^a`` (log), < 0.9·Nyquist  ``f0/1.5 … 1.5·f0``
``sz_<ax>``    ``ζ0 + SHAPER_DAMPING_SPAN·a``, within [0, 0.9]        ``ζ0 ± 0.2``
=============  =====================================================  ===================

The last four only when the machine shapes both axes (``[controller.shaper.x|y] type``,
``twin.controller.shaping``): its input shapers' frequency and damping, centred on the
machine file's values (unset: the model's mode), so that a tuner can find where the belt
mode really is. Without shapers the space has the eleven coordinates above (``DIM``).

``K_v = kp0·K_H`` is the analytic velocity gain of the position loop (1/s), so the integral
corner ``ki/kp0`` spans three decades below the loop's crossover; ``a ≤ 0`` switches the
integrator off, which keeps the analytic point (``ki = 0``) inside the space. The DCU
coefficients move relative to their analytic values because the derivation is exact only
for the linear model: friction, the bridge reversal pause and the elastic mode are what is
left for a tuner to find.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig
from twin.controller.gains import RegulatorGains, default_gains
from twin.controller.linear import LinearAxisModel
from twin.controller.shaping import axis_shapers
from twin.errors import ConfigError

__all__ = ["ALPHA_SPAN", "DIM", "KI_DECADES", "NAMES", "SHAPER_DAMPING_SPAN",
           "SHAPER_FREQUENCY_SPAN", "SHAPER_NAMES", "SHAPER_NYQUIST_SHARE", "TuningSettings",
           "TuningSpace",
           "check_action", "settings_from_dict"]

ALPHA_SPAN = (0.02, 0.2, 0.5)
"""Relative half-range of α1, α2, α3 around the analytic values (1)."""
KI_DECADES = 3.0
"""Decades of ``ki`` below ``kp0·K_v`` the positive half of the ki coordinate spans."""
_PER_AXIS = ("kp", "ki", "a1", "a2", "a3")
DIM = len(AXES) * len(_PER_AXIS) + 1
NAMES = (*(f"{n}_{a}" for a in AXES for n in _PER_AXIS), "max_jerk")
"""Coordinate names: ``kp_x, ki_x, a1_x, a2_x, a3_x, kp_y, …, max_jerk``."""
"""Length of a tuning vector: five coordinates per axis and the jerk limit (11)."""
SHAPER_NAMES = tuple(f"{n}_{a}" for a in AXES for n in ("sf", "sz"))
"""The shaper coordinates a shaped machine adds: ``sf_x, sz_x, sf_y, sz_y``."""
SHAPER_FREQUENCY_SPAN = 1.5
"""Factor from the shaper's frequency to either end of its log-scaled coordinate."""
SHAPER_DAMPING_SPAN = 0.2
"""Half-range of the shaper's damping ratio about its centre (1)."""
SHAPER_NYQUIST_SHARE = 0.9
"""A decoded shaper frequency stays below this share of the Nyquist rate."""


@dataclass(frozen=True)
class TuningSettings:
    """What one tuning run sets on the machine.

    Attributes
    ----------
    gains : RegulatorGains
        Position regulator gains, per axis (V/m, V/(m·s), DCU α in V/m).
    max_jerk : float
        Contour jerk limit of the planner (m/s³).
    shaper : tuple of 2 (frequency, damping), optional
        The input shapers' design frequency (Hz) and damping (1) of x and y, for a machine
        that shapes both axes; None: the machine's shapers as they are.
    """

    gains: RegulatorGains
    max_jerk: float
    shaper: tuple[tuple[float, float], tuple[float, float]] | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.max_jerk, int | float) and math.isfinite(self.max_jerk)
                and self.max_jerk > 0.0):
            raise ConfigError("max_jerk", f"must be a finite number > 0 (m/s³), got "
                              f"{self.max_jerk!r}")

    def to_dict(self) -> dict[str, object]:
        """Plain per-axis values: ``{"kp": [x, y], "ki": [x, y], "dcu_alpha": [[…], […]],
        "max_jerk": J}`` (SI)."""
        g = self.gains
        out: dict[str, object] = {"kp": list(_pair(g.kp)), "ki": list(_pair(g.ki)),
                                  "dcu_alpha": [list(row) for row in _rows(g.dcu_alpha)],
                                  "max_jerk": float(self.max_jerk)}
        if self.shaper is not None:
            out["shaper_frequency"] = [float(f) for f, _ in self.shaper]
            out["shaper_damping"] = [float(z) for _, z in self.shaper]
        return out

    def overrides(self) -> dict[str, float]:
        """The machine overrides these settings make besides the gains (dotted keys, SI):
        the jerk limit, and the shapers' frequency and damping when tuned."""
        out = {"controller.limits.max_jerk": float(self.max_jerk)}
        for axis, (f, z) in zip(AXES, self.shaper or (), strict=False):
            out[f"controller.shaper.{axis}.frequency"] = float(f)
            out[f"controller.shaper.{axis}.damping"] = float(z)
        return out


def _pair(value: float | tuple[float, ...]) -> tuple[float, float]:
    return value if isinstance(value, tuple) else (value, value)  # type: ignore[return-value]


def _rows(alpha: tuple) -> tuple[tuple[float, ...], ...]:
    return alpha if isinstance(alpha[0], tuple) else (alpha, alpha)


@dataclass(frozen=True)
class TuningSpace:
    """The map between a normalised action and ``TuningSettings`` for one machine.

    Attributes
    ----------
    analytic : RegulatorGains
        The analytic design (per axis), the centre of the space.
    max_jerk : float
        The machine's contour jerk limit, the centre of the jerk coordinate (m/s³).
    velocity_gain : tuple of float, (x, y)
        ``K_H`` of each axis (m/(V·s)), for the ki scale.
    kp_span, jerk_span : float
        Factor from the centre to either end of the log-scaled kp and jerk coordinates.
    shaper : tuple of 2 (frequency, damping), optional
        The centre of the shaper coordinates (Hz, 1), x and y; None: no such coordinates.
    shaper_limit : float
        Highest shaper frequency a decoded action gets (Hz): ``SHAPER_NYQUIST_SHARE`` of
        the controller period's Nyquist rate (a shaper cannot act above it).
    """

    analytic: RegulatorGains
    max_jerk: float
    velocity_gain: tuple[float, float]
    kp_span: float = 4.0
    jerk_span: float = 4.0
    shaper: tuple[tuple[float, float], tuple[float, float]] | None = None
    shaper_limit: float = math.inf

    def __post_init__(self) -> None:
        for name in ("kp_span", "jerk_span"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 1.0):
                raise ConfigError(name, f"must be a finite number > 1, got {v!r}")

    @classmethod
    def from_machine(cls, cfg: MachineConfig, models: Sequence[LinearAxisModel], **options
                     ) -> TuningSpace:
        """The space of machine ``cfg`` whose axes have the linear models ``models``: the
        analytic order-3 DCU design with the machine's DAC and trip limit."""
        reg = cfg.controller.regulator
        base = default_gains(list(models), cfg.controller.period, dcu_order=3,
                             following_error_limit=reg.following_error_limit)
        # saturation at each axis' DAC full scale; the DAC (the plant) quantises
        base = dataclasses.replace(base, output_limit=tuple(cfg.axes[a].dac.full_scale
                                                            for a in AXES), dac_bits=None)
        kh = tuple(float(m.velocity_gain) for m in models)
        shapers = axis_shapers(cfg.controller.shaper, cfg.axes, cfg.controller.period)
        if all(s is not None for s in shapers):
            options.setdefault("shaper", tuple((s.frequency, s.damping) for s in shapers))
            options.setdefault("shaper_limit", SHAPER_NYQUIST_SHARE * 0.5
                               / cfg.controller.period)
        return cls(base, cfg.controller.limits.max_jerk, kh, **options)  # type: ignore[arg-type]

    @property
    def names(self) -> tuple[str, ...]:
        """Coordinate names (``NAMES``, then ``SHAPER_NAMES`` when shaped)."""
        return NAMES if self.shaper is None else (*NAMES, *SHAPER_NAMES)

    @property
    def dim(self) -> int:
        """Number of coordinates (``DIM``, 4 more when shaped)."""
        return DIM if self.shaper is None else DIM + len(SHAPER_NAMES)

    def _ki_scale(self, k: int) -> float:
        kp0 = _pair(self.analytic.kp)[k]
        return kp0 * kp0 * self.velocity_gain[k]

    def decode(self, action: Sequence[float] | np.ndarray) -> TuningSettings:
        """Settings of a normalised action (clipped to [-1, 1]).

        Raises
        ------
        ValueError
            If the action has the wrong length or a NaN/inf entry.
        """
        a = check_action(action, self.dim)
        kp0, alpha0 = _pair(self.analytic.kp), _rows(self.analytic.dcu_alpha)
        kp, ki, alpha = [], [], []
        for k in range(len(AXES)):
            u = a[5 * k: 5 * k + 5]
            kp.append(kp0[k] * self.kp_span ** u[0])
            ki.append(0.0 if u[1] <= 0.0
                      else self._ki_scale(k) * 10.0 ** (KI_DECADES * (u[1] - 1.0)))
            alpha.append(tuple(a0 * (1.0 + span * x) for a0, span, x
                               in zip(alpha0[k], ALPHA_SPAN, u[2:], strict=True)))
        gains = dataclasses.replace(self.analytic, kp=tuple(kp), ki=tuple(ki),
                                    dcu_alpha=tuple(alpha))
        jerk = float(self.max_jerk * self.jerk_span ** a[DIM - 1])
        if self.shaper is None:
            return TuningSettings(gains, jerk)
        u = a[DIM:]
        shaper = tuple((float(min(self.shaper_limit, f0 * SHAPER_FREQUENCY_SPAN ** u[2 * k])),
                        float(min(0.9, max(0.0, z0 + SHAPER_DAMPING_SPAN * u[2 * k + 1]))))
                       for k, (f0, z0) in enumerate(self.shaper))
        return TuningSettings(gains, jerk, shaper)  # type: ignore[arg-type]

    def encode(self, settings: TuningSettings) -> np.ndarray:
        """The action of ``settings`` (the inverse of ``decode``, clipped to [-1, 1]; a
        ``ki`` of 0 maps to 0)."""
        g = settings.gains
        kp0, alpha0 = _pair(self.analytic.kp), _rows(self.analytic.dcu_alpha)
        out = []
        for k in range(len(AXES)):
            out.append(math.log(_pair(g.kp)[k] / kp0[k]) / math.log(self.kp_span))
            ki = _pair(g.ki)[k]
            out.append(0.0 if ki <= 0.0
                       else 1.0 + math.log10(ki / self._ki_scale(k)) / KI_DECADES)
            for a, a0, span in zip(_rows(g.dcu_alpha)[k], alpha0[k], ALPHA_SPAN, strict=True):
                out.append(0.0 if a0 == 0.0 else (a / a0 - 1.0) / span)
        out.append(math.log(settings.max_jerk / self.max_jerk) / math.log(self.jerk_span))
        if self.shaper is not None:
            tuned = settings.shaper or self.shaper
            for (f, z), (f0, z0) in zip(tuned, self.shaper, strict=True):
                out += [math.log(f / f0) / math.log(SHAPER_FREQUENCY_SPAN),
                        (z - z0) / SHAPER_DAMPING_SPAN]
        return np.clip(np.asarray(out), -1.0, 1.0)


def settings_from_dict(values: Mapping[str, Any], base: RegulatorGains) -> TuningSettings:
    """``TuningSettings`` of ``TuningSettings.to_dict``'s plain values (SI); ``base``
    supplies the DAC, output and trip limits."""
    gains = RegulatorGains(kp=tuple(float(v) for v in values["kp"]),
                           ki=tuple(float(v) for v in values["ki"]),
                           dcu_alpha=tuple(tuple(float(v) for v in row)
                                           for row in values["dcu_alpha"]),
                           output_limit=base.output_limit, dac_bits=base.dac_bits,
                           following_error_limit=base.following_error_limit)
    shaper = None
    if "shaper_frequency" in values:
        shaper = tuple((float(f), float(z)) for f, z in zip(
            values["shaper_frequency"], values["shaper_damping"], strict=True))
    return TuningSettings(gains, float(values["max_jerk"]), shaper)  # type: ignore[arg-type]


def check_action(action: Sequence[float] | np.ndarray, dim: int) -> np.ndarray:
    """``action`` as a float64 vector clipped to [-1, 1].

    Raises
    ------
    ValueError
        Wrong shape, or a NaN/inf entry (naming its index).
    """
    a = np.asarray(action, dtype=float).reshape(-1)
    if a.shape != (dim,):
        raise ValueError(f"action must have {dim} entries, got shape "
                         f"{np.shape(action)}")
    bad = np.flatnonzero(~np.isfinite(a))
    if bad.size:
        raise ValueError(f"action[{bad[0]}] is {a[bad[0]]}: actions must be finite numbers "
                         "in [-1, 1]")
    return np.clip(a, -1.0, 1.0)


__all__ += ["check_action"]
