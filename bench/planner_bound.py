"""The look-ahead planner against the time-optimal bound, on CAM-like programs (issue 12).

For each program of ``twin.analysis.studies.cam`` (a chorded nest of 32.6 m, lettering outlines, a
pocket zig-zag) on a machine (default ``laser_belt``, seed 001's laser table), and each
acceleration law:

* ``lookahead_s`` / ``stop_s``: the planned cycle time (the sum of the blocks' profile
  durations and the dwells) with look-ahead, and with a stop at every node;
* ``bound_s``: the time-optimal traversal of the same path (the look-ahead's, its corners
  rounded within the contour tolerance) under the same limits — per-axis velocity and
  acceleration, the contour feed and acceleration, stops where the program stops — computed
  by TOPP-RA (``toppra``, a bench-only dependency: ``pip install -e '.[bench]'``) with the
  constraints evaluated at grid points every ``--grid`` mm and at every segment end; the
  contour acceleration |a| ≤ A is its circumscribed 16-gon (a relaxation, so the bound stays
  a bound). No jerk limit: it bounds every law;
* ``ratio`` = lookahead / bound, ``stop_ratio`` = stop / bound;
* ``bound_share_changing_speed``: the share φ of the bound's time spent accelerating or
  braking: a law whose speed changes take k_a times as long at the same peak acceleration
  (parabolic 1.5, cosine π/2, cubic 1.875) is held to about ``1 + φ·(k_a − 1)`` of the bound
  on such a program, whatever its planner;
* ``mean_bound_s`` / ``ratio_to_mean_bound`` (parabolic, cosine, cubic): the same bound
  with the path acceleration also held to the law's mean over a speed change, A/k_a (the
  peak still within the limits above): what the law's fixed shape allows at best for its
  speed changes. Not a strict bound (a curve's speed limit may cut a change short), a
  like-for-like yardstick for the smooth laws;
* ``axis_acceleration``: the largest |second difference| of the position reference over one
  controller period, as the interpolator produces it, relative to each axis' limit (velocity
  steps at nodes count as Δv/T there);
* ``blocks_per_s``: planning throughput in memory (the speeds at the nodes; a block's
  speed profile is made when it is used, ``PlannedBlock.profile``).

Then the chord-independence table (circles of r = 2 and 20 mm as G3 and as chords of 0.001 …
0.5 mm: the planned speed at mid-circle), and the planner's throughput on a 100 000-block
chord program in memory (also with every block's profile made, as the interpolator makes it)
and streamed from a file through the G-code reader (peak RSS).

Prints one JSON object. ``--quick``: one law set on smaller programs (a sanity run).
"""

from __future__ import annotations

import argparse
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

from twin.analysis.studies import cam
from twin.config import load_machine
from twin.controller.gcode import parse
from twin.controller.geometry import Arc
from twin.controller.planner import PlannedBlock, Planner
from twin.controller.profiles import LAWS

GRID = 0.25e-3                 # m: the bound's largest grid step
ARC_STEP = 0.05                # rad: the bound's largest grid step on arcs
POLYGON = 16                   # sides of the contour-acceleration polygon


# ----------------------------------------------------------------------------- planning
def plan(cfg, text: str, law: str, mode: str = "lookahead") -> tuple[list, float]:
    """(planned items, planning seconds) of a G-code text."""
    items = list(parse(text, start=(0.01, 0.01)))
    planner = Planner.from_settings(cfg.controller, cfg.axes, law=law, mode=mode,
                                    work_zone=None)
    t0 = time.perf_counter()
    out = list(planner.plan(items))
    return out, time.perf_counter() - t0


def cycle_time(items: list) -> float:
    """Sum of the blocks' profile durations and the dwells (s)."""
    total = 0.0
    for it in items:
        if isinstance(it, PlannedBlock):
            total += it.profile().duration
        elif hasattr(it, "duration"):
            total += it.duration
    return total


def pieces(items: list) -> tuple[list[list[PlannedBlock]], float]:
    """The blocks split where the machine stops (rapids, dwells, events, kinks passed at
    rest), and the dwells' total time (s)."""
    out: list[list[PlannedBlock]] = []
    cur: list[PlannedBlock] = []
    dwell = 0.0
    for it in items:
        if isinstance(it, PlannedBlock):
            if cur and (it.rapid != cur[-1].rapid or it.v_start == 0.0):
                out.append(cur)
                cur = []
            cur.append(it)
        else:
            dwell += getattr(it, "duration", 0.0)
            if cur:
                out.append(cur)
                cur = []
    if cur:
        out.append(cur)
    return out, dwell


# ----------------------------------------------------------------------------- the bound
def _grid(blocks: list[PlannedBlock]) -> tuple[np.ndarray, list[tuple[int, float]]]:
    """Grid points along the blocks (m, from 0) and per point (block index, local s).

    A block's start point is its own (TOPP-RA's collocation constrains the acceleration of
    the interval that follows a grid point by that point's geometry: the interval after a
    block boundary lies on the next block); the last block keeps its end point.
    """
    s_all, where = [], []
    offset = 0.0
    for k, b in enumerate(blocks):
        seg = b.segment
        step = GRID
        if isinstance(seg, Arc):
            step = min(step, ARC_STEP * seg.radius)
        n = max(1, math.ceil(seg.length / step))
        local = np.linspace(0.0, seg.length, n + 1)
        if k < len(blocks) - 1:
            local = local[:-1]
        for u in local:
            s_all.append(offset + u)
            where.append((k, float(u)))
        offset += seg.length
    return np.array(s_all), where


def bound_time(blocks: list[PlannedBlock], cfg, k_a: float = 1.0) -> tuple[float, float]:
    """TOPP-RA's time for one piece that starts and ends at rest (s), and the part of it
    spent changing speed (path acceleration above 1 % of the contour limit) (s). With
    ``k_a`` > 1 the path acceleration is also held to |s̈| ≤ A/k_a: a smooth law's mean
    acceleration over a speed change (its peak stays within the same limits as above)."""
    import toppra
    import toppra.algorithm as algo
    from toppra.constraint import DiscretizationType, LinearConstraint

    grid, where = _grid(blocks)
    n = len(grid)
    tx, ty, nx, ny, cap = (np.zeros(n) for _ in range(5))
    axes = [cfg.axes[a].limits for a in "xy"]
    contour = cfg.controller.limits
    for i, (k, u) in enumerate(where):
        b = blocks[k]
        _, _, t0, t1, kappa, _ = b.segment.frame(u)
        tx[i], ty[i] = t0, t1
        nx[i], ny[i] = -t1 * kappa, t0 * kappa           # κ·n̂ (n̂ = t̂ turned +90°)
        v = cfg.controller.rapid_velocity if b.rapid else min(b.feed, contour.max_velocity)
        for comp, lim in ((abs(t0), axes[0]), (abs(t1), axes[1])):
            if comp * v > lim.max_velocity:
                v = lim.max_velocity / comp
        cap[i] = v
    # at a block boundary both blocks' speed caps hold (the speed is continuous there)
    for i in range(1, n):
        if where[i][0] != where[i - 1][0]:
            cap[i] = min(cap[i], cap[i - 1])
    angles = np.arange(POLYGON) * 2.0 * math.pi / POLYGON
    rows = [[1, 0], [-1, 0], [0, 1], [0, -1]] + [[math.cos(a), math.sin(a)] for a in angles]
    limit_c = contour.max_acceleration          # the circumscribed 16-gon: apothem A
    g = np.array([axes[0].max_acceleration] * 2 + [axes[1].max_acceleration] * 2
                 + [limit_c] * POLYGON)

    class Limits(LinearConstraint):
        def __init__(self):
            super().__init__()
            self.identical = True
            self.discretization_type = DiscretizationType.Collocation

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            a = np.stack([tx, ty], axis=1)
            b = np.stack([nx, ny], axis=1)
            c = np.zeros((n, 2))
            xbound = np.stack([np.zeros(n), cap * cap], axis=1)
            return a, b, c, np.array(rows, float), g, None, xbound

    class Path(toppra.interpolator.AbstractGeometricPath):
        def __call__(self, path_positions, order=0):
            return np.zeros((np.size(path_positions), 2))

        @property
        def dof(self):
            return 2

        @property
        def path_interval(self):
            return np.array([grid[0], grid[-1]])

    class Mean(LinearConstraint):
        def __init__(self):
            super().__init__()
            self.identical = True
            self.discretization_type = DiscretizationType.Collocation

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            mean = limit_c / k_a
            return (np.ones((n, 1)), np.zeros((n, 1)), np.zeros((n, 1)),
                    np.array([[1.0], [-1.0]]), np.array([mean, mean]), None, None)

    constraints = [Limits()] if k_a == 1.0 else [Limits(), Mean()]
    inst = algo.TOPPRA(constraints, Path(), gridpoints=grid, solver_wrapper="seidel")
    inst.compute_parameterization(0.0, 0.0)
    sd = inst.problem_data.sd_vec
    if sd is None:
        raise RuntimeError(f"TOPP-RA found no parameterisation: {inst.problem_data}")
    ds = np.diff(grid)
    dt = 2.0 * ds / (sd[:-1] + sd[1:])
    sdd = (sd[1:] ** 2 - sd[:-1] ** 2) / (2.0 * ds)
    changing = np.abs(sdd) > 0.01 * contour.max_acceleration
    return float(np.sum(dt)), float(np.sum(dt[changing]))


K_A = {"parabolic": 1.5, "cosine": math.pi / 2, "cubic": 1.875}
"""Peak over mean acceleration of a speed change of each smooth law with a fixed shape
(φ'(u) at its peak: 6u(1 − u), (π/2)·sin πu, 30u²(1 − u)²); the jerk-limited law's depends
on the change."""


# ----------------------------------------------------------------------------- limits
def axis_acceleration(items: list, cfg) -> list[float]:
    """Largest |Δ²p|/T² of the sampled position reference per axis over its limit."""
    acc = cam.sampled_acceleration(items, cfg.controller.period)
    return [float(acc[k] / cfg.axes[a].limits.max_acceleration) for k, a in enumerate("xy")]


# ----------------------------------------------------------------------------- figures
def program_figures(cfg, name: str, text: str, laws, check_limits: bool) -> dict:
    out: dict = {}
    bound = None
    for law in laws:
        items, seconds = plan(cfg, text, law)
        stop_items, _ = plan(cfg, text, law, "stop")
        if bound is None:            # the path is the same for every law: its blends
            parts, dwell = pieces(items)
            times = [bound_time(p, cfg) for p in parts]
            bound = sum(t for t, _ in times) + dwell
            changing = sum(c for _, c in times) / bound
        blocks = sum(isinstance(i, PlannedBlock) for i in items)
        la, st = cycle_time(items), cycle_time(stop_items)
        row = {"lookahead_s": round(la, 3), "stop_s": round(st, 3),
               "ratio": round(la / bound, 4), "stop_ratio": round(st / bound, 4),
               "blocks": blocks, "blocks_per_s": round(blocks / seconds)}
        if law in K_A:
            mean = sum(bound_time(p, cfg, K_A[law])[0] for p in parts) + dwell
            row["mean_bound_s"] = round(mean, 3)
            row["ratio_to_mean_bound"] = round(la / mean, 4)
        if check_limits:
            row["axis_acceleration"] = [round(r, 3) for r in axis_acceleration(items, cfg)]
        out[law] = row
    return {"bound_s": round(bound, 3), "bound_share_changing_speed": round(changing, 4),
            "laws": out}


def mid_circle_speed(cfg, text: str, law: str) -> float:
    """The planned path speed at the middle of a circle program's circle (m/s)."""
    return cam.middle_speed(plan(cfg, text, law)[0])


def chord_independence(cfg, laws) -> dict:
    out = {}
    for r in (2.0, 20.0):
        for law in laws:
            speeds = {"G3": mid_circle_speed(cfg, cam.circle(r), law)}
            for chord in (0.001, 0.01, 0.1, 0.5):
                speeds[f"{chord:g}"] = mid_circle_speed(cfg, cam.circle(r, chord=chord), law)
            v = list(speeds.values())
            out[f"r{r:g}_{law}"] = {"mm_per_s": {k: round(x * 1e3, 3) for k, x in speeds.items()},
                                    "spread": round(max(v) / min(v) - 1.0, 4)}
    return out


_STREAM = """
import sys, time
from twin.config import load_machine
from twin.controller.gcode import read_file
from twin.controller.planner import Planner
cfg = load_machine(sys.argv[2])
planner = Planner.from_settings(cfg.controller, cfg.axes, law=sys.argv[3], work_zone=None)
t0 = time.perf_counter()
count = sum(1 for _ in planner.plan(read_file(sys.argv[1], start=(0.01, 0.01))))
seconds = time.perf_counter() - t0
with open("/proc/self/status") as status:
    hwm = next(line.split()[1] for line in status if line.startswith("VmHWM:"))
print(count, seconds, hwm)
"""


def throughput(cfg, machine: str, laws, blocks: int) -> dict:
    text = cam.chords(blocks)
    items = list(parse(text, start=(0.01, 0.01)))
    lines = sum(type(i).__name__ == "Move" for i in items)
    out = {"program_blocks": lines}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "chords.ngc"
        path.write_text(text)
        for law in laws:
            planner = Planner.from_settings(cfg.controller, cfg.axes, law=law, work_zone=None)
            t0 = time.perf_counter()
            planned = sum(1 for _ in planner.plan(items))
            mem = time.perf_counter() - t0
            # the same, with every block's speed profile made as the interpolator makes it
            # when it reaches the block (plan_move, or the block's part of its run's move)
            planner = Planner.from_settings(cfg.controller, cfg.axes, law=law, work_zone=None)
            t0 = time.perf_counter()
            for block in planner.plan(items):
                if type(block) is PlannedBlock:
                    block.profile()
            profiled = time.perf_counter() - t0
            done = subprocess.run([sys.executable, "-c", _STREAM, str(path), machine, law],
                                  capture_output=True, text=True, check=True)
            _, seconds, hwm = done.stdout.split()
            out[law] = {"in_memory_blocks_per_s": round(lines / mem),
                        "in_memory_with_profiles_blocks_per_s": round(lines / profiled),
                        "planned_items": planned,
                        "streamed_blocks_per_s": round(lines / float(seconds)),
                        "streamed_peak_rss_mb": round(int(hwm) / 1024, 1)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--machine", default="laser_belt")
    parser.add_argument("--quick", action="store_true", help="smaller programs, two laws")
    parser.add_argument("--no-limits", action="store_true",
                        help="skip interpolating the references (the slow part)")
    args = parser.parse_args()
    cfg = load_machine(args.machine)
    laws = ("trapezoid", "parabolic") if args.quick else LAWS
    programs = {
        "chorded_nest": cam.chorded_nest(*((2, 2) if args.quick else (6, 4))),
        "lettering": cam.lettering("XY 26" if args.quick else "XY-twin 2026"),
        "pocket": cam.pocket(),
    }
    t0 = time.perf_counter()
    result = {"machine": args.machine, "grid_mm": GRID * 1e3,
              "programs": {name: program_figures(cfg, name, text, laws, not args.no_limits)
                           for name, text in programs.items()},
              "chord_independence": chord_independence(cfg, laws),
              "throughput": throughput(cfg, args.machine, laws,
                                       10_000 if args.quick else 100_000),
              "seconds": None, "cpus": os.cpu_count(),
              "load_average_1min": round(os.getloadavg()[0], 2),
              "python": platform.python_version()}
    result["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
