"""Compare acceleration laws: the same program and machine once per law (``twin compare``).

Each law is one ``twin.session.run.run`` with ``RunSpec(profile=law)``; its summary gets the figures
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
residual vibration
    The free vibration of the same deflection left once the (shaped) reference stops
    accelerating, about its settled value (``twin.analysis.vibration``): what an input shaper
    cancels, where the elastic oscillation above also counts the quasi-static ``m·a/k``.
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
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.analysis.spectrum import amplitude_density, peak
from twin.analysis.vibration import residual_vibration
from twin.controller.metrics import contour_error, oscillation
from twin.plant.model import mode_periods
from twin.session.run import RunResult, RunSpec, run
from twin.system.jsonio import output_dir
from twin.telemetry.sink import Sink

__all__ = ["FIGURES", "LAW_COLOURS", "LAW_COLOUR_NAMES", "Comparison", "LawRun", "compare",
           "elastic_oscillation", "figure_value", "junction_speed_jump", "junctions",
           "law_colour", "law_colour_name", "law_figures", "mode_periods",
           "true_contour_error", "verdict", "widest_difference"]

FIGURES = (
    ("cycle time", "cycle_time_s", "s"),
    ("max contour error", "max_contour_error_um", "µm"),
    ("RMS contour error", "rms_contour_error_um", "µm"),
    ("max coordinate error X", ("max_coordinate_error_um", "x"), "µm"),
    ("max coordinate error Y", ("max_coordinate_error_um", "y"), "µm"),
    ("max velocity error X", ("max_velocity_error_um_s", "x"), "µm/s"),
    ("max velocity error Y", ("max_velocity_error_um_s", "y"), "µm/s"),
    ("peak reference jerk |Δa|/T", "peak_reference_jerk_m_per_s3", "m/s³"),
    ("speed jump at junctions", "junction_speed_jump_mm_per_s", "mm/s"),
    ("elastic oscillation", "elastic_oscillation_um", "µm"),
    ("residual vibration", "residual_vibration_um", "µm"),
    ("settling travel (loop lag)", "settling_travel_um", "µm"),
)
"""The figures laws are compared by: label, summary key (or (key, axis)), unit. Smaller is
better for every one of them."""

TIE = 1e-3
"""Relative difference below which two laws tie on a figure (0.1 %)."""

LAW_COLOURS = {"trapezoid": (214, 39, 40), "parabolic": (31, 119, 180),
               "cosine": (44, 160, 44), "cubic": (148, 103, 189),
               "jerk-limited": (255, 127, 14)}
"""One colour per law (RGB), shared by the PNG report and the rerun overlay."""

LAW_COLOUR_NAMES = {"trapezoid": "red", "parabolic": "blue", "cosine": "green",
                    "cubic": "purple", "jerk-limited": "orange"}
"""The names of ``LAW_COLOURS``, for the overlay's titles (its plots name their series)."""


def law_colour(profile: str) -> tuple[int, int, int]:
    """The colour of a profile (RGB): its law's (``LAW_COLOURS``), darkened by half for
    ``law+shaper``; grey for an unknown law."""
    law, _, shaper = profile.partition("+")
    rgb = LAW_COLOURS.get(law, (90, 90, 90))
    if shaper and shaper != "none":
        return (rgb[0] // 2, rgb[1] // 2, rgb[2] // 2)
    return rgb


def law_colour_name(profile: str) -> str:
    """``law_colour``'s name: the law's (``LAW_COLOUR_NAMES``), "dark …" when shaped."""
    law, _, shaper = profile.partition("+")
    name = LAW_COLOUR_NAMES.get(law, "grey")
    return f"dark {name}" if shaper and shaper != "none" else name


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


def law_figures(result: RunResult, contour: np.ndarray | None = None) -> dict[str, float]:
    """The figures ``compare`` adds to a run's summary (units in the key names); the elastic
    oscillation from the run's drive-rate samples when it kept them (``keep_fine``), else
    from its per-tick truth record. ``contour``: the run's ``true_contour_error`` when the
    caller has it already."""
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
    periods = mode_periods(cfg)
    f_hz, density = amplitude_density(rec["t"], rec["following_error"])
    # the loop's and the mode's band, not the moves' own slow content
    out["following_error_peak_hz"] = peak(f_hz, density, above=0.5 / max(periods))[0]
    out["elastic_oscillation_um"] = elastic_oscillation(t, d, periods) * 1e6
    out["residual_vibration_um"] = residual_vibration(rec["t"], rec["ref_acceleration"], t, d,
                                                      periods) * 1e6
    contour = true_contour_error(result) if contour is None else contour
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


def figure_value(summary: Mapping[str, Any], key: str | tuple[str, str]) -> float | None:
    """The value of ``key`` (a summary key, or (key, axis)) in ``summary``; None if absent."""
    value = summary.get(key[0], {}).get(key[1]) if isinstance(key, tuple) else summary.get(key)
    return None if value is None else float(value)


def verdict(summaries: Mapping[str, Mapping[str, Any]],
            figures: Sequence[tuple[str, Any, str]] = FIGURES) -> list[dict[str, Any]]:
    """Which law wins each figure (the smallest value), and by how much.

    Returns one entry per figure that every law has: ``label``, ``unit``, ``values``
    ({law: value}), ``winner`` (the law, or None when the best two tie within ``TIE``),
    ``runner_up``, ``margin`` (runner-up minus winner, in the figure's unit) and
    ``margin_ratio`` (runner-up / winner, inf when the winner is 0)."""
    out = []
    for label, key, unit in figures:
        values = {law: figure_value(s, key) for law, s in summaries.items()}
        if not values or any(v is None for v in values.values()):
            continue
        ranked = sorted(values, key=values.__getitem__)
        best = values[ranked[0]]
        entry = {"label": label, "key": key if isinstance(key, str) else ".".join(key),
                 "unit": unit, "values": values, "winner": ranked[0], "runner_up": None,
                 "margin": 0.0, "margin_ratio": 1.0}
        if len(ranked) > 1:
            second = values[ranked[1]]
            tie = abs(second - best) <= TIE * max(abs(second), abs(best))
            entry.update(winner=None if tie else ranked[0], runner_up=ranked[1],
                         margin=second - best,
                         margin_ratio=second / best if best > 0 else math.inf)
        out.append(entry)
    return out


def widest_difference(comparison: Comparison, *, pad: float = 0.3
                      ) -> tuple[float, float, str] | None:
    """The time window (s) around the place where the laws' contour errors differ most, and
    a label for it. Per block, each law's largest true contour error; in the block whose
    spread across the laws is largest, the window spans every law's peak there, padded by
    ``pad`` s each side (at most the block). None with fewer than two laws or when the
    laws' blocks do not correspond (different block counts)."""
    runs = list(comparison.runs.values())
    if len(runs) < 2:
        return None
    blocks = [r.record["block"].ravel() for r in runs]
    count = {int(b.max()) for b in blocks}
    if len(count) != 1 or next(iter(count)) < 0:
        return None
    n = next(iter(count)) + 1
    peaks = np.zeros((len(runs), n))
    at = np.full((len(runs), n), np.nan)          # when each law peaks in each block (s)
    spans = np.full((len(runs), n, 2), np.nan)
    for i, (r, b) in enumerate(zip(runs, blocks, strict=True)):
        t = r.record["t"]
        for k in np.unique(b[b >= 0]):
            ticks = np.flatnonzero(b == k)
            j = ticks[np.argmax(r.contour[ticks])]
            peaks[i, k], at[i, k] = r.contour[j], t[j]
            spans[i, k] = t[ticks[[0, -1]]]
    spread = peaks.max(axis=0) - peaks.min(axis=0)
    k = int(np.argmax(spread))
    t0 = max(float(np.nanmin(at[:, k])) - pad, float(np.nanmin(spans[:, k, 0])))
    t1 = min(float(np.nanmax(at[:, k])) + pad, float(np.nanmax(spans[:, k, 1])))
    line = runs[0].record["line"].ravel()[blocks[0] == k]
    where = f"block {k}" + (f" (line {int(line[0])})" if line.size and line[0] > 0 else "")
    return t0, t1, (f"{where}, where the laws' contour errors differ most "
                    f"({spread[k] * 1e6:.3g} µm)")


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
    contour : ndarray
        The table's true contour error per tick (m), shape (n,): ``true_contour_error``,
        computed once (the summary's max and RMS, the report's plot and zoom).
    """

    law: str
    summary: dict[str, Any]
    record: dict[str, np.ndarray]
    path: list
    fine_t: np.ndarray
    fine_deflection: np.ndarray
    contour: np.ndarray


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
        self.colour = law_colour(law)

    def static_path(self, entity: str, points: np.ndarray, *,
                    color: tuple[int, int, int] = (160, 160, 160)) -> None:
        self.shared.static_path(self.prefix + entity, points, color=color)

    def scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        self.shared.scalars(t, {self.prefix + k: v for k, v in columns.items()})

    def points(self, t: np.ndarray, columns: Mapping[str, np.ndarray], *,
               colors: Mapping[str, np.ndarray] | None = None) -> None:
        """The law's path in its colour (the overlay's, not the error's): the table's true
        path (the twin's truth, which the laws are judged by), the encoder's where there is
        none; its reference path is not drawn (the programmed path is)."""
        entity = "path/table" if "path/table" in columns else "path/actual"
        if entity in columns:
            values = columns[entity]
            rgb = np.broadcast_to(np.array(self.colour, dtype=np.uint8), (len(values), 3))
            self.shared.points(t, {self.prefix + entity: values},
                               colors={self.prefix + entity: rgb})

    def event(self, t: float, text: str, *, level: str = "INFO") -> None:
        self.shared.event(t, f"{self.law}: {text}", level=level)

    def spectrum(self, frequency: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """The law's spectra (``twin.telemetry.spectra``), at its end."""
        spectrum = getattr(self.shared, "spectrum", None)
        if spectrum is not None:
            spectrum(frequency, {self.prefix + k: v for k, v in columns.items()})

    def style(self, entity: str, *, name: str | list[str],
              color: tuple[int, int, int] | list[tuple[int, int, int]] | None = None,
              marker: str | None = None) -> None:
        """The law's series in the law's colour, named ``<law>: <name>`` (a reference
        keeps its own colour)."""
        style = getattr(self.shared, "style", None)
        if style is None:
            return
        names = [name] if isinstance(name, str) else list(name)
        colours = [color] if isinstance(color, tuple) else list(color or [])
        if not entity.endswith("/reference"):
            colours = [self.colour] * len(names)
        style(self.prefix + entity, name=[f"{self.law}: {n}" for n in names],
              color=colours or None, **({"marker": marker} if marker is not None else {}))

    def close(self) -> None:
        """The shared sink stays open for the next law."""


def _shared_sink(path: Path, laws: Sequence[str], run_id: str) -> Sink:
    from twin.telemetry.blueprint import overlay_blueprint
    from twin.telemetry.rerun_sink import RerunSink

    names = {law: law_colour_name(law) for law in laws}
    sink = RerunSink(path, recording_id=run_id, recording_name=run_id,
                     blueprint=lambda extents: overlay_blueprint(names, extents))
    sink.machine_frame("laws")          # the paths in mm, Y up, as in a run's layout
    return sink


def compare(spec: RunSpec, laws: Sequence[str], *, out_dir: str | Path = "runs",
            recording: bool | str | Path = True, run_id: str = "compare",
            on_law: Callable[[str, int, int], None] | None = None) -> Comparison:
    """Run ``spec`` once per law.

    Parameters
    ----------
    spec : RunSpec
        Program, machine, overrides … (its ``profile`` is replaced by each law).
    laws : sequence of str
        Acceleration laws (``twin.controller.profiles.LAWS``).
    out_dir : path
        Each run's ``<run_id>-<law>.json`` and the shared ``<run_id>.rrd`` go here.
    recording : bool or path
        Write the shared ``.rrd``: True into ``out_dir`` as ``<run_id>.rrd``, or to this
        path; False: none.
    run_id : str
        Name of the comparison.
    on_law : callable(law, k, n), optional
        Told as the ``k``-th of ``n`` laws starts (progress).

    Returns
    -------
    Comparison
    """
    out = output_dir(out_dir)
    rrd = Path(recording) if isinstance(recording, str | Path) else out / f"{run_id}.rrd"
    shared = _shared_sink(rrd, laws, run_id) if recording is not False else None
    runs: dict[str, LawRun] = {}
    try:
        for k, law in enumerate(laws):
            if on_law is not None:
                on_law(law, k, len(laws))
            law_spec = dataclasses.replace(spec, profile=law)
            sink = _LawSink(shared, law) if shared is not None else None
            result = run(law_spec, out_dir=out, rerun="none", run_id=f"{run_id}-{law}",
                         sink=sink, keep_fine=True)
            summary = {k: v for k, v in result.summary.items() if k not in ("config", "spec")}
            contour = true_contour_error(result)
            summary.update(law_figures(result, contour))
            fine_t, fine_d = (result.fine["t"], result.fine["screw_deflection"]) \
                if result.fine is not None else (result.record["t"],
                                                 result.record["screw_deflection"])
            runs[law] = LawRun(law, summary, result.record, result.path, fine_t, fine_d,
                               contour)
    finally:
        if shared is not None:
            shared.close()
    return Comparison(runs, str(rrd) if recording is not False else None)
