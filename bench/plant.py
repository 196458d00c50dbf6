"""Benchmark: cost of the plant (drives + MuJoCo) against bare MuJoCo on the same model.

Scenario: both axes from mid-travel under sinusoidal speed references (X: sine, Y: cosine,
±2 V, 0.5 Hz, so the tables sweep a few millimetres and reverse, the friction and the bridge
reversals included), stepped one controller period at a time, as the controller would.

``bare_mujoco_s_per_sim_s`` replays the torque sequence that the plant's drives produced on
a second MjData of the same model from the same state: the same ``mj_step(m, d, nstep)``
calls on the same trajectory, without drives, DAC, switches or status. ``ratio`` is plant
over bare (the brief requires ≤ 1.5); ``real_time_factor`` is simulated over wall time
(required ≥ 50). Plant and bare runs alternate ``--repeat`` times and each figure is the
best of its runs, which keeps the comparison fair on a shared, noisy machine. The ``_cpu``
figures use the process CPU time instead of the wall clock: on a loaded machine (see
``load_average_1min`` against ``cpus``) they are the better estimate of one core's speed.

Prints one JSON object. Usage: ``python bench/plant.py [--machine tomsk_xy] [--seconds 2]
[--timestep 2.5e-4 --drive-substeps 4]`` (the overrides serve the timestep study).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time

os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(os.getcwd(), ".cache", "numba"))

import mujoco
import numpy as np

from twin.config import load_machine
from twin.plant import Plant


def _references(period: float, n: int) -> np.ndarray:
    t = period * np.arange(n)
    phase = 2.0 * math.pi * 0.5 * t
    return 2.0 * np.stack([np.sin(phase), np.cos(phase)], axis=1)


def _run_plant(plant: Plant, refs: np.ndarray, period: float) -> tuple[float, float]:
    """(wall, CPU) time of the plant stepping one controller period per reference."""
    plant.reset(positions=_mid_travel(plant))
    step = plant.step
    t0, c0 = time.perf_counter(), time.process_time()
    for u in refs:
        step(u, period)
    return time.perf_counter() - t0, time.process_time() - c0


def _record_torques(plant: Plant, refs: np.ndarray, period: float) -> np.ndarray:
    """The rotor torque of every drive interval of the same run (stepped per interval,
    which gives the identical trajectory)."""
    plant.reset(positions=_mid_travel(plant))
    rotor = _rotor_dofs(plant.model)
    per_period = round(period / plant.drive_dt)
    torques = np.empty((len(refs) * per_period, 2))
    i = 0
    for u in refs:
        for _ in range(per_period):
            plant.step(u, plant.drive_dt)
            torques[i] = plant.data.qfrc_applied[rotor]
            i += 1
    return torques


def _rotor_dofs(m: mujoco.MjModel) -> slice:
    first = int(m.joint("x_rotor").dofadr[0])
    return slice(first, first + 2)


def _run_bare(plant: Plant, torques: np.ndarray) -> tuple[float, float]:
    """(wall, CPU) time of bare mj_step replaying ``torques`` from the plant's start."""
    m = plant.model
    d = mujoco.MjData(m)
    plant.reset(positions=_mid_travel(plant))
    mujoco.mj_setState(m, d, _full_state(plant), mujoco.mjtState.mjSTATE_FULLPHYSICS)
    qfrc, mj_step = d.qfrc_applied[_rotor_dofs(m)], mujoco.mj_step
    k = plant.config.simulation.drive_substeps
    t0, c0 = time.perf_counter(), time.process_time()
    for tau in torques:
        qfrc[:] = tau
        mj_step(m, d, k)
    return time.perf_counter() - t0, time.process_time() - c0


def _full_state(plant: Plant) -> np.ndarray:
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state = np.empty(mujoco.mj_stateSize(plant.model, spec))
    mujoco.mj_getState(plant.model, plant.data, state, spec)
    return state


def _mid_travel(plant: Plant) -> np.ndarray:
    return np.array([sum(plant.config.axes[a].mechanics.travel) / 2.0 for a in ("x", "y")])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machine", default="tomsk_xy")
    parser.add_argument("--seconds", type=float, default=2.0, help="simulated time per run")
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--timestep", type=float, help="override simulation.timestep (s)")
    parser.add_argument("--drive-substeps", type=int, help="override simulation.drive_substeps")
    args = parser.parse_args()

    cfg = load_machine(args.machine)
    overrides = {"simulation.timestep": args.timestep,
                 "simulation.drive_substeps": args.drive_substeps}
    cfg = cfg.with_overrides({k: v for k, v in overrides.items() if v is not None})
    plant = Plant(cfg)
    # one controller period per step; where the period is no multiple of the drive interval
    # (a machine-file inconsistency the plant rejects), the nearest multiple
    period = plant.drive_dt * max(1, round(plant.config.controller.period / plant.drive_dt))
    n = round(args.seconds / period)
    refs = _references(period, n)
    torques = _record_torques(plant, refs, period)
    load_before = os.getloadavg()[0]
    plant_best, bare_best = [math.inf, math.inf], [math.inf, math.inf]
    for _ in range(args.repeat):
        plant_best = list(map(min, plant_best, _run_plant(plant, refs, period)))
        bare_best = list(map(min, bare_best, _run_bare(plant, torques)))
    sim = n * period
    (plant_wall, plant_cpu), (bare_wall, bare_cpu) = plant_best, bare_best
    result = {
        "machine": args.machine,
        "plant_s_per_sim_s": plant_wall / sim,
        "bare_mujoco_s_per_sim_s": bare_wall / sim,
        "ratio": plant_wall / bare_wall,
        "real_time_factor": sim / plant_wall,
        "plant_cpu_s_per_sim_s": plant_cpu / sim,
        "bare_mujoco_cpu_s_per_sim_s": bare_cpu / sim,
        "ratio_cpu": plant_cpu / bare_cpu,
        "real_time_factor_cpu": sim / plant_cpu,
        "timestep": plant.model.opt.timestep,
        "drive_dt": plant.drive_dt,
        "step_duration": period,
        "controller_period": plant.config.controller.period,
        "simulated_s": sim,
        "repeat": args.repeat,
        "load_average_1min": [load_before, os.getloadavg()[0]],
        "cpus": os.cpu_count(),
        "integrator": mujoco.mjtIntegrator(plant.model.opt.integrator).name,
        "mujoco": mujoco.__version__,
        "python": platform.python_version(),
        "required": {"ratio_max": 1.5, "real_time_factor_min": 50.0},
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
