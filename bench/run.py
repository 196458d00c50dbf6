"""Benchmark: the full stack (controller + drives + MuJoCo + telemetry to a file) against
bare MuJoCo stepping of the same model, on the default program.

* ``full_s_per_sim_s``: wall seconds per simulated second of ``twin run`` (default program,
  telemetry to an ``.rrd`` file in a temporary directory; record and summary included).
* ``bare_mujoco_s_per_sim_s``: the same model, timestep and number of ``mj_step(m, d,
  drive_substeps)`` calls, with the motor torques the run produced replayed per controller
  period, measured in the same process right after.
* ``plant_only_s_per_sim_s``: the plant alone — compiled drives and MuJoCo, one
  ``Plant.step`` per controller period — replaying the run's DAC requests and enable: the
  physics' own cost (``plant_only_ratio_vs_bare_mujoco``); the rest of ``full`` is the
  controller, the driver, the run's bookkeeping and telemetry.
* ``ratio_vs_bare_mujoco`` = full / bare (issue 4: ≤ 1.5); ``real_time_factor`` (≥ 50);
  ``telemetry_share``: wall time spent building and sending telemetry over the run's wall
  time (≤ 0.10).
* ``loop_us_per_tick``: where a tick's wall time goes, from one more run with each part
  timed (so a little slower than ``full``: each timer costs some tenths of a µs): the driver's
  read (the plant's sensors), the controller's tick, the driver's write (the plant's step,
  and the plant step alone inside it), the read-ahead, the truth row, and every 50 ticks
  the checkpoint (stop signals, the drive-rate samples, a telemetry batch); ``rest`` is
  the loop itself.

Each figure is the best of ``--repeat`` runs (full and bare alternate), which keeps the
comparison fair on a shared machine. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time

os.environ.setdefault("RERUN_ANALYTICS", "0")
os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(os.getcwd(), ".cache", "numba"))

import mujoco
import numpy as np

from twin.session.run import RunSpec, prepare, run


def _full(machine: str, out: str) -> tuple[float, float, float, np.ndarray, np.ndarray,
                                           np.ndarray]:
    """(wall, sim time, telemetry wall, per-tick rotor torque, DAC requests, enable) of one
    default run."""
    p = prepare(RunSpec(machine=machine))
    result = run(RunSpec(machine=machine), out_dir=out, prepared=p)
    s = result.summary
    # Motor torque k·i at the end of every period: what the bare replay applies.
    tau = result.record["armature_current"] * np.array(
        [p.cfg.axes[a].motor.emf_constant for a in ("x", "y")])
    return (s["wall_time_s"], s["sim_time_s"], s["telemetry_wall_s"], tau,
            result.record["dac_volts"], result.record["enable"])


def _plant_only(machine: str, dac: np.ndarray, enable: np.ndarray) -> float:
    """Wall time of the plant alone (the compiled drives and MuJoCo, ``Plant.step`` per
    controller period) replaying the run's DAC requests and enable: the physics' own cost,
    without the controller, the driver and the run's bookkeeping."""
    p = prepare(RunSpec(machine=machine))
    plant, period = p.plant, p.cfg.controller.period
    step, on = plant.step, None
    rows = np.ascontiguousarray(dac, dtype=np.float64)
    flags = enable.astype(bool).tolist()
    t0 = time.perf_counter()
    for volts, flag in zip(rows, flags, strict=True):
        if flag is not on:
            plant.enable(flag)
            on = flag
        step(volts, period)
    return time.perf_counter() - t0


def _breakdown(machine: str, out: str) -> dict[str, float]:
    """µs per tick of each part of one default run's loop (see the module docstring)."""
    import twin.session.run as session

    p = prepare(RunSpec(machine=machine))
    spent: dict[str, float] = {}
    clock = time.perf_counter

    def timed(owner: object, name: str, part: str) -> None:
        call = getattr(owner, name)

        def wrapper(*args, **kwargs):
            t0 = clock()
            try:
                return call(*args, **kwargs)
            finally:
                spent[part] = spent.get(part, 0.0) + clock() - t0
        setattr(owner, name, wrapper)

    timed(p.driver, "read", "read")
    timed(p.driver, "write", "write")
    timed(p.plant, "step", "write_plant_step")
    timed(p.controller, "tick", "tick")
    timed(p.controller, "read_ahead", "read_ahead")
    timed(p.plant, "truth_row", "truth_row")
    checkpoint = session._Loop._checkpoint
    try:
        timed(session._Loop, "_checkpoint", "checkpoint")
        s = run(RunSpec(machine=machine), out_dir=out, prepared=p).summary
    finally:
        session._Loop._checkpoint = checkpoint
    ticks = s["sim_time_s"] / p.cfg.controller.period
    parts = {k: v / ticks * 1e6 for k, v in spent.items()}
    loop = s["wall_time_s"] / ticks * 1e6
    parts["rest"] = loop - sum(v for k, v in parts.items() if k != "write_plant_step")
    parts["loop"] = loop
    return {k: round(v, 2) for k, v in parts.items()}


def _bare(machine: str, torques: np.ndarray) -> float:
    """Wall time of bare mj_step over the same intervals, replaying the per-period torque."""
    p = prepare(RunSpec(machine=machine))
    m = p.plant.model
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    k = p.cfg.simulation.drive_substeps
    per_period = round(p.cfg.controller.period / p.plant.drive_dt)
    first = int(m.joint("x_rotor").dofadr[0])
    qfrc = d.qfrc_applied[first:first + 2]
    mj_step = mujoco.mj_step
    t0 = time.perf_counter()
    for tau in torques:
        qfrc[:] = tau
        for _ in range(per_period):
            mj_step(m, d, k)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machine", default="tomsk_xy")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    full, bare, tele, plant = [], [], [], []
    with tempfile.TemporaryDirectory() as out:
        for _ in range(args.repeat):
            wall, sim, tel, tau, dac, enable = _full(args.machine, out)
            full.append(wall / sim)
            tele.append(tel / wall)
            bare.append(_bare(args.machine, tau) / sim)
            plant.append(_plant_only(args.machine, dac, enable) / sim)
        parts = _breakdown(args.machine, out)
    f, b, pl = min(full), min(bare), min(plant)
    print(json.dumps({
        "machine": args.machine,
        "program": "default",
        "sim_time_s": sim,
        "full_s_per_sim_s": f,
        "bare_mujoco_s_per_sim_s": b,
        "ratio_vs_bare_mujoco": f / b,
        "plant_only_s_per_sim_s": pl,
        "plant_only_ratio_vs_bare_mujoco": pl / b,
        "real_time_factor": 1.0 / f,
        "telemetry_share": min(tele),
        "loop_us_per_tick": parts,
        "repeat": args.repeat,
        "cpus": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "python": platform.python_version(),
        "mujoco": mujoco.__version__,
    }))


if __name__ == "__main__":
    main()
