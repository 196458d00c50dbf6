"""What every reproduction study shares: running a program built in memory on the twin
(optionally with the deflection probe of ``twin.compare``), and the small numeric helpers of
the reports.

A study builds its program as planner items (``MotionBlock``s of lines and splines) from the
table's start position, so ``run_items`` wires a run the way ``twin.run.prepare`` does and
swaps in a controller for those items: the same plant, driver, controller and metrics as
``twin run``, nothing re-implemented.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from twin.compare import DeflectionProbe
from twin.config import MachineConfig
from twin.controller.controller import Controller
from twin.controller.library import program_path
from twin.run import RunResult, RunSpec, axis_models, prepare, run

__all__ = ["ProgramBuilder", "fit_line", "percent", "run_items"]

ProgramBuilder = Callable[[MachineConfig, np.ndarray], list[Any]]
"""``build(cfg, start) -> items``: a program (planner items) from the table position (m)."""


def run_items(spec: RunSpec, build: ProgramBuilder, *, probe: bool = False,
              out_dir: str | None = None, **controller_options: Any
              ) -> tuple[RunResult, DeflectionProbe | None]:
    """Run an in-memory program on the twin through the full controller.

    Parameters
    ----------
    spec : RunSpec
        Machine, law, planner, DCU order and overrides (its program fields are ignored).
    build : callable(cfg, start) -> list
        The program, from the machine configuration and the table's start position (m).
    probe : bool
        Sample the screw deflection every drive interval (``DeflectionProbe``).
    out_dir : str, optional
        Where ``run`` writes its summary JSON; default a temporary directory.
    **controller_options
        Passed to ``Controller.from_machine`` (e.g. ``corner_model``); ``axis_models``
        defaults to the twin's own linear models (``twin.run.axis_models``).

    Returns
    -------
    (RunResult, DeflectionProbe or None)
    """
    spec = dataclasses.replace(spec, program=None, builtin="none")
    p = prepare(spec)
    start = p.plant.truth().table_position
    items = build(p.cfg, start)
    controller_options.setdefault("axis_models", axis_models(p.cfg))
    controller = Controller.from_machine(p.cfg, items, mode=spec.mode, start=start,
                                         **controller_options)
    fine = DeflectionProbe(p.driver) if probe else None
    p = dataclasses.replace(p, items=items, path=program_path(items), controller=controller,
                            driver=fine or p.driver)
    with tempfile.TemporaryDirectory(prefix="xy-twin-study-") as tmp:
        result = run(spec, out_dir=out_dir or tmp, rerun="none", prepared=p)
    return result, fine


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
