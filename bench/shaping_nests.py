"""Issue 31's shaping result re-checked on random nests it was not tuned on (JSON to stdout).

The shaping study (`twin.analysis.studies.shaping_laser`) judged trapezoid + shaper with the
reference compensations on seed 001's one nest, and chose its ``COMPENSATED_SHARE`` there.
This bench draws other nests of the same class (the parts of `twin.analysis.studies.nest`:
flange, bracket, sprocket, cam, comb) with random grids, cell sizes, part kinds and size
parameters, and runs each on laser_belt with the study's own settings and metrics: plain
trapezoid, trapezoid + ZVD / EI compensated, trapezoid compensated. Per run it also gives
where the largest true contour error sits (time, table position, the nearest programmed
segment and whether that segment is a rapid).

    python bench/shaping_nests.py --seeds 1 2 3 --runs trapezoid zvd
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any

import numpy as np

from twin.analysis.studies import shaping_laser
from twin.analysis.studies.nest import KINDS, Nest, Part, layout, nest, random_nest
from twin.analysis.studies.shaping_laser import COMPENSATED, COMPENSATED_SHARE
from twin.controller.gcode import parse
from twin.controller.gcode.items import Move

_COMP_SHAPED = {**COMPENSATED, "controller.shaper.curve_share": COMPENSATED_SHARE}
RUNS = {"trapezoid": ("trapezoid", {}),
        "zvd": ("trapezoid+zvd", _COMP_SHAPED),
        "ei": ("trapezoid+ei", _COMP_SHAPED),
        "zv": ("trapezoid+zv", _COMP_SHAPED),
        "mzv": ("trapezoid+mzv", _COMP_SHAPED),
        "comp": ("trapezoid", COMPENSATED)}
"""Short name: (profile, overrides) exactly as the study sets them."""


def _random(seed: int) -> tuple[Nest, dict[str, Any]]:
    """`nest.random_nest` and what it holds."""
    job, parts = random_nest(seed)
    return job, _facts(job, parts, seed)


def _facts(job: Nest, parts: list[Part], label: Any) -> dict[str, Any]:
    p0 = parts[0]
    return {"seed": label, "cells": len(parts),
            "cell_mm": [round(p0.width, 1), round(p0.height, 1)],
            "parts": [{"kind": p.kind, "s": round(p.size, 3), "lines": list(lines)}
                      for p, lines in zip(parts, job.part_lines, strict=True)],
            "contours": job.contours, "blocks": job.blocks,
            "cut_length_mm": round(job.cut_length, 1),
            "idle_length_mm": round(job.idle_length, 1)}


def _where(result, contour: np.ndarray, moves: list, gcode_lines: list[str]
           ) -> dict[str, Any]:
    """Where the largest contour error sits: time, table position, the nearest programmed
    segment and the G-code move it comes from (matched by its end points)."""
    i = int(np.argmax(contour))
    p = np.asarray(result.record["table_position"])[i, :2]
    dist = [float(seg.distance(p)) for seg in result.path]
    seg = result.path[int(np.argmin(dist))]
    a, b = np.asarray(seg.start), np.asarray(seg.end)
    move = min(moves, key=lambda m: math.dist(m.start, a) + math.dist(m.end, b))
    s_near = float(seg.closest(p)[0])
    out = {"t_s": round(float(result.record["t"][i]), 3),
           "x_mm": round(float(p[0]) * 1e3, 3), "y_mm": round(float(p[1]) * 1e3, 3),
           "segment": type(seg).__name__, "segment_length_mm": round(seg.length * 1e3, 3),
           "to_segment_end_mm": round(min(s_near, seg.length - s_near) * 1e3, 3),
           "move": move.kind, "line": move.line, "gcode": gcode_lines[move.line - 1]}
    if move.center is not None:
        out["radius_mm"] = round(math.dist(move.center, move.start) * 1e3, 3)
    return out


def single_part(kind: str, size: float, s: float) -> tuple[Nest, dict[str, Any]]:
    """One part of ``kind`` in a ``size`` × ``size`` mm cell at (20, 20) mm."""
    parts = [Part(kind, 20.0, 20.0, size, size, s)]
    job = layout(parts, title=f"single {kind}")
    return job, _facts(job, parts, f"{kind} {size:g} mm s={s:g}")


def nest_run(gcode: str, profile: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """The study's figures of the run, plus where the largest contour error sits."""
    t0 = time.process_time()
    result, contour, figures = shaping_laser.nest_run(gcode, profile, overrides)
    start = tuple(np.asarray(result.record["table_position"])[0, :2].tolist())
    moves = [m for m in parse(gcode, start=start) if isinstance(m, Move)]
    return {**{k: v for k, v in figures.items() if k != "elastic_oscillation_um"},
            "worst": _where(result, contour, moves, gcode.splitlines()),
            "cpu_s": round(time.process_time() - t0, 1)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--runs", nargs="+", choices=list(RUNS), default=["trapezoid", "zvd"])
    ap.add_argument("--single", nargs="*", choices=KINDS, default=None,
                    help="one part of each kind (180 mm cell, s=0.5) instead of seeds")
    ap.add_argument("--seed001", action="store_true",
                    help="seed 001's nest itself (the study's), to check this bench against it")
    ap.add_argument("--describe", action="store_true", help="only the nests, no runs")
    args = ap.parse_args(argv)
    jobs = ([lambda k=k: single_part(k, 180.0, 0.5) for k in args.single]
            if args.single is not None else
            [lambda seed=seed: _random(seed) for seed in args.seeds])
    if args.seed001:
        def study() -> tuple[Nest, dict[str, Any]]:
            job = nest()
            return job, {"seed": "seed 001 (study)", "contours": job.contours,
                         "parts": job.parts, "cut_length_mm": round(job.cut_length, 1),
                         "idle_length_mm": round(job.idle_length, 1)}
        jobs = [study]
    for make in jobs:
        job, info = make()
        out: dict[str, Any] = {"nest": info, "runs": {}}
        if not args.describe:
            for name in args.runs:
                profile, ov = RUNS[name]
                out["runs"][name] = nest_run(job.gcode, profile, ov)
            base = out["runs"].get("trapezoid")
            if base:
                for r in out["runs"].values():
                    r["cycle_time_vs_trapezoid_pct"] = 100.0 * (
                        r["cycle_time_s"] / base["cycle_time_s"] - 1.0)
                    r["residual_vibration_cut_pct"] = 100.0 * (
                        1.0 - r["residual_vibration_um"] / base["residual_vibration_um"])
        print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
