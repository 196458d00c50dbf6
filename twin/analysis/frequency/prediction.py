"""What the linearised twin predicts: the frequency responses a measurement is compared with.

The axis, linearised about a steady motion (continuous conduction, friction a constant
force)::

    U ── DAC stage (1 + gain error) ── closed speed loop ω/U ── rotor ── chain ── table

The closed speed loop is the drive's own (``twin.drive.linear.speed_response``) with the
rotor's mechanics given by the elastic chain behind it (``twin.plant.model.axis_mechanics``
at the measured nut position, with the slide's and the rotor's viscous friction): the
rotor's admittance Y(s) = ω/τ and the transmissibility X_table/X_rotor come from the chain's
mass, damping and stiffness matrices point by point, so every mode and anti-resonance of the
chain enters as it is.

Responses sampled by the controller (tacho, encoder) are those of a zero-order-held input
read at the period T: the continuous response summed over its aliases,

    H_T(ω) = Σ_n H(j(ω + n·ω_s))·(1 − e^(−j(ω + n·ω_s)·T))/(j(ω + n·ω_s)·T),   ω_s = 2π/T,

which is exactly the pulse transfer function of the held input to the samples. The
accelerometer samples fast enough for the measurement to divide out the hold and its own
averaging, so its response is compared as the continuous H.

The position loop opened at the DAC is L(z) = C(z)·G_T(z)·z⁻¹: the regulator's feedback
(P, I, D of ``RegulatorGains``) on the encoder's sampled position, one period of
computation delay (the controller computes ahead). ``design_loop`` is the same loop on the
controller's own linear model (rigid, ``twin.controller.linear``): the design the gains
were derived from.
"""

from __future__ import annotations

import math

import numpy as np

from twin.config import AXES, MachineConfig
from twin.controller.gains import RegulatorGains
from twin.controller.linear import LinearAxisModel
from twin.drive.linear import speed_response
from twin.plant.model import axis_mechanics

__all__ = ["ALIASES", "chain_response", "design_loop", "loop_response", "regulator_response",
           "sampled", "table_response"]

ALIASES = 60
"""Aliases summed on each side for a sampled response (the terms fall as 1/n³ or faster)."""


def chain_response(cfg: MachineConfig, axis: str, position: float, s: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The rotor's admittance Y(s) = ω/τ (rad/(s·N·m)) and the transmissibility
    X_table/(r·θ_rotor) (1) of ``axis`` with the nut at ``position`` (m), at ``s``."""
    ax = cfg.axes[axis]
    chain = axis_mechanics(cfg, axis, position)
    mass, stiffness, damping = chain.matrices("free")
    r = chain.ratio
    damping = damping.copy()
    damping[0, 0] += ax.mechanics.rotor_viscous / r**2
    damping[-1, -1] += ax.mechanics.slide_viscous
    s = np.asarray(s, dtype=complex)
    dynamic = (mass[None] * (s**2)[:, None, None] + damping[None] * s[:, None, None]
               + stiffness[None])
    # only the first column of the inverse: the response to a force on the rotor
    unit = np.zeros((len(s), len(mass)), dtype=complex)
    unit[:, 0] = 1.0
    column = np.linalg.solve(dynamic, unit[..., None])[..., 0]
    return s * column[:, 0] / r**2, column[:, -1] / column[:, 0]


def table_response(cfg: MachineConfig, axis: str, position: float, s: np.ndarray
                   ) -> dict[str, np.ndarray]:
    """Continuous responses of ``axis`` per DAC volt at ``s``: ``omega`` (motor speed,
    rad/(s·V)), ``tacho`` (the tacho as its ADC reads it, through its filter, V/V),
    ``motor_position`` (table travel the encoder reports, r·θ, m/V) and
    ``table_velocity``, ``table_acceleration`` (m/(s·V), m/(s²·V))."""
    ax = cfg.axes[axis]
    s = np.asarray(s, dtype=complex)
    admittance, transmissibility = chain_response(cfg, axis, position, s)
    omega = (1.0 + ax.dac.gain_error) * speed_response(
        ax, s, admittance, moving_mass=cfg.moving_masses()[axis])
    r = ax.transmission.ratio
    table_velocity = omega * r * transmissibility
    return {"omega": omega,
            "tacho": omega * ax.tacho.gain / (ax.tacho.filter_time_constant * s + 1.0),
            "motor_position": omega * r / s, "table_velocity": table_velocity,
            "table_acceleration": table_velocity * s}


def sampled(cfg: MachineConfig, axis: str, position: float, frequency: np.ndarray,
            output: str, *, aliases: int = ALIASES) -> np.ndarray:
    """The response ``output`` (a key of :func:`table_response`) as the controller sees it:
    the held DAC input, the output sampled every period (the module docstring's alias
    sum), at ``frequency`` (Hz, below the Nyquist frequency)."""
    period = cfg.controller.period
    w = 2.0 * math.pi * np.asarray(frequency, dtype=float)
    n = np.arange(-aliases, aliases + 1)
    wn = (w[:, None] + 2.0 * math.pi * n[None, :] / period).ravel()
    hold = (1.0 - np.exp(-1j * wn * period)) / (1j * wn * period)
    h = table_response(cfg, axis, position, 1j * wn)[output] * hold
    return h.reshape(len(w), len(n)).sum(axis=1)


def regulator_response(gains: RegulatorGains, axis: str, period: float,
                       frequency: np.ndarray) -> np.ndarray:
    """The position regulator's feedback C(e^(jωT)) on the error (V/m): kp + ki·T/(1 − z⁻¹)
    + kd·(1 − z⁻¹)/T, as ``twin.controller.regulator`` computes it."""
    k = AXES.index(axis)

    def gain(name: str) -> float:
        value = getattr(gains, name)
        return float(value[k] if isinstance(value, tuple) else value)

    back = 1.0 - np.exp(-2j * math.pi * np.asarray(frequency, dtype=float) * period)
    return gain("kp") + gain("ki") * period / back + gain("kd") * back / period


def loop_response(cfg: MachineConfig, axis: str, position: float, gains: RegulatorGains,
                  frequency: np.ndarray) -> np.ndarray:
    """The position loop opened at the DAC, L(e^(jωT)) = C·G_T·e^(−jωT) (1), of the
    machine ``cfg`` (elastic, linearised) under ``gains``."""
    period = cfg.controller.period
    g = sampled(cfg, axis, position, frequency, "motor_position")
    delay = np.exp(-2j * math.pi * np.asarray(frequency, dtype=float) * period)
    return regulator_response(gains, axis, period, frequency) * g * delay


def design_loop(model: LinearAxisModel, gains: RegulatorGains, axis: str, period: float,
                frequency: np.ndarray) -> np.ndarray:
    """The position loop the gains were designed on: C·G(z) of the controller's rigid
    linear model with its one period of delay (``LinearAxisModel.frequency_response``)."""
    w = 2.0 * math.pi * np.asarray(frequency, dtype=float)
    g = model.frequency_response(w, period=period, delay_ticks=1)
    return regulator_response(gains, axis, period, frequency) * g
