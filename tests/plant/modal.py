"""Shared measurements for the plant tests: excite the bare mechanics, find the elastic mode.

Method (also in twin/models/README.md, "Checking the modes"): apply a force step and record
the screw deflection rate δ̇ (the tendon velocity). Between two masses, δ obeys
δ̈ + 2ζω·δ̇ + ω²·δ = F/M_driven, so δ̈(s) = (F/M)·s/(s² + 2ζωs + ω²): the spectrum of the
deflection's second derivative (ω² times that of the deflection) peaks exactly at the
undamped natural frequency ω for ANY damping ratio, which matters for the belt (ζ ≈ 0.4-0.6),
where the deflection spectrum itself would peak at ω·√(1 − 2ζ²).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from twin.config import MachineConfig
from twin.plant.model import load_model

__all__ = ["mid_travel", "peak_frequency", "step_response_rate"]


def mid_travel(cfg: MachineConfig) -> np.ndarray:
    """Middle of the travel of both axes (m), shape (2,)."""
    return np.array([sum(cfg.axes[a].mechanics.travel) / 2.0 for a in ("x", "y")])


def step_response_rate(cfg: MachineConfig, axis: str, *, rotor_torque: float = 0.0,
                       table_force: float = 0.0, duration: float = 0.3) -> tuple[np.ndarray,
                                                                                  float]:
    """Screw deflection rate δ̇ (m/s) after a rotor torque (N·m) and/or table force (N) step
    applied at rest at mid-travel; returns (δ̇ at every physics step, timestep (s))."""
    m = load_model(cfg)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    x0 = mid_travel(cfg)["xy".index(axis)]
    d.qpos[m.joint(axis).qposadr[0]] = x0
    d.qpos[m.joint(f"{axis}_rotor").qposadr[0]] = x0 / cfg.axes[axis].transmission.ratio
    d.qfrc_applied[m.joint(f"{axis}_rotor").dofadr[0]] = rotor_torque
    d.qfrc_applied[m.joint(axis).dofadr[0]] = table_force
    screw = m.tendon(f"{axis}_screw").id
    n = round(duration / m.opt.timestep)
    rate = np.zeros(n + 1)
    for i in range(n):
        mujoco.mj_step(m, d)
        rate[i + 1] = d.ten_velocity[screw]
    if d.warning.number.any():
        raise AssertionError(f"MuJoCo warnings: {d.warning.number}")
    return rate, m.opt.timestep


def peak_frequency(rate: np.ndarray, dt: float, band: tuple[float, float], *,
                   resolution: float = 1e-3) -> float:
    """Frequency (rad/s) of the largest peak of the spectrum of d(rate)/dt within ``band``.

    The record is zero-padded so that the frequency grid is finer than ``resolution`` times
    the lower band edge; the transient must have decayed within the record.
    """
    acc = np.diff(rate) / dt
    spacing = resolution * band[0]
    n_fft = 1 << max(math.ceil(math.log2(2.0 * math.pi / (dt * spacing))),
                     len(acc).bit_length())
    spectrum = np.abs(np.fft.rfft(acc, n_fft))
    w = 2.0 * math.pi * np.fft.rfftfreq(n_fft, dt)
    spectrum[(w < band[0]) | (w > band[1])] = 0.0
    return float(w[np.argmax(spectrum)])
