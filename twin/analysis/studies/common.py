"""What every reproduction study shares: running a program built in memory on the twin
(optionally keeping the twin's drive-rate samples), and the small numeric helpers of
the reports.

A study builds its program as planner items (``MotionBlock``s of lines and splines) from the
table's start position, so ``run_items`` wires it with ``twin.session.setup.wire``, the
wiring of every run: the same plant, driver, controller and metrics as ``twin run``,
nothing re-implemented.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from twin.config import MachineConfig
from twin.session.run import RunResult, RunSpec, run
from twin.session.setup import RECORD_CHUNK, wire

__all__ = ["ProgramBuilder", "fit_line", "gcode_program", "percent", "run_items"]

ProgramBuilder = Callable[[MachineConfig, np.ndarray], list[Any]]
"""``build(cfg, start) -> items``: a program (planner items) from the table position (m)."""


def gcode_program(gcode: str) -> ProgramBuilder:
    """The ``build`` of a G-code text: its items read from the table's start position."""
    from twin.controller.gcode import parse

    def build(cfg: MachineConfig, start: np.ndarray) -> list[Any]:
        return list(parse(gcode, start=tuple(start.tolist())))

    return build


def run_items(spec: RunSpec, build: ProgramBuilder, *, keep_fine: bool = False,
              out_dir: str | None = None, **controller_options: Any) -> RunResult:
    """Run an in-memory program on the twin through the full controller.

    Parameters
    ----------
    spec : RunSpec
        Machine, law, planner, DCU order and overrides (its program fields are ignored).
    build : callable(cfg, start) -> list
        The program, from the machine configuration and the table's start position (m).
    keep_fine : bool
        Keep the twin's drive-rate samples in ``RunResult.fine``.
    out_dir : str, optional
        Where ``run`` writes its summary JSON; default a temporary directory.
    **controller_options
        Passed to ``Controller.from_machine`` (e.g. ``corner_model``); the axis models and
        axes default to the controller's model of the machine (``spec.controller_model``,
        or the machine itself: ``wire``).

    Returns
    -------
    RunResult
    """
    spec = dataclasses.replace(spec, program=None, builtin="none")
    cfg = spec.machine_config()
    p = wire(cfg, lambda start: build(cfg, start), belief=spec.belief(cfg), start=spec.start,
             drives_off=spec.drives_off, mode=spec.mode, record_capacity=RECORD_CHUNK,
             **controller_options)
    with tempfile.TemporaryDirectory(prefix="xy-twin-study-") as tmp:
        return run(spec, out_dir=out_dir or tmp, rerun="none", prepared=p,
                   keep_fine=keep_fine)


def percent(value: float, reference: float) -> float:
    """``100·value/reference`` (%); NaN when the reference is 0."""
    return 100.0 * value / reference if reference else math.nan


def fit_line(x: Sequence[float], y: Sequence[float]) -> dict[str, float]:
    """Least-squares line ``y = slope·x + intercept`` and its coefficient of determination.

    Returns
    -------
    dict
        ``slope``, ``intercept``, ``r2`` (1 for a perfect fit) and ``intercept_share``:
        ``|intercept| / max|y|`` (how far the line is from proportional).
    """
    xs, ys = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    slope, intercept = np.polyfit(xs, ys, 1)
    resid = ys - (slope * xs + intercept)
    total = float(np.sum((ys - ys.mean()) ** 2))
    r2 = 1.0 - float(np.sum(resid**2)) / total if total > 0 else 1.0
    return {"slope": float(slope), "intercept": float(intercept), "r2": r2,
            "intercept_share": abs(float(intercept)) / float(np.max(np.abs(ys)))}
