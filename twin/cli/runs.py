"""``twin runs``: the runs of a folder, which are incomplete, and cleaning up after them."""

from __future__ import annotations

import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from twin.cli.common import err
from twin.system.jsonio import json_text

__all__ = ["register"]


def runs(
    folder: Path = typer.Argument(Path("runs"), help="The folder of run records."),
    do_clean: bool = typer.Option(False, "--clean", help="Remove what incomplete runs left "
                                  "behind (a recording without its summary, .partial "
                                  "files), after asking."),
    yes: bool = typer.Option(False, "--yes", "-y", help="With --clean: do not ask."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """List the runs of a folder (id, program, machine, status, key figures), marking the
    incomplete ones; --clean removes their leftovers."""
    from twin.session.folder import clean, inventory

    if folder.exists() and not folder.is_dir():
        err.print(f"[bold red]error:[/] {folder} is not a folder", highlight=False)
        raise typer.Exit(2)
    inv = inventory(folder)
    removed: list[Path] = []
    if do_clean and inv.orphans:
        if not yes:
            for path in inv.orphans:
                err.print(f"  {path}", highlight=False)
            if not sys.stdin.isatty() or not typer.confirm(
                    f"remove these {len(inv.orphans)} files?", err=True):
                err.print("nothing removed (--yes removes without asking)")
                raise typer.Exit(1)
        removed = clean(inv)
        inv = inventory(folder)
    rows = [r.row() for r in inv.runs]
    if as_json:
        sys.stdout.write(json_text({"folder": str(folder), "runs": rows,
                                    "incomplete": sum(not r["complete"] for r in rows),
                                    "removed": [str(p) for p in removed]}) + "\n")
        return
    table = Table(title=f"{folder}: {len(rows)} runs")
    for col in ("run", "program", "machine", "status", "cycle (s)", "max contour (µm)",
                "record"):
        table.add_column(col, justify="right" if "(" in col else "left")
    for r in rows:
        status = r["status"] or "—"
        if r["reason"]:
            status += f" ({r['reason']})"
        record = "ok" if r["complete"] else f"[yellow]{r['problem']}[/]"
        table.add_row(r["run_id"], r["program"] or "—", r["machine"] or "—", status,
                      _figure(r["cycle_time_s"]), _figure(r["max_contour_error_um"]), record)
    Console().print(table)
    for path in removed:
        err.print(f"removed {path}", highlight=False)
    left = len(inv.orphans)
    if left:
        err.print(f"{left} leftover files of incomplete runs; twin runs {folder} --clean "
                  "removes them", highlight=False)


def _figure(value: float | None) -> str:
    return "—" if value is None else f"{value:.4g}"


def register(app: typer.Typer) -> None:
    """Add ``runs`` to the ``twin`` app."""
    app.command("runs")(runs)
