"""``twin identify``: calibrate the twin from a machine's own I/O."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import typer
from rich.table import Table

from twin.cli.common import CONTROLLER_MODEL_HELP, choices, err, fail, refusal
from twin.config import AXES
from twin.errors import ExperimentAborted, FitError, TwinError
from twin.system.jsonio import json_text

__all__ = ["register"]

IdentifyAxes = choices("IdentifyAxes", ("x", "y", "xy"))


def identify(
    output: Path = typer.Option(..., "--output", "-o",
                                help="The calibrated machine file to write (.toml)."),
    machine: str = typer.Option("tomsk_xy", "--machine", "-m",
                                help="BASE: the machine model (preset or TOML file) the "
                                     "experiments are scaled with and whose fields the fit "
                                     "replaces."),
    driver: str = typer.Option("sim", "--driver", help="Where the experiments run: sim (the "
                               "twin of BASE), sim:FILE (the twin of another machine file, "
                               "a stand-in for a real one), modbus://HOST:PORT (real I/O "
                               "or twin hil-server)."),
    controller_model: str | None = typer.Option(None, "--controller-model",
                                                help=CONTROLLER_MODEL_HELP),
    axes: IdentifyAxes = typer.Option("xy", "--axes", help="The axes to identify (the "
                                      "other is held in position and keeps BASE's values)."),
    amplitude: float = typer.Option(1.0, "--amplitude", help="Scale of every experiment's "
                                    "speeds, (0, 1]: lower it on a machine with little room."),
    from_log: Path | None = typer.Option(None, "--from-log", help="Fit the experiments "
                                         "recorded in this directory instead of moving "
                                         "the machine."),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for the experiments' "
                             "record (identify-<id>/: experiments.json, .rrd, fit.png)."),
    noise: bool = typer.Option(True, "--noise/--no-noise", help="sim drivers: the machine "
                               "file's sensor noise."),
    rt_priority: int = typer.Option(0, "--rt-priority", min=0, max=99, help="With real "
                                    "I/O: SCHED_FIFO priority of the loop (best effort)."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object on "
                                 "stdout."),
) -> None:
    """Identify the twin's physical parameters from experiments on a machine and write a
    calibrated machine file (BASE with the identified fields replaced)."""
    from twin.identify import identify as run_identify

    def say(msg: str) -> None:
        err.print(msg, highlight=False, soft_wrap=True)

    try:
        result = run_identify(machine, output, driver=driver,
                              controller_model=controller_model, amplitude=amplitude,
                              from_log=from_log, out_dir=out, noise=noise,
                              rt_priority=rt_priority, axes=axes.value, progress=say)
    except ExperimentAborted as exc:
        _stopped(exc, as_json, "ABORTED")
        err.print(f"[bold red]experiments aborted, the machine was stopped:[/] {exc}",
                  highlight=False, soft_wrap=True)
        raise typer.Exit(1) from None
    except FitError as exc:
        _stopped(exc, as_json, "FAILED")
        err.print(f"[bold red]identification failed:[/] {exc}; {output} was not written",
                  highlight=False, soft_wrap=True)
        raise typer.Exit(1) from None
    except TwinError as exc:
        fail(exc, as_json)
    if as_json:
        sys.stdout.write(json_text(result) + "\n")
        return
    from twin.identify.report import FIELDS

    for a in AXES:
        if a not in result["axes"]:
            err.print(f"axis {a}: not excited, BASE's values kept", highlight=False)
            continue
        table = Table(title=f"axis {a}: identified (details: the file's header)")
        for col in ("parameter", "value", "95 % interval", "unit"):
            table.add_column(col, justify="left" if col in ("parameter", "unit")
                             else "right")
        for name, (_where, unit, scale) in FIELDS.items():
            e = result["estimates"][a][name]
            lo = f"{scale * e['low']:.4g}" if math.isfinite(e["low"]) else "?"
            hi = f"{scale * e['high']:.4g}" if math.isfinite(e["high"]) else "?"
            interval = "—" if lo == hi == "?" else f"{lo} … {hi}"
            value = f"{scale * e['value']:.5g}" + ("" if e["identifiable"] else
                                                 " (BASE)" if e["kept"] == "base" else
                                                 " (bound)" if e["kept"] == "bound" else
                                                 " (given " + ", ".join(e["given"]) + ")"
                                                 if e["given"] else " (?)")
            table.add_row(name.replace("_", " "), value, interval, unit)
        d = result["derived"][a]
        table.add_row("K_H (derived)", f"{1e3 * d['K_H']:.5g}", "", "mm/(s·V)")
        err.print(table)
    worst = max(max(v.values()) for v in result["nrmse"].values())
    err.print(f"held-out ramps: NRMSE {100 * worst:.2f} %; machine time "
                  f"{result['machine_time_s']:.1f} s; fit {result['fit_wall_time_s']:.1f} s",
                  highlight=False)
    err.print(f"calibrated machine: {result['calibrated']}\nreport: {result['report']}",
                  highlight=False)


def _stopped(exc: BaseException, as_json: bool, status: str) -> None:
    """With ``--json``: the one object, saying why nothing was identified."""
    if as_json:
        sys.stdout.write(json_text(refusal(exc, status)) + "\n")


def register(app: typer.Typer) -> None:
    """Add ``identify`` to the ``twin`` app."""
    app.command("identify")(identify)
