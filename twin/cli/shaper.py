"""``twin shaper``: which input shaper, at which acceleration (``twin.analysis.shaper``)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.table import Table

from twin.cli.common import CONTROLLER_MODEL_HELP, err, fail
from twin.config.overrides import SET_HELP
from twin.errors import ConfigError, TwinError
from twin.system.jsonio import json_text, output_dir, record_id, write_json_atomic

__all__ = ["register"]


def _modes(spec: Any, driver: str | None) -> list[Any]:
    """The modes to shape: measured through ``driver`` (``twin measure``), or the machine
    file's model."""
    from twin.analysis.shaper import Mode, model_modes

    if driver is None:
        return model_modes(spec.machine_config())
    from twin.analysis.frequency import measure

    modes = []
    for axis in ("x", "y"):
        fr = measure(spec.machine, driver=driver, axis=axis, loop="mechanics",
                     controller_model=spec.controller_model)
        if not fr.resonances:
            raise ConfigError("--driver", f"the measurement on {axis} found no resonance")
        r = min(fr.resonances, key=lambda r: r.frequency)
        modes.append(Mode(axis, r.frequency, r.damping, f"measured on {driver}"))
    return modes


def _table(rows: list[dict[str, Any]], best: str, tolerance_um: float, title: str) -> Table:
    table = Table(title=title)
    for name, justify in (("shaper", "left"), ("vibration at f", "right"),
                          ("worst f±band", "right"), ("worst ζ band", "right"),
                          ("worst both", "right"), ("delay", "right"), ("lag", "right"),
                          ("corners", "right"), ("added", "right"), ("circle", "right"),
                          ("added ", "right"), ("residual vibr.", "right"),
                          (f"max accel. (≤ {tolerance_um:g} µm)", "right")):
        table.add_column(name, justify=justify)  # type: ignore[arg-type]
    table.add_row("", "%", "%", "%", "%", "ms", "ms", "µm", "µm", "µm", "µm", "µm", "mm/s²",
                  style="dim")
    for r in rows:
        v = r["vibration_percent"]
        acc = r["max_acceleration_mm_per_s2"]
        cells = [r["shaper"] + (" ← recommended" if r["shaper"] == best else ""),
                 f"{v['at_mode']:.1f}", f"{v['worst_frequency']:.1f}",
                 f"{v['worst_damping']:.1f}", f"{v['worst']:.1f}", f"{r['delay_ms']:.1f}",
                 f"{r['lag_ms']:.1f}", f"{r['corner_contour_error_um']:.1f}",
                 f"{r['added_corner_error_um']:+.1f}", f"{r['circle_contour_error_um']:.1f}",
                 f"{r['added_circle_error_um']:+.1f}", f"{r['residual_vibration_um']:.1f}",
                 "—" if acc is None else f"{acc:.0f}"]
        table.add_row(*cells, style="bold" if r["shaper"] == best else None)
    return table


def shaper_cmd(
    machine: str = typer.Option("tomsk_xy", "--machine", "-m",
                                help="Machine preset name or TOML file (the plant)."),
    controller_model: str | None = typer.Option(None, "--controller-model",
                                                help=CONTROLLER_MODEL_HELP),
    driver: str | None = typer.Option(None, "--driver", help="Measure the resonances "
                                      "(twin measure: sim, sim:FILE, modbus://HOST:PORT); "
                                      "default: the machine file's modes."),
    shapers: str = typer.Option(",".join(("zv", "mzv", "zvd", "ei", "2hump-ei", "3hump-ei")),
                                "--shapers", help="Comma-separated shapers to score."),
    frequency_spread: float = typer.Option(0.2, "--frequency-spread", help="Relative "
                                           "uncertainty of the mode frequency (1)."),
    damping_spread: float = typer.Option(0.5, "--damping-spread", help="Relative "
                                         "uncertainty of the mode damping (1)."),
    radius: float = typer.Option(25.0, "--radius", help="Test circle radius (mm)."),
    steps: int = typer.Option(5, "--steps", help="Bisection steps of the highest "
                              "acceleration."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    out: Path = typer.Option(Path("runs/shaper"), "--out", help="Output directory: each call "
                             "writes a folder of its own (shaper.json, shaper.toml)."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """Score each input shaper (remaining vibration, contour error from closed-loop runs,
    highest acceleration within the contour tolerance); recommend one and write it as a
    machine override file."""
    from twin.analysis.shaper import evaluate, recommend, write_override
    from twin.config.overrides import parse_sets
    from twin.controller.shaping import SHAPERS
    from twin.session.run import RunSpec

    try:
        names = [s.strip().lower().replace("_", "-") for s in shapers.split(",") if s.strip()]
        for n in names:
            if n not in SHAPERS:
                raise ConfigError("--shapers", f"unknown shaper {n!r}; one of "
                                  f"{', '.join(SHAPERS)}")
        if not names:
            raise ConfigError("--shapers", "names no shaper")
        if not 0.0 <= frequency_spread < 1.0:
            raise ConfigError("--frequency-spread", f"must lie in [0, 1), got "
                              f"{frequency_spread}")
        if not 0.0 <= damping_spread < 1.0:
            raise ConfigError("--damping-spread", f"must lie in [0, 1), got {damping_spread}")
        if not radius > 0.0:
            raise ConfigError("--radius", f"must be > 0 (mm), got {radius}")
        if not 0 <= steps <= 20:
            raise ConfigError("--steps", f"must lie in 0 … 20, got {steps}")
        spec = RunSpec(machine=machine, controller_model=controller_model,
                       overrides=parse_sets(sets))
        cfg = spec.machine_config()
        modes = _modes(spec, driver)
        for m in modes:
            if m.frequency >= 0.5 / cfg.controller.period:
                raise ConfigError("--driver" if driver else "--machine",
                                  f"the {m.axis} mode ({m.frequency:.4g} Hz) is at or above "
                                  f"the Nyquist rate of the controller period: no shaper "
                                  f"can cancel it")
        rows = evaluate(spec, modes, names, frequency_spread=frequency_spread,
                        damping_spread=damping_spread, radius=radius * 1e-3, steps=steps,
                        progress=lambda n: err.print(f"shaper: {n} …", highlight=False))
        best = recommend(rows)
        folder = output_dir(output_dir(out) / record_id(suffix=4))
        tolerance_um = cfg.controller.contour_tolerance * 1e6
        header = [f"twin shaper --machine {machine}: recommended {best.name}",
                  "modes: " + "; ".join(f"{m.axis} {m.frequency:.4g} Hz, ζ {m.damping:.3g} "
                                        f"({m.source})" for m in modes)]
        toml = write_override(folder / "shaper.toml", best, modes, cfg, header)
        result = {"machine": machine, "modes": [vars(m) for m in modes],
                  "frequency_spread": frequency_spread, "damping_spread": damping_spread,
                  "contour_tolerance_um": tolerance_um, "rows": [r.to_dict() for r in rows],
                  "recommended": best.name, "override": str(toml), "folder": str(folder)}
        write_json_atomic(folder / "shaper.json", result)
    except TwinError as exc:
        fail(exc, as_json)
    if as_json:
        sys.stdout.write(json_text(result) + "\n")
        return
    console = Console(width=None if sys.stdout.isatty() else 200)
    for m in modes:
        console.print(f"mode {m.axis}: {m.frequency:.4g} Hz, ζ = {m.damping:.3g} "
                      f"({m.source})", highlight=False)
    console.print(_table(result["rows"], best.name, tolerance_um,
                         f"input shapers on {machine}: f ±{frequency_spread:.0%}, "
                         f"ζ ±{damping_spread:.0%}; test path: 4 corners, circle R "
                         f"{radius:g} mm at feed"))
    console.print(f"recommended: [bold]{best.name}[/] → {toml}  (twin run --set-file "
                  f"{toml})", highlight=False)


def register(app: typer.Typer) -> None:
    """Add ``twin shaper`` to ``app``."""
    app.command("shaper")(shaper_cmd)
