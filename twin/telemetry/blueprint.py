"""The rerun layouts, built for feed-drive engineers: the analogues of LinuxCNC's Axis
preview (the path) and halscope (the loop's signals, one unit per plot).

The first tab of a run's layout, "Run", is what a run is judged by:
- the path in machine orientation (X right, Y up, mm, on a labelled grid with a scale bar):
  the programmed path whole, and the actual path up to the time cursor coloured by its
  contour error (``error_colors``: green at 0, yellow at the contour tolerance, red from
  twice it);
- the contour error (µm) and the feed (mm/min: programmed F, commanded, actual);
- per axis, the following error (µm) above the regulator's terms (V: p, i, d, FF, DCU);
- the event log (blocks, status changes, tool on/off).

Then one drive tab per axis, split by unit (DAC and tacho V, converter voltage V, armature
current A, motor speed rpm, conduction), one motion tab per axis (position mm, velocity
mm/min, screw deflection µm), and the spectra of the following error and of the screw
deflection (``twin.telemetry.spectra``: dB re 1 µm/√Hz against frequency, x and y, a marker
at the model's first elastic mode). The spectra lie on their own timeline, ``frequency_hz``:
rerun's plots draw against the timeline chosen in the time panel, so the tab's name says
which to choose.

Every plot is framed on the data: the time axis on the recording's time span, the y axis on
the range of what it shows (``twin.telemetry.extent.tick_range``: at least two labelled
ticks), the path view on the whole path. A layout is built from an ``Extents`` (what the
sink was given); before any data it leaves the ranges to the viewer. The plots carry no
legend box over the traces: each title names its series and their colours.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import rerun.encodings as rrd

from twin.config import AXES
from twin.telemetry.channels import AXIS_COLOURS, SERIES
from twin.telemetry.extent import Extents, tick_range
from twin.telemetry.sink import PROGRAMMED
from twin.telemetry.spectra import DB_SPAN, FREQUENCY, QUANTITIES, spectrum_entity

__all__ = ["PATH_TRANSFORM", "PathGrid", "default_blueprint", "experiment_blueprint",
           "frame_bounds", "overlay_blueprint", "path_view"]

PATH_TRANSFORM = rr.Transform3D(mat3x3=[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])
"""Logged on ``/path``: Y up (rerun's 2-D views draw Y down). The data are in mm."""

_WHOLE_RUN = [rrb.VisibleTimeRange("sim_time", start=rrb.TimeRangeBoundary.infinite(),
                                   end=rrb.TimeRangeBoundary.cursor_relative())]
"""Everything from the start up to the time cursor (the path drawn whole, not a dot)."""

_NO_LEGEND = rrb.PlotLegend(visible=False)


def _time_axis(extents: Extents | None) -> rrb.TimeAxis:
    """The plots' time axis: the data's time span (rerun's default follows the last
    minute); the whole timeline while it is not known yet."""
    if extents is None or extents.time is None:
        start = end = rrb.TimeRangeBoundary.infinite()
    else:
        t0, t1 = extents.time           # to the nanosecond, outwards: every sample inside
        start = rrb.TimeRangeBoundary.absolute(nanos=math.floor(t0 * 1e9))
        end = rrb.TimeRangeBoundary.absolute(nanos=math.ceil(max(t1, t0 + 1e-3) * 1e9))
    return rrb.TimeAxis(view_range=rrd.TimeRange(start=start, end=end))


def _legend(entities: Sequence[str], names: Mapping[str, str] | None = None) -> str:
    """``": reference grey, actual orange"`` for the series of ``entities`` (``SERIES``),
    or ``names`` (entity → "name colour") when given; "" for a single series."""
    if names is not None:
        parts = [names[e] for e in entities if e in names]
    else:
        parts = []
        for e in entities:
            entry = next((v for k, v in SERIES.items()
                          if k.format(a=e.split("/")[2] if e.startswith("/axes/") else "")
                          == e.lstrip("/")), None)
            parts += [f"{name} {colour}" for name, colour in (entry[1] if entry else ())]
    return ": " + ", ".join(parts) if len(parts) > 1 else ""


def _series(title: str, entities: Sequence[str], extents: Extents | None, *,
            names: Mapping[str, str] | None = None) -> rrb.TimeSeriesView:
    """A plot of ``entities`` titled ``title`` (with its unit) and the colours of its
    series, on the data's time span and value range."""
    y = extents.value_range(*entities) if extents is not None else None
    y_range = tick_range(*y) if y is not None else None
    return rrb.TimeSeriesView(
        name=title + _legend(entities, names), origin="/", contents=list(entities),
        axis_x=_time_axis(extents), plot_legend=_NO_LEGEND,
        axis_y=rrb.ScalarAxis(range=y_range, zoom_lock=False) if y_range else None)


def _errors(axis: str, ext: Extents | None) -> rrb.Container:
    base = f"/axes/{axis}"
    return rrb.Vertical(
        _series(f"{axis.upper()} following error (µm)", [f"{base}/following_error_um"], ext),
        _series(f"{axis.upper()} regulator terms (V)", [f"{base}/regulator"], ext),
    )


def _drive(axis: str, ext: Extents | None) -> rrb.Container:
    base = f"/axes/{axis}/drive"
    a = axis.upper()
    return rrb.Vertical(
        _series(f"{a} DAC and tacho (V)", [f"{base}/dac_volts", f"{base}/tacho_volts"], ext),
        _series(f"{a} converter voltage (V)", [f"{base}/converter_voltage"], ext),
        _series(f"{a} armature current (A)", [f"{base}/armature_current"], ext),
        _series(f"{a} motor speed (rpm)", [f"{base}/motor_speed"], ext),
        _series(f"{a} conduction (share of each drive interval)", [f"{base}/conduction"],
                ext),
        name=f"{a} drive",
    )


def _motion(axis: str, ext: Extents | None) -> rrb.Container:
    base = f"/axes/{axis}"
    a = axis.upper()
    return rrb.Vertical(
        _series(f"{a} position (mm)", [f"{base}/position/reference",
                                       f"{base}/position/actual"], ext),
        _series(f"{a} velocity (mm/min)", [f"{base}/velocity/reference",
                                           f"{base}/velocity/actual"], ext),
        _series(f"{a} screw deflection (µm)", [f"{base}/screw_deflection_um"], ext),
        name=f"{a} motion",
    )


SPECTRA_TAB = f"Spectra (timeline {FREQUENCY})"
"""The spectra's tab: its name says which timeline shows them."""


def _spectrum(title: str, entities: Sequence[str], extents: Extents | None, *,
              names: Mapping[str, str]) -> rrb.TimeSeriesView:
    """A plot of the spectra ``entities`` and their elastic-mode markers (``<entity>_mode``)
    against frequency: ``title``, its unit, the series' colours (``names``: entity → "name
    colour") and the modes marked; framed on the band (from 0 Hz) and on whole 10 dB
    steps from the highest level down ``DB_SPAN``."""
    marks = [f"{e}_mode" for e in entities]
    axis_x = axis_y = None
    band = extents.band_range(*entities) if extents is not None else None
    if band is not None:
        axis_x = rrb.TimeAxis(view_range=rrd.TimeRange(
            start=rrb.TimeRangeBoundary.absolute(seq=0),      # labels at 0, 10, 20 …
            end=rrb.TimeRangeBoundary.absolute(seq=math.ceil(band[1]))))
    y = extents.value_range(*entities, *marks) if extents is not None else None
    if y is not None:
        hi = 10.0 * math.ceil(y[1] / 10.0)
        lo = min(10.0 * math.floor(max(y[0], y[1] - DB_SPAN) / 10.0), hi - 10.0)
        axis_y = rrb.ScalarAxis(range=(lo - 2.0, hi + 2.0), zoom_lock=False)
    modes = {}                     # axis → its marked mode (Hz), the same for every law
    for m in marks:
        found = extents.band.get(m.lstrip("/")) if extents is not None else None
        if found is not None:
            modes.setdefault(m.rsplit("/", 1)[1].removesuffix("_mode"), found[0])
    marked = ("; ◆ first elastic mode (model) "
              + ", ".join(f"{a} {f:.0f} Hz" for a, f in modes.items())) if modes else ""
    return rrb.TimeSeriesView(       # the essentials first: a narrow panel cuts the end
        name=f"{title} (dB re 1 µm/√Hz vs Hz): {', '.join(names[e] for e in entities)}"
             f"{marked}",
        origin="/", contents=[*entities, *marks], axis_x=axis_x, axis_y=axis_y,
        plot_legend=_NO_LEGEND)


def _spectra(ext: Extents | None, laws: Mapping[str, str] | None = None) -> rrb.Container:
    """The spectra tab: the following error above the screw deflection, x and y in one
    plot; or, with ``laws`` ({law: its colour's name}), one plot per quantity and axis
    with one series per law (entities under ``laws/<law>/``)."""
    rows: list[rrb.TimeSeriesView | rrb.Container] = []
    for q, what in QUANTITIES.items():
        if laws is None:
            entities = [f"/{spectrum_entity(q, a)}" for a in AXES]
            rows.append(_spectrum(f"{what.capitalize()} spectrum", entities, ext, names={
                e: f"{a} {AXIS_COLOURS[a]}" for e, a in zip(entities, AXES, strict=True)}))
            continue
        plots = []
        for a in AXES:
            entities = [f"/laws/{law}/{spectrum_entity(q, a)}" for law in laws]
            plots.append(_spectrum(f"{a.upper()} {what} spectrum", entities, ext, names={
                e: f"{law} {colour}" for e, (law, colour) in zip(entities, laws.items(),
                                                                 strict=True)}))
        rows.append(rrb.Horizontal(*plots))
    return rrb.Vertical(*rows, name=SPECTRA_TAB)


def frame_bounds(extents: Extents | None, *patterns: str, margin: float = 0.06
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """The 2-D frame of the points matching ``patterns`` (mm, data coordinates, Y up):
    (lower left, upper right), a ``margin`` (share of the larger extent, at least 1 mm)
    on each side; None before any point."""
    found = extents.point_bounds(*patterns) if extents is not None else None
    if found is None:
        return None
    lo, hi = found
    pad = max(margin * float(np.max(hi - lo)), 1.0)
    return lo - pad, hi + pad


def _visual_bounds(frame: tuple[np.ndarray, np.ndarray] | None) -> rrb.VisualBounds2D | None:
    """The view's bounds of a frame: rerun's 2-D view coordinates, Y negated as
    ``PATH_TRANSFORM`` draws it."""
    if frame is None:
        return None
    lo, hi = frame
    return rrb.VisualBounds2D(x_range=(float(lo[0]), float(hi[0])),
                              y_range=(float(-hi[1]), float(-lo[1])))


class PathGrid:
    """The grid and scale bar of a path view framed on (``lo``, ``hi``) (mm, Y up).

    Attributes
    ----------
    step : float
        Grid spacing (mm): 1, 2 or 5 × 10^k.
    lines : list of ndarray, shape (2, 2)
        The grid lines, spanning the frame.
    label_positions : ndarray, shape (n, 2)
        Where each grid line's coordinate is written: along the lower and the left edge.
    labels : list of str
    scale : ndarray, shape (2, 2)
        The scale bar: one step long, in the lower right corner.
    scale_label : str
        Its length, e.g. "20 mm".
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, *, lines_across: int = 8):
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        size = float(np.max(hi - lo))
        raw = size / lines_across
        mag = 10.0 ** math.floor(math.log10(raw))
        self.step = next(m * mag for m in (1.0, 2.0, 5.0, 10.0) if m * mag >= raw)
        # the view keeps its aspect ratio: the grid reaches a frame's size beyond it
        far_lo, far_hi = lo - size, hi + size
        xs, ys = (np.arange(math.ceil(far_lo[k] / self.step),
                            math.floor(far_hi[k] / self.step) + 1) * self.step
                  for k in (0, 1))
        self.lines = ([np.array([[x, far_lo[1]], [x, far_hi[1]]]) for x in xs]
                      + [np.array([[far_lo[0], y], [far_hi[0], y]]) for y in ys])
        inset = 0.03 * size
        xl = xs[(xs >= lo[0]) & (xs <= hi[0])]
        yl = ys[(ys >= lo[1] + 2 * inset) & (ys <= hi[1])]
        self.label_positions = np.array([[x, lo[1] + inset] for x in xl]
                                        + [[lo[0] + inset, y] for y in yl]).reshape(-1, 2)
        self.labels = [f"{v:g}" for v in (*xl, *yl)]
        right, bottom = hi[0] - inset, lo[1] + 2.5 * inset
        self.scale = np.array([[right - self.step, bottom], [right, bottom]])
        self.scale_label = f"{self.step:g} mm"


def _table_shown(extents: Extents | None) -> bool:
    """Whether a recording holds the table's true contour error (a simulated run: the twin's
    truth; of every law in a comparison) and so its true path."""
    return extents is not None and any(e.endswith("errors/table_contour_um")
                                       for e in extents.values)


def path_view(extents: Extents | None = None, *, name: str | None = None,
              origin: str = "/", contents: Sequence[str] = (f"/{PROGRAMMED}", "/path/actual",
                                                            "/path/table", "/path/grid/**"),
              frame: Sequence[str] = (PROGRAMMED, "path/actual")) -> rrb.Spatial2DView:
    """The path in machine orientation (mm, Y up) on its grid, framed on the points of
    ``frame`` (the whole programmed and actual path). ``origin`` must lie above the
    entity that carries ``PATH_TRANSFORM`` (a view's origin frame is its own, untransformed).
    A simulated run adds the table's true path (``path/table``)."""
    table = _table_shown(extents)
    return rrb.Spatial2DView(
        name=name or "Path (mm, Y up; grid and scale bar in mm): programmed grey; actual "
                     "(encoder) green → yellow at the contour tolerance → red at twice it"
                     + ("; table: teal halo" if table else ""),
        origin=origin, contents=list(contents), time_ranges=_WHOLE_RUN,
        visual_bounds=_visual_bounds(frame_bounds(extents, *frame)))


def default_blueprint(extents: Extents | None = None) -> rrb.Blueprint:
    """The "Run" tab (path, contour error, feed, following errors with the regulator's
    terms, events), then the drive and motion tabs per axis, framed on ``extents``."""
    ext = extents
    run = rrb.Vertical(
        rrb.Horizontal(
            path_view(ext),
            rrb.Vertical(
                _series("Contour error (µm)", ["/errors/contour_um"] + (
                    ["/errors/table_contour_um"] if _table_shown(ext) else []), ext),
                _series("Feed (mm/min)", ["/feed/programmed", "/feed/commanded",
                                          "/feed/actual"], ext),
                rrb.TextLogView(name="Events", origin="/events"),
                row_shares=[2, 2, 1],
            ),
            column_shares=[3, 2],
        ),
        rrb.Horizontal(_errors("x", ext), _errors("y", ext)),
        row_shares=[3, 2],
        name="Run",
    )
    return rrb.Blueprint(
        rrb.Tabs(run, *(_drive(a, ext) for a in AXES), *(_motion(a, ext) for a in AXES),
                 _spectra(ext), active_tab=0),
        collapse_panels=True,
    )


def overlay_blueprint(laws: Mapping[str, str], extents: Extents | None = None
                      ) -> rrb.Blueprint:
    """A layout that overlays the laws (``{law: its colour's name}``): the paths, the
    contour error, the velocity and the screw deflection of each axis ("Laws"), and the
    spectra of each axis's following error and screw deflection (the spectra tab), one
    entity subtree per law (``laws/<law>/...``), framed on ``extents``."""
    def plot(title: str, entity: str) -> rrb.TimeSeriesView:
        entities = [f"/laws/{law}/{entity}" for law in laws]
        names = {e: f"{law} {colour}" for e, (law, colour)
                 in zip(entities, laws.items(), strict=True)}
        return _series(title, entities, extents, names=names)

    programmed = ", ".join(f"{law} {colour}" for law, colour in laws.items())
    # a simulated comparison shows the table's true paths and contour errors (the laws are
    # judged by them), else the encoder's
    table = _table_shown(extents)
    overlay = rrb.Horizontal(
        rrb.Vertical(
            path_view(extents, name=f"Paths (mm, Y up; grid and scale bar in mm): "
                                    f"programmed grey; "
                                    f"{'the table, ' if table else ''}{programmed}",
                      origin="/", contents=["/laws/**"], frame=("laws/**",)),
            rrb.TextLogView(name="Events", origin="/events"),
            row_shares=[4, 1],
        ),
        rrb.Vertical(
            plot("Contour error of the table (µm)" if table else "Contour error (µm)",
                 "errors/table_contour_um" if table else "errors/contour_um"),
            *(plot(f"{a.upper()} velocity (mm/min)", f"axes/{a}/velocity/actual")
              for a in AXES),
            *(plot(f"{a.upper()} screw deflection (µm)", f"axes/{a}/screw_deflection_um")
              for a in AXES),
        ),
        column_shares=[2, 3],
        name="Laws",
    )
    return rrb.Blueprint(rrb.Tabs(overlay, _spectra(extents, laws), active_tab=0),
                         collapse_panels=True)


def experiment_blueprint(axis: str, extents: Extents | None = None) -> rrb.Blueprint:
    """The layout of a step or ramp experiment on ``axis`` (``twin experiment``): position
    (closed loop) and velocity above the DAC volts, the armature current and the screw
    deflection, framed on ``extents``."""
    base, a = f"/axes/{axis}", axis.upper()
    return rrb.Blueprint(
        rrb.Vertical(
            _series(f"{a} position from the start (mm)", [f"{base}/position/reference",
                                                          f"{base}/position/actual"],
                    extents),
            _series(f"{a} velocity (mm/min)", [f"{base}/velocity/actual"], extents),
            _series(f"{a} DAC (V)", [f"{base}/drive/dac_volts"], extents),
            _series(f"{a} armature current (A)", [f"{base}/drive/armature_current"], extents),
            _series(f"{a} screw deflection (µm)", [f"{base}/screw_deflection_um"], extents),
            name=f"{a} response",
        ),
        collapse_panels=True,
    )
