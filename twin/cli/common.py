"""What every ``twin`` command shares: the stderr console and the one way to fail.

Human output goes to stderr (tables may go to stdout when no ``--json`` is asked for);
``--json`` prints exactly one JSON object on stdout, a refusal's too (``refusal``); bad
input exits with code 2 and a message naming the place.
"""

from __future__ import annotations

import enum
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from twin.errors import ConfigError, GCodeError
from twin.system.jsonio import drop_unused_outputs, json_text

__all__ = [
    "CONTROLLER_MODEL_HELP",
    "METRIC_ROWS",
    "RUN_ROWS",
    "err",
    "fail",
    "parse_position",
    "print_paths",
    "refusal",
    "summary_table",
    "usage_text",
]

CONTROLLER_MODEL_HELP = (
    "The machine as the controller believes it to be (preset or TOML file): its gains, "
    "DCU, feed-forward and corner model are derived from this model; the physics runs "
    "--machine. Default: the machine itself.")
"""Help of every command's ``--controller-model``."""

err = Console(stderr=True)
"""Console on stderr for messages, progress and errors."""


def choices(name: str, values: Sequence[str]) -> type[enum.Enum]:
    """A str Enum of fixed choices: typer lists them in the help and refuses anything else
    (exit 2, naming the option and the choices)."""
    return enum.Enum(name, {v.replace("-", "_"): v for v in values}, type=str)  # type: ignore


PROGRAM_NAMES = ("default", "compact", "tiny", "spline_line", "corner")
"""The built-in programs, as ``twin.controller.library.PROGRAMS`` names them (a test keeps
the two equal): written out so that ``twin --help`` does not import the planner."""
LAW_NAMES = ("trapezoid", "parabolic", "cosine", "cubic", "jerk-limited")
"""The acceleration laws, as ``twin.controller.profiles.laws.LAWS`` names them."""


Builtin = choices("Builtin", PROGRAM_NAMES)
"""The built-in programs (``twin.controller.library.PROGRAMS``): ``twin run --builtin``,
``twin compare --builtin`` and ``twin tune --program`` take the same names."""
Law = choices("Law", LAW_NAMES)
"""The acceleration laws."""
PlannerMode = choices("PlannerMode", ("lookahead", "stop"))
Axis = choices("Axis", ("x", "y"))
Axes = choices("Axes", ("x", "y", "xy", "yx"))

RERUN_HELP = ("Where the telemetry goes: file (a .rrd beside the .json in --out), none, or "
              "PATH.rrd")
"""The one ``--rerun`` convention; ``twin run`` adds the live modes spawn and serve."""


def rerun_target(value: str, *, live: bool = False) -> str:
    """Check a ``--rerun`` value: ``file``, ``none``, a path ending in ``.rrd`` (and with
    ``live``, ``spawn`` or ``serve``). Raises ``ConfigError`` naming ``--rerun``."""
    modes = ("file", "none", *(("spawn", "serve") if live else ()))
    if value in modes or value.endswith(".rrd"):
        return value
    raise ConfigError("--rerun", f"must be {', '.join(modes)} or a path ending in .rrd, got "
                      f"{value!r}")


def parse_position(text: str | None, option: str = "--from") -> tuple[float, float] | None:
    """``"X,Y"`` in mm (the one convention of every command's coordinates) → (x, y) in m;
    None for None. Raises ``ConfigError`` naming ``option``."""
    if text is None:
        return None
    parts = text.split(",")
    try:
        if len(parts) != 2:
            raise ValueError
        x, y = (float(v) * 1e-3 for v in parts)
    except ValueError:
        raise ConfigError(option, f"expected X,Y in mm (e.g. 50,20), got {text!r}") from None
    return (x, y)


_PLAIN = {
    "less_than_equal": "must be at most {le}", "less_than": "must be less than {lt}",
    "greater_than_equal": "must be at least {ge}", "greater_than": "must be more than {gt}",
    "int_parsing": "must be a whole number", "int_from_float": "must be a whole number",
    "float_parsing": "must be a number", "bool_parsing": "must be true or false",
    "finite_number": "must be a finite number",
}
"""Plain words for the checks typer leaves to pydantic (its ``Input should be ...``)."""


def usage_text(exc: BaseException) -> str:
    """The one line of a usage error (an option's bad value, an unknown option): click's
    message on one line, and a value typer checked with pydantic in plain words, naming the
    option and the value (``--dcu-order: must be at most 3, got 7``)."""
    cause = exc.__cause__
    errors = getattr(cause, "errors", None)
    param = getattr(exc, "param", None)
    if callable(errors) and param is not None:
        name = (param.opts[0] if getattr(param, "opts", None) else param.name) or "value"
        found = list(errors())
        if found and all(e.get("type") in _PLAIN for e in found):
            return f"{name}: " + "; ".join(
                f"{_PLAIN[e['type']].format(**e.get('ctx', {}))}, got {e.get('input')!s}"
                for e in found)
    format_message = getattr(exc, "format_message", None)
    message = format_message() if format_message is not None else str(exc)
    return " ".join(message.split())    # click lists choices on lines of their own


def refusal(exc: BaseException, status: str = "REFUSED") -> dict[str, Any]:
    """The one JSON object ``--json`` prints when a command stops on ``exc``: its status,
    the message's first line as ``error``, and the place it names (``field``; ``line``,
    ``column``, ``code`` and ``file`` of a G-code error)."""
    doc: dict[str, Any] = {"status": status, "error": str(exc).splitlines()[0] if str(exc)
                           else type(exc).__name__}
    if isinstance(exc, ConfigError):
        doc["field"] = exc.field
    if isinstance(exc, GCodeError):
        doc.update(line=exc.line, column=exc.column, code=exc.code, file=exc.file)
    return doc


def fail(exc: BaseException, as_json: bool = False, *, code: int = 2,
         status: str = "REFUSED") -> NoReturn:
    """Print ``exc`` (which names its place) on stderr and exit with ``code`` (2: bad
    input); with ``as_json``, first its ``refusal`` object on stdout, the one object
    ``--json`` promises."""
    if as_json:
        sys.stdout.write(json_text(refusal(exc, status)) + "\n")
        sys.stdout.flush()
    err.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
    if code == 2:                       # refused: the folders made for its results go
        drop_unused_outputs()
    raise typer.Exit(code)


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
)
"""The rows of one run's summary table (``twin run``, ``demo``, ``home``, ``jog``); the
recording's path follows the table on a line of its own (``print_paths``), whole at any
width."""


def print_paths(console: Console, summary: Mapping[str, Any], out: Path | None = None
                ) -> None:
    """The files of a run, one line each, never cut: ``record:`` (the summary's .json in
    ``out``) and ``recording:`` (its .rrd)."""
    if out is not None:
        console.print(f"record: {out / (summary['run_id'] + '.json')}", highlight=False,
                      soft_wrap=True)
    if summary.get("recording"):
        console.print(f"recording: {summary['recording']}", highlight=False, soft_wrap=True)


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


def report_dry_run(s: dict, out: Path, as_json: bool) -> None:
    """Print a dry run's summary (``twin.session.dry_run``): one JSON object, or its table."""
    if as_json:
        sys.stdout.write(json_text({k: v for k, v in s.items() if k != "spec"}) + "\n")
        return
    what = s["program"] or ", ".join(s["commands"])
    table = Table(title=f"dry run {s['run_id']}: {what} on {s['machine']} (planned, "
                        "nothing driven)")
    for col in ("quantity", "value", "limit", "share of limit"):
        table.add_column(col, justify="left" if col == "quantity" else "right")
    table.add_row("status", s["status"], "", "")
    table.add_row("cycle time (s)", f"{s['cycle_time_s']:.3f}", "", "")
    table.add_row("path length (mm)", f"{s['path_length_mm']:.4g}", "", "")
    table.add_row("peak feed (mm/min)", f"{s['peak_feed_mm_per_min']:.4g}",
                  f"{s['feed_limit_mm_per_min']:.4g}",
                  f"{s['peak_feed_mm_per_min'] / s['feed_limit_mm_per_min']:.0%}")
    for ax, d in s["axes"].items():
        for q, f in d.items():
            table.add_row(f"{ax.upper()} peak {q} ({f['unit']})", f"{f['peak']:.4g}",
                          f"{f['limit']:.4g}", f"{f['ratio']:.0%}")
    for ax, (lo, hi) in s["extent_mm"].items():
        zone = (s["work_zone_mm"] or {}).get(ax)
        table.add_row(f"{ax.upper()} extent (mm)", f"{lo:.4g} … {hi:.4g}",
                      "" if zone is None else f"{zone[0]:.4g} … {zone[1]:.4g}", "")
    Console().print(table)
    if s["over_limits"]:
        err.print(f"[yellow]warning:[/] the planned reference exceeds the axis limits: "
                  f"{', '.join(s['over_limits'])}", highlight=False)
    Console().print(f"record: {out / (s['run_id'] + '.json')}", highlight=False)
