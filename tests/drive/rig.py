"""Test rig for the drives: a rigid rotor with friction, integrated here in plain numpy.

J·dω/dt = τ_motor − c·sign(ω) − b·ω − τ_load, with sticking: a resting rotor stays at rest
while |τ_motor − τ_load| <= c, and a rotor whose speed would cross zero within a sub-step
stops there. The drive's interval-average torque is held over ``substeps`` sub-steps, as
the plant does with MuJoCo.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from twin.drive import Drives

__all__ = ["Run", "simulate"]


@dataclass(frozen=True)
class Run:
    """Time series of a simulation, one row per drive update (values at its end)."""

    time: np.ndarray          # (m,) s
    omega: np.ndarray         # (m, n) rad/s
    angle: np.ndarray         # (m, n) rad
    current: np.ndarray       # (m, n) A
    voltage: np.ndarray       # (m, n) V
    bridge: np.ndarray        # (m, n) int
    firing_angle: np.ndarray  # (m, n) rad
    torque: np.ndarray        # (m, n) N·m, average over the update
    current_reference: np.ndarray  # (m, n) A
    tacho: np.ndarray         # (m, n) V
    speed_reference: np.ndarray    # (m, n) V


def simulate(drives: Drives, reference: Callable[[float], np.ndarray] | np.ndarray,
             duration: float, *, inertia: np.ndarray | float | None = None,
             coulomb: np.ndarray | float = 0.0, viscous: np.ndarray | float = 0.0,
             load: Callable[[float], np.ndarray] | np.ndarray | float = 0.0,
             substeps: int = 5, omega0: np.ndarray | float = 0.0) -> Run:
    """Run ``drives`` coupled to rigid rotors for ``duration`` seconds.

    ``reference`` and ``load`` are constants or functions of the time at the start of each
    update; ``inertia`` defaults to the design inertia of each drive.
    """
    n = len(drives.designs)
    j = np.array([d.inertia for d in drives.designs]) if inertia is None else (
        np.broadcast_to(np.asarray(inertia, float), (n,)))
    c = np.broadcast_to(np.asarray(coulomb, float), (n,))
    b = np.broadcast_to(np.asarray(viscous, float), (n,))
    w = np.broadcast_to(np.asarray(omega0, float), (n,)).copy()
    theta = np.zeros(n)
    h = drives.dt / substeps
    steps = round(duration / drives.dt)
    rec: dict[str, list[np.ndarray]] = {k: [] for k in Run.__dataclass_fields__}
    for _ in range(steps):
        t = drives.time
        u = np.broadcast_to(reference(t) if callable(reference) else reference, (n,))
        tl = np.broadcast_to(load(t) if callable(load) else load, (n,))
        tau = drives.step(np.array(u, float), w)
        for _ in range(substeps):
            drive = tau - tl - b * w
            moving = w != 0.0
            breakaway = ~moving & (np.abs(drive) > c)
            direction = np.where(moving, np.sign(w), np.sign(drive))
            w_new = np.where(moving | breakaway, w + (drive - c * direction) / j * h, 0.0)
            w_new = np.where((moving | breakaway) & (w_new * direction < 0.0), 0.0, w_new)
            theta += 0.5 * (w + w_new) * h
            w = w_new
        rec["time"].append(np.array(drives.time))
        rec["omega"].append(w.copy())
        rec["angle"].append(theta.copy())
        rec["current"].append(drives.current)
        rec["voltage"].append(drives.voltage)
        rec["bridge"].append(drives.bridge)
        rec["firing_angle"].append(drives.firing_angle)
        rec["torque"].append(tau)
        rec["current_reference"].append(drives.current_reference)
        rec["tacho"].append(drives.tacho_volts)
        rec["speed_reference"].append(drives.speed_reference)
    return Run(**{k: np.array(v) for k, v in rec.items()})
