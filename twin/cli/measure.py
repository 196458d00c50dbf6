"""``twin measure``: the frequency response of one axis, with its coherence, resonances and
(position loop) margins, against the linearised twin of the controller's belief."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import typer
from rich.table import Table

from twin.cli.common import CONTROLLER_MODEL_HELP, choices, err, fail, refusal
from twin.errors import ConfigError, ExperimentAborted, TwinError
from twin.system.jsonio import json_text

__all__ = ["register"]

Axis = choices("MeasureAxis", ("x", "y"))
Loop = choices("MeasureLoop", ("mechanics", "speed", "position"))
Sensor = choices("MeasureSensor", ("accelerometer", "motor"))
Signal = choices("MeasureSignal", ("multisine", "prbs", "hammer"))

_OPTIONS = {"amplitude": "--amplitude", "offset": "--offset", "f_max": "--f-max",
            "f_min": "--f-min", "averages": "--averages", "sensor": "--sensor",
            "driver": "--driver", "axis": "--axis", "loop": "--loop",
            "excitation": "--excitation", "out": "--out",
            "hammer_force": "--hammer-force", "hammer_duration": "--hammer-duration",
            "periods": "--periods"}
"""The options a refusal of ``measure`` may name, by the field it raised on."""


def measure(
    machine: str = typer.Option("tomsk_xy", "--machine", "-m", help="The machine model "
                                "(preset or TOML file): its I/O, limits and controller."),
    driver: str = typer.Option("sim", "--driver", help="sim (the twin of --machine), "
                               "sim:FILE (the twin of another machine file, a stand-in for "
                               "a real one), modbus://HOST:PORT (real I/O or twin "
                               "hil-server)."),
    axis: Axis = typer.Option("x", "--axis", help="The axis measured (the other is held)."),
    loop: Loop = typer.Option("mechanics", "--loop", help="mechanics: table acceleration "
                              "per DAC volt; speed: table speed per DAC volt (the drive's "
                              "speed loop); position: the position loop opened at the DAC "
                              "(margins, bandwidth)."),
    sensor: Sensor = typer.Option("accelerometer", "--sensor", help="accelerometer: one on "
                                  "the table (mounted on the twin for the test); motor: the "
                                  "encoder and tacho alone."),
    excitation: Signal = typer.Option("multisine", "--excitation", help="multisine "
                                      "(random-phase realisations), PRBS, or hammer: an "
                                      "impact test, the table struck while the drives "
                                      "hold (sim drivers only; accelerance per newton)."),
    hammer_force: float | None = typer.Option(None, "--hammer-force", help="hammer: peak "
                                              "force of a blow (N); default 2000."),
    hammer_duration: float | None = typer.Option(None, "--hammer-duration", help="hammer: "
                                                 "length of a blow (ms; a half-sine, "
                                                 "usable to ≈ 1.3/length); default 2."),
    amplitude: float | None = typer.Option(None, "--amplitude", help="Peak of the "
                                           "excitation as table speed (mm/s); default a "
                                           "quarter of the speed limit."),
    offset: float | None = typer.Option(None, "--offset", help="Table speed kept meanwhile "
                                        "(mm/s), so that friction does not reverse; default "
                                        "half the speed limit."),
    averages: int = typer.Option(8, "--averages", help="Realisations (multisine), "
                                 "periods (PRBS) or blows (hammer) averaged."),
    periods: int | None = typer.Option(None, "--periods", help="multisine: periods "
                                       "measured per realisation (each realisation runs "
                                       "the other way). Default 8 with the accelerometer, "
                                       "else 1."),
    f_min: float | None = typer.Option(None, "--f-min", help="Lowest line (Hz); sets the "
                                       "resolution. Default 1 Hz."),
    f_max: float | None = typer.Option(None, "--f-max", help="Highest line (Hz), at most the "
                                       "Nyquist frequency (the accelerometer's for what it "
                                       "sees, else the controller's)."),
    controller_model: str | None = typer.Option(None, "--controller-model",
                                                help=CONTROLLER_MODEL_HELP),
    out: Path = typer.Option(Path("runs"), "--out", help="Directory for measure-<id>/ "
                             "(measurement.json, bode.png, measurement.rrd)."),
    noise: bool = typer.Option(True, "--noise/--no-noise", help="sim drivers: the machine "
                               "file's sensor noise."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object on "
                                 "stdout."),
) -> None:
    """Measure one axis' frequency response: coherence, resonances, the position loop's
    margins, and a Bode plot against the twin's linearised prediction."""
    from twin.analysis.frequency import measure as run_measure

    def say(msg: str) -> None:
        err.print(msg, highlight=False, soft_wrap=True)

    try:
        result = run_measure(
            machine, driver=driver, axis=axis.value, loop=loop.value, sensor=sensor.value,
            amplitude=None if amplitude is None else amplitude * 1e-3,
            offset=None if offset is None else offset * 1e-3, averages=averages,
            periods=periods,
            f_min=f_min, f_max=f_max, excitation=excitation.value, out_dir=out,
            controller_model=controller_model, noise=noise, hammer_force=hammer_force,
            hammer_duration=None if hammer_duration is None else hammer_duration * 1e-3,
            progress=say)
    except ExperimentAborted as exc:
        if as_json:
            sys.stdout.write(json_text(refusal(exc, "ABORTED")) + "\n")
        err.print(f"[bold red]measurement aborted, the machine was stopped:[/] {exc}",
                  highlight=False, soft_wrap=True)
        raise typer.Exit(1) from None
    except ConfigError as exc:
        option = _OPTIONS.get(exc.field)
        fail(ConfigError(option, exc.message) if option else exc, as_json)
    except TwinError as exc:
        fail(exc, as_json)
    doc = result.to_json()
    if as_json:
        sys.stdout.write(json_text({"status": "OK", **_summary(doc)}) + "\n")
        return
    _print(doc)


def _summary(doc: dict) -> dict:
    """The JSON's figures without the per-line arrays (they are in measurement.json)."""
    return {k: v for k, v in doc.items() if k not in ("frequency_hz", "response",
                                                       "coherence", "prediction")}


def _print(doc: dict) -> None:
    table = Table(title=f"axis {doc['axis']}: resonances ({doc['sensor']}, at "
                        f"{doc['position_mm']:.1f} mm)")
    for col in ("frequency (Hz)", "± sd (Hz)", "damping ζ", "peak over rigid (dB)"):
        table.add_column(col, justify="right")
    spread = doc.get("resonance_sd_hz") or [None] * len(doc["resonances"])
    for r, sd in zip(doc["resonances"], spread, strict=True):
        table.add_row(f"{r['frequency_hz']:.2f}", "–" if sd is None else f"{sd:.2f}",
                      f"{r['damping']:.3f}", f"{r['peak_db']:+.1f}")
    err.print(table)
    for name, m in (("measured", doc["margins"]), ("design", doc.get("design_margins"))):
        if m:
            gm = m["gain_margin_db"]
            err.print(f"position loop ({name}): gain margin "
                      f"{'∞' if gm is None else f'{gm:.1f} dB'}, phase margin "
                      f"{_f(m['phase_margin_deg'], '°')} at {_f(m['crossover_hz'], ' Hz')}, "
                      f"bandwidth {_f(m['bandwidth_hz'], ' Hz')}", highlight=False)
    for u in doc["unseen"]:
        err.print(f"not seen: {u}", highlight=False)
    a = doc["agreement"]
    if a["lines_coherent"]:
        err.print(f"against the linearised twin, on the {a['lines_coherent']} lines with "
                  f"γ² ≥ 0.9: within {a['max_gain_error_db']:.2f} dB and "
                  f"{a['max_phase_error_deg']:.1f}°", highlight=False)
    paths = doc.get("paths", {})
    if paths:
        err.print(f"Bode plot: {paths['bode']}\nrecord: {paths['record']}", highlight=False)


def _f(value, unit: str) -> str:
    return "—" if value is None or not math.isfinite(value) else f"{value:.2f}{unit}"


def register(app: typer.Typer) -> None:
    """Add ``measure`` to the ``twin`` app."""
    app.command("measure")(measure)
