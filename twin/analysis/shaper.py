"""Choosing an input shaper (``twin shaper``): Klipper's ``SHAPER_CALIBRATE`` table with
closed-loop figures instead of its abstract smoothing score.

For each shaper (``twin.controller.shaping.SHAPERS``, and "none" as the reference), each axis
designed at its own mode (frequency f, damping ζ: the machine file's model, or a
measurement):

remaining vibration
    Singer & Seering's residual vibration (% of an unshaped step's) at f, the worst over
    ``f·(1 ± frequency_spread)`` (±20 %: the mode is not where it was measured), and the
    worst over ``ζ·(1 ± damping_spread)`` and that band together; the worse axis.
delay
    How much later a shaped move ends (``InputShaper.duration``), and the lag along a path
    at constant speed (``InputShaper.lag``), ms.
contour error
    Closed-loop twin runs of a standard test path (``test_program``: a square's four 90°
    corners and a circle at the machine's feed) through the full controller: the largest
    contour error of the table's true path on the corners and on the circle (µm), and what
    the shaper adds to the unshaped run's.
highest acceleration
    The largest contour acceleration (``controller.limits.max_acceleration``) at which the
    test path's corners stay within the contour tolerance (or, where the machine alone uses
    it up, at most a quarter of it above the unshaped run at that acceleration), by
    bisection between 10 % and 100 % of the machine's (None: not even at 10 %; the
    machine's when it holds there already). The circle at feed does not depend on it: its
    error is reported, not searched.

``recommend`` picks, among the shapers whose worst remaining vibration is at most
``ROBUST`` (10 %), the one with the highest such acceleration, then the least contour
error added on the corners; ``write_override`` writes it as a machine override file
(``twin run --set-file``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.analysis.compare import law_figures, true_contour_error
from twin.analysis.studies.common import gcode_program, run_items
from twin.config import AXES, MachineConfig
from twin.controller.shaped_corner import SHAPER_SHARE
from twin.controller.shaping import SHAPERS, believed_mode, design, residual_vibration
from twin.session.run import RunSpec

__all__ = ["ROBUST", "Mode", "ShaperRow", "evaluate", "model_modes", "recommend",
           "test_program", "write_override"]

ROBUST = 0.10
"""Largest worst-case remaining vibration (1) a recommended shaper may leave."""

CIRCLE_LINE = 7
"""Source line of the test program's circle (``test_program``)."""

CORNER_LINES = (3, 4, 5, 6)
"""Source lines of the test program's square (the rapid into the work zone is line 2)."""


@dataclass(frozen=True)
class Mode:
    """One axis' mode to shape: ``frequency`` (Hz), ``damping`` (1) and where it came from."""

    axis: str
    frequency: float
    damping: float
    source: str


def model_modes(cfg: MachineConfig) -> list[Mode]:
    """Each axis' first elastic mode as the machine file's model has it
    (``shaping.believed_mode``)."""
    return [Mode(a, *believed_mode(cfg.axes, a), "machine file (the model's analytic mode)")
            for a in AXES]


def test_program(feed: float, side: float, radius: float) -> str:
    """The standard test path (relative moves from where the table stands): a rapid of
    ``radius`` + 10 mm on both axes into the work zone, a square of ``side`` (m) with four
    90° corners, then a full circle of ``radius`` (m) entered tangentially, at ``feed``
    (m/s). The corners are lines ``CORNER_LINES``, the circle line ``CIRCLE_LINE``."""
    f, s, r = feed * 60e3, side * 1e3, radius * 1e3
    return (f"G91 G21\nG0 X{r + 10:.4f} Y{r + 10:.4f}\nG1 X{s:.4f} F{f:.1f}\nG1 Y{s:.4f}\n"
            f"G1 X{-s:.4f}\nG1 Y{-s:.4f}\nG3 X0 Y0 I{r:.4f} J0\n")


def vibration(name: str, mode: Mode, frequency_spread: float, damping_spread: float
              ) -> dict[str, float]:
    """Remaining vibration (1) of shaper ``name`` designed for ``mode``: at the mode, the
    worst over the frequency band, over the damping band, and over both."""
    if name == "none":
        return {"at_mode": 1.0, "worst_frequency": 1.0, "worst_damping": 1.0, "worst": 1.0}
    s = design(name, mode.frequency, mode.damping)
    f = mode.frequency * np.linspace(1 - frequency_spread, 1 + frequency_spread, 81)
    z = np.clip(mode.damping * np.linspace(1 - damping_spread, 1 + damping_spread, 21), 0.0,
                0.95)
    grid = residual_vibration(s.amplitudes, s.times, f[:, None], z[None, :])
    return {"at_mode": float(s.residual(mode.frequency)),
            "worst_frequency": float(np.max(s.residual(f))),
            "worst_damping": float(np.max(s.residual(mode.frequency, z))),
            "worst": float(np.max(grid))}


@dataclass
class ShaperRow:
    """One line of the table (SI; the CLI shows µm, mm/s², ms, %)."""

    name: str
    vibration: dict[str, float]
    duration: float
    lag: float
    corner_error: float = math.nan
    circle_error: float = math.nan
    added_corner_error: float = math.nan
    added_circle_error: float = math.nan
    residual_vibration: float = math.nan
    cycle_time: float = math.nan
    max_acceleration: float | None = None
    runs: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, in the units people read (keys name them)."""
        um = 1e6
        return {"shaper": self.name,
                "vibration_percent": {k: 100 * v for k, v in self.vibration.items()},
                "delay_ms": self.duration * 1e3, "lag_ms": self.lag * 1e3,
                "corner_contour_error_um": self.corner_error * um,
                "circle_contour_error_um": self.circle_error * um,
                "added_corner_error_um": self.added_corner_error * um,
                "added_circle_error_um": self.added_circle_error * um,
                "residual_vibration_um": self.residual_vibration * um,
                "cycle_time_s": self.cycle_time,
                "max_acceleration_mm_per_s2": None if self.max_acceleration is None
                else self.max_acceleration * 1e3}


def _overrides(name: str, modes: Sequence[Mode], acceleration: float) -> dict[str, Any]:
    out: dict[str, Any] = {"controller.limits.max_acceleration": acceleration}
    for m in modes:
        out[f"controller.shaper.{m.axis}.type"] = name
        if name != "none":
            out[f"controller.shaper.{m.axis}.frequency"] = m.frequency
            out[f"controller.shaper.{m.axis}.damping"] = m.damping
    return out


def _run(spec: RunSpec, gcode: str, name: str, modes: Sequence[Mode], acceleration: float
         ) -> dict[str, float]:
    """One closed-loop run of the test path: contour errors of corners and circle (m),
    residual vibration (m), cycle time (s)."""
    overrides = {**dict(spec.overrides), **_overrides(name, modes, acceleration)}
    result = run_items(RunSpec(machine=spec.machine, controller_model=spec.controller_model,
                               profile="trapezoid", overrides=overrides, max_time=600.0),
                       gcode_program(gcode), keep_fine=True)
    contour = true_contour_error(result)
    circle = result.record["line"] == CIRCLE_LINE
    corners = np.isin(result.record["line"], CORNER_LINES)
    figures = law_figures(result, contour)
    return {"acceleration": acceleration, "status": result.summary["status"],
            "corner_error": float(contour[corners].max()) if corners.any() else 0.0,
            "circle_error": float(contour[circle].max()) if circle.any() else 0.0,
            "residual_vibration": figures["residual_vibration_um"] * 1e-6,
            "cycle_time": float(result.summary["cycle_time_s"])}


class _Judge:
    """Whether a shaped run keeps the contour: its corners within the tolerance, or adding
    at most the shapers' share of it (``shaped_corner.SHAPER_SHARE``) to the unshaped
    run's error at the same acceleration, where the machine alone uses the tolerance up
    (on laser_belt the belt holds the slides' friction, 5 N / 10⁵ N/m = 50 µm, where the
    motor encoder cannot see it). The circle's error does not depend on the acceleration
    limit: it is reported, not judged. Unshaped runs are kept per acceleration."""

    def __init__(self, spec: RunSpec, gcode: str, modes: Sequence[Mode], tolerance: float):
        self.spec, self.gcode, self.modes, self.tolerance = spec, gcode, modes, tolerance
        self.unshaped: dict[float, dict[str, Any]] = {}

    def run(self, name: str, acceleration: float) -> dict[str, Any]:
        if name == "none" and acceleration in self.unshaped:
            return self.unshaped[acceleration]
        r = _run(self.spec, self.gcode, name, self.modes, acceleration)
        if name == "none":
            self.unshaped[acceleration] = r
        return r

    def bound(self, acceleration: float) -> float:
        """The corner error a shaped run may have at ``acceleration`` (m)."""
        return max(self.tolerance, self.run("none", acceleration)["corner_error"]
                   + SHAPER_SHARE * self.tolerance)

    def holds(self, run: dict[str, Any]) -> bool:
        return run["status"] == "FINISHED" and run["corner_error"] <= self.bound(
            run["acceleration"])


def evaluate(spec: RunSpec, modes: Sequence[Mode], shapers: Sequence[str] = SHAPERS, *,
             frequency_spread: float = 0.2, damping_spread: float = 0.5,
             side: float = 0.02, radius: float = 0.025, steps: int = 5,
             progress: Callable[[str], None] | None = None) -> list[ShaperRow]:
    """The table: "none" and each of ``shapers`` (see the module docstring).

    Parameters
    ----------
    spec : RunSpec
        The machine (and its controller model, overrides) the runs use; law trapezoid.
    modes : sequence of Mode
        The mode of each axis to shape.
    shapers : sequence of str
        Names from ``SHAPERS``.
    frequency_spread, damping_spread : float
        Relative uncertainty of the modes' frequency and damping (1).
    side, radius : float
        The test path's square side and circle radius (m).
    steps : int
        Bisection steps of the highest acceleration (0: only the machine's is tried).
    """
    cfg = spec.machine_config()
    limits = cfg.controller.limits
    tolerance = cfg.controller.contour_tolerance
    gcode = test_program(limits.max_velocity, side, radius)
    a_max = limits.max_acceleration
    rows = []
    base: dict[str, float] | None = None
    judge = _Judge(spec, gcode, modes, tolerance)
    for name in ("none", *shapers):
        if progress is not None:
            progress(name)
        worst = {k: max(vibration(name, m, frequency_spread, damping_spread)[k]
                        for m in modes) for k in ("at_mode", "worst_frequency",
                                                  "worst_damping", "worst")}
        designed = [design(name, m.frequency, m.damping) for m in modes] \
            if name != "none" else []
        row = ShaperRow(name, worst, max((d.duration for d in designed), default=0.0),
                        max((d.lag for d in designed), default=0.0))
        first = judge.run(name, a_max)
        row.runs.append(first)
        base = first if name == "none" else base
        row.corner_error, row.circle_error = first["corner_error"], first["circle_error"]
        row.residual_vibration, row.cycle_time = first["residual_vibration"], first["cycle_time"]
        row.added_corner_error = first["corner_error"] - base["corner_error"]
        row.added_circle_error = first["circle_error"] - base["circle_error"]
        row.max_acceleration = _highest(judge, name, a_max, steps, first, row.runs)
        rows.append(row)
    return rows


def _highest(judge: _Judge, name: str, a_max: float, steps: int, first: dict[str, Any],
             runs: list[dict[str, Any]]) -> float | None:
    """Bisection (geometric) of the highest acceleration whose run ``judge`` accepts."""
    if judge.holds(first):
        return a_max
    lo, hi = 0.1 * a_max, a_max
    low = judge.run(name, lo)
    runs.append(low)
    if not judge.holds(low):
        return None
    for _ in range(steps):
        mid = math.sqrt(lo * hi)
        r = judge.run(name, mid)
        runs.append(r)
        lo, hi = (mid, hi) if judge.holds(r) else (lo, mid)
    return lo


def recommend(rows: Sequence[ShaperRow]) -> ShaperRow:
    """The shaper to use: among the shapers leaving at most ``ROBUST`` worst-case vibration
    (if none does, all of them), the highest acceleration within the contour tolerance
    (None counts as 0), then the least contour error added on the corners."""
    shaped = [r for r in rows if r.name != "none"]
    robust = [r for r in shaped if r.vibration["worst"] <= ROBUST] or shaped
    return max(robust, key=lambda r: (r.max_acceleration or 0.0, -r.added_corner_error))


def write_override(path: Path, row: ShaperRow, modes: Sequence[Mode], cfg: MachineConfig,
                   header: Sequence[str] = ()) -> Path:
    """The recommended shaper as a machine override file (``twin run --set-file``): each
    axis' type, frequency and damping; the highest acceleration keeping the contour
    tolerance on the test path as a commented suggestion (it costs cycle time)."""
    lines = [f"# {h}" for h in header]
    for m in modes:
        lines += ["", f"[controller.shaper.{m.axis}]", f'type = "{row.name}"',
                  f"frequency = {m.frequency:.6g}    # Hz, {m.source}",
                  f"damping = {m.damping:.6g}"]
    a = row.max_acceleration
    lines += ["", "[controller.limits]",
              f"# max_acceleration = {a:.4g}    # m/s²: the highest keeping the contour "
              f"tolerance ({cfg.controller.contour_tolerance * 1e6:g} µm) on the test path; "
              f"the machine's is {cfg.controller.limits.max_acceleration:g}"
              if a is not None else "# no acceleration keeps the contour tolerance on the "
              "test path with this shaper", ""]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text("\n".join(lines), encoding="utf-8")
    tmp.replace(path)
    return path
