"""What every ``twin`` command shares: the stderr console and the one way to fail.

Human output goes to stderr (tables may go to stdout when no ``--json`` is asked for);
``--json`` prints exactly one JSON object on stdout; bad input exits with code 2 and a
message naming the place.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

__all__ = ["CONTROLLER_MODEL_HELP", "METRIC_ROWS", "RUN_ROWS", "err", "fail",
           "summary_table"]

CONTROLLER_MODEL_HELP = (
    "The machine as the controller believes it to be (preset or TOML file): its gains, "
    "DCU, feed-forward and corner model are derived from this model; the physics runs "
    "--machine. Default: the machine itself.")
"""Help of every command's ``--controller-model``."""

err = Console(stderr=True)
"""Console on stderr for messages, progress and errors."""


def fail(exc: BaseException) -> None:
    """Print ``exc`` (which names its place) on stderr and exit with code 2."""
    err.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


METRIC_ROWS = (
    ("max contour error", "max_contour_error_um", "µm"),
    ("RMS contour error", "rms_contour_error_um", "µm"),
    ("max coordinate error X", ("max_coordinate_error_um", "x"), "µm"),
    ("max coordinate error Y", ("max_coordinate_error_um", "y"), "µm"),
    ("max velocity error X", ("max_velocity_error_um_s", "x"), "µm/s"),
    ("max velocity error Y", ("max_velocity_error_um_s", "y"), "µm/s"),
)
"""The error rows every run table shows: label, summary key (or (key, axis)), unit."""

RUN_ROWS = (
    ("status", "status", ""), ("fault", "fault", ""), ("aborted", "aborted", ""),
    ("timeout", "timeout", ""), ("cycle time", "cycle_time_s", "s"),
    ("path length", "path_length_mm", "mm"),
    *METRIC_ROWS,
    ("elastic oscillation", "elastic_oscillation_um", "µm"),
    ("settling travel", "settling_travel_um", "µm"),
    ("real-time factor", "real_time_factor", "×"),
    ("recording", "recording", ""),
)
"""The rows of one run's summary table (``twin run``, ``demo``, ``home``, ``jog``)."""


def _value(summary: Mapping[str, Any], key: Any) -> Any:
    return summary.get(key[0], {}).get(key[1]) if isinstance(key, tuple) else summary.get(key)


def summary_table(summaries: Mapping[str, Mapping[str, Any]], rows: Sequence[tuple], *,
                  title: str, skip_missing: bool = False) -> Table:
    """A table of run summaries: one row per ``(label, key, unit)`` of ``rows``, one
    column per summary (named by its key in ``summaries``). A value a summary lacks shows
    as "—", or its row is left out with ``skip_missing`` (for a single run)."""
    table = Table(title=title)
    table.add_column("quantity")
    for name in summaries:
        table.add_column(name, justify="right")
    table.add_column("unit")
    for label, key, unit in rows:
        values = [_value(s, key) for s in summaries.values()]
        if skip_missing and all(v is None for v in values):
            continue
        cells = ["—" if v is None else f"{v:.4g}" if isinstance(v, float) else str(v)
                 for v in values]
        table.add_row(label, *cells, unit)
    return table
