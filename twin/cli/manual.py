"""``twin experiment``, ``twin home`` and ``twin jog``: typical experiments and manual mode."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from twin.cli.common import (
    CONTROLLER_MODEL_HELP,
    RERUN_HELP,
    RUN_ROWS,
    Axes,
    Axis,
    choices,
    err,
    fail,
    parse_position,
    print_paths,
    report_dry_run,
    rerun_target,
    summary_table,
)
from twin.config.overrides import SET_HELP
from twin.errors import TwinError
from twin.system.jsonio import json_text

__all__ = ["register"]

Experiment = choices("Experiment", ("step", "ramp"))



def experiment(
    kind: Experiment = typer.Argument(..., help="The input: a step or a ramp."),
    axis: Axis = typer.Option("x", "--axis", help="The axis."),
    amplitude: float = typer.Option(..., "--amplitude", help="Closed loop: step (mm) or "
                                    "ramp rate (mm/s). Open loop: volts or volts/s."),
    duration: float = typer.Option(1.0, help="Record length after the input (s)."),
    open_loop: bool = typer.Option(False, "--open-loop",
                                   help="Apply to the drive's speed reference instead."),
    machine: str = typer.Option("tomsk_xy", "--machine", "-m",
                                help="Machine preset name or TOML file (the plant)."),
    controller_model: str | None = typer.Option(None, "--controller-model",
                                                help=CONTROLLER_MODEL_HELP),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    rerun: str = typer.Option("file", "--rerun", help=RERUN_HELP + "."),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for the record (.json "
                             "and .rrd)."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """A typical experiment (seed 000): step or ramp response of one axis; its figures
    and recording are written like a run's."""
    from twin.config import load_machine
    from twin.config.overrides import parse_sets
    from twin.session.experiments import record_experiment

    kind, axis = kind.value, axis.value
    try:
        rerun = rerun_target(rerun)
        cfg = load_machine(machine).with_overrides(parse_sets(sets))
        belief = load_machine(controller_model) if controller_model else None
        scale = 1.0 if open_loop else 1e-3
        result, summary = record_experiment(cfg, out_dir=out, rerun=rerun, belief=belief,
                                            kind=kind, axis=axis,
                                            amplitude=amplitude * scale, duration=duration,
                                            open_loop=open_loop)
    except TwinError as exc:
        fail(exc, as_json)
    report = result.to_report()
    if as_json:
        sys.stdout.write(json_text({**report, "run_id": summary["run_id"],
                                    "recording": summary["recording"]}) + "\n")
        return
    table = Table(title=f"{kind} response, axis {axis}, {'open' if open_loop else 'closed'}"
                        " loop")
    table.add_column("figure")
    table.add_column("value", justify="right")
    quantity = "speed (µm/s)" if open_loop else "position (µm)"
    for label, value in (("final " + quantity, report["final_value"]),
                         ("rise time (ms)", report["rise_time_ms"]),
                         ("overshoot (%)", report["overshoot_percent"]),
                         ("settling time, 2 % (ms)", report["settling_time_ms"]),
                         ("steady-state error (µm or µm/s)", report["steady_state_error"]),
                         ("elastic mode (Hz)", report["elastic_mode_hz"])):
        table.add_row(label, "—" if math.isnan(value) else f"{value:.4g}")
    Console().print(table)
    print_paths(Console(), summary, Path(out))


def _manual(commands: list[str], machine: str, out: Path, as_json: bool,
            start: tuple[float, float] | None, dry_run: bool,
            ignore_soft_limits: bool, title: str) -> None:
    from twin.session.run import RunSpec, run

    sets = {"controller.soft_limits": False} if ignore_soft_limits else {}
    try:
        spec = RunSpec(machine=machine, builtin="none", commands=tuple(commands),
                       start=start, overrides=sets)
        if dry_run:
            from twin.session.dry_run import dry_run as plan_only

            planned = plan_only(spec, out_dir=out)
            report_dry_run(planned, out, as_json)
            if planned["status"] != "FINISHED":
                raise typer.Exit(1)
            return
        result = run(spec, out_dir=out)
    except TwinError as exc:
        fail(exc, as_json)
    s = result.summary
    pos = result.record["position"][-1] if len(result.record["t"]) else [math.nan] * 2
    s["final_position_mm"] = {"x": pos[0] * 1e3, "y": pos[1] * 1e3}
    if as_json:
        sys.stdout.write(json_text({k: v for k, v in s.items()
                                    if k not in ("config", "spec")}) + "\n")
    else:
        Console().print(summary_table({"value": s}, RUN_ROWS, title=title, skip_missing=True))
        Console().print(f"final position: X {pos[0] * 1e3:.4f} mm, Y {pos[1] * 1e3:.4f} mm")
        print_paths(Console(), s, out)
    if s["status"] != "FINISHED":
        why = s.get("fault") or s.get("aborted") or s.get("timeout") or ""
        err.print(f"[bold red]stopped:[/] {s['status']} {why}".rstrip())
        raise typer.Exit(1)


def home(
    axes: Axes = typer.Option("xy", "--axes", help="Axes to home, in this order."),
    machine: str = typer.Option("tomsk_xy", "--machine", "-m", help="Machine preset name "
                                "or TOML file."),
    start: str | None = typer.Option(None, "--from", help="Where the table stands at the "
                                     "start, X,Y in mm (default: mid travel)."),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for run records."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """Reference search: move each axis to its home switch and set the coordinates."""
    axes = axes.value
    from twin.config import load_machine

    try:
        pos = parse_position(start)
        if pos is None:
            cfg = load_machine(machine)
            pos = tuple(0.5 * (a.switches.limit_min + a.switches.limit_max)
                        for a in cfg.axes.values())
    except TwinError as exc:
        fail(exc, as_json)
    _manual([f"home {a}" for a in axes], machine, out, as_json, pos, False, False,
            title=f"home {', '.join(a.upper() for a in axes)}")


def jog(
    axis: Axis = typer.Option(..., "--axis", help="The axis."),
    distance: float = typer.Option(..., "--distance", help="Relative move (mm)."),
    machine: str = typer.Option("tomsk_xy", "--machine", "-m", help="Machine preset name "
                                "or TOML file."),
    start: str | None = typer.Option(None, "--from", help="Start position X,Y in mm "
                                     "(default: the home position)."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Plan the move against the "
                                 "machine's limits without the drives or the physics (it "
                                 "never trips)."),
    ignore_soft_limits: bool = typer.Option(False, "--ignore-soft-limits", help="Let the "
                                            "move run into the end switches (testing)."),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for run records."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """Jog one axis by a distance, within the soft limits of the work zone."""
    axis = axis.value
    try:
        pos = parse_position(start)
    except TwinError as exc:
        fail(exc, as_json)
    _manual([f"jog {axis} {distance:.15g} mm"], machine, out, as_json, pos, dry_run,
            ignore_soft_limits, title=f"jog {axis.upper()} {distance:+g} mm")


def register(app: typer.Typer) -> None:
    """Add these commands to the ``twin`` app."""
    app.command()(experiment)
    app.command()(home)
    app.command()(jog)
