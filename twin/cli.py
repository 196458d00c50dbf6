"""The ``twin`` command: run programs on the twin, run experiments, tune, view recordings."""

from __future__ import annotations

import json

import typer
from rich.console import Console
from rich.table import Table

from twin.config import available_machines, load_machine
from twin.errors import TwinError

__all__ = ["app"]

app = typer.Typer(help="xy-twin: a digital twin of a two-axis CNC cross table.",
                  no_args_is_help=True, add_completion=False)
console = Console(stderr=True)


@app.callback()
def main() -> None:
    """xy-twin: a digital twin of a two-axis CNC cross table."""


def _fail(exc: Exception) -> None:
    console.print(f"[bold red]error:[/] {exc}")
    raise typer.Exit(2)


@app.command()
def machines(
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """List the machine presets and their key figures."""
    rows = []
    for name in available_machines():
        try:
            cfg = load_machine(name)
        except TwinError as exc:
            _fail(exc)
        ax = cfg.axes["x"]
        rows.append({
            "name": name,
            "description": cfg.description,
            "converter": ax.converter.kind,
            "transmission": ax.transmission.kind,
            "counts_per_um": ax.counts_per_metre * 1e-6,
            "max_velocity_mm_per_min": cfg.controller.limits.max_velocity * 60e3,
            "period_ms": cfg.controller.period * 1e3,
        })
    if as_json:
        print(json.dumps({"machines": rows}))
        return
    table = Table(title="machines")
    keys = [k for k in rows[0] if k != "description"]
    for key in keys:
        table.add_column(key)
    for r in rows:
        table.add_row(*(f"{r[k]:g}" if isinstance(r[k], float) else str(r[k]) for k in keys))
    Console().print(table)


if __name__ == "__main__":
    app()
