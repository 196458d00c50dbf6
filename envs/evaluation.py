"""One tuning run — a program on the twin with given gains — and the cost of its result.

``tuning_run`` wires a fresh plant and controller (no telemetry, no files), ticks the
program to its end and condenses the record into the eight ``METRICS`` (SI). It never
raises for a bad setting: a diverged simulation (``SimulationError``, non-finite state) or a
controller trip comes back as a failed ``RunOutcome``.

``cost_terms`` turns an outcome into the weighted, dimensionless terms that tuning
minimises (and the gymnasium env returns as minus its reward): each metric divided by its
``scale`` — the analytic baseline's value on the same machine and program, floored so that a
zero baseline (no overshoot) does not divide by zero — times its weight. A failed run
costs ``penalty`` and nothing else.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from envs.programs import tuning_program
from envs.space import TuningSettings
from twin.config import MachineConfig
from twin.controller.controller import ControllerStatus
from twin.controller.linear import LinearAxisModel
from twin.controller.summary import summarize
from twin.errors import ConfigError, SimulationError
from twin.session.loop import TickLoop
from twin.session.setup import wire

__all__ = ["METRICS", "METRIC_UNITS", "RunOutcome", "Weights", "cost_terms",
           "cycle_time_limit", "measure", "metric_scales", "reported", "tuning_run"]

METRICS = ("max_coordinate_error", "rms_coordinate_error", "max_contour_error",
           "rms_contour_error", "overshoot", "settling_travel", "cycle_time",
           "saturation_time")
"""What a tuning run measures (m, m, m, m, m, m, s, s); coordinate errors are the larger
of the two axes."""

METRIC_UNITS = {m: ("s", 1.0) if "time" in m else ("µm", 1e6) for m in METRICS}
"""The unit each metric is reported in, and its factor from SI."""

_FLOORS = {"cycle_time": 1e-3, "saturation_time": None}
_LENGTH_FLOOR = 1e-6  # m: below a micrometre a baseline error is noise, not a scale
_SATURATION_FRACTION = 0.01  # saturation scale: 1 % of the baseline cycle time


@dataclass(frozen=True)
class RunOutcome:
    """The result of one tuning run.

    Attributes
    ----------
    metrics : dict of str to float
        ``METRICS`` (SI); NaN when the run failed.
    status : str
        The controller's final status name, or ``"DIVERGED"``.
    diverged : bool
        The simulation diverged (``SimulationError``, non-finite state or reference).
    tripped : bool
        The controller stopped on a fault (following error, limit switch, drive fault) or
        the run did not finish within its time limit.
    sim_time : float
        Simulated time (s).
    wall_time : float
        Wall-clock time of the run (s).
    message : str
        What went wrong, empty for a good run.
    trace : dict of str to ndarray, optional
        With ``tuning_run(..., trace=True)`` and a finished run: ``t`` (s), ``error``
        (N, 2), the measured position minus the reference (m), and ``speed`` (N,), the
        reference's path speed (m/s). None otherwise.
    """

    metrics: dict[str, float]
    status: str
    diverged: bool = False
    tripped: bool = False
    sim_time: float = 0.0
    wall_time: float = 0.0
    message: str = ""
    trace: dict[str, np.ndarray] | None = None

    @property
    def failed(self) -> bool:
        """True when the run diverged or tripped."""
        return self.diverged or self.tripped

    def vector(self) -> np.ndarray:
        """``metrics`` in ``METRICS`` order, shape (8,)."""
        return np.array([self.metrics[m] for m in METRICS])


@dataclass(frozen=True)
class Weights:
    """Weight of each cost term (1, ≥ 0); the default stresses the max coordinate error."""

    max_coordinate_error: float = 1.0
    rms_coordinate_error: float = 0.5
    max_contour_error: float = 0.5
    rms_contour_error: float = 0.25
    overshoot: float = 0.5
    settling_travel: float = 0.25
    cycle_time: float = 1.0
    saturation_time: float = 0.5

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0.0):
                raise ConfigError(f"weights.{f.name}", f"must be a finite number >= 0, "
                                  f"got {v!r}")

    @classmethod
    def from_mapping(cls, values: Mapping[str, float] | None) -> Weights:
        """Weights from a (partial) mapping; unknown names raise ``ConfigError``."""
        values = dict(values or {})
        unknown = set(values) - set(METRICS)
        if unknown:
            raise ConfigError(f"weights.{sorted(unknown)[0]}", "unknown term; valid: "
                              + ", ".join(METRICS))
        return cls(**values)


def _failed(status: str, *, diverged: bool, message: str, sim_time: float,
            wall: float) -> RunOutcome:
    return RunOutcome({m: math.nan for m in METRICS}, status, diverged=diverged,
                      tripped=not diverged, sim_time=sim_time, wall_time=wall,
                      message=message)


_DIVERGED = (ControllerStatus.INVALID_INPUT,)


def tuning_run(cfg: MachineConfig, settings: TuningSettings, *,
               models: Sequence[LinearAxisModel], program: str = "compact",
               max_time: float = 600.0, model_axes: Mapping[str, Any] | None = None,
               trace: bool = False) -> RunOutcome:
    """Run ``program`` on machine ``cfg`` with ``settings`` and measure it.

    Parameters
    ----------
    cfg : MachineConfig
        The machine (its jerk limit, and its shapers' frequency and damping when tuned,
        replaced by ``settings``: ``TuningSettings.overrides``).
    settings : TuningSettings
        Gains and jerk limit.
    models : sequence of 2 LinearAxisModel
        The axes' linear models (for the corner model's servo lag).
    program : str
        Tuning program name (``envs.programs.PROGRAMS``).
    max_time : float
        Simulated time after which an unfinished run counts as tripped (s).
    model_axes : mapping, optional
        The axes the controller believes the machine has (its corner model); default the
        machine's.
    trace : bool
        Keep the run's coordinate errors and path speed against time
        (``RunOutcome.trace``), for a report that draws two runs over each other.

    Returns
    -------
    RunOutcome
    """
    wall = time.perf_counter()
    cfg = cfg.with_overrides(settings.overrides())
    p = wire(cfg, lambda start: tuning_program(program, cfg, start), gains=settings.gains,
             axis_models=list(models), model_axes=model_axes)
    ctrl = p.controller
    loop = TickLoop(ctrl, p.driver)
    try:
        loop.run(round(max_time / cfg.controller.period))
    except (SimulationError, FloatingPointError) as exc:
        return _failed("DIVERGED", diverged=True, message=str(exc),
                       sim_time=loop.ticks * cfg.controller.period,
                       wall=time.perf_counter() - wall)
    sim_time = loop.ticks * cfg.controller.period
    status = ctrl.status
    if status != ControllerStatus.FINISHED:
        why = "did not finish within max_time" if not ctrl.done else f"stopped: {status.name}"
        return _failed("DIVERGED" if status in _DIVERGED else status.name,
                       diverged=status in _DIVERGED, message=why, sim_time=sim_time,
                       wall=time.perf_counter() - wall)
    rec = ctrl.record.as_arrays()
    metrics = measure(rec, p.path, settings)
    bad = [m for m, v in metrics.items() if not math.isfinite(v)]
    if bad:
        return _failed("DIVERGED", diverged=True, message=f"{bad[0]} is not finite",
                       sim_time=sim_time, wall=time.perf_counter() - wall)
    kept = None if not trace else {
        "t": np.array(rec["t"], dtype=float),
        "error": np.asarray(rec["position"], dtype=float) - rec["ref_position"],
        "speed": np.hypot(*np.asarray(rec["ref_velocity"], dtype=float).T)}
    return RunOutcome(metrics, status.name, sim_time=sim_time,
                      wall_time=time.perf_counter() - wall, trace=kept)


def measure(rec: Mapping[str, np.ndarray], path: list, settings: TuningSettings
            ) -> dict[str, float]:
    """``METRICS`` of a controller record (SI).

    The velocity error is not among them, so the table velocity passed to ``summarize`` is
    the derivative of the measured position (no twin truth channel needed).
    """
    t, pos = rec["t"], rec["position"]
    segment = np.clip(rec["block"], 0, len(path) - 1)
    velocity = np.gradient(pos, t, axis=0) if len(t) > 1 else np.zeros_like(pos)
    m = summarize(t, rec["ref_position"], rec["ref_velocity"], pos, velocity, path,
                  segment=segment)
    gains = settings.gains
    # the output stage's limit per axis (a quantising regulator's top code is 1 LSB below)
    full = np.broadcast_to(np.subtract(gains.output_limit, np.multiply(gains.dac_lsb, 1.5)),
                           (2,))
    period = float(t[1] - t[0]) if len(t) > 1 else 0.0
    saturated = np.any(np.abs(rec["dac_volts"]) >= full, axis=1)
    return {
        "max_coordinate_error": max(m.max_coordinate_error),
        "rms_coordinate_error": max(m.rms_coordinate_error),
        "max_contour_error": m.max_contour_error,
        "rms_contour_error": m.rms_contour_error,
        "overshoot": m.overshoot,
        "settling_travel": m.settling_travel,
        "cycle_time": m.cycle_time,
        "saturation_time": float(np.count_nonzero(saturated)) * period,
    }


def metric_scales(baseline: RunOutcome) -> dict[str, float]:
    """Scale of each metric: the baseline's value, at least 1 µm for lengths, 1 ms for the
    cycle time and 1 % of the baseline cycle time for the saturation time.

    Raises
    ------
    ValueError
        If the baseline run failed (it cannot scale anything).
    """
    if baseline.failed:
        raise ValueError(f"the baseline run failed ({baseline.status}: {baseline.message})")
    out = {}
    for m in METRICS:
        floor = _FLOORS.get(m, _LENGTH_FLOOR)
        if floor is None:
            floor = _SATURATION_FRACTION * baseline.metrics["cycle_time"]
        out[m] = max(baseline.metrics[m], floor)
    return out


def cost_terms(outcome: RunOutcome, scales: Mapping[str, float], weights: Weights, *,
               penalty: float) -> dict[str, float]:
    """Weighted dimensionless cost terms of ``outcome``: ``METRICS`` plus ``"failure"``.

    Their sum is the cost (minus the env's reward): ``w_i·metric_i/scale_i`` for a good run
    (``failure`` = 0), ``penalty`` in ``failure`` and zeros elsewhere for a failed one.
    """
    if outcome.failed:
        return {**{m: 0.0 for m in METRICS}, "failure": float(penalty)}
    terms: dict[str, Any] = {m: getattr(weights, m) * outcome.metrics[m] / scales[m]
                             for m in METRICS}
    terms["failure"] = 0.0
    return terms


def reported(metrics: Mapping[str, float]) -> dict[str, float]:
    """``METRICS`` (SI) in the units people read, the unit in each key:
    ``max_coordinate_error_um``, ``cycle_time_s`` (NaN stays NaN)."""
    out = {}
    for m, v in metrics.items():
        unit, k = METRIC_UNITS.get(m, ("", 1.0))
        out[f"{m}_{'um' if unit == 'µm' else unit}" if unit else m] = v * k
    return out


def cycle_time_limit(outcome: RunOutcome, baseline_cycle: float, max_increase: float,
                     weight: float) -> float:
    """The cost of a run that breaks the constraint "the cycle time grows by at most
    ``max_increase`` (1, e.g. 0.0 or 0.05) over the analytic design's ``baseline_cycle``
    (s)": 0 within it (and for a failed run, which costs the failure penalty);
    ``weight·(1 + 100·excess)`` beyond it, ``excess`` the share of ``baseline_cycle``
    over the limit. With ``weight`` the sum of the cost weights, a run that breaks it
    costs more than the analytic design does."""
    if outcome.failed:
        return 0.0
    excess = outcome.metrics["cycle_time"] / baseline_cycle - 1.0 - max_increase
    return weight * (1.0 + 100.0 * excess) if excess > 1e-9 else 0.0
