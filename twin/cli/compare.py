"""``twin compare``: the same program and machine once per acceleration law, side by side."""

from __future__ import annotations

import dataclasses
import shutil
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
    from twin.analysis.report import margin_text, readable

    table = Table(title=title)
    table.add_column("figure (smaller is better)")
    for law in laws:
        table.add_column(law, justify="right")
    table.add_column("unit")
    table.add_column("winner")
    table.add_column("margin", justify="right")
    for e in verdicts:
        cells = [f"[bold]{readable(e['values'][law])}[/]" if law == e["winner"]
                 else readable(e["values"][law]) for law in laws]
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


def _check_shapers(spec: Any, law: str) -> None:
    """The shapers ``law`` puts on the machine can be built (a mode above the Nyquist rate
    of the controller period cannot be shaped), or a ``ConfigError`` naming ``--profiles``."""
    from twin.controller.shaping import axis_shapers

    cfg = spec.machine_config()
    try:
        axis_shapers(cfg.controller.shaper, spec.belief(cfg).axes, cfg.controller.period)
    except ConfigError as exc:
        raise ConfigError("--profiles", f"{law}: {exc.field}: {exc.message}") from None


def _call_folder(out: Path) -> Path:
    """A folder of its own for this call under ``out`` (time stamp + random suffix): a
    second comparison never overwrites the first's outputs."""

    return output_dir(output_dir(out) / record_id(suffix=4))


def _parse_sweep(text: str) -> tuple[str, list[Any]]:
    """``key=v1,v2,...`` → (key, values); a value with a unit (``600mm/min``) in SI.
    Raises ``ConfigError`` naming ``--sweep`` for an unknown key or a bad value."""
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
                                      "cubic, jerk-limited; LAW+SHAPER adds an input shaper "
                                      "on both axes (zv, mzv, zvd, ei, 2hump-ei, 3hump-ei, "
                                      "none), e.g. trapezoid,trapezoid+mzv."),
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
    from twin.config.shaper_settings import split_profile
    from twin.session.run import RunSpec

    laws = [p.strip().replace("_", "-") for p in profiles.split(",") if p.strip()]
    folder = None
    title = f"{Path(program).name if program else builtin.value} on {machine}"
    try:
        rerun = rerun_target(rerun)
        for law in laws:
            split_profile(law, "--profiles")
        if not laws:
            raise ConfigError("--profiles", "names no law")
        base = RunSpec(machine=machine, controller_model=controller_model,
                       program=str(program) if program else None,
                       builtin=builtin.value, planner=None if planner is None
                       else planner.value, dcu_order=dcu_order,
                       overrides=parse_sets(sets))
        base.belief(base.machine_config())
        for law in laws:                  # a shaper the period cannot act on: before any run
            _check_shapers(dataclasses.replace(base, profile=law), law)
        swept = _parse_sweep(sweep) if sweep is not None else None    # before any file
        folder = _call_folder(out)
        say = _Say(len(laws))
        if swept is not None:
            result = _sweep(base, laws, swept, figure, folder, write_sweep_report, say,
                            title)
        else:
            with say:
                comparison = compare(base, laws, out_dir=folder, on_law=say.law,
                                     recording={"file": True, "none": False}.get(rerun, rerun))
            report = write_report(comparison, folder / "compare.png", title=title)
            result = {"profiles": comparison.summaries(),
                      "verdict": verdict(comparison.summaries()), "report": str(report),
                      "recording": comparison.recording}
            write_json_atomic(folder / "verdict.json", result["verdict"])
        result["folder"] = str(folder)
    except TwinError as exc:
        if folder is not None:      # refused: this call's own folder goes with it
            shutil.rmtree(folder, ignore_errors=True)
        fail(exc, as_json)
    if as_json:
        sys.stdout.write(json_text(result) + "\n")
        return
    # a log (not a terminal) gets the table whole rather than folded to 80 columns
    console = Console(width=None if sys.stdout.isatty() else 160)
    if sweep is None:
        console.print(_table(result["verdict"], laws, title))
        console.print(_wins(result["verdict"]), highlight=False)
    else:
        console.print(_sweep_table(result["sweep"], laws, title))
    console.print(f"report: {result['report']}", highlight=False)
    if result.get("recording"):
        console.print(f"recording: {result['recording']}", highlight=False)


class _Say:
    """Progress of a comparison: a spinner on a terminal; elsewhere (a log, a pipe) one
    plain line on stderr as each law starts."""

    def __init__(self, laws: int):
        self.laws, self.prefix = laws, ""
        self._status = None

    def __enter__(self) -> _Say:
        if err.is_terminal:
            self._status = err.status("starting …")
            self._status.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._status is not None:
            self._status.__exit__(*exc)
            self._status = None

    def law(self, law: str, k: int, n: int) -> None:
        text = f"{self.prefix}{law} ({k + 1} of {n}) …"
        if self._status is not None:
            self._status.update(text)
        else:
            err.print(f"compare: {text}", highlight=False, soft_wrap=True)


def _sweep_table(sweep: dict[str, Any], laws: list[str], title: str) -> Table:
    """The figure and the cycle time per law at each swept value, units in the header."""
    from twin.analysis.report import figure_label, figure_unit
    from twin.config import field_unit

    unit = field_unit(sweep["key"])
    name = sweep["key"].rsplit(".", 1)[-1]
    label = figure_label(sweep["figure"])
    table = Table(title=f"{title}: {label} against {name}")
    table.add_column(f"{name} ({unit})" if unit else name, justify="right")
    for law in laws:
        table.add_column(f"{law}\n{label} ({figure_unit(sweep['figure'])})",
                         justify="right")
        table.add_column(f"{law}\ncycle time (s)", justify="right")
    for i, v in enumerate(sweep["values"]):
        table.add_row(f"{v:g}" if isinstance(v, float) else str(v),
                      *(cell for law in laws for cell in (
                          f"{sweep['table'][law][i]:.4g}",
                          f"{sweep['cycle_time_s'][law][i]:.3f}")))
    return table


def _sweep(base, laws: list[str], swept: tuple[str, list[Any]], figure: str, out: Path,
           plot, say: _Say, title: str) -> dict[str, Any]:
    """Every law at each value of the swept key; the figure against the value."""
    import dataclasses

    from twin.analysis.compare import compare
    from twin.config import field_unit
    from twin.config.overrides import resolve_key

    key, values = swept
    path = resolve_key(key)
    table: dict[str, list[float]] = {law: [] for law in laws}
    cycle: dict[str, list[float]] = {law: [] for law in laws}
    runs: dict[str, list[dict[str, Any]]] = {law: [] for law in laws}
    for i, value in enumerate(values):
        spec = dataclasses.replace(base, overrides={**base.overrides, path: value})
        say.prefix = f"{key} = {value:g}: " if isinstance(value, float) else f"{key} = {value}: "
        with say:
            comparison = compare(spec, laws, out_dir=out, recording=False,
                                 run_id=f"sweep-{i}", on_law=say.law)
        for law, summary in comparison.summaries().items():
            if figure not in summary:
                raise ConfigError("--figure", f"not a summary figure: {figure!r}; e.g. "
                                  + ", ".join(k for k, v in summary.items()
                                              if isinstance(v, float))[:400])
            table[law].append(float(summary[figure]))
            cycle[law].append(float(summary["cycle_time_s"]))
            runs[law].append(summary)
    report = plot(key, values, figure, table, out / "sweep.png", cycle_times=cycle,
                  key_unit=field_unit(path), title=title)
    return {"sweep": {"key": path, "values": values, "figure": figure, "table": table,
                      "cycle_time_s": cycle},
            "profiles": runs, "report": str(report)}


def register(app: typer.Typer) -> None:
    """Add ``twin compare`` to the ``twin`` command."""
    app.command("compare")(compare_cmd)
