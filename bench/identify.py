"""Benchmark: ``twin identify`` on machines it has not seen.

For each seed an unseen machine is drawn (``twin.identify.perturb``: tacho gain ±20 %, rotor
inertia ×0.7-1.5, friction ×0.5-3, R and L ±30 %, lost motion 0-20 µm, DAC gain error ±1 %
and offset ±20 mV; with ``--drive as_built`` also a hand-set analog drive without DCM
adaptation: speed gain ×0.5-1.5, integral time ×0.5-2, brush drop 1-2 V; ``--drive
mistuned``: the speed gain and integral time only, digital with the adaptation),
identified from BASE =
tomsk_xy at each ``--amplitudes``, lock-step (``--driver sim:FILE``) or, with
``--modbus``, over Modbus/TCP from a ``twin hil-server --machine FILE`` on loopback, and
judged against its own file:

- ``coverage``: per field, whether the truth lies in the reported 95 % interval, or the
  field was declared not identifiable; the summary gives, per amplitude, the share of
  identified fields whose interval holds the truth (the issue asks ≥ 90 %);
- the errors of K_H, inertia, friction at the motor, the speed regulator's gain and
  integral time (%), the lost motion (µm), whether the DCM adaptation was decided right;
- the machine time of the experiments and the wall and CPU time of the fit (s);
- with ``--transfer``: the max coordinate error (µm, DCU 3) of the machine run with the
  calibrated file, its own file (the oracle) and the nominal tomsk_xy as the controller's
  model, on the Table-2 move and the default program, and their ratio.

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twin.config import AXES, load_machine
from twin.config.writer import machine_to_toml
from twin.identify.perturb import perturbed_machine, true_params
from twin.identify.replay import axis_figures
from twin.session.run import RunSpec, run

BASE = "tomsk_xy"
FIELDS = ("tacho_gain", "gain_error", "offset", "inertia", "coulomb", "viscous", "breakaway",
          "backlash", "resistance", "inductance", "speed_kp", "speed_ti", "reference_filter")


def coordinate_error(machine: Path, model: str, builtin: str, out: Path) -> float:
    """Max coordinate error (µm, DCU 3) of ``machine`` with ``model`` as the controller's
    model, on the builtin program."""
    spec = RunSpec(machine=str(machine), controller_model=model, builtin=builtin, dcu_order=3)
    summary = run(spec, out_dir=out, rerun="none").summary
    if summary["status"] != "FINISHED":
        return math.inf
    return max(summary["max_coordinate_error_um"].values())


def transfer(path: Path, calibrated: Path, out: Path) -> dict:
    """The sim-to-real table of one machine."""
    table = {}
    for b in ("spline_line", "default"):
        row = {name: round(coordinate_error(path, model, b, out), 2)
               for name, model in (("calibrated", str(calibrated)), ("oracle", str(path)),
                                   ("nominal", BASE))}
        row["ratio"] = round(row["calibrated"] / row["oracle"], 3) if row["oracle"] else None
        table[b] = row
    return table


def coverage(result: dict, truth: dict) -> dict[str, dict[str, str]]:
    """Per axis and field: ``in`` (the truth in the interval), ``OUT`` (not), ``declared``
    (declared not identifiable)."""
    out = {}
    for a in result["axes"]:
        row = {}
        for name in FIELDS:
            e = result["estimates"][a][name]
            if not e["identifiable"]:
                row[name] = "declared"
                continue
            t = getattr(truth[a], name)
            lo = -math.inf if e["low"] is None else e["low"]
            hi = math.inf if e["high"] is None else e["high"]
            row[name] = "in" if lo - 1e-12 * abs(t) <= t <= hi + 1e-12 * abs(t) else "OUT"
        out[a] = row
    return out


def identify_cli(args: list[str]) -> dict:
    proc = subprocess.run([sys.executable, "-m", "twin.cli", "identify", *args, "--json"],
                          capture_output=True, text=True,
                          env={**os.environ, "RERUN_ANALYTICS": "0"}, check=False)
    if proc.returncode != 0:
        return {"error": proc.stderr.strip().splitlines()[-3:]}
    return json.loads(proc.stdout)


def one(seed: int, where: Path, amplitude: float, *, drive: str | None, modbus: bool,
        with_transfer: bool) -> dict:
    base = load_machine(BASE)
    true = perturbed_machine(base, np.random.default_rng(seed), name=f"unseen_{seed}",
                             drive=drive)
    path = where / f"unseen_{seed}.toml"
    path.write_text(machine_to_toml(true), encoding="utf-8")
    out = where / f"calibrated_{seed}_{amplitude}.toml"
    common = ["--machine", BASE, "--amplitude", str(amplitude), "-o", str(out), "--out",
              str(where / "runs")]
    t0 = time.perf_counter()
    if modbus:
        from twin.hardware.hil_process import spawn_hil_server

        with spawn_hil_server("--machine", str(path), ready_timeout=600.0) as server:
            res = identify_cli([*common, "--driver",
                                f"modbus://127.0.0.1:{server.info['port']}?retries=1"])
    else:
        res = identify_cli([*common, "--driver", f"sim:{path}"])
    wall = time.perf_counter() - t0
    row: dict = {"seed": seed, "amplitude": amplitude}
    if "error" in res:
        row["error"] = res["error"]
        return row
    truth, figures = true_params(base, true), axis_figures(true)
    row.update({"machine_time_s": res["machine_time_s"],
                "fit_wall_time_s": round(res["fit_wall_time_s"], 1),
                "fit_cpu_time_s": round(res.get("fit_cpu_time_s", math.nan), 1),
                "replays": res["replays"], "total_wall_time_s": round(wall, 1),
                "held_out_nrmse_pct": round(100 * max(max(v.values())
                                                       for v in res["nrmse"].values()), 3),
                "coverage": coverage(res, truth)})
    for a in AXES:
        d, e, t, f = res["derived"][a], res["estimates"][a], truth[a], figures[a]

        def err(name: str, e=e, t=t) -> float:
            return round(100 * (e[name]["value"] / getattr(t, name) - 1), 2)

        row[a] = {"K_H_err_pct": round(100 * (d["K_H"] / f["K_H"] - 1), 3),
                  "inertia_err_pct": err("inertia"),
                  "speed_kp_err_pct": err("speed_kp"), "speed_ti_err_pct": err("speed_ti"),
                  "reference_filter_err_pct": err("reference_filter"),
                  "coulomb_err_pct": round(100 * (d["coulomb_at_motor"]
                                                  / f["coulomb_at_motor"] - 1), 2),
                  "viscous_err_pct": round(100 * (d["viscous_at_motor"]
                                                  / f["viscous_at_motor"] - 1), 2),
                  "lost_motion_err_um": round(1e6 * (e["backlash"]["value"] - t.backlash), 2),
                  "identifiable": {n: e[n]["identifiable"] for n in
                                   ("inertia", "speed_kp", "speed_ti")},
                  "dcm": res["dcm_compensation"].get(a),
                  "dcm_true": bool(t.dcm_compensation), "analog_true": bool(t.analog)}
    if with_transfer:
        row["max_coordinate_error_um"] = transfer(path, out, where / "runs")
    return row


def summarise(rows: list[dict]) -> dict:
    out = {}
    for amp in sorted({r["amplitude"] for r in rows}):
        mine = [r for r in rows if r["amplitude"] == amp and "coverage" in r]
        marks = [m for r in mine for a in r["coverage"].values() for m in a.values()]
        ident = [m for m in marks if m != "declared"]
        out[str(amp)] = {"machines": len(mine),
                         "failed": sum(1 for r in rows if r["amplitude"] == amp
                                       and "error" in r),
                         "fields": len(marks), "declared_unidentifiable": len(marks)
                         - len(ident), "identified": len(ident),
                         "truth_in_interval": sum(m == "in" for m in ident),
                         "coverage": round(sum(m == "in" for m in ident) / len(ident), 3)
                         if ident else None,
                         "out_fields": sorted({f"{a}.{n}" for r in mine
                                               for a, c in r["coverage"].items()
                                               for n, m in c.items() if m == "OUT"}),
                         "fit_wall_time_s_max": max((r["fit_wall_time_s"] for r in mine),
                                                    default=None),
                         "machine_time_s_max": max((r["machine_time_s"] for r in mine),
                                                   default=None)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--amplitudes", type=float, nargs="+", default=[1.0])
    parser.add_argument("--drive", choices=("mistuned", "as_built"), default=None,
                        help="hand-set drives: mistuned speed regulators (digital, DCM "
                             "adaptation), or as built (also analog, no DCM adaptation, "
                             "brush drop)")
    parser.add_argument("--modbus", action="store_true",
                        help="identify over Modbus/TCP from a twin hil-server")
    parser.add_argument("--transfer", action="store_true",
                        help="also run each machine with the calibrated, oracle and nominal "
                             "controller models")
    args = parser.parse_args()
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for amp in args.amplitudes:
            for s in args.seeds:
                rows.append(one(s, Path(tmp), amp, drive=args.drive, modbus=args.modbus,
                                with_transfer=args.transfer))
                print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    print(json.dumps({"base": BASE, "drive": args.drive, "modbus": args.modbus,
                      "summary": summarise(rows), "machines": rows}, indent=1))


if __name__ == "__main__":
    main()
