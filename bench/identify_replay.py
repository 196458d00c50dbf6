"""Benchmark: the speed of one ``twin identify`` replay (``identify.replay.replay``).

The experiments of ``twin identify`` are run once on the twin of BASE (lock-step, seeded,
with the sensor noise), or read from ``--log DIR``. Each of ``--machines`` unseen machines
(``identify.perturb``, a hand-set drive with ``--drive``; their parameters as the fit
would find them, ``perturb.true_params``) then replays that log at a random
mains phase in two ways, in this one process:

- ``ticks``: the reference, the plant driven tick by tick through ``Plant.read_into``,
  ``Plant.enable`` and ``Plant.step`` (how ``replay`` ran before ``Plant.run_open_loop``),
  with the encoder counts unwrapped as the controller does;
- ``replay``: ``replay.replay`` of ``replay.candidate(…, mains_phase=…)``, as the fit's
  ``Problem.simulate`` calls it.

Prints one JSON object: per machine the CPU time of each (s per replay, the best of
``--repeat``), their ratio, and the largest difference of positions (m) and tacho volts
(V) between the two (0: bit for bit); and the summary: replays per CPU second of each, the
median ratio.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from twin.config import AXES, load_machine
from twin.controller.encoder import EncoderUnwrapper
from twin.controller.io import Inputs
from twin.identify import open_identification_driver
from twin.identify.experiments import run_plan
from twin.identify.log import IdentLog
from twin.identify.perturb import perturbed_machine, true_params
from twin.identify.plan import default_plan
from twin.identify.replay import candidate, replay
from twin.plant import Plant


def experiments(base, amplitude: float) -> IdentLog:
    """The default plan on the twin of BASE (lock-step, with its sensor noise)."""
    plan = default_plan(min(base.controller.limits.max_velocity,
                            *(base.axes[a].limits.max_velocity for a in AXES)),
                        amplitude=amplitude,
                        home_width=max(base.axes[a].switches.home_width for a in AXES))
    io, paced = open_identification_driver("sim", base)
    try:
        return run_plan(io, base, plan, paced=paced)
    finally:
        io.close()


def by_ticks(cfg, log: IdentLog, phase: float) -> tuple[np.ndarray, np.ndarray]:
    """The reference: the replay's ticks one by one through the plant's public calls."""
    cfg = cfg.with_overrides({"axes.*.converter.mains_phase": phase})
    plant = Plant(cfg, noise=False)
    plant.reset(positions=np.array([0.5 * sum(cfg.axes[a].mechanics.travel) for a in AXES]))
    t = log.data["t"]
    steps = np.diff(t, append=t[-1] + cfg.controller.period)
    intervals = np.maximum(np.round(steps / plant.drive_dt), 1).astype(int)
    dac = np.column_stack([log.data["dac_x"], log.data["dac_y"]])
    enable = log.data["enable"] != 0.0
    enc = EncoderUnwrapper([cfg.axes[a].counts_per_metre for a in AXES],
                           bits=[cfg.axes[a].encoder.bits for a in AXES])
    inputs = Inputs()
    pos, tacho = np.empty((log.ticks, 2)), np.empty((log.ticks, 2))
    plant.read_into(inputs)
    enc.reset(inputs.encoder_counts)
    for k in range(log.ticks):
        plant.read_into(inputs)
        pos[k] = enc.update(inputs.encoder_counts)
        tacho[k] = inputs.tacho_volts
        if enable[k] != plant.drives.enabled:
            plant.enable(bool(enable[k]))
        plant.step(dac[k], int(intervals[k]) * plant.drive_dt)
    return pos, tacho


def best_cpu(fn, repeat: int):
    """(the result, the least CPU time of ``repeat`` calls (s))."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return out, best


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--machine", default="tomsk_xy", help="BASE")
    ap.add_argument("--log", help="an identify record directory (default: run the plan)")
    ap.add_argument("--amplitude", type=float, default=1.0)
    ap.add_argument("--machines", type=int, default=4)
    ap.add_argument("--drive", choices=("mistuned", "as_built"), default=None)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    base = load_machine(args.machine)
    log = IdentLog.load(args.log) if args.log else experiments(base, args.amplitude)
    rng = np.random.default_rng(args.seed)
    rows = []
    for i in range(args.machines):
        params = true_params(base, perturbed_machine(base, rng, drive=args.drive))
        phase = float(rng.uniform(0.0, 2.0 * np.pi))
        cfg = candidate(base, params)
        ref, t_ref = best_cpu(lambda c=cfg, f=phase: by_ticks(c, log, f), args.repeat)
        new, t_new = best_cpu(lambda p=params, f=phase: replay(
            candidate(base, p, mains_phase=f), log), args.repeat)
        rows.append({"machine": i, "ticks": log.ticks, "cpu_ticks": round(t_ref, 4),
                     "cpu_replay": round(t_new, 4), "ratio": round(t_ref / t_new, 3),
                     "max_position_difference": float(np.max(np.abs(ref[0] - new[0]))),
                     "max_tacho_difference": float(np.max(np.abs(ref[1] - new[1])))})
    out = {"base": args.machine, "log": args.log, "amplitude": args.amplitude,
           "drive": args.drive, "rows": rows,
           "replays_per_cpu_s_ticks": round(len(rows) / sum(r["cpu_ticks"] for r in rows), 3),
           "replays_per_cpu_s_replay": round(len(rows) / sum(r["cpu_replay"] for r in rows),
                                             3),
           "median_ratio": statistics.median(r["ratio"] for r in rows)}
    print(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
