"""``twin compare``: the same program and machine once per acceleration law, side by side."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.table import Table

from twin.cli_common import CONTROLLER_MODEL_HELP, METRIC_ROWS, err, fail, summary_table
from twin.errors import ConfigError, TwinError
from twin.jsonio import json_text, output_dir

__all__ = ["ROWS", "register"]


ROWS = (
    ("cycle time", "cycle_time_s", "s"),
    *METRIC_ROWS,
    ("peak reference jerk |Δa|/T", "peak_reference_jerk_m_per_s3", "m/s³"),
    ("speed jump at junctions", "junction_speed_jump_mm_per_s", "mm/s"),
    ("elastic oscillation", "elastic_oscillation_um", "µm"),
    ("settling travel (loop lag)", "settling_travel_um", "µm"),
)
"""Rows of the comparison table: label, summary key (or (key, axis)), unit."""


def _table(summaries: dict[str, dict[str, Any]], title: str) -> Table:
    return summary_table(summaries, ROWS, title=title)


def _parse_sweep(text: str) -> tuple[str, list[Any]]:
    from twin.overrides import parse_sets

    key, sep, values = text.partition("=")
    if not sep or not values.strip():
        raise ConfigError("--sweep", f"expected key=v1,v2,..., got {text!r}")
    parsed = [next(iter(parse_sets([f"{key}={v}"]).values())) for v in values.split(",")]
    return key.strip(), parsed


def compare_cmd(
    program: Path | None = typer.Argument(None, help="G-code file; none: the built-in "
                                           "program (--builtin)."),
    profiles: str = typer.Option("trapezoid,parabolic", "--profiles",
                                 help="Comma-separated laws: trapezoid, parabolic, cosine, "
                                      "cubic, jerk-limited."),
    machine: str = typer.Option("tomsk_xy", "--machine", "-m",
                                help="Machine preset name or TOML file (the plant)."),
    controller_model: str | None = typer.Option(None, "--controller-model",
                                                help=CONTROLLER_MODEL_HELP),
    sets: list[str] = typer.Option([], "--set", help="key=value overrides (repeatable)."),
    planner: str | None = typer.Option(None, help="lookahead or stop."),
    dcu_order: int | None = typer.Option(None, "--dcu-order", min=0, max=3),
    builtin: str = typer.Option("default", "--builtin",
                                help="Built-in program when no PROGRAM is given."),
    out: Path = typer.Option(Path("runs/compare"), "--out", help="Output directory."),
    sweep: str | None = typer.Option(None, "--sweep", help="key=v1,v2,...: run every law "
                                     "at each value and plot --figure against it."),
    figure: str = typer.Option("max_contour_error_um", "--figure",
                               help="Summary figure plotted by --sweep."),
    rerun: bool = typer.Option(True, "--rerun/--no-rerun", help="Write the overlaid .rrd."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """Run one program once per acceleration law; table, PNG report and one overlaid .rrd."""
    from twin.compare import compare
    from twin.compare_report import write_report, write_sweep_report
    from twin.controller.profiles.laws import check_law
    from twin.overrides import parse_sets
    from twin.run import RunSpec

    laws = [p.strip().replace("_", "-") for p in profiles.split(",") if p.strip()]
    try:
        for law in laws:
            check_law(law)
        base = RunSpec(machine=machine, controller_model=controller_model,
                       program=str(program) if program else None,
                       builtin=builtin, planner=planner, dcu_order=dcu_order,
                       overrides=parse_sets(sets))
        base.belief(base.machine_config())
        output_dir(out)
        if sweep is not None:
            result = _sweep(base, laws, sweep, figure, out, write_sweep_report)
        else:
            with err.status(f"running {len(laws)} laws …"):
                comparison = compare(base, laws, out_dir=out, recording=rerun)
            report = write_report(comparison, out / "compare.png",
                                  title=f"{program or builtin} on {machine}")
            result = {"profiles": comparison.summaries(), "report": str(report),
                      "recording": comparison.recording}
    except TwinError as exc:
        fail(exc)
    if as_json:
        sys.stdout.write(json_text(result) + "\n")
        return
    console = Console()
    if sweep is None:
        console.print(_table(result["profiles"], f"{program or builtin} on {machine}"))
    else:
        table = Table(title=f"{figure} against {result['sweep']['key']}")
        table.add_column("value")
        for law in laws:
            table.add_column(law, justify="right")
        for i, v in enumerate(result["sweep"]["values"]):
            table.add_row(str(v), *(f"{result['sweep']['table'][law][i]:.4g}" for law in laws))
        console.print(table)
    console.print(f"report: {result['report']}", highlight=False)
    if result.get("recording"):
        console.print(f"recording: {result['recording']}", highlight=False)


def _sweep(base, laws: list[str], text: str, figure: str, out: Path, plot) -> dict[str, Any]:
    """Every law at each value of the swept key; the figure against the value."""
    import dataclasses

    from twin.compare import compare
    from twin.overrides import resolve_key

    key, values = _parse_sweep(text)
    path = resolve_key(key)
    table: dict[str, list[float]] = {law: [] for law in laws}
    runs: dict[str, list[dict[str, Any]]] = {law: [] for law in laws}
    for i, value in enumerate(values):
        spec = dataclasses.replace(base, overrides={**base.overrides, path: value})
        with err.status(f"{key} = {value} …"):
            comparison = compare(spec, laws, out_dir=out, recording=False,
                                 run_id=f"sweep-{i}")
        for law, summary in comparison.summaries().items():
            if figure not in summary:
                raise ConfigError("--figure", f"not a summary figure: {figure!r}; e.g. "
                                  + ", ".join(k for k, v in summary.items()
                                              if isinstance(v, float))[:400])
            table[law].append(float(summary[figure]))
            runs[law].append(summary)
    report = plot(key, values, figure, table, out / "sweep.png")
    return {"sweep": {"key": path, "values": values, "figure": figure, "table": table},
            "profiles": runs, "report": str(report)}


def register(app: typer.Typer) -> None:
    """Add ``twin compare`` to the ``twin`` command."""
    app.command("compare")(compare_cmd)
