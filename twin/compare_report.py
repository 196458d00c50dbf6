"""The pictures of ``twin compare``: a PNG report (matplotlib, Agg) and the rerun blueprint
that overlays the laws.

Report panels, one colour per law (``twin.compare.LAW_COLOURS``), against time: the contour
speed (reference dashed, table solid), the reference's acceleration and jerk (magnitudes of
the vectors; the jerk as the drive sees it, ``|Δa_ref|/T``), the contour error; and the
programmed path with every law's table path, and the key figures side by side. The sweep
report plots one summary figure against the swept parameter, one line per law.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from twin.compare import LAW_COLOURS, Comparison
from twin.telemetry.channels import programmed_polyline

__all__ = ["overlay_blueprint", "write_report", "write_sweep_report"]


def _colour(law: str) -> tuple[float, float, float]:
    r, g, b = LAW_COLOURS.get(law, (90, 90, 90))
    return r / 255.0, g / 255.0, b / 255.0


def _figure(rows: int, cols: int, size: tuple[float, float]):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    return fig, fig.subplots(rows, cols, squeeze=False)


def write_report(comparison: Comparison, path: str | Path, *, title: str = "") -> Path:
    """Write the comparison PNG to ``path`` and return it."""
    from twin.controller.metrics import contour_error

    fig, ax = _figure(3, 2, (13.0, 11.0))
    speed, acc, jerk, err = ax[0, 0], ax[1, 0], ax[2, 0], ax[1, 1]
    paths = ax[0, 1]
    for law, r in comparison.runs.items():
        rec, c = r.record, _colour(law)
        t = rec["t"]
        speed.plot(t, np.hypot(*rec["ref_velocity"].T) * 1e3, "--", color=c, lw=0.8)
        speed.plot(t, np.hypot(*rec["table_velocity"].T) * 1e3, color=c, lw=1.0, label=law)
        acc.plot(t, np.hypot(*rec["ref_acceleration"].T), color=c, lw=1.0, label=law)
        jerk.plot(t[1:], np.hypot(*np.diff(rec["ref_acceleration"], axis=0).T)
                  / r.summary["spec_period_s"], color=c, lw=1.0, label=law)
        hint = np.clip(rec["block"], 0, len(r.path) - 1)
        err.plot(t, contour_error(r.path, rec["position"], hint=hint) * 1e6, color=c, lw=1.0,
                 label=law)
        paths.plot(*(rec["table_position"] * 1e3).T, color=c, lw=1.0, label=law)
    first = next(iter(comparison.runs.values()), None)
    if first is not None:
        paths.plot(*(programmed_polyline(first.path) * 1e3).T, color="0.6", lw=0.6, ls=":",
                   label="programmed")
    for a, ylabel in ((speed, "contour speed (mm/s)"), (acc, "|a_ref| (m/s²)"),
                      (jerk, "|Δa_ref|/T (m/s³)"), (err, "contour error (µm)")):
        a.set_xlabel("time (s)")
        a.set_ylabel(ylabel)
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8)
    jerk.set_yscale("symlog", linthresh=1.0)
    paths.set_xlabel("x (mm)")
    paths.set_ylabel("y (mm)")
    paths.set_aspect("equal", adjustable="datalim")
    paths.legend(fontsize=8)
    paths.set_title("paths (table)")
    _summary_bars(ax[2, 1], comparison)
    fig.suptitle(title or "acceleration laws compared")
    out = Path(path)
    fig.savefig(out, dpi=110)
    return out


def _summary_bars(a, comparison: Comparison) -> None:
    """Key figures per law, each relative to its largest value across the laws."""
    keys = (("cycle_time_s", "cycle time"), ("max_contour_error_um", "max contour err"),
            ("junction_speed_jump_mm_per_s", "junction speed jump"),
            ("elastic_oscillation_um", "elastic oscillation"))
    laws = list(comparison.runs)
    width = 0.8 / max(1, len(laws))
    for i, law in enumerate(laws):
        s = comparison.runs[law].summary
        vals = []
        for key, _ in keys:
            top = max(float(comparison.runs[k].summary.get(key) or 0.0) for k in laws) or 1.0
            vals.append(float(s.get(key) or 0.0) / top)
        a.bar(np.arange(len(keys)) + i * width, vals, width, color=_colour(law), label=law)
    a.set_xticks(np.arange(len(keys)) + 0.4 - width / 2, [k[1] for k in keys], fontsize=8)
    a.set_ylabel("relative to the largest")
    a.legend(fontsize=8)


def write_sweep_report(key: str, values: Sequence[float], figure: str,
                       table: Mapping[str, Sequence[float]], path: str | Path) -> Path:
    """Plot ``figure`` against the swept ``key``, one line per law; return the PNG path."""
    fig, ax = _figure(1, 1, (7.5, 5.0))
    a = ax[0, 0]
    for law, ys in table.items():
        a.plot(values, ys, "o-", color=_colour(law), label=law)
    a.set_xlabel(key)
    a.set_ylabel(figure)
    a.grid(True, alpha=0.3)
    a.legend(fontsize=8)
    fig.suptitle(f"{figure} against {key}")
    out = Path(path)
    fig.savefig(out, dpi=110)
    return out


def overlay_blueprint(laws: Sequence[str]):
    """A rerun blueprint that overlays the laws: the paths, the contour error, the contour
    speed of each axis and the screw deflection, one entity subtree per law."""
    import rerun.blueprint as rrb

    def series(entity: str) -> list[str]:
        return [f"/laws/{law}/{entity}" for law in laws]

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name="Paths (m)", origin="/laws"),
            rrb.Vertical(
                rrb.TimeSeriesView(name="Contour error (µm)",
                                   contents=series("errors/contour_um")),
                rrb.TimeSeriesView(name="X velocity (m/s)",
                                   contents=series("axes/x/velocity/actual")),
                rrb.TimeSeriesView(name="Y velocity (m/s)",
                                   contents=series("axes/y/velocity/actual")),
                rrb.TimeSeriesView(name="Screw deflection (µm)",
                                   contents=series("axes/x/screw_deflection_um")
                                   + series("axes/y/screw_deflection_um")),
                rrb.TextLogView(name="Events", origin="/events"),
            ),
            column_shares=[2, 3],
        ),
        collapse_panels=True,
    )
