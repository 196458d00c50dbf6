"""Benchmark: tuning throughput — complete tuning runs per second with 1 and 2 workers.

A fixed batch of tuning vectors (seeded, spread over the whole space) is evaluated by
``tuning.evaluator.Evaluator`` on ``--machine`` and ``--program``, once in-process
(``workers_1``) and once by a pool of two spawned worker processes (``workers_2``; the
pool is started and warmed up with one run per worker before the clock starts). Each
figure: ``runs_per_s`` (tuning runs per wall second) and ``sim_s_per_wall_s`` (simulated
seconds per wall second, all workers together). ``speedup`` = workers_2 / workers_1 runs
per second; the 1-minute load average before and after tells whether the machine was
shared.

The yardstick, measured in the same run: ``bare_mujoco_s_per_sim_s`` is bare ``mj_step`` of
the same model, timestep and substeps over one baseline run's simulated time (no drives, no
controller, no Python per step but the loop); two cores of it would simulate
``2 / bare_mujoco_s_per_sim_s`` seconds per wall second, and ``ratio_to_two_bare_cores`` is
what the two tuning workers reach of that (issue 13 asks ≥ 0.9 on the default program).
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

# This file is bench/tuning.py: run as a script, its folder would shadow the tuning package.
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _HERE]

os.environ.setdefault("RERUN_ANALYTICS", "0")
os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(os.getcwd(), ".cache", "numba"))

import numpy as np  # noqa: E402

from tuning.evaluator import Evaluator  # noqa: E402


def _measure(ev: Evaluator, xs: list[np.ndarray]) -> dict[str, float]:
    start = len(ev.trials)
    t0 = time.perf_counter()
    trials = ev.evaluate(xs)
    wall = time.perf_counter() - t0
    sim = sum(t.sim_time for t in trials)
    failed = sum(t.failed for t in ev.trials[start:])
    return {"runs": len(trials), "wall_s": wall, "runs_per_s": len(trials) / wall,
            "sim_s_per_wall_s": sim / wall, "failed_runs": failed}


def _bare_mujoco(machine: str, sim_time: float) -> float:
    """Wall seconds per simulated second of bare mj_step of the machine's model."""
    import mujoco

    from twin.session.run import RunSpec, prepare

    p = prepare(RunSpec(machine=machine))
    m = p.plant.model
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    k = p.cfg.simulation.drive_substeps
    n = round(sim_time / p.plant.drive_dt)
    p.driver.close()
    step = mujoco.mj_step
    t0 = time.perf_counter()
    for _ in range(n):
        step(m, d, k)
    return (time.perf_counter() - t0) / (n * p.plant.drive_dt)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machine", default="tomsk_xy")
    parser.add_argument("--program", default="default")
    parser.add_argument("--runs", type=int, default=16)
    parser.add_argument("--spread", type=float, default=0.3,
                        help="Vectors are drawn uniformly from ±spread (normalised units).")
    args = parser.parse_args()
    load0 = os.getloadavg()[0]
    rng = np.random.default_rng(0)
    ev = Evaluator.create(args.machine, args.program)
    xs = [rng.uniform(-args.spread, args.spread, ev.dim) for _ in range(args.runs)]
    one = _measure(ev, xs)
    with Evaluator(ev.tuning, workers=2) as par:
        par.evaluate(xs[:2])                      # start and warm up the pool
        two = _measure(par, xs)
    bare = _bare_mujoco(args.machine, ev.tuning.baseline.sim_time)
    print(json.dumps({
        "machine": args.machine, "program": args.program,
        "baseline_sim_time_s": ev.tuning.baseline.sim_time,
        "workers_1": one, "workers_2": two,
        "speedup": two["runs_per_s"] / one["runs_per_s"],
        "bare_mujoco_s_per_sim_s": bare,
        "two_bare_cores_sim_s_per_wall_s": 2.0 / bare,
        "ratio_to_two_bare_cores": two["sim_s_per_wall_s"] * bare / 2.0,
        "cpu_count": os.cpu_count(), "load_average_before": load0,
        "load_average_after": os.getloadavg()[0],
    }, indent=1))


if __name__ == "__main__":
    main()
