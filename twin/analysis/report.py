"""The pictures of ``twin compare``: a PNG report (matplotlib, Agg) and the rerun blueprint
that overlays the laws.

Report panels, one colour per law (``twin.analysis.compare.LAW_COLOURS``), against time: the
contour speed in mm/min (the feed's unit; reference dashed, table solid, as the legend
says), the reference's acceleration and jerk (magnitudes of the vectors; the jerk as the
drive sees it, ``|Δa_ref|/T``), the contour error, zoomed to the block where the laws'
contour errors differ most (``widest_difference``; the whole run is in the ``.rrd``); the
programmed path with every law's table path, the zoomed stretch marked; and the table of
figures with each one's winner and margin (``twin.analysis.compare.verdict``). The sweep
report plots the figure against the swept parameter, and the cycle time against the
figure (what a law trades for it), one line per law. Every PNG is titled with its program
and machine; each axis names its quantity and its unit once; numbers are written without
exponents (``readable``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from twin.analysis.compare import FIGURES, Comparison, law_colour, verdict, widest_difference
from twin.telemetry.channels import programmed_polyline

__all__ = ["figure_label", "figure_unit", "margin_text", "readable", "write_report",
           "write_sweep_report"]


def _colour(law: str) -> tuple[float, float, float]:
    r, g, b = law_colour(law)
    return r / 255.0, g / 255.0, b / 255.0


def _figure(rows: int, cols: int, size: tuple[float, float]):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    return fig, fig.subplots(rows, cols, squeeze=False)


def write_report(comparison: Comparison, path: str | Path, *, title: str = "") -> Path:
    """Write the comparison PNG to ``path`` and return it."""
    from matplotlib.lines import Line2D

    fig = _figure_only((13.0, 17.5))
    grid = fig.add_gridspec(5, 2, height_ratios=[1.0, 1.0, 1.0, 1.0, 1.15])
    speed, acc, jerk = (fig.add_subplot(grid[i, 0]) for i in range(3))
    paths, err = fig.add_subplot(grid[0, 1]), fig.add_subplot(grid[1:3, 1])
    _spectra(fig.add_subplot(grid[3, 0]), fig.add_subplot(grid[3, 1]), comparison)
    table = fig.add_subplot(grid[4, :])
    per_min = 60e3                                              # m/s → mm/min
    for law, r in comparison.runs.items():
        rec, c = r.record, _colour(law)
        t = rec["t"]
        speed.plot(t, np.hypot(*rec["ref_velocity"].T) * per_min, "--", color=c, lw=0.8)
        speed.plot(t, np.hypot(*rec["table_velocity"].T) * per_min, color=c, lw=1.0,
                   label=law)
        acc.plot(t, np.hypot(*rec["ref_acceleration"].T), color=c, lw=1.0, label=law)
        jerk.plot(t[1:], np.hypot(*np.diff(rec["ref_acceleration"], axis=0).T)
                  / r.summary["spec_period_s"], color=c, lw=1.0, label=law)
        err.plot(t, r.contour * 1e6, color=c, lw=1.0, label=law)
        paths.plot(*(rec["table_position"] * 1e3).T, color=c, lw=1.0, label=law)
    first = next(iter(comparison.runs.values()), None)
    if first is not None:
        paths.plot(*(programmed_polyline(first.path) * 1e3).T, color="0.6", lw=0.6, ls=":",
                   label="programmed")
    for a, ylabel in ((speed, "contour speed (mm/min)"), (acc, "|a_ref| (m/s²)"),
                      (jerk, "|Δa_ref|/T (m/s³)"), (err, "contour error (µm)")):
        a.set_xlabel("time (s)")
        a.set_ylabel(ylabel)
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8, loc="best")
    styles = [Line2D([], [], color="0.3", lw=1.0, label="table (solid)"),
              Line2D([], [], color="0.3", lw=0.8, ls="--", label="reference (dashed)")]
    speed.add_artist(speed.legend(fontsize=8, loc="upper left"))
    speed.legend(handles=styles, fontsize=8, loc="lower right")
    # a magnitude: from 0 up, log above 1 m/s³ (the trapezoid's steps are 10× the others)
    jerk.set_yscale("symlog", linthresh=1.0)
    zoom = widest_difference(comparison)
    if zoom is not None:
        t0, t1, where = zoom
        for a in (speed, acc, jerk, err):
            a.set_xlim(t0, t1)
            _fit_y(a, t0, t1)
        speed.set_title(f"zoomed to {where}; the whole run is in the .rrd", fontsize=9)
        if first is not None:
            t = first.record["t"]
            inside = (t >= t0) & (t <= t1)
            stretch = first.record["table_position"][inside] * 1e3
            paths.plot(*stretch.T, color="k", lw=4.0, alpha=0.4, label="zoomed stretch",
                       zorder=0)
            if len(stretch):
                paths.annotate("zoomed", xy=tuple(stretch[len(stretch) // 2]), fontsize=8,
                               xytext=(-40, -30), textcoords="offset points",
                               arrowprops={"arrowstyle": "->", "color": "0.3"})
    jerk.set_ylim(bottom=0.0)
    paths.set_xlabel("x (mm)")
    paths.set_ylabel("y (mm)")
    paths.set_aspect("equal", adjustable="datalim")
    paths.legend(fontsize=8)
    paths.set_title("paths (table)")
    _verdict_table(table, comparison)
    fig.suptitle(title or "acceleration laws compared")
    out = Path(path)
    fig.savefig(out, dpi=110)
    return out


def _spectra(ferr, fdef, comparison: Comparison) -> None:
    """Amplitude spectral densities (``twin.analysis.spectrum``) of each law's following
    error (per tick) and screw deflection (per drive interval), log-log."""
    from twin.analysis.spectrum import amplitude_density

    for law, r in comparison.runs.items():
        c = _colour(law)
        f, d = amplitude_density(r.record["t"], r.record["following_error"])
        ferr.loglog(f[1:], d[1:] * 1e6, color=c, lw=1.0, label=law)
        f, d = amplitude_density(r.fine_t, r.fine_deflection)
        fdef.loglog(f[1:], d[1:] * 1e6, color=c, lw=1.0, label=law)
    for a, what in ((ferr, "following error"), (fdef, "screw deflection")):
        a.set_xlabel("frequency (Hz)")
        a.set_ylabel(f"{what} (µm/√Hz)")
        a.set_title(f"spectrum of the {what} (x and y in power, 1 s Hann windows)",
                    fontsize=9)
        a.grid(True, which="both", alpha=0.3)
        a.legend(fontsize=8, loc="best")


def _figure_only(size: tuple[float, float]):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    return Figure(figsize=size, layout="constrained")


def _fit_y(a, t0: float, t1: float) -> None:
    """Scale ``a``'s y axis to its lines' data inside [t0, t1]."""
    lo, hi = np.inf, -np.inf
    for line in a.get_lines():
        x, y = (np.asarray(v, dtype=float) for v in line.get_data())
        y = y[(x >= t0) & (x <= t1) & np.isfinite(y)]
        if y.size:
            lo, hi = min(lo, y.min()), max(hi, y.max())
    if np.isfinite(lo) and hi > lo:
        pad = 0.05 * (hi - lo)
        a.set_ylim(lo - pad, hi + pad)


def margin_text(entry: dict) -> str:
    """How much the winner of a ``verdict`` entry wins by: '-12.3 % vs parabolic'."""
    if entry["runner_up"] is None:
        return ""
    if entry["winner"] is None:
        return f"tie with {entry['runner_up']}"
    second = entry["values"][entry["runner_up"]]
    share = entry["margin"] / second if second else 0.0
    return f"{-100.0 * share:.1f} % vs {entry['runner_up']}"


def _verdict_table(a, comparison: Comparison) -> None:
    """The figures per law, with the winner's cell bold and the margin in the last column."""
    rows = verdict(comparison.summaries())
    laws = list(comparison.runs)
    a.axis("off")
    cells = [[f"{e['label']} ({e['unit']})",
              *(readable(e['values'][law]) for law in laws),
              e["winner"] or "tie", margin_text(e)] for e in rows]
    share = 0.5 / max(1, len(laws))
    tab = a.table(cellText=cells, colLabels=["figure (smaller is better)", *laws, "winner",
                                              "margin"], loc="center", cellLoc="right",
                  colWidths=[0.25, *[share] * len(laws), 0.1, 0.15])
    tab.auto_set_font_size(False)
    tab.set_fontsize(8.5)
    tab.scale(1.0, 1.25)
    for j, law in enumerate(laws, start=1):
        tab[0, j].set_text_props(color=_colour(law), weight="bold")
    for i, e in enumerate(rows, start=1):
        tab[i, 0].set_text_props(ha="left")
        if e["winner"] is not None:
            j = laws.index(e["winner"]) + 1
            tab[i, j].set_text_props(weight="bold")
            tab[i, j].set_facecolor((0.9, 0.97, 0.9))


def readable(value: float, digits: int = 4) -> str:
    """``value`` to ``digits`` significant digits without an exponent: ``10180``,
    ``0.1858``, ``64.2`` (a table an engineer reads; ``1.018e+04`` is not)."""
    if value == 0 or not np.isfinite(value):
        return f"{value:g}"
    decimals = max(0, digits - 1 - int(np.floor(np.log10(abs(value)))))
    return f"{round(value, decimals):.{decimals}f}"


def figure_label(figure: str) -> str:
    """A summary figure in words, without its unit: ``FIGURES``' label, else the key
    without its unit suffix (``max_contour_error_um`` → "max contour error")."""
    for label, key, _ in FIGURES:
        if (key if isinstance(key, str) else key[0]) == figure:
            return label
    for suffix in ("_um_s", "_mm_per_s", "_m_per_s3", "_mm_per_min", "_um", "_mm", "_s"):
        if figure.endswith(suffix):
            return figure[:-len(suffix)].replace("_", " ")
    return figure.replace("_", " ")


def figure_unit(figure: str) -> str:
    """The unit of a summary figure: from ``FIGURES``, else from its key's suffix."""
    for _, key, unit in FIGURES:
        if (key if isinstance(key, str) else key[0]) == figure:
            return unit
    for suffix, unit in (("_um_s", "µm/s"), ("_mm_per_s", "mm/s"), ("_m_per_s3", "m/s³"),
                         ("_mm_per_min", "mm/min"), ("_um", "µm"), ("_mm", "mm"),
                         ("_s", "s")):
        if figure.endswith(suffix):
            return unit
    return "1"


def write_sweep_report(key: str, values: Sequence[float], figure: str,
                       table: Mapping[str, Sequence[float]], path: str | Path, *,
                       cycle_times: Mapping[str, Sequence[float]] | None = None,
                       key_unit: str = "", title: str = "") -> Path:
    """Plot ``figure`` against the swept ``key``, one line per law, and (``cycle_times``)
    the cycle time against the figure, each point labelled with its value of ``key``;
    titled with ``title`` (program and machine); return the PNG path."""
    unit, label = figure_unit(figure), figure_label(figure)
    name = key.rsplit(".", 1)[-1]
    swept = f"{name} ({key_unit})" if key_unit else name
    fig, ax = _figure(1, 2 if cycle_times else 1, (13.0 if cycle_times else 7.5, 5.2))
    a = ax[0, 0]
    for law, ys in table.items():
        a.plot(values, ys, "o-", color=_colour(law), label=law)
    a.set_xlabel(swept)
    a.set_ylabel(f"{label} ({unit})")
    a.grid(True, alpha=0.3)
    a.legend(fontsize=8)
    a.set_title(f"{label} against {name}", fontsize=10)
    if cycle_times:
        b = ax[0, 1]
        for law, ys in table.items():
            b.plot(ys, cycle_times[law], "o-", color=_colour(law), label=law)
            for x, y, v in zip(ys, cycle_times[law], values, strict=True):
                b.annotate(f"{v:g}", (x, y), fontsize=7, xytext=(3, 3),
                           textcoords="offset points")
        b.set_xlabel(f"{label} ({unit})")
        b.set_ylabel("cycle time (s)")
        b.grid(True, alpha=0.3)
        b.legend(fontsize=8)
        b.set_title(f"the trade: cycle time against {label}\n(points labelled with {swept})",
                    fontsize=10)
    fig.suptitle(f"{title}: {name} swept" if title else f"{name} swept")
    out = Path(path)
    fig.savefig(out, dpi=110)
    return out
