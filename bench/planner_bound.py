"""Each acceleration law against its own yardstick, on CAM-like programs (issues 12, 30).

For each program — three fixed ones of ``twin.analysis.studies.cam`` (a chorded nest of
32.6 m, large lettering, a pocket zig-zag) and ``--instances`` random instances of each
class of ``twin.analysis.studies.cam_classes`` (small text, densely chorded small radii, a
3-axis raster flattened to XY), drawn from ``--seed`` — on a machine (default
``laser_belt``, seed 001's laser table), and each acceleration law:

* ``lookahead_s``: the planned cycle time (the blocks' profile durations and the dwells);
* ``yardstick_s``: the law's own yardstick. The time-optimal traversal of the same path
  (the look-ahead's, corners rounded within the contour tolerance) under the same limits —
  per-axis velocity and acceleration, the contour feed and acceleration (its circumscribed
  16-gon: a relaxation, so the bound stays a bound), stops where the program stops —
  computed by TOPP-RA (``toppra``, a bench-only dependency: ``pip install -e '.[bench]'``)
  on grid points every ``GRID`` (at least ``MIN_STEPS`` per block) and at every segment
  end, with the path acceleration also
  held to |s̈| ≤ A/k_a, the law's mean acceleration over one speed change at peak A:

  ========================  ==================================================
  trapezoid                 k_a = 1: the plain time-optimal bound (no jerk limit)
  parabolic, cosine, cubic  k_a = 1.5, π/2, 1.875 (``K_A``)
  jerk-limited              A_eff = A / (1 + A²/(J·v)), v the piece's top feed
  ========================  ==================================================

  For the fixed-shape laws the yardstick is a like-for-like reference, not a strict
  bound: their own jerk limit may make a short speed change slower than A/k_a (the
  planner must keep it), and a curve's speed limit may cut a change short. For the
  jerk-limited law it is an **estimate**: A_eff is the mean acceleration of the S-curve
  from rest to the feed (|Δv|/A + A/J per change); a smaller change has a lower mean, a
  change that does not start at rest may save the ramps. Hence its target is 1.10×;
* ``ratio`` = lookahead / yardstick; ``ratio_to_bound``: lookahead / the plain bound;
  ``ratio_to_capped``: lookahead / the yardstick with the speed also held to the planner's
  own caps of blocks and nodes (the curves' acceleration and jerk caps, the corner model,
  the velocity and curvature steps): what the speed profiles lose, apart from the caps;
* ``ratio_to_jerk_aware`` (the laws that limit jerk): lookahead / the yardstick with the
  speed also held where jerk itself decides it on this path, whatever the planner: on a
  curve the acceleration vector turns at v·κ, a jerk of v³κ² at steady speed (``v³κ² ≤
  J``), and where the curvature steps by Δκ between blocks the normal acceleration steps
  by v²·Δκ within one period T of the controller (``v²·|Δκ| ≤ J·T``), J the contour's
  max_jerk. The yardstick of the issue leaves jerk out; these two caps are what a
  jerk-limited motion on the same rounded path cannot beat (the planner's own, in
  ``ratio_to_capped``, split the budgets more conservatively);
* ``axis_acceleration``, ``axis_jerk``: the largest |Δ²p|/T² and |Δ³p|/T³ of the sampled
  position reference per axis (every controller period T, as the interpolator produces
  it) over the axis' max_acceleration and max_jerk. A velocity step at a node counts as
  Δv/T, an acceleration step as Δa/T (the trapezoid's jerk is impulsive: reported, not
  held). ``limits_ok``: acceleration ≤ 1.05 for every law, jerk ≤ 1.05 for the
  jerk-limited law;
* per program: blocks, median chord, the blends' radius percentiles p10/p50/p90 (mm).

Then the chord-independence table (`twin.analysis.studies.circles`): full circles of
r = 0.5 … 20 mm as a G3 arc, as chords of 0.001 … 0.5 mm (written exactly) and as chords
within a chordal tolerance of 0.001 … 0.02 mm (written with 3 decimals, as CAM posts do);
the feed moves' cycle time per law and its spread over the representations; and the planner's
throughput on a 100 000-block chord program in memory (also with every block's profile
made, as the interpolator makes it) and streamed from a file through the G-code reader
(peak RSS), in lines per second of process CPU time, and the path stage (fairing and
blending) alone.

With ``--twin`` each program also runs on the twin with each law (the full controller;
``--set KEY=VALUE`` overrides the machine, e.g.
``controller.compensation.stretch=true``): the twin's cycle time and the largest contour
error of the table's true path (``table_max_contour_error_um``) and of the encoder's
(``encoder_max_contour_error_um``), the issue's "twin's max contour error" against which a
faster path is held (a belt's table lags its motor by the stretch: the two differ).

Prints one JSON object; ``--markdown`` also prints the summary tables to stderr.
``--quick``: smaller programs, one instance per class, two laws (a sanity run).
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
from collections import deque
from pathlib import Path

import numpy as np

from twin.analysis.studies import cam
from twin.analysis.studies.cam_classes import CLASSES
from twin.analysis.studies.circles import RADII, chord_independence
from twin.analysis.studies.common import gcode_program, run_items
from twin.config import load_machine
from twin.config.overrides import parse_sets
from twin.controller.blend import Blender
from twin.controller.blocks import MotionBlock, segments_from_program
from twin.controller.gcode import parse
from twin.controller.geometry import Arc, Line
from twin.controller.planner import PlannedBlock, Planner
from twin.controller.profiles import LAWS

GRID = 0.25e-3                 # m: the bound's largest grid step
ARC_STEP = 0.05                # rad: the bound's largest grid step on arcs
POLYGON = 16                   # sides of the contour-acceleration polygon
MIN_STEPS = 8                  # grid steps per block at least (short chords, small text)


# ----------------------------------------------------------------------------- planning
def plan(cfg, text: str, law: str, mode: str = "lookahead") -> tuple[list, float]:
    """(planned items, planning seconds) of a G-code text."""
    items = list(parse(text, start=(0.01, 0.01)))
    planner = Planner.from_settings(cfg.controller, cfg.axes, law=law, mode=mode,
                                    work_zone=None)
    t0 = time.perf_counter()
    out = list(planner.plan(items))
    return out, time.perf_counter() - t0


def cycle_time(items: list, feed_only: bool = False) -> float:
    """Sum of the blocks' profile durations and the dwells (s) (`cam.planned_time`)."""
    return cam.planned_time(items, feed_only)


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


def _max_curvature(seg) -> float:
    """Largest |κ| of a segment (1/m): exact on lines and arcs, sampled on other curves."""
    if isinstance(seg, Line):
        return 0.0
    if isinstance(seg, Arc):
        return 1.0 / seg.radius
    return float(np.abs(seg.curvature(np.linspace(0.0, seg.length, 33))).max())


def path_figures(items: list) -> dict:
    """Blocks, median chord and the blends' radius percentiles of a plan (mm)."""
    feed = [b for b in items if isinstance(b, PlannedBlock) and not b.rapid]
    chords = [b.segment.length for b in feed if isinstance(b.segment, Line)]
    radii = [1.0 / k for k in (_max_curvature(b.segment) for b in feed if b.blend) if k > 0]
    out = {"feed_blocks": len(feed), "feed_length_mm": round(
        sum(b.segment.length for b in feed) * 1e3, 1)}
    if chords:
        out["median_line_mm"] = round(float(np.median(chords)) * 1e3, 4)
    if radii:
        out["blend_radius_p10_p50_p90_mm"] = [round(float(x) * 1e3, 3)
                                             for x in np.percentile(radii, [10, 50, 90])]
    return out


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
        kappa = _max_curvature(seg)
        if kappa > 0.0:
            step = min(step, ARC_STEP / kappa)
        n = max(MIN_STEPS, math.ceil(seg.length / step))
        local = np.linspace(0.0, seg.length, n + 1)
        if k < len(blocks) - 1:
            local = local[:-1]
        for u in local:
            s_all.append(offset + u)
            where.append((k, float(u)))
        offset += seg.length
    return np.array(s_all), where


def _feed_cap(cfg, b: PlannedBlock) -> float:
    """A block's speed before any geometric cap (m/s)."""
    contour = cfg.controller.limits
    return cfg.controller.rapid_velocity if b.rapid else min(b.feed, contour.max_velocity)


def planner_rules(cfg, law: str):
    """The rules of blocks and nodes of a planner of ``law`` on ``cfg`` (`BlockRules`)."""
    return Planner.from_settings(cfg.controller, cfg.axes, law=law, work_zone=None)._rules


def _followed(rules, blocks: list[PlannedBlock]):
    """Each block of a piece as the planner sees it (a `WindowBlock`) with the one before it
    (None for the first), after `BlockRules.follow` (a sliver takes its curve's curvature)."""
    prev = None
    for b in blocks:
        wb = rules.block(b.segment, b.feed, b.line, b.blend)
        if prev is not None:
            rules.follow(prev, wb)
        yield b, wb, prev
        prev = wb


def rule_caps(cfg, rules, blocks: list[PlannedBlock]) -> list[tuple[float, float]]:
    """Per block of a piece, the planner's own caps (m/s; ``rules``: `planner_rules`): the
    block's speed cap (`BlockRules.block`: feed, axes, a curve's acceleration and jerk) and
    its start node's (`BlockRules.node_cap`: corner model, velocity and curvature steps)."""
    return [(wb.v_nom, 0.0 if prev is None else rules.node_cap(prev, wb))
            for _, wb, prev in _followed(rules, blocks)]


def jerk_caps(cfg, rules, blocks: list[PlannedBlock]) -> list[tuple[float, float]]:
    """Per block of a piece, the speed caps jerk itself sets on its path (m/s): on the block
    ``v³κ² ≤ J`` (κ its largest curvature) and at its start node ``v²·|Δκ| ≤ J·T`` (module
    doc), the curvatures at the node as the planner sees them (a sliver of line between two
    curves, passed within a fraction of a period, takes the curve's: `BlockRules.follow`);
    ``inf`` where nothing caps."""
    j, period = cfg.controller.limits.max_jerk, cfg.controller.period
    out = []
    for b, wb, prev in _followed(rules, blocks):
        kappa = _max_curvature(b.segment)
        node = math.inf
        if prev is not None and wb.k0 != prev.k1:
            node = math.sqrt(j * period / abs(wb.k0 - prev.k1))
        out.append(((j / kappa**2) ** (1.0 / 3.0) if kappa > 0.0 else math.inf, node))
    return out


def _path_data(blocks: list[PlannedBlock], cfg, caps) -> tuple[np.ndarray, ...]:
    """The bound's grid (`_grid`) and per grid point the tangent (tx, ty), κ·n̂ (nx, ny) and
    the speed cap (m/s): the feed, the axes' velocities along the tangent, ``caps``."""
    grid, where = _grid(blocks)
    n = len(grid)
    tx, ty, nx, ny, cap = (np.zeros(n) for _ in range(5))
    axes = [cfg.axes[a].limits for a in "xy"]
    for i, (k, u) in enumerate(where):
        b = blocks[k]
        _, _, t0, t1, kappa, _ = b.segment.frame(u)
        tx[i], ty[i] = t0, t1
        nx[i], ny[i] = -t1 * kappa, t0 * kappa           # κ·n̂ (n̂ = t̂ turned +90°)
        v = _feed_cap(cfg, b)
        for comp, lim in ((abs(t0), axes[0]), (abs(t1), axes[1])):
            if comp * v > lim.max_velocity:
                v = lim.max_velocity / comp
        if caps is not None:
            v = min(v, caps[k][0])
            if u == 0.0 and k > 0:
                v = min(v, caps[k][1])
        cap[i] = v
    # at a block boundary both blocks' speed caps hold (the speed is continuous there)
    for i in range(1, n):
        if where[i][0] != where[i - 1][0]:
            cap[i] = min(cap[i], cap[i - 1])
    return grid, tx, ty, nx, ny, cap


def bound_time(blocks: list[PlannedBlock], cfg, mean: float | None = None,
               caps: list[tuple[float, float]] | None = None) -> float:
    """TOPP-RA's time for one piece that starts and ends at rest (s). With ``mean`` the
    path acceleration is also held to |s̈| ≤ mean (m/s²): a law's mean acceleration over a
    speed change (its peak stays within the same limits as above). With ``caps``
    (`rule_caps`) the speed is also held to the planner's caps of blocks and nodes."""
    import toppra
    import toppra.algorithm as algo
    from toppra.constraint import DiscretizationType, LinearConstraint

    grid, tx, ty, nx, ny, cap = _path_data(blocks, cfg, caps)
    n = len(grid)
    axes = [cfg.axes[a].limits for a in "xy"]
    angles = np.arange(POLYGON) * 2.0 * math.pi / POLYGON
    rows = [[1, 0], [-1, 0], [0, 1], [0, -1]] + [[math.cos(a), math.sin(a)] for a in angles]
    limit_c = cfg.controller.limits.max_acceleration   # the circumscribed 16-gon: apothem A
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
            return (np.ones((n, 1)), np.zeros((n, 1)), np.zeros((n, 1)),
                    np.array([[1.0], [-1.0]]), np.array([mean, mean]), None, None)

    constraints = [Limits()] if mean is None else [Limits(), Mean()]
    inst = algo.TOPPRA(constraints, Path(), gridpoints=grid, solver_wrapper="seidel")
    inst.compute_parameterization(0.0, 0.0)
    sd = inst.problem_data.sd_vec
    if sd is None:
        raise RuntimeError(f"TOPP-RA found no parameterisation: {inst.problem_data}")
    ds = np.diff(grid)
    return float(np.sum(2.0 * ds / (sd[:-1] + sd[1:])))


K_A = {"trapezoid": 1.0, "parabolic": 1.5, "cosine": math.pi / 2, "cubic": 1.875}
"""Peak over mean acceleration of a speed change of each law with a fixed shape (φ'(u) at
its peak: 1, 6u(1 − u), (π/2)·sin πu, 30u²(1 − u)²); the jerk-limited law's depends on the
change (``yardstick_acceleration``)."""


def yardstick_acceleration(cfg, law: str, blocks: list[PlannedBlock]) -> float | None:
    """The path acceleration a law's yardstick allows on a piece (m/s²); None: no hold
    beyond the limits (the trapezoid)."""
    lim = cfg.controller.limits
    if law == "trapezoid":
        return None
    if law in K_A:
        return lim.max_acceleration / K_A[law]
    v = max(_feed_cap(cfg, b) for b in blocks)        # the S-curve from rest to the feed
    a, j = lim.max_acceleration, lim.max_jerk
    return a / (1.0 + a * a / (j * v))


def yardstick(cfg, law: str, parts: list, dwell: float, caps=None) -> float:
    """A law's yardstick for a whole plan (s): its pieces' bounds and the dwells; ``caps``
    (`rule_caps`, `jerk_caps`): also under those caps of blocks and nodes, by one planner's
    rules for every piece."""
    rules = planner_rules(cfg, law) if caps is not None else None
    return sum(bound_time(p, cfg, yardstick_acceleration(cfg, law, p),
                          caps(cfg, rules, p) if caps is not None else None)
               for p in parts) + dwell


# ----------------------------------------------------------------------------- limits
LIMIT_SLACK = 1.05
"""The sampled reference may show this much over an axis' limits (issue 30)."""


def sampled_limits(items: list, cfg) -> tuple[list[float], list[float]]:
    """Largest |Δ²p|/T² and |Δ³p|/T³ of the sampled position reference per axis over the
    axis' max_acceleration and max_jerk."""
    acc, jerk = cam.sampled_extremes(cam.sampled_reference(items, cfg.controller.period),
                                     cfg.controller.period)
    return ([float(acc[k] / cfg.axes[a].limits.max_acceleration) for k, a in enumerate("xy")],
            [float(jerk[k] / cfg.axes[a].limits.max_jerk) for k, a in enumerate("xy")])


# ----------------------------------------------------------------------------- figures
def program_figures(cfg, text: str, laws, check_limits: bool) -> dict:
    out: dict = {}
    parts = dwell = bound = None
    for law in laws:
        items, seconds = plan(cfg, text, law)
        if parts is None:            # the path is the same for every law: its blends
            parts, dwell = pieces(items)
            bound = yardstick(cfg, "trapezoid", parts, dwell)
            figures = path_figures(items)
        stick = bound if law == "trapezoid" else yardstick(cfg, law, parts, dwell)
        blocks = sum(isinstance(i, PlannedBlock) for i in items)
        la = cycle_time(items)
        capped = yardstick(cfg, law, parts, dwell, caps=rule_caps)
        aware = stick if law == "trapezoid" else yardstick(
            cfg, law, parts, dwell, caps=jerk_caps)
        row = {"lookahead_s": round(la, 3), "yardstick_s": round(stick, 3),
               "ratio": round(la / stick, 4), "ratio_to_bound": round(la / bound, 4),
               "ratio_to_capped": round(la / capped, 4),
               "ratio_to_jerk_aware": round(la / aware, 4), "blocks_per_s": round(blocks / seconds)}
        if check_limits:
            acc, jerk = sampled_limits(items, cfg)
            row["axis_acceleration"] = [round(r, 3) for r in acc]
            row["axis_jerk"] = [round(r, 3) for r in jerk]
            row["limits_ok"] = max(acc) <= LIMIT_SLACK and (
                law != "jerk-limited" or max(jerk) <= LIMIT_SLACK)
        out[law] = row
    return {**figures, "bound_s": round(bound, 3), "laws": out}


def twin_figures(machine: str, text: str, laws, overrides: dict) -> dict:
    """Per law, the twin's run of a program: cycle time (s), and the largest contour error
    of the table's true path and of the encoder's (µm)."""
    from twin.session.run import RunSpec

    out = {}
    for law in laws:
        s = run_items(RunSpec(machine=machine, profile=law, planner="lookahead",
                              overrides=overrides, max_time=4000.0), gcode_program(text)).summary
        out[law] = {"status": s["status"], "cycle_time_s": round(s["cycle_time_s"], 3),
                    "table_max_contour_error_um": round(s["table_max_contour_error_um"], 1),
                    "encoder_max_contour_error_um": round(s["max_contour_error_um"], 1)}
    return out


def programs(args) -> dict[str, str]:
    """The bench's programs by name: the fixed ones and the random instances."""
    out = {
        "chorded_nest": cam.chorded_nest(*((2, 2) if args.quick else (6, 4))),
        "lettering": cam.lettering("XY 26" if args.quick else "XY-twin 2026"),
        "pocket": cam.pocket(),
    }
    rng = np.random.default_rng(args.seed)
    for name, make in CLASSES.items():
        for k in range(args.instances):
            out[f"{name}_{k}"] = make(rng)[0]
    return out


_STREAM = """
import sys, time
from twin.config import load_machine
from twin.config.overrides import parse_sets
from twin.controller.gcode import read_file
from twin.controller.planner import Planner
cfg = load_machine(sys.argv[2])
planner = Planner.from_settings(cfg.controller, cfg.axes, law=sys.argv[3], work_zone=None)
t0 = time.process_time()
count = sum(1 for _ in planner.plan(read_file(sys.argv[1], start=(0.01, 0.01))))
seconds = time.process_time() - t0
with open("/proc/self/status") as status:
    hwm = next(line.split()[1] for line in status if line.startswith("VmHWM:"))
print(count, seconds, hwm)
"""


REPEATS = 3
"""In-memory runs per law; the fastest counts (the machine is shared: a slow run is the
other processes', not the planner's)."""


def _cpu_seconds(run, repeats: int = REPEATS) -> float:
    """The least process CPU time of ``repeats`` calls of ``run`` (s)."""
    best = math.inf
    for _ in range(repeats):
        t0 = time.process_time()
        run()
        best = min(best, time.process_time() - t0)
    return best


def throughput(cfg, machine: str, laws, blocks: int) -> dict:
    """Per law, lines planned per second of process CPU time (the machine is shared: wall
    time counts the other processes' turns too): in memory (the best of ``REPEATS`` runs),
    in memory with every block's profile made, and streamed from a file through the G-code
    reader (and its peak RSS); and the path stage alone (fairing and blending the program's
    lines, law-independent) with its share of the parabolic law's in-memory time."""
    text = cam.chords(blocks)
    items = list(parse(text, start=(0.01, 0.01)))
    lines = sum(type(i).__name__ == "Move" for i in items)
    out = {"program_blocks": lines, "clock": "process CPU time"}
    ctl = cfg.controller
    chords = [(b.segment, b.feed, b.line) if type(b) is MotionBlock else b
              for b in segments_from_program(items)]
    path = _cpu_seconds(lambda: deque(
        Blender(ctl.corner_blend * ctl.contour_tolerance).blend(chords), 0))
    out["path_stage_lines_per_s"] = round(lines / path)
    with tempfile.TemporaryDirectory() as tmp:
        file = Path(tmp) / "chords.ngc"
        file.write_text(text)
        for law in laws:
            mem = _cpu_seconds(lambda law=law: deque(Planner.from_settings(
                cfg.controller, cfg.axes, law=law, work_zone=None).plan(items), 0))
            planned = sum(1 for _ in Planner.from_settings(
                cfg.controller, cfg.axes, law=law, work_zone=None).plan(items))
            # the same, with every block's speed profile made as the interpolator makes it
            # when it reaches the block (plan_move, or the block's part of its run's move)
            planner = Planner.from_settings(cfg.controller, cfg.axes, law=law, work_zone=None)
            t0 = time.process_time()
            for block in planner.plan(items):
                if type(block) is PlannedBlock:
                    block.profile()
            profiled = time.process_time() - t0
            done = subprocess.run([sys.executable, "-c", _STREAM, str(file), machine, law],
                                  capture_output=True, text=True, check=True)
            _, seconds, hwm = done.stdout.split()
            out[law] = {"in_memory_blocks_per_s": round(lines / mem),
                        "in_memory_with_profiles_blocks_per_s": round(lines / profiled),
                        "planned_items": planned,
                        "streamed_blocks_per_s": round(lines / float(seconds)),
                        "streamed_peak_rss_mb": round(int(hwm) / 1024, 1)}
            if law == "parabolic":
                out["path_stage_share_of_parabolic"] = round(path / mem, 3)
    return out


def markdown(result: dict) -> str:
    """The summary tables of a result (markdown)."""
    lines: list[str] = []
    if result["programs"]:
        laws = list(next(iter(result["programs"].values()))["laws"])
        lines += ["Ratio to the law's yardstick (a, j: the sampled reference's largest "
                  "acceleration and jerk over the axis limits; ✗: beyond 1.05)", "",
                  "| program | blends p10/p50/p90 mm | " + " | ".join(laws) + " |",
                  "|---|---|" + "---|" * len(laws)]
        for name, p in result["programs"].items():
            radii = "/".join(f"{r:g}" for r in p.get("blend_radius_p10_p50_p90_mm", []))
            cells = []
            for law in laws:
                row = p["laws"][law]
                cell = f"{row['ratio']:.3f}"
                if "axis_acceleration" in row:
                    cell += (f" (a {max(row['axis_acceleration']):.2f}, "
                             f"j {max(row['axis_jerk']):.2f})")
                    if not row["limits_ok"]:
                        cell += " ✗"
                cells.append(cell)
            lines.append(f"| {name} | {radii} | " + " | ".join(cells) + " |")
        lines += ["", "Ratio to the jerk-aware yardstick (the laws that limit jerk; the caps "
                  "v³κ² ≤ J and v²·|Δκ| ≤ J·T added) and to the planner's own caps", "",
                  "| program | " + " | ".join(laws) + " |", "|---|" + "---|" * len(laws)]
        for name, p in result["programs"].items():
            lines.append(f"| {name} | " + " | ".join(
                f"{p['laws'][law]['ratio_to_jerk_aware']:.3f} / "
                f"{p['laws'][law]['ratio_to_capped']:.3f}" for law in laws) + " |")
    twin = {name: p["twin"] for name, p in result["programs"].items() if "twin" in p}
    if twin:
        laws = list(next(iter(twin.values())))
        lines += ["", "On the twin: cycle time (s), the table's true max contour error and the "
                  "encoder's (µm)" + ("; " + ", ".join(f"{k} = {v}" for k, v in
                                        result["overrides"].items())
                                        if result["overrides"] else ""),
                  "", "| program | " + " | ".join(laws) + " |", "|---|" + "---|" * len(laws)]
        for name, per in twin.items():
            lines.append(f"| {name} | " + " | ".join(
                f"{r['cycle_time_s']:.2f} s, {r['table_max_contour_error_um']:.1f} "
                f"({r['encoder_max_contour_error_um']:.1f})" for r in per.values()) + " |")
    chords = result["chord_independence"]
    if chords:
        radii = list(next(iter(chords.values()))["radii"])
        lines += ["", "| law | worst spread | " + " | ".join(radii) + " |",
                  "|---|---|" + "---|" * len(radii)]
        for law, c in chords.items():
            lines.append(f"| {law} | {100 * c['worst_spread']:.1f} % | " + " | ".join(
                f"{100 * x['spread']:.1f} %" for x in c["radii"].values()) + " |")
    if result["throughput"]:
        t = result["throughput"]
        lines += ["", f"Path stage alone (fairing, blending): {t['path_stage_lines_per_s']} "
                  "lines/s" + (f", {100 * t['path_stage_share_of_parabolic']:.0f} % of the "
                               "parabolic plan" if "path_stage_share_of_parabolic" in t
                               else ""), "",
                  "| law | in memory blocks/s | with profiles | streamed lines/s | "
                  "RSS MB |", "|---|---|---|---|---|"]
    for law, t in result["throughput"].items():
        if isinstance(t, dict):
            lines.append(f"| {law} | {t['in_memory_blocks_per_s']} | "
                         f"{t['in_memory_with_profiles_blocks_per_s']} | "
                         f"{t['streamed_blocks_per_s']} | {t['streamed_peak_rss_mb']} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--machine", default="laser_belt")
    parser.add_argument("--quick", action="store_true", help="smaller programs, two laws")
    parser.add_argument("--seed", type=int, default=30, help="seed of the random programs")
    parser.add_argument("--instances", type=int, default=None,
                        help="random programs per class (default 3, --quick 1)")
    parser.add_argument("--laws", default=None, help="comma-separated laws (default all)")
    parser.add_argument("--no-limits", action="store_true",
                        help="skip interpolating the references (the slow part)")
    parser.add_argument("--markdown", action="store_true", help="tables on stderr")
    parser.add_argument("--twin", action="store_true",
                        help="also run each program on the twin with each law")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override of the machine for the twin runs (repeatable)")
    parser.add_argument("--skip", default="", help="comma-separated parts to skip: "
                        "programs, chords, throughput")
    args = parser.parse_args()
    if args.instances is None:
        args.instances = 1 if args.quick else 3
    cfg = load_machine(args.machine)
    laws = tuple(args.laws.split(",")) if args.laws else (
        ("trapezoid", "parabolic") if args.quick else LAWS)
    skip = set(filter(None, args.skip.split(",")))
    overrides = parse_sets(args.set)          # as `twin run --set` reads them
    t0 = time.perf_counter()
    result = {"machine": args.machine, "grid_mm": GRID * 1e3, "seed": args.seed,
              "overrides": overrides,
              "programs": {} if "programs" in skip else {
                  name: {**program_figures(cfg, text, laws, not args.no_limits),
                         **({"twin": twin_figures(args.machine, text, laws, overrides)}
                            if args.twin else {})}
                  for name, text in programs(args).items()},
              "chord_independence": {} if "chords" in skip else chord_independence(
                  cfg, laws, RADII[:3] if args.quick else RADII),
              "throughput": {} if "throughput" in skip else throughput(
                  cfg, args.machine, laws, 10_000 if args.quick else 100_000),
              "seconds": None, "cpus": os.cpu_count(),
              "load_average_1min": round(os.getloadavg()[0], 2),
              "python": platform.python_version()}
    result["seconds"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(result))
    if args.markdown:
        print(markdown(result), file=sys.stderr)


if __name__ == "__main__":
    main()
