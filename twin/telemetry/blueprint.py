"""The default rerun layout, built for feed-drive engineers: the analogues of LinuxCNC's Axis
preview (the path) and halscope (the loop's signals, one unit per plot).

The first tab, "Run", is what a run is judged by:
- the path in machine orientation (X right, Y up, mm): the programmed path whole, and the
  actual path up to the time cursor coloured by its contour error (``error_colors``: green
  at 0, yellow at the contour tolerance, red from twice it);
- the contour error (µm) and the feed (mm/min: programmed F, commanded, actual);
- per axis, the following error (µm) above the regulator's terms (V: p, i, d, FF, DCU);
- the event log (blocks, status changes, tool on/off).

Then one drive tab per axis, split by unit (control voltages ±10 V, converter voltage V,
armature current A, motor speed rad/s, conduction), and one motion tab per axis (position
m, velocity m/s, screw deflection µm).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import rerun.encodings as rrd

from twin.telemetry.sink import PROGRAMMED

__all__ = ["PATH_TRANSFORM", "default_blueprint", "overlay_blueprint", "path_bounds"]

PATH_TRANSFORM = rr.Transform3D(mat3x3=[[1e3, 0.0, 0.0], [0.0, -1e3, 0.0], [0.0, 0.0, 1.0]])
"""Logged on ``/path``: metres to millimetres, and Y up (rerun's 2-D views draw Y down). The
data stay in metres; only the view is in machine orientation."""

_WHOLE_RUN = [rrb.VisibleTimeRange("sim_time", start=rrb.TimeRangeBoundary.infinite(),
                                   end=rrb.TimeRangeBoundary.cursor_relative())]
"""Everything from the start up to the time cursor (the path drawn whole, not a dot)."""


_ALL_TIME = rrb.TimeAxis(view_range=rrd.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                   end=rrb.TimeRangeBoundary.infinite()))
"""The plots' time axis: the whole run (rerun's default follows the last minute)."""


def _series(name: str, *entities: str) -> rrb.TimeSeriesView:
    return rrb.TimeSeriesView(name=name, origin="/", contents=list(entities), axis_x=_ALL_TIME)


def _errors(axis: str) -> rrb.Container:
    base = f"/axes/{axis}"
    return rrb.Vertical(
        _series(f"{axis.upper()} following error (µm)", f"{base}/following_error_um"),
        _series(f"{axis.upper()} regulator terms: p, i, d, FF, DCU (V)", f"{base}/regulator"),
    )


def _drive(axis: str) -> rrb.Container:
    base = f"/axes/{axis}/drive"
    return rrb.Vertical(
        _series(f"{axis.upper()} DAC and tacho (V)", f"{base}/dac_volts", f"{base}/tacho_volts"),
        _series(f"{axis.upper()} converter voltage (V)", f"{base}/converter_voltage"),
        _series(f"{axis.upper()} armature current (A)", f"{base}/armature_current"),
        _series(f"{axis.upper()} motor speed (rad/s)", f"{base}/motor_speed"),
        _series(f"{axis.upper()} conduction (share of each drive interval)",
                f"{base}/conduction"),
        name=f"{axis.upper()} drive",
    )


def _motion(axis: str) -> rrb.Container:
    base = f"/axes/{axis}"
    return rrb.Vertical(
        _series(f"{axis.upper()} position (m)", f"{base}/position/**"),
        _series(f"{axis.upper()} velocity (m/s)", f"{base}/velocity/**"),
        _series(f"{axis.upper()} screw deflection (µm)", f"{base}/screw_deflection_um"),
        name=f"{axis.upper()} motion",
    )


def path_bounds(points: np.ndarray, margin: float = 0.04) -> tuple[Sequence[float],
                                                                 Sequence[float]]:
    """The path view's ranges, (x, y) in the view's coordinates (mm, Y negated as
    `PATH_TRANSFORM` draws it), holding every point of ``points`` ((n, 2), m) with a
    ``margin`` (share of the larger extent, at least 1 mm) on each side.

    rerun fits a 2-D view to the data of the first frames it sees; a run's path starts
    at one point and grows, so the view is told the whole programmed path instead."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2) * 1e3
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = max(margin * float(np.max(hi - lo)), 1.0)
    return ((lo[0] - pad, hi[0] + pad), (-hi[1] - pad, -lo[1] + pad))


def path_view(points: np.ndarray | None = None) -> rrb.Spatial2DView:
    """The path in machine orientation (mm, Y up), actual path coloured by contour error;
    fitted to ``points`` ((n, 2), m: the programmed path) when given."""
    bounds = None
    if points is not None and len(points):
        x_range, y_range = path_bounds(points)
        bounds = rrb.VisualBounds2D(x_range=x_range, y_range=y_range)
    return rrb.Spatial2DView(
        name="Path (mm, Y up): programmed grey; actual green → yellow at the contour "
             "tolerance → red at twice it",
        origin="/", contents=[f"/{PROGRAMMED}", "/path/actual"], time_ranges=_WHOLE_RUN,
        visual_bounds=bounds)


def default_blueprint(path: np.ndarray | None = None) -> rrb.Blueprint:
    """The "Run" tab (path, contour error, feed, following errors with the regulator's
    terms, events), then the drive and motion tabs per axis. ``path`` ((n, 2), m), the
    programmed path, fits the path view to it."""
    run = rrb.Vertical(
        rrb.Horizontal(
            path_view(path),
            rrb.Vertical(
                _series("Contour error (µm)", "/errors/contour_um"),
                _series("Feed (mm/min): programmed F, commanded, actual", "/feed/**"),
                rrb.TextLogView(name="Events", origin="/events"),
                row_shares=[2, 2, 1],
            ),
            column_shares=[3, 2],
        ),
        rrb.Horizontal(_errors("x"), _errors("y")),
        row_shares=[3, 2],
        name="Run",
    )
    return rrb.Blueprint(
        rrb.Tabs(run, _drive("x"), _drive("y"), _motion("x"), _motion("y"), active_tab=0),
        collapse_panels=True,
    )


def overlay_blueprint(laws: Sequence[str]) -> rrb.Blueprint:
    """A rerun blueprint that overlays the laws: the paths, the contour error, the contour
    speed of each axis and the screw deflection, one entity subtree per law."""
    def series(entity: str) -> list[str]:
        return [f"/laws/{law}/{entity}" for law in laws]

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name="Paths (mm, Y up)", origin="/laws"),
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
