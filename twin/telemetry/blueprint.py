"""The default rerun layout: the path view beside the error plots, per-axis tabs below."""

from __future__ import annotations

import rerun.blueprint as rrb

__all__ = ["default_blueprint"]


def _axis_tab(axis: str) -> rrb.Container:
    base = f"/axes/{axis}"
    return rrb.Vertical(
        rrb.TimeSeriesView(name=f"{axis.upper()} position (m)", origin=f"{base}/position"),
        rrb.TimeSeriesView(name=f"{axis.upper()} velocity (m/s)", origin=f"{base}/velocity"),
        rrb.TimeSeriesView(name=f"{axis.upper()} drive", origin=f"{base}/drive"),
        rrb.TimeSeriesView(name=f"{axis.upper()} screw deflection (µm)",
                           origin=f"{base}/screw_deflection_um"),
        name=f"Axis {axis.upper()}",
    )


def default_blueprint() -> rrb.Blueprint:
    """Path view (programmed vs actual) and the error plots first; axis details in tabs."""
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(
                rrb.Spatial2DView(name="Path (m)", origin="/path"),
                rrb.Vertical(
                    rrb.TimeSeriesView(name="Contour error (µm)", origin="/errors"),
                    rrb.TimeSeriesView(
                        name="Following error (µm)",
                        contents=["/axes/x/following_error_um", "/axes/y/following_error_um"],
                    ),
                    rrb.TextLogView(name="Events", origin="/events"),
                ),
                column_shares=[3, 2],
            ),
            rrb.Tabs(_axis_tab("x"), _axis_tab("y")),
            row_shares=[3, 2],
        ),
        collapse_panels=True,
    )
