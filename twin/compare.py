"""Compare acceleration laws: the same program and machine once per law (``twin compare``).

Each law is one ``twin.run.run`` with ``RunSpec(profile=law)``; its summary gets the figures
that tell the laws apart (all defined here, SI inside, µm and mm/s in the report):

peak reference jerk
    ``max ‖Δa_ref‖/T`` over the ticks (m/s³, T the controller period): the jerk the drive
    is asked for. The trapezoid's acceleration steps show as ``A/T`` (its profile's own
    jerk is zero between the steps), the other laws stay near their jerk limit.
speed jump at junctions
    Seed 000 compares "speed jumps at the junctions of the acceleration/deceleration
    intervals". A junction is a tick where the reference's tangential acceleration starts
    or stops (a speed change begins or ends) or a new block starts; the jump is the largest
    ``|‖v‖ − ‖v_ref‖|`` of the table's true contour speed against the reference within
    ``window`` (0.1 s) after any junction (m/s).
elastic oscillation
    The screw deflection minus its moving average over one period of the axis' first
    elastic mode (which removes that oscillation and keeps the quasi-static part, m·a/k and
    friction): the largest magnitude over the run, per axis, then the larger axis (m). The
    deflection is sampled every drive interval (``DeflectionProbe``), because the modes
    (93 and 161 Hz on tomsk_xy) lie near or above the Nyquist rate of the controller period.
contour error (max and RMS)
    Of the table's true path, searched over the whole program (``true_contour_error``);
    they replace the run summary's, which measures the encoder position near the active
    block only.
residual vibration
    The run summary's: peak deviation from the final position after the motion.

The telemetry of all laws goes into ONE ``.rrd``: one recording whose entity tree holds one
subtree per law (``laws/<law>/...``, the entity paths of ``twin run`` below it), with a
blueprint that overlays the laws in each plot, one colour per law.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig
from twin.controller.io import Inputs, Outputs
from twin.controller.metrics import contour_error
from twin.run import RunResult, RunSpec, prepare, run
from twin.telemetry.sink import Sink

__all__ = ["LAW_COLOURS", "Comparison", "DeflectionProbe", "LawRun", "compare",
           "elastic_oscillation", "junction_speed_jump", "junctions", "law_figures",
           "mode_periods", "true_contour_error"]

LAW_COLOURS = {"trapezoid": (214, 39, 40), "parabolic": (31, 119, 180),
               "cosine": (44, 160, 44), "cubic": (148, 103, 189),
               "jerk-limited": (255, 127, 14)}
"""One colour per law (RGB), shared by the PNG report and the rerun overlay."""


class DeflectionProbe:
    """A ``MachineIO`` over a ``SimDriver`` that advances the plant one drive interval at a
    time and keeps the screw deflection after each (the rest is exactly ``SimDriver.write``:
    same enable logic, same DAC value for the whole period).

    Attributes
    ----------
    t : list of float
        Plant time after each drive interval (s).
    deflection : list of tuple
        Screw deflection of (x, y) after each drive interval (m).
    """

    def __init__(self, driver: Any):
        self.driver = driver
        self.plant = driver.plant
        self.steps = max(1, round(driver.period / self.plant.drive_dt))
        self.t: list[float] = []
        self.deflection: list[tuple[float, float]] = []
        self._zero = np.zeros(2)

    def read(self) -> Inputs:
        """The driver's sample of the sensors."""
        return self.driver.read()

    def write(self, outputs: Outputs) -> None:
        """Apply the outputs for one period, sampling the deflection every drive interval."""
        plant = self.plant
        enable = bool(outputs.enable) and not self.driver.dry_run
        plant.enable(enable)
        dac = outputs.dac_volts if enable else self._zero
        dt = plant.drive_dt
        for _ in range(self.steps):
            plant.step(dac, dt)
            self.t.append(plant.time)
            self.deflection.append(tuple(plant.truth().screw_deflection.tolist()))

    def close(self) -> None:
        """Disable the drives."""
        self.driver.close()

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``(t (n,) s, deflection (n, 2) m)``."""
        return np.asarray(self.t), np.asarray(self.deflection).reshape(-1, 2)


# --------------------------------------------------------------------------- metrics
def mode_periods(cfg: MachineConfig) -> tuple[float, float]:
    """Period of the first (locked-rotor) elastic mode of x and y (s): ``2π/√(k/m)``, the
    x axis carrying the y carriage (see ``twin/models/README.md``)."""
    masses = {"x": cfg.axes["x"].mechanics.carriage_mass + cfg.axes["y"].mechanics.carriage_mass,
              "y": cfg.axes["y"].mechanics.carriage_mass}
    return tuple(2.0 * math.pi / math.sqrt(cfg.axes[a].transmission.axial_stiffness
                                           / masses[a]) for a in AXES)  # type: ignore


def elastic_oscillation(t, deflection, periods: Sequence[float]) -> float:
    """Largest oscillating part of the screw deflection (m).

    Parameters
    ----------
    t : array_like, shape (n,)
        Sample times (s), equally spaced.
    deflection : array_like, shape (n, 2)
        Screw deflection of x and y (m).
    periods : sequence of 2 float
        Period of each axis' elastic mode (s): the moving-average window (rounded to an
        odd number of samples, so that it is centred and removes a ramp exactly).

    Returns
    -------
    float
        ``max_k max_i |d_k(i) − mean_{window}(d_k)(i)|``; the record's ends (half a window)
        are left out.
    """
    t = np.asarray(t, dtype=float)
    d = np.asarray(deflection, dtype=float).reshape(-1, 2)
    if t.size < 3:
        return 0.0
    dt = float(np.median(np.diff(t)))
    peak = 0.0
    for k, period in enumerate(periods):
        w = max(1, round(period / dt)) | 1       # odd: the average is centred on a sample
        if w >= d.shape[0]:
            continue
        smooth = np.convolve(d[:, k], np.ones(w) / w, mode="valid")
        lo = w // 2
        peak = max(peak, float(np.abs(d[lo:lo + smooth.size, k] - smooth).max()))
    return peak


def junctions(rec: Mapping[str, np.ndarray]) -> np.ndarray:
    """Ticks where a speed change of the reference starts or ends, or a block starts.

    The reference's tangential acceleration ``(v_ref·a_ref)/‖v_ref‖`` (``‖a_ref‖`` at rest)
    is "on" above 10⁻⁶ of its peak; a junction is a change of that state or of ``block``.
    """
    v, a = rec["ref_velocity"], rec["ref_acceleration"]
    speed = np.hypot(v[:, 0], v[:, 1])
    tangential = np.where(speed > 0.0, np.sum(v * a, axis=1) / np.where(speed > 0, speed, 1),
                          np.hypot(a[:, 0], a[:, 1]))
    peak = float(np.abs(tangential).max()) if tangential.size else 0.0
    on = np.abs(tangential) > 1e-6 * peak
    block = rec["block"]
    change = np.zeros(len(on), dtype=bool)
    change[1:] = (on[1:] != on[:-1]) | ((block[1:] != block[:-1]) & (block[1:] >= 0))
    return np.flatnonzero(change)


def junction_speed_jump(rec: Mapping[str, np.ndarray], period: float, *,
                        window: float = 0.1) -> float:
    """Largest ``|‖v‖ − ‖v_ref‖|`` within ``window`` (s) after any junction (m/s).

    ``v`` is the table's true velocity (``table_velocity``), ``period`` the tick (s).
    """
    ref = np.hypot(*rec["ref_velocity"].T)
    act = np.hypot(*rec["table_velocity"].T)
    gap = np.abs(act - ref)
    w = max(1, round(window / period))
    peak = 0.0
    for j in junctions(rec):
        peak = max(peak, float(gap[j:j + w].max()))
    return peak


def law_figures(result: RunResult, probe: DeflectionProbe | None) -> dict[str, float]:
    """The figures ``compare`` adds to a run's summary (units in the key names)."""
    rec, cfg = result.record, result.config
    period = cfg.controller.period
    step = np.diff(rec["ref_acceleration"], axis=0) / period
    jerk = float(np.hypot(*step.T).max()) if step.size else 0.0
    out = {"spec_period_s": period, "peak_reference_jerk_m_per_s3": jerk,
           "junction_speed_jump_mm_per_s": junction_speed_jump(rec, period) * 1e3}
    if probe is not None:
        t, d = probe.arrays()
    else:
        t, d = rec["t"], rec["screw_deflection"]
    out["elastic_oscillation_um"] = elastic_oscillation(t, d, mode_periods(cfg)) * 1e6
    contour = true_contour_error(result)
    out["max_contour_error_um"] = float(contour.max()) * 1e6
    out["rms_contour_error_um"] = float(np.sqrt(np.mean(contour**2))) * 1e6
    return out


def true_contour_error(result: RunResult) -> np.ndarray:
    """Contour error of the table's true path, searched over the whole program (m), (n,).

    ``twin run``'s summary measures the encoder position against the active block ± 1;
    when the table lags the reference by more than one short block (polylines of 1 mm
    chords at 50 mm/s with 1 mm of servo lag) that window misses the nearest segment.
    """
    return contour_error(result.path, result.record["table_position"])


# --------------------------------------------------------------------------- runs
@dataclass(frozen=True)
class LawRun:
    """One law's run: its summary (with ``law_figures``) and records.

    Attributes
    ----------
    law : str
    summary : dict
        ``twin run``'s summary (without ``config``/``spec``) plus the compare figures.
    record : dict of ndarray
        The run record (SI).
    path : list of Segment
        The programmed path.
    fine_t, fine_deflection : ndarray
        Screw deflection per drive interval (s, m), shape (n,) and (n, 2).
    """

    law: str
    summary: dict[str, Any]
    record: dict[str, np.ndarray]
    path: list
    fine_t: np.ndarray
    fine_deflection: np.ndarray


@dataclass(frozen=True)
class Comparison:
    """Every law's run of one program; ``recording`` is the shared ``.rrd`` (or None)."""

    runs: dict[str, LawRun]
    recording: str | None

    def summaries(self) -> dict[str, dict[str, Any]]:
        """``{law: summary}`` (JSON-ready)."""
        return {law: r.summary for law, r in self.runs.items()}


class _LawSink:
    """A view of the shared sink that puts one law's entities under ``laws/<law>/`` and
    colours its series; ``close`` is left to the owner of the shared sink."""

    def __init__(self, shared: Sink, law: str):
        self.shared, self.law = shared, law
        self.prefix = f"laws/{law}/"
        self.colour = LAW_COLOURS.get(law, (90, 90, 90))
        self.style("errors/contour_um", name="contour error (µm)")

    def static_path(self, entity: str, points: np.ndarray, *,
                    color: tuple[int, int, int] = (160, 160, 160)) -> None:
        self.shared.static_path(self.prefix + entity, points, color=color)

    def scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        self.shared.scalars(t, {self.prefix + k: v for k, v in columns.items()})

    def points(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        self.shared.points(t, {self.prefix + k: v for k, v in columns.items()})

    def event(self, t: float, text: str, *, level: str = "INFO") -> None:
        self.shared.event(t, f"{self.law}: {text}", level=level)

    def style(self, entity: str, *, name: str, color: tuple[int, int, int] | None = None
              ) -> None:
        style = getattr(self.shared, "style", None)
        if style is not None:
            colour = color if entity.endswith("/reference") else self.colour
            style(self.prefix + entity, name=f"{self.law}: {name}", color=colour)

    def close(self) -> None:
        """The shared sink stays open for the next law."""


def _shared_sink(path: Path, laws: Sequence[str], run_id: str) -> Sink:
    from twin.compare_report import overlay_blueprint
    from twin.telemetry.rerun_sink import RerunSink

    return RerunSink(path, recording_id=run_id, recording_name=run_id,
                     blueprint=overlay_blueprint(laws))


def compare(spec: RunSpec, laws: Sequence[str], *, out_dir: str | Path = "runs",
            recording: bool = True, run_id: str = "compare") -> Comparison:
    """Run ``spec`` once per law.

    Parameters
    ----------
    spec : RunSpec
        Program, machine, overrides … (its ``profile`` is replaced by each law).
    laws : sequence of str
        Acceleration laws (``twin.controller.profiles.LAWS``).
    out_dir : path
        Each run's ``<run_id>-<law>.json`` and the shared ``<run_id>.rrd`` go here.
    recording : bool
        Write the shared ``.rrd``.
    run_id : str
        Name of the comparison.

    Returns
    -------
    Comparison
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rrd = out / f"{run_id}.rrd"
    shared = _shared_sink(rrd, laws, run_id) if recording else None
    runs: dict[str, LawRun] = {}
    try:
        for law in laws:
            law_spec = dataclasses.replace(spec, profile=law)
            p = prepare(law_spec)
            probe = DeflectionProbe(p.driver) if p.plant is not None else None
            if probe is not None:
                p = dataclasses.replace(p, driver=probe)
            sink = _LawSink(shared, law) if shared is not None else None
            result = run(law_spec, out_dir=out, rerun="none", run_id=f"{run_id}-{law}",
                         sink=sink, prepared=p)
            summary = {k: v for k, v in result.summary.items() if k not in ("config", "spec")}
            summary.update(law_figures(result, probe))
            fine_t, fine_d = probe.arrays() if probe is not None else (
                result.record["t"], result.record["screw_deflection"])
            runs[law] = LawRun(law, summary, result.record, result.path, fine_t, fine_d)
    finally:
        if shared is not None:
            shared.close()
    return Comparison(runs, str(rrd) if recording else None)
