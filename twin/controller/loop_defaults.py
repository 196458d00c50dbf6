"""What the cyclic controller assumes about the position loop when it is not told.

* ``estimated_axis_model``: a first-order model of an axis' closed speed loop from its
  configuration, for the gain rules and the DCU until the twin's own model is passed in;
* ``loop_gains``: the regulator gains of the machine settings, the unset ones derived;
* ``servo_lag``: the time constant of the closed position loop, for the corner model;
* ``default_corner_model``: the corner model of a machine, the one the controller and
  ``Planner.from_settings`` both use.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

from twin.config import AxisConfig, ControllerSettings
from twin.controller.corner import SeedCornerModel
from twin.controller.gains import RegulatorGains, default_gains
from twin.controller.linear import LinearAxisModel

__all__ = ["default_corner_model", "estimated_axis_model", "loop_gains", "servo_lag"]


def estimated_axis_model(axis: AxisConfig) -> LinearAxisModel:
    """A first-order estimate ``K_H/(p(T·p + 1))`` of an axis from its configuration.

    ``K_H = 1/volts_per_speed`` (m/s per V). T is the closed speed loop by the tuning rules
    the drive uses: converter dead time ``T_μ = firing_period/2``, current loop (modulus
    optimum) ≈ ``2·T_μ``, speed-loop small time constant ``T_σ = 2·T_μ + T_tacho``, and
    the symmetric optimum with its reference filter ≈ a first-order lag ``a²·T_σ``. Pass
    the twin's own linear model (``axis_models=``) where accuracy matters (issue 5).
    """
    t_mu = 0.5 * axis.converter.firing_period
    t_sigma = 2.0 * t_mu + axis.tacho.filter_time_constant
    a = axis.speed_loop.symmetric_optimum_a
    return LinearAxisModel.servo(1.0 / axis.volts_per_speed, a * a * t_sigma)


def servo_lag(gains: RegulatorGains, models: Sequence[LinearAxisModel], period: float
              ) -> float:
    """Time constant of the slowest closed position loop, for the corner model (s).

    A type-1 loop with velocity gain ``K_v = kp·K_H`` follows a ramp of speed V with the
    error ``V·(1 − ff1·K_H)/K_v``; with full velocity feed-forward the lag left is the
    drive's own (the sum of the model's time constants) plus the one-period computation
    delay. The larger of the two, per axis.
    """
    lags = []
    for k, model in enumerate(models):
        kh = model.velocity_gain
        kp = gains.kp[k] if isinstance(gains.kp, tuple) else gains.kp
        ff1 = gains.ff1[k] if isinstance(gains.ff1, tuple) else gains.ff1
        den = model.den
        own = (float(den[-3] / den[-2]) if den.size >= 3 else 0.0) + period
        loop = abs(1.0 - ff1 * kh) / (kp * kh) if kp > 0.0 else math.inf
        lags.append(max(loop, own))
    return max(lags)


def loop_gains(settings: ControllerSettings, axes: Sequence[AxisConfig],
               models: Sequence[LinearAxisModel], dcu_order: int) -> RegulatorGains:
    """Regulator gains of ``settings``; values left ``None`` there come from
    ``default_gains`` of the axis models (with ``dcu_order``). The output saturates at each
    axis' DAC full scale; it is not quantised here: the DAC is the machine's (the twin's
    plant, or the I/O module behind the driver), which quantises the volts once."""
    reg = settings.regulator
    base = default_gains(list(models), settings.period, dcu_order=dcu_order,
                         following_error_limit=reg.following_error_limit)
    given = {name: getattr(reg, name) for name in ("kp", "ki", "kd", "ff1", "ff2", "ff3")
             if getattr(reg, name) is not None}
    if reg.dcu_alpha is not None:  # explicit coefficients (a tuning job's) win
        given["dcu_alpha"] = reg.dcu_alpha
    return dataclasses.replace(base, output_limit=tuple(ax.dac.full_scale for ax in axes),
                               dac_bits=None, **given)


def default_corner_model(settings: ControllerSettings, axes: Mapping[str, AxisConfig], *,
                         model_axes: Mapping[str, AxisConfig] | None = None,
                         axis_models: Sequence[LinearAxisModel] | None = None,
                         gains: RegulatorGains | None = None) -> SeedCornerModel:
    """The machine's corner model: seed 001's relation for the believed axes (``model_axes``,
    default ``axes``) with the servo time constant of the position loop (`servo_lag`) of
    ``gains`` (default the settings' gains, `loop_gains`) on ``axis_models`` (default
    `estimated_axis_model` of the believed axes). The controller passes its own gains and
    models; ``Planner.from_settings`` uses the defaults: the same model either way."""
    believed = axes if model_axes is None else model_axes
    models = (list(axis_models) if axis_models is not None
              else [estimated_axis_model(believed[a]) for a in ("x", "y")])
    if gains is None:
        gains = loop_gains(settings, [axes[a] for a in ("x", "y")], models,
                           settings.regulator.dcu_order)
    return SeedCornerModel.from_axes(believed, servo_time_constant=servo_lag(
        gains, models, settings.period))
