"""``twin compare``: the same program and machine once per acceleration law, side by side."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.table import Table

from twin.cli.common import (
    CONTROLLER_MODEL_HELP,
    RERUN_HELP,
    Builtin,
    PlannerMode,
    err,
    fail,
    rerun_target,
)
from twin.config.overrides import SET_HELP
from twin.errors import ConfigError, TwinError
from twin.system.jsonio import json_text, output_dir, record_id, write_json_atomic

__all__ = ["register"]


def _table(verdicts: list[dict[str, Any]], laws: list[str], title: str) -> Table:
    """Every figure per law, the winner (bold) and its margin."""
    from twin.analysis.report import margin_text

    table = Table(title=title)
    table.add_column("figure (smaller is better)")
    for law in laws:
        table.add_column(law, justify="right")
    table.add_column("unit")
    table.add_column("winner")
    table.add_column("margin", justify="right")
    for e in verdicts:
        cells = [f"[bold]{e['values'][law]:.4g}[/]" if law == e["winner"]
                 else f"{e['values'][law]:.4g}" for law in laws]
        table.add_row(e["label"], *cells, e["unit"], e["winner"] or "tie", margin_text(e))
    return table


def _wins(verdicts: list[dict[str, Any]]) -> str:
    """One line: how many figures each law wins, and which ("parabolic wins 8 of 11 ...")."""
    by_law: dict[str, list[str]] = {}
    for e in verdicts:
        by_law.setdefault(e["winner"] or "tie", []).append(e["label"])
    parts = [f"[bold]{law}[/] wins {len(labels)} of {len(verdicts)} figures"
             + (f" ({', '.join(labels)})" if len(labels) <= 3 else "")
             for law, labels in sorted(by_law.items(), key=lambda kv: -len(kv[1]))
             if law != "tie"]
    if "tie" in by_law:
        parts.append(f"tied: {', '.join(by_law['tie'])}")
    return "; ".join(parts)


def _call_folder(out: Path) -> Path:
    """A folder of its own for this call under ``out`` (time stamp + random suffix): a
    second comparison never overwrites the first's outputs."""

    return output_dir(output_dir(out) / record_id(suffix=4))


def _parse_sweep(text: str) -> tuple[str, list[Any]]:
    """``key=v1,v2,...`` → (key, values); a value with a unit (``600mm/min``) in SI."""
    from twin.config.overrides import parse_sets, resolve_key
    from twin.config.quantities import to_si
    from twin.config.schema import field_meta

    key, sep, values = text.partition("=")
    if not sep or not values.strip():
        raise ConfigError("--sweep", f"expected key=v1,v2,..., got {text!r}")
    unit = str(field_meta(resolve_key(key)).get("unit", ""))
    parsed = []
    for v in values.split(","):
        value = next(iter(parse_sets([f"{key}={v}"]).values()))
        parsed.append(to_si(value, unit, key.strip()) if isinstance(value, str) and unit
                      else value)
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
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    planner: PlannerMode | None = typer.Option(None, help="Look ahead, or stop at every "
                                               "node (default: the machine's)."),
    dcu_order: int | None = typer.Option(None, "--dcu-order", min=0, max=3,
                                         help="Order of the digital correcting device."),
    builtin: Builtin = typer.Option("default", "--builtin",
                                    help="Built-in program when no PROGRAM is given."),
    out: Path = typer.Option(Path("runs/compare"), "--out", help="Output directory: each "
                             "call writes into a new folder of its own inside it."),
    sweep: str | None = typer.Option(None, "--sweep", help="key=v1,v2,...: run every law "
                                     "at each value and plot --figure against it."),
    figure: str = typer.Option("max_contour_error_um", "--figure",
                               help="Summary figure plotted by --sweep."),
    rerun: str = typer.Option("file", "--rerun", help=RERUN_HELP + " (the laws overlaid in "
                              "one recording)."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """Run one program once per acceleration law; table, PNG report and one overlaid .rrd."""
    from twin.analysis.compare import compare, verdict
    from twin.analysis.report import write_report, write_sweep_report
    from twin.config.overrides import parse_sets
    from twin.controller.profiles.laws import check_law
    from twin.session.run import RunSpec

    laws = [p.strip().replace("_", "-") for p in profiles.split(",") if p.strip()]
    try:
        rerun = rerun_target(rerun)
        for law in laws:
            check_law(law)
        base = RunSpec(machine=machine, controller_model=controller_model,
                       program=str(program) if program else None,
                       builtin=builtin.value, planner=None if planner is None
                       else planner.value, dcu_order=dcu_order,
                       overrides=parse_sets(sets))
        base.belief(base.machine_config())
        folder = _call_folder(out)
        if sweep is not None:
            result = _sweep(base, laws, sweep, figure, folder, write_sweep_report)
        else:
            with err.status(f"running {len(laws)} laws …"):
                comparison = compare(base, laws, out_dir=folder,
                                     recording={"file": True, "none": False}.get(rerun, rerun))
            report = write_report(comparison, folder / "compare.png",
                                  title=f"{program or builtin.value} on {machine}")
            result = {"profiles": comparison.summaries(),
                      "verdict": verdict(comparison.summaries()), "report": str(report),
                      "recording": comparison.recording}
            write_json_atomic(folder / "verdict.json", result["verdict"])
        result["folder"] = str(folder)
    except TwinError as exc:
        fail(exc, as_json)
    if as_json:
        sys.stdout.write(json_text(result) + "\n")
        return
    # a log (not a terminal) gets the table whole rather than folded to 80 columns
    console = Console(width=None if sys.stdout.isatty() else 160)
    if sweep is None:
        console.print(_table(result["verdict"], laws, f"{program or builtin.value} on {machine}"))
        console.print(_wins(result["verdict"]), highlight=False)
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

    from twin.analysis.compare import compare
    from twin.config import field_unit
    from twin.config.overrides import resolve_key

    key, values = _parse_sweep(text)
    path = resolve_key(key)
    table: dict[str, list[float]] = {law: [] for law in laws}
    cycle: dict[str, list[float]] = {law: [] for law in laws}
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
            cycle[law].append(float(summary["cycle_time_s"]))
            runs[law].append(summary)
    report = plot(key, values, figure, table, out / "sweep.png", cycle_times=cycle,
                  key_unit=field_unit(path))
    return {"sweep": {"key": path, "values": values, "figure": figure, "table": table,
                      "cycle_time_s": cycle},
            "profiles": runs, "report": str(report)}


def register(app: typer.Typer) -> None:
    """Add ``twin compare`` to the ``twin`` command."""
    app.command("compare")(compare_cmd)
