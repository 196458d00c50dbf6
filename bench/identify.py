"""Benchmark: ``twin identify`` on machines it has not seen.

For each seed, an unseen machine is drawn (``twin.identify.perturb``: tacho gain ±20 %,
rotor inertia ×0.7-1.5, friction ×0.5-3, R and L ±30 %, lost motion 0-20 µm), identified
lock-step from BASE = tomsk_xy (``--driver sim:FILE``), and judged against its own file.
Reported per machine and axis: the errors of K_H, rotor inertia, Coulomb and viscous
friction at the motor (%), of the lost motion (µm), the held-out NRMSE (%), the machine time
of the experiments and the wall time of the fit (s); with ``--transfer`` also the max
coordinate error (µm, DCU 3) of the machine run with the calibrated file, its own file (the
oracle) and the nominal tomsk_xy as the controller's model, on the Table-2 move and the
default program. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from twin.config import AXES, load_machine
from twin.config.writer import machine_to_toml
from twin.identify import identify
from twin.identify.perturb import perturbed_machine
from twin.identify.replay import axis_figures
from twin.session.run import RunSpec, run

BASE = "tomsk_xy"


def _coordinate_error(machine: Path, model: str, builtin: str, out: Path) -> float:
    spec = RunSpec(machine=str(machine), controller_model=model, builtin=builtin, dcu_order=3)
    return max(run(spec, out_dir=out, rerun="none").summary["max_coordinate_error_um"].values())


def one(seed: int, where: Path, transfer: bool) -> dict:
    true = perturbed_machine(load_machine(BASE), np.random.default_rng(seed),
                             name=f"unseen_{seed}")
    path = where / f"unseen_{seed}.toml"
    path.write_text(machine_to_toml(true), encoding="utf-8")
    out = where / f"calibrated_{seed}.toml"
    t0 = time.perf_counter()
    res = identify(BASE, out, driver=f"sim:{path}", out_dir=where / "runs")
    wall = time.perf_counter() - t0
    truth = axis_figures(true)
    row: dict = {"seed": seed, "machine_time_s": res["machine_time_s"],
                 "fit_wall_time_s": round(res["fit_wall_time_s"], 1),
                 "total_wall_time_s": round(wall, 1),
                 "held_out_nrmse_pct": round(100 * max(max(v.values())
                                                        for v in res["nrmse"].values()), 3)}
    for a in AXES:
        d, e, t = res["derived"][a], res["estimates"][a], truth[a]
        row[a] = {
            "K_H_err_pct": round(100 * (d["K_H"] / t["K_H"] - 1), 3),
            "inertia_err_pct": round(100 * (e["inertia"]["value"] / t["inertia"] - 1), 2),
            "coulomb_err_pct": round(100 * (d["coulomb_at_motor"] / t["coulomb_at_motor"]
                                            - 1), 2),
            "viscous_err_pct": round(100 * (d["viscous_at_motor"] / t["viscous_at_motor"]
                                            - 1), 2),
            "lost_motion_err_um": round(1e6 * (e["backlash"]["value"] - t["backlash"]), 2),
            "lost_motion_true_um": round(1e6 * t["backlash"], 2),
        }
    if transfer:
        row["max_coordinate_error_um"] = {
            b: {name: round(_coordinate_error(path, model, b, where / "runs"), 2)
                for name, model in (("calibrated", str(out)), ("oracle", str(path)),
                                    ("nominal", BASE))}
            for b in ("spline_line", "default")}
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--transfer", action="store_true",
                        help="also run each machine with the calibrated, oracle and nominal "
                             "controller models")
    args = parser.parse_args()
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    with tempfile.TemporaryDirectory() as tmp:
        rows = [one(s, Path(tmp), args.transfer) for s in args.seeds]
    print(json.dumps({"base": BASE, "machines": rows}, indent=1))


if __name__ == "__main__":
    main()
