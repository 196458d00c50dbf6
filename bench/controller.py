"""Benchmark of the controller stack: planner throughput, streaming memory, tick latency.

Prints one JSON object:

* ``planner_blocks_per_s``: line blocks per second through ``segments_from_program`` +
  ``Planner.plan`` with look-ahead on (target ≥ 50 000), best of 3, wall clock;
* ``planner_peak_rss_mb``: peak resident memory (VmHWM) of a subprocess that streams a
  generated 1 000 000-line G-code file through ``gcode.read_file`` and the planner (target
  ≤ 200 MB);
* ``tick_p99_us``: 99th percentile of one ``Controller.tick`` — encoder, interpolation,
  regulation, record: the time from reading the machine to writing it — over a program of
  short lines (target ≤ 15 µs). The controller runs as ``TickLoop`` runs it: the
  read-ahead (the next block's profile and tables) follows the write, and is reported
  beside the tick (``read_ahead_us``) and summed with it (``tick_and_read_ahead_us``, the
  work of one period);

with the context (program, settings, machine load) needed to read them.

Run: ``.venv/bin/python bench/controller.py [--quick]`` (``--quick``: smaller sizes).
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twin.config import load_machine
from twin.controller.controller import Controller
from twin.controller.gcode import parse
from twin.controller.gcode.items import Move
from twin.controller.io import Inputs, Outputs
from twin.controller.planner import Planner

MACHINE = "tomsk_xy"
FEED = 0.01                       # m/s = 600 mm/min
STEP = (0.5e-3, 2e-3)             # segment lengths (m)
TURN = 0.5                        # largest change of heading per block (rad)


def polyline(n: int, seed: int = 0, step: tuple[float, float] = STEP):
    """(x, y) vertices (m) of a random polyline inside the work zone: n + 1 points."""
    rng = np.random.default_rng(seed)
    x, y, heading = 0.05, 0.05, 0.0
    yield x, y
    for _ in range(n):
        heading += rng.uniform(-TURN, TURN)
        length = rng.uniform(*step)
        x = min(max(x + length * math.cos(heading), 0.01), 0.19)
        y = min(max(y + length * math.sin(heading), 0.01), 0.19)
        yield x, y


def bench_planner(n: int) -> dict:
    cfg = load_machine(MACHINE)
    pts = list(polyline(n))
    moves = [Move("line", pts[i], pts[i + 1], FEED, line=i + 1) for i in range(n)
             if pts[i] != pts[i + 1]]
    out = {}
    for law in ("parabolic", "trapezoid", "jerk-limited"):
        planner = Planner.from_settings(cfg.controller, cfg.axes, law=law)
        best, cpu = math.inf, math.inf
        for _ in range(3):
            t0, c0 = time.perf_counter(), time.process_time()
            count = sum(1 for _ in planner.plan(moves))
            best = min(best, time.perf_counter() - t0)
            cpu = min(cpu, time.process_time() - c0)
        out[law] = {"blocks": count, "blocks_per_s": round(count / best),
                    "blocks_per_s_cpu": round(count / cpu)}
    return out


_STREAM = """
import sys
from twin.config import load_machine
from twin.controller.gcode import read_file
from twin.controller.planner import Planner
# a million short moves at a slow feed take longer than a day: allow it
cfg = load_machine({machine!r}).with_overrides({{'controller.max_program_time': 3.2e7}})
planner = Planner.from_settings(cfg.controller, cfg.axes)
count = sum(1 for _ in planner.plan(read_file(sys.argv[1], start=(0.05, 0.05))))
with open("/proc/self/status") as status:
    hwm = next(line.split()[1] for line in status if line.startswith("VmHWM:"))
print(count, hwm)
"""


def bench_stream(lines: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.ngc"
        with path.open("w") as f:
            f.write(f"G21 G90 G1 X50 Y50 F{FEED * 60e3:.0f}\n")
            for x, y in polyline(lines - 1, seed=1):
                f.write(f"G1 X{x * 1e3:.4f} Y{y * 1e3:.4f}\n")
        size_mb = path.stat().st_size / 1e6
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-c", _STREAM.format(machine=MACHINE),
                               str(path)], capture_output=True, text=True, check=True)
        elapsed = time.perf_counter() - t0
    blocks, peak_kb = (int(v) for v in done.stdout.split())
    return {"lines": lines, "file_mb": round(size_mb, 1), "blocks": blocks,
            "seconds": round(elapsed, 1), "peak_rss_mb": round(peak_kb / 1024, 1),
            "measured_by": "VmHWM of the child's /proc/self/status (ru_maxrss of children "
                           "would include the parent's image copied by fork)"}


class _Servo:
    """A minimal machine for the tick benchmark: each axis integrates K_H·u (ideal drive)."""

    def __init__(self, cfg, start):
        self.kh = [1.0 / cfg.axes[a].volts_per_speed for a in "xy"]
        self.cpm = [cfg.axes[a].counts_per_metre for a in "xy"]
        self.period = cfg.controller.period
        self.x = list(start)
        self.inputs = Inputs()

    def read(self) -> Inputs:
        for k in (0, 1):
            self.inputs.encoder_counts[k] = math.floor(self.x[k] * self.cpm[k]) % 2**32
        return self.inputs

    def write(self, out: Outputs) -> None:
        if out.enable:
            for k in (0, 1):
                self.x[k] += self.kh[k] * float(out.dac_volts[k]) * self.period


def bench_tick(blocks: int, ticks: int, step: tuple[float, float] = STEP) -> dict:
    cfg = load_machine(MACHINE)
    text = [f"G21 G90 G1 X50 Y50 F{FEED * 60e3:.0f}"]
    text += [f"G1 X{x * 1e3:.4f} Y{y * 1e3:.4f}" for x, y in polyline(blocks, 2, step)]
    prog = parse("\n".join(text), start=(0.05, 0.05))
    ctrl = Controller.from_machine(cfg, prog, start=(0.05, 0.05))
    ctrl.read_ahead_in_tick = False          # as TickLoop runs it: read ahead after the write
    io = _Servo(cfg, (0.05, 0.05))
    clock = time.perf_counter_ns
    times = np.empty(ticks)
    after = np.empty(ticks)
    gc.collect()
    gc.disable()                             # as TickLoop: no cyclic collection inside
    n = 0
    while n < ticks and not ctrl.done:
        inputs = io.read()
        t0 = clock()
        out = ctrl.tick(inputs)
        t1 = clock()
        io.write(out)
        t2 = clock()
        ctrl.read_ahead()
        times[n] = t1 - t0
        after[n] = clock() - t2
        n += 1
    gc.enable()
    us, ahead = times[:n] / 1e3, after[:n] / 1e3
    p50, p90, p99, p999 = np.percentile(us, [50, 90, 99, 99.9])
    return {"ticks": n, "segments_mm": [1e3 * v for v in step], "status": ctrl.status.name,
            "p50_us": round(p50, 1),
            "p90_us": round(p90, 1), "p99_us": round(p99, 1), "p999_us": round(p999, 1),
            "max_us": round(float(us.max()), 1), "over_1ms": int((us > 1000).sum()),
            "read_ahead_us": _percentiles(ahead),
            "tick_and_read_ahead_us": _percentiles(us + ahead),
            "blocks_run": int(ctrl.interpolator.reference.block) + 1}


def _percentiles(us: np.ndarray) -> dict:
    p50, p90, p99, p999 = np.percentile(us, [50, 90, 99, 99.9])
    return {"p50": round(p50, 1), "p90": round(p90, 1), "p99": round(p99, 1),
            "p999": round(p999, 1), "max": round(float(us.max()), 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller sizes (smoke run)")
    args = parser.parse_args()
    n_plan, n_stream, n_ticks = (20_000, 50_000, 5_000) if args.quick else \
        (200_000, 1_000_000, 30_000)
    planner = bench_planner(n_plan)
    stream = bench_stream(n_stream)
    tick = bench_tick(4_000, n_ticks)
    dense = bench_tick(20_000, n_ticks, step=(0.02e-3, 0.1e-3))     # a block every tick
    cfg = load_machine(MACHINE)
    print(json.dumps({
        "planner_blocks_per_s": planner["parabolic"]["blocks_per_s"],
        "planner_peak_rss_mb": stream["peak_rss_mb"],
        "tick_p99_us": tick["p99_us"],
        "context": {
            "machine": MACHINE, "law": cfg.controller.profile,
            "lookahead": cfg.controller.lookahead, "period_s": cfg.controller.period,
            "program": f"random polyline, segments {STEP[0] * 1e3}-{STEP[1] * 1e3} mm, "
                       f"heading change up to ±{TURN} rad per block, feed {FEED * 60e3:.0f} "
                       "mm/min",
            "planner_by_law": planner, "stream": stream, "tick": tick, "tick_dense": dense,
            "python": platform.python_version(), "cpus": os.cpu_count(),
            "load_average": [round(v, 2) for v in os.getloadavg()],
            "quick": args.quick,
        },
    }))


if __name__ == "__main__":
    main()
