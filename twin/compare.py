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
    deflection is sampled every drive interval (the twin's drive-rate samples), because the
    modes (93 and 161 Hz on tomsk_xy) lie near or above the Nyquist rate of the controller
    period. Every run summary has it (``elastic_oscillation_um``).
contour error (max and RMS)
    Of the table's true path, searched over the whole program (``true_contour_error``);
    they replace the run summary's, which measures the encoder position near the active
    block only.
settling travel
    The run summary's: how far the table still travelled after the motion ended (mostly the
    position loop catching up its lag).

The telemetry of all laws goes into ONE ``.rrd``: one recording whose entity tree holds one
subtree per law (``laws/<law>/...``, the entity paths of ``twin run`` below it), with a
blueprint that overlays the laws in each plot, one colour per law.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.controller.metrics import contour_error, oscillation
from twin.jsonio import output_dir
from twin.model import mode_periods
from twin.run import RunResult, RunSpec, run
from twin.telemetry.sink import Sink

__all__ = ["LAW_COLOURS", "Comparison", "LawRun", "compare", "elastic_oscillation",
           "junction_speed_jump", "junctions", "law_figures", "mode_periods",
           "true_contour_error"]

LAW_COLOURS = {"trapezoid": (214, 39, 40), "parabolic": (31, 119, 180),
               "cosine": (44, 160, 44), "cubic": (148, 103, 189),
               "jerk-limited": (255, 127, 14)}
"""One colour per law (RGB), shared by the PNG report and the rerun overlay."""


# --------------------------------------------------------------------------- metrics
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
        are left out (``twin.controller.metrics.oscillation``, which every run summary
        computes on the fly as ``elastic_oscillation_um``).
    """
    t = np.asarray(t, dtype=float)
    d = np.asarray(deflection, dtype=float).reshape(-1, 2)
    if t.size < 3:
        return 0.0
    dt = float(np.median(np.diff(t)))
    return oscillation(d, [max(1, round(p / dt)) | 1 for p in periods])


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


def law_figures(result: RunResult) -> dict[str, float]:
    """The figures ``compare`` adds to a run's summary (units in the key names); the elastic
    oscillation from the run's drive-rate samples when it kept them (``keep_fine``), else
    from its per-tick truth record."""
    rec, cfg = result.record, result.config
    period = cfg.controller.period
    step = np.diff(rec["ref_acceleration"], axis=0) / period
    jerk = float(np.hypot(*step.T).max()) if step.size else 0.0
    out = {"spec_period_s": period, "peak_reference_jerk_m_per_s3": jerk,
           "junction_speed_jump_mm_per_s": junction_speed_jump(rec, period) * 1e3}
    if result.fine is not None:
        t, d = result.fine["t"], result.fine["screw_deflection"]
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

    def points(self, t: np.ndarray, columns: Mapping[str, np.ndarray], *,
               colors: Mapping[str, np.ndarray] | None = None) -> None:
        """The law's points, in its colour (the overlay's, not the error's)."""
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
    out = output_dir(out_dir)
    rrd = out / f"{run_id}.rrd"
    shared = _shared_sink(rrd, laws, run_id) if recording else None
    runs: dict[str, LawRun] = {}
    try:
        for law in laws:
            law_spec = dataclasses.replace(spec, profile=law)
            sink = _LawSink(shared, law) if shared is not None else None
            result = run(law_spec, out_dir=out, rerun="none", run_id=f"{run_id}-{law}",
                         sink=sink, keep_fine=True)
            summary = {k: v for k, v in result.summary.items() if k not in ("config", "spec")}
            summary.update(law_figures(result))
            fine_t, fine_d = (result.fine["t"], result.fine["screw_deflection"]) \
                if result.fine is not None else (result.record["t"],
                                                 result.record["screw_deflection"])
            runs[law] = LawRun(law, summary, result.record, result.path, fine_t, fine_d)
    finally:
        if shared is not None:
            shared.close()
    return Comparison(runs, str(rrd) if recording else None)
