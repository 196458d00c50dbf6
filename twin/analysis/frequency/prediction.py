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
from twin.drive.design import axis_inertia
from twin.drive.linear import speed_response
from twin.plant.model import axis_mechanics

__all__ = ["ALIASES", "accelerance", "chain_response", "closed_loop_modes", "design_loop",
           "drive_impedance", "loop_response", "predict", "regulator_response",
           "rigid_response", "sampled", "table_response"]

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


def rigid_response(cfg: MachineConfig, axis: str, s: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """As :func:`chain_response` for a rigid chain: Y(s) = 1/(J·s + c) with J the total
    inertia at the shaft and c the rotor's and the slide's viscous friction, and a
    transmissibility of 1."""
    ax = cfg.axes[axis]
    r = ax.transmission.ratio
    inertia = axis_inertia(ax, cfg.moving_masses()[axis])
    viscous = ax.mechanics.rotor_viscous + r**2 * ax.mechanics.slide_viscous
    s = np.asarray(s, dtype=complex)
    return 1.0 / (inertia * s + viscous), np.ones_like(s)


def table_response(cfg: MachineConfig, axis: str, position: float, s: np.ndarray, *,
                   rigid: bool = False) -> dict[str, np.ndarray]:
    """Continuous responses of ``axis`` per DAC volt at ``s``: ``omega`` (motor speed,
    rad/(s·V)), ``tacho`` (the tacho as its ADC reads it, through its filter, V/V),
    ``motor_position`` (table travel the encoder reports, r·θ, m/V) and
    ``table_velocity``, ``table_acceleration`` (m/(s·V), m/(s²·V)); ``rigid``: of the
    rigid chain (:func:`rigid_response`)."""
    ax = cfg.axes[axis]
    s = np.asarray(s, dtype=complex)
    admittance, transmissibility = (rigid_response(cfg, axis, s) if rigid else
                                    chain_response(cfg, axis, position, s))
    omega = (1.0 + ax.dac.gain_error) * speed_response(
        ax, s, admittance, moving_mass=cfg.moving_masses()[axis])
    r = ax.transmission.ratio
    table_velocity = omega * r * transmissibility
    return {"omega": omega,
            "tacho": omega * ax.tacho.gain / (ax.tacho.filter_time_constant * s + 1.0),
            "motor_position": omega * r / s, "table_velocity": table_velocity,
            "table_acceleration": table_velocity * s}


def sampled(cfg: MachineConfig, axis: str, position: float, frequency: np.ndarray,
            output: str, *, aliases: int = ALIASES, rigid: bool = False) -> np.ndarray:
    """The response ``output`` (a key of :func:`table_response`) as the controller sees it:
    the held DAC input, the output sampled every period (the module docstring's alias
    sum), at ``frequency`` (Hz, below the Nyquist frequency)."""
    period = cfg.controller.period
    w = 2.0 * math.pi * np.asarray(frequency, dtype=float)
    n = np.arange(-aliases, aliases + 1)
    wn = (w[:, None] + 2.0 * math.pi * n[None, :] / period).ravel()
    hold = (1.0 - np.exp(-1j * wn * period)) / (1j * wn * period)
    h = table_response(cfg, axis, position, 1j * wn, rigid=rigid)[output] * hold
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
                  frequency: np.ndarray, *, rigid: bool = False) -> np.ndarray:
    """The position loop opened at the DAC, L(e^(jωT)) = C·G_T·e^(−jωT) (1), of the
    machine ``cfg`` (elastic, linearised; ``rigid``: the rigid chain) under ``gains``."""
    period = cfg.controller.period
    g = sampled(cfg, axis, position, frequency, "motor_position", rigid=rigid)
    delay = np.exp(-2j * math.pi * np.asarray(frequency, dtype=float) * period)
    return regulator_response(gains, axis, period, frequency) * g * delay


def design_loop(model: LinearAxisModel, gains: RegulatorGains, axis: str, period: float,
                frequency: np.ndarray) -> np.ndarray:
    """The position loop the gains were designed on: C·G(z) of the controller's rigid
    linear model with its one period of delay (``LinearAxisModel.frequency_response``)."""
    w = 2.0 * math.pi * np.asarray(frequency, dtype=float)
    g = model.frequency_response(w, period=period, delay_ticks=1)
    return regulator_response(gains, axis, period, frequency) * g


def predict(cfg: MachineConfig, axis: str, position: float, loop: str, sensor: str,
            frequency: np.ndarray, gains: RegulatorGains | None = None, *,
            rigid: bool = False) -> np.ndarray:
    """What a measurement of ``loop`` with ``sensor`` (``twin.analysis.frequency.LOOPS``,
    ``SENSORS``) sees at ``frequency`` (Hz) on the machine ``cfg``, in the measurement's
    unit: the table's acceleration (``mechanics``) or speed (``speed``) per DAC volt, seen
    by the accelerometer (continuous: the measurement divides out the hold and the sensor's
    averaging) or by the tacho (sampled; its volts over K_C times r, differenced for the
    acceleration); ``position``: the loop transfer function under ``gains``."""
    f = np.asarray(frequency, dtype=float)
    if loop == "position":
        if gains is None:
            raise ValueError("the position loop's prediction needs the regulator's gains")
        return loop_response(cfg, axis, position, gains, f, rigid=rigid)
    if sensor == "accelerometer":
        key = "table_acceleration" if loop == "mechanics" else "table_velocity"
        s = 2j * math.pi * f
        # the physics step (semi-implicit Euler) integrates each step's acceleration from
        # the state at its start: what the table does lags by half a step
        return (table_response(cfg, axis, position, s, rigid=rigid)[key]
                * np.exp(-0.5 * s * cfg.simulation.timestep))
    ax = cfg.axes[axis]
    speed = (sampled(cfg, axis, position, f, "tacho", rigid=rigid)
             * ax.transmission.ratio / ax.tacho.gain)
    if loop == "speed":
        return speed
    period = cfg.controller.period
    return speed * (1.0 - np.exp(-2j * math.pi * f * period)) / period


def drive_impedance(cfg: MachineConfig, axis: str, s: np.ndarray) -> np.ndarray:
    """The torque the drive's closed speed loop opposes to the rotor's speed with its
    reference held, Z(s) = −τ/ω (N·m·s/rad), at ``s``: the drive is linear in its reference
    U and the rotor's speed, τ = A·U − Z·ω, so ω/U = Y·A/(1 + Y·Z) under any load Y, and
    ``speed_response`` under two loads gives A and Z (the drive's loop is written once)."""
    ax = cfg.axes[axis]
    s = np.asarray(s, dtype=complex)
    moving = cfg.moving_masses()[axis]
    loads = [1.0 / (ax.mechanics.rotor_inertia * s), 0.5 / (ax.mechanics.rotor_inertia * s)]
    q = [y / speed_response(ax, s, y, moving_mass=moving) for y in loads]
    z_over_a = (q[0] - q[1]) / (loads[0] - loads[1])
    return z_over_a / (q[0] - loads[0] * z_over_a)


def accelerance(cfg: MachineConfig, axis: str, position: float, frequency: np.ndarray, *,
                rigid: bool = False) -> np.ndarray:
    """The table's acceleration per force on the table, A/F ((m/s²)/N), at ``frequency``
    (Hz): what a modal hammer measures, the drive holding the rotor by its closed speed loop
    (``drive_impedance``; the position loop, far slower than the modes, left open), the
    elastic chain at the nut ``position`` (m) (``rigid``: the rigid chain)."""
    ax = cfg.axes[axis]
    s = 2j * math.pi * np.asarray(frequency, dtype=float)
    r = ax.transmission.ratio
    held = drive_impedance(cfg, axis, s) / r**2 + ax.mechanics.rotor_viscous / r**2
    if rigid:
        mass = axis_inertia(ax, cfg.moving_masses()[axis]) / r**2
        return s / (mass * s + held + ax.mechanics.slide_viscous)
    mass, stiffness, damping = axis_mechanics(cfg, axis, position).matrices("free")
    damping = damping.copy()
    damping[-1, -1] += ax.mechanics.slide_viscous
    dynamic = (mass[None] * (s**2)[:, None, None] + damping[None] * s[:, None, None]
               + stiffness[None])
    dynamic[:, 0, 0] += held * s
    unit = np.zeros((len(s), len(mass)), dtype=complex)
    unit[:, -1] = 1.0
    return s**2 * np.linalg.solve(dynamic, unit[..., None])[:, -1, 0]


def closed_loop_modes(cfg: MachineConfig, axis: str, position: float, *,
                      iterations: int = 60) -> list[complex]:
    """The poles s (1/s, Im s > 0, ascending) of the axis' table acceleration per DAC volt
    near each elastic pole of the bare chain: the chain's modes as the drive's closed speed
    loop shifts them. Each is a zero of 1/H(s) found by Muller's iteration started at the
    chain's pole (``AxisMechanics.poles``): the analytic reference a measured resonance is
    compared with."""
    chain = axis_mechanics(cfg, axis, position)

    def g(s: complex) -> complex:
        h = table_response(cfg, axis, position, np.array([s]))["table_acceleration"][0]
        return 1.0 / h

    found: list[complex] = []
    for start in chain.poles("free"):
        x = [start * 0.98, start * 1.02, complex(start)]
        y = [g(v) for v in x]
        for _ in range(iterations):
            q = (x[2] - x[1]) / (x[1] - x[0])
            a = q * y[2] - q * (1 + q) * y[1] + q * q * y[0]
            b = (2 * q + 1) * y[2] - (1 + q) ** 2 * y[1] + q * q * y[0]
            c = (1 + q) * y[2]
            root = np.sqrt(b * b - 4 * a * c)
            den = b + root if abs(b + root) >= abs(b - root) else b - root
            if den == 0:
                break
            new = x[2] - (x[2] - x[1]) * 2 * c / den
            x, y = [x[1], x[2], new], [y[1], y[2], g(new)]
            if abs(x[2] - x[1]) < 1e-10 * abs(x[2]):
                break
        s = x[2]
        if s.imag > 0 and all(abs(s - o) > 1e-6 * abs(s) for o in found):
            found.append(complex(s))
    return sorted(found, key=abs)
