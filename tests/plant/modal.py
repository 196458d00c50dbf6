"""Shared measurements for the plant tests: excite the mechanics, find the elastic modes.

Two methods (also in twin/models/README.md, "Checking the modes"):

- **Spectral peak after a step** (:func:`step_response_rate`, :func:`peak_frequency`):
  apply a force step and record the screw deflection rate δ̇ (the axial tendon's velocity).
  Between two masses, δ obeys δ̈ + 2ζω·δ̇ + ω²·δ = F/M_driven, so
  δ̈(s) = (F/M)·s/(s² + 2ζωs + ω²): the spectrum of the deflection's second derivative
  peaks exactly at the undamped ω for ANY damping ratio, which matters for the belt
  (ζ ≈ 0.4-0.6), where the deflection spectrum itself would peak at ω·√(1 − 2ζ²).
- **Free vibration of the plant** (:func:`free_vibration`, :func:`discrete_poles`): the
  real ``Plant`` (drives off, friction off so that the mechanics are linear:
  :func:`linear_plant`) released from a random deflection of every body at one nut
  position, its full state recorded after every physics step. One physics step of a
  linear model is a linear map x' = A·x; a least-squares fit of A to the record (dynamic
  mode decomposition) recovers it, and its eigenvalues z give the simulated poles
  s = ln(z)/Δt, every mode at once.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from twin.config import AXES, MachineConfig
from twin.plant import Plant
from twin.plant.model import axis_mechanics, load_model

__all__ = ["LINEAR", "discrete_poles", "free_vibration", "linear_plant", "mid_travel",
           "modal_timestep",
           "peak_frequency", "random_screw_machine", "step_response_rate", "three_positions"]

LINEAR = {"axes.*.mechanics.slide_coulomb": 0.0, "axes.*.mechanics.rotor_coulomb": 0.0,
          "axes.*.mechanics.slide_breakaway": 0.0, "axes.*.mechanics.rotor_breakaway": 0.0,
          "axes.*.transmission.backlash": 0.0}
"""Overrides that leave only linear mechanics (no friction constraint, no dead band)."""


def mid_travel(cfg: MachineConfig) -> np.ndarray:
    """Middle of the travel of both axes (m), shape (2,)."""
    return np.array([sum(cfg.axes[a].mechanics.travel) / 2.0 for a in ("x", "y")])


def three_positions(cfg: MachineConfig, axis: str) -> list[float]:
    """Table positions (m) with the nut near the drive-end bearing, in the middle and at
    the far end: 2 %, 50 % and 98 % of the travel from the bearing's end."""
    lo, hi = cfg.axes[axis].mechanics.travel
    near = [lo + f * (hi - lo) for f in (0.02, 0.5, 0.98)]
    return near if cfg.axes[axis].transmission.drive_end == "min" else near[::-1]


def step_response_rate(cfg: MachineConfig, axis: str, *, rotor_torque: float = 0.0,
                       table_force: float = 0.0, duration: float = 0.3) -> tuple[np.ndarray,
                                                                                  float]:
    """Axial spring deflection rate (m/s) after a rotor torque (N·m) and/or table force (N)
    step applied at rest at mid-travel, on the bare compiled model with its springs as at
    mid-travel; returns (rate at every physics step, timestep (s))."""
    m = load_model(cfg)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    x0 = mid_travel(cfg)["xy".index(axis)]
    tr = cfg.axes[axis].transmission
    d.qpos[m.joint(axis).qposadr[0]] = x0
    d.qpos[m.joint(f"{axis}_rotor").qposadr[0]] = x0 / tr.ratio
    if tr.screw_diameter > 0.0:
        d.qpos[m.joint(f"{axis}_shaft").qposadr[0]] = x0 / tr.screw_ratio
    chain = axis_mechanics(cfg, axis, x0)
    screw = m.tendon(f"{axis}_screw").id
    m.tendon_stiffness[screw] = chain.stiffness
    m.tendon_damping[screw] = chain.damping
    d.qfrc_applied[m.joint(f"{axis}_rotor").dofadr[0]] = rotor_torque
    d.qfrc_applied[m.joint(axis).dofadr[0]] = table_force
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


def linear_plant(cfg: MachineConfig) -> Plant:
    """The plant of ``cfg`` with :data:`LINEAR` mechanics, one physics step per drive
    interval, no sensor noise."""
    return Plant(cfg.with_overrides({**LINEAR, "simulation.drive_substeps": 1}), noise=False)


def free_vibration(plant: Plant, axis: str, position: float, *, steps: int = 200,
                   seed: int = 0) -> tuple[np.ndarray, float]:
    """The free vibration of ``axis`` of ``plant`` (a :func:`linear_plant`) with the table
    at ``position`` (m).

    The drives are disabled (no torque); the bodies are released from random deflections
    of a few µm and random speeds with zero total momentum (so the table stays at
    ``position``). Returns the state after each of ``steps`` physics steps, every
    coordinate referred to the table (m, m/s): rows of (table, rotor r·θ[, screw r_s·θ_s],
    then their speeds), shape (steps + 1, 4 or 6), and the timestep (s).
    """
    cfg = plant.config
    start = mid_travel(cfg)
    start["xy".index(axis)] = position
    plant.reset(positions=start)
    plant.enable(False)
    m, d = plant.model, plant.data
    tr = cfg.axes[axis].transmission
    chain = axis_mechanics(cfg, axis, position)
    joints = [axis, f"{axis}_rotor"] + ([f"{axis}_shaft"] if chain.has_screw else [])
    scale = np.array([1.0, tr.ratio] + ([tr.screw_ratio] if chain.has_screw else []))
    masses = np.array([chain.moving_mass, chain.reflected_mass, chain.screw_mass][:len(joints)])
    qadr = [int(m.joint(j).qposadr[0]) for j in joints]
    dadr = [int(m.joint(j).dofadr[0]) for j in joints]
    rng = np.random.default_rng(seed)
    omega = chain.frequencies("free")[0]
    shift = rng.normal(0.0, 5e-6, len(joints))
    speed = rng.normal(0.0, 5e-6 * omega, len(joints))
    speed -= masses @ speed / masses.sum()               # no momentum: no drift of the nut
    d.qpos[qadr] += shift / scale
    d.qvel[dadr] = speed / scale
    rest = d.qpos[qadr] * scale - shift
    states = np.empty((steps + 1, 2 * len(joints)))
    zero = np.zeros(2)
    for i in range(steps + 1):
        if i:
            plant.step(zero, plant.drive_dt)
        states[i] = np.concatenate([d.qpos[qadr] * scale - rest, d.qvel[dadr] * scale])
    if d.warning.number.any():
        raise AssertionError(f"MuJoCo warnings: {d.warning.number}")
    return states, plant.drive_dt


def discrete_poles(states: np.ndarray, dt: float) -> np.ndarray:
    """The oscillating poles s (1/s, Im s > 0, ascending in |s|) of the linear one-step map
    fitted to ``states`` (rows: consecutive states, as :func:`free_vibration` returns).

    The free rotor's rigid-body motion (a double eigenvalue z = 1, split by the viscous
    friction) is left out: poles with |s|·Δt < 1e-3, far below any elastic mode the
    physics step resolves."""
    scale = np.abs(states).max(axis=0)
    x = states / scale
    a, *_ = np.linalg.lstsq(x[:-1], x[1:], rcond=None)   # x[n+1] = x[n]·a
    s = np.log(np.linalg.eigvals(a.T).astype(complex)) / dt
    s = s[(s.imag > 0.0) & (np.abs(s) * dt > 1e-3)]
    return s[np.argsort(np.abs(s))]


def random_screw_machine(rng: np.random.Generator, base: MachineConfig) -> MachineConfig:
    """A random machine of the lead-screw class, three-mass with a varying screw on both
    axes: masses, rotor inertia, travel, lead, gear, screw diameter and length, support and
    drive end, every stiffness component and the damping drawn at random (ranges below),
    the timestep by :func:`modal_timestep`."""
    over: dict = {}
    for a in AXES:
        span = rng.uniform(0.1, 0.6)
        support = str(rng.choice(["fixed-free", "fixed-fixed"]))
        nut = rng.uniform(0.04, 0.25)
        lead = rng.uniform(2e-3, 10e-3)
        screw_ratio = lead / (2.0 * math.pi)
        torsion = math.exp(rng.uniform(math.log(100.0), math.log(3000.0)))  # N·m/rad
        over |= {
            f"axes.{a}.mechanics.carriage_mass": rng.uniform(10.0, 150.0),
            f"axes.{a}.mechanics.rotor_inertia": math.exp(rng.uniform(math.log(2e-4),
                                                                      math.log(5e-3))),
            f"axes.{a}.mechanics.travel": [0.0, span],
            f"axes.{a}.mechanics.slide_viscous": rng.uniform(0.0, 500.0),
            f"axes.{a}.mechanics.rotor_viscous": rng.uniform(0.0, 5e-4),
            f"axes.{a}.switches.limit_min": 0.002,
            f"axes.{a}.switches.home": 0.01,
            f"axes.{a}.switches.limit_max": span - 0.002,
            f"axes.{a}.transmission.lead": lead,
            f"axes.{a}.transmission.gear_ratio": rng.uniform(1.0, 15.0),
            f"axes.{a}.transmission.damping_ratio": rng.uniform(0.01, 0.2),
            f"axes.{a}.transmission.screw_diameter": rng.uniform(0.01, 0.04),
            f"axes.{a}.transmission.screw_support": support,
            f"axes.{a}.transmission.drive_end": str(rng.choice(["min", "max"])),
            f"axes.{a}.transmission.nut_start": nut,
            f"axes.{a}.transmission.screw_length": nut + span + rng.uniform(0.03, 0.3),
            f"axes.{a}.transmission.stiffness": {
                "screw": math.exp(rng.uniform(math.log(3e7), math.log(5e8))),
                "nut": math.exp(rng.uniform(math.log(5e7), math.log(5e8))),
                "bearing": math.exp(rng.uniform(math.log(1e8), math.log(1e9))),
                "gear": min(torsion / screw_ratio**2, 1e11),
            },
        }
    fine = {"simulation.timestep": 1e-6, "simulation.drive_substeps": 1,
            "controller.period": 1e-3}
    cfg = base.with_overrides({**over, **fine})
    return cfg.with_overrides({"simulation.timestep": modal_timestep(cfg)})


def modal_timestep(cfg: MachineConfig, *, decay: float = 1e-3) -> float:
    """A physics step (s), a whole fraction of 1 ms, short enough to measure the model and
    not the integrator: the fastest mode within the machine file's rule (ω·Δt ≤ 0.4 < 0.5),
    the first mode over ≥ 40 steps, and ζ₁·ω₁·Δt ≤ ``decay`` (implicit damping lowers a
    mode by about that fraction: README, "Checking the modes")."""
    dt = math.inf
    for a in AXES:
        ax = cfg.axes[a]
        dt = min(dt, 0.4 / ax.transmission.fastest_mode(
            cfg.moving_masses()[a], ax.mechanics.rotor_inertia, ax.mechanics.travel))
        for position in ax.mechanics.travel:
            chain = axis_mechanics(cfg, a, position)
            first = chain.frequencies("free")[0]
            zeta = 0.5 * chain.damping_per_stiffness * first
            dt = min(dt, 2.0 * math.pi / first / 40.0, decay / (zeta * first))
    return 1e-3 / math.ceil(1e-3 / dt)
