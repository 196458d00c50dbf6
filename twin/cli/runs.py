"""``twin runs``: the runs of a folder, which are incomplete, cleaning up after them, and
``twin runs diff A B``: two runs side by side."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import typer
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from twin.cli.common import RUN_ROWS, err, fail
from twin.errors import ConfigError
from twin.system.jsonio import json_text

__all__ = ["register"]

SETTINGS = ("machine", "controller_model", "program", "builtin", "commands", "profile",
            "planner", "dcu_order", "period", "mode", "driver", "max_time", "start")
"""The run settings ``twin runs diff`` compares (``RunSpec``'s), before the overrides and
the machine files' fields."""


def _console() -> Console:
    """stdout: the terminal's width (or ``COLUMNS``), or when piped a width that cuts no
    line."""
    return Console(width=None if sys.stdout.isatty() or "COLUMNS" in os.environ else 200)


def runs(
    args: list[str] | None = typer.Argument(None, metavar="[FOLDER | diff A B]",
                                            help="The folder of run records (default runs); "
                                            "or diff and two runs (ids in --folder, or "
                                            ".json files)."),
    folder_opt: Path = typer.Option(Path("runs"), "--folder", help="Where diff finds run "
                                    "ids."),
    do_clean: bool = typer.Option(False, "--clean", help="Remove what incomplete runs left "
                                  "behind (a recording without its summary, .partial "
                                  "files), after asking."),
    yes: bool = typer.Option(False, "--yes", "-y", help="With --clean: do not ask."),
    as_json: bool = typer.Option(False, "--json", help="Print exactly one JSON object."),
) -> None:
    """List the runs of a folder (id, program, machine, status, key figures), marking the
    incomplete ones; --clean removes their leftovers. ``twin runs diff A B`` shows two
    runs' figures and settings side by side, and where they differ."""
    args = list(args or [])
    if args and args[0] == "diff" and not (len(args) == 1 and Path("diff").is_dir()):
        if len(args) != 3:
            fail(ConfigError("twin runs diff", f"expects two runs (A B), got {len(args) - 1}"))
        _diff(args[1], args[2], folder_opt, as_json)
        return
    if len(args) > 1:
        fail(ConfigError("twin runs", f"expects one folder, got {len(args)}: "
                         f"{' '.join(args)} (two runs compare with: twin runs diff A B)"))
    _list(Path(args[0]) if args else Path("runs"), do_clean, yes, as_json)


def _list(folder: Path, do_clean: bool, yes: bool, as_json: bool) -> None:
    from twin.session.folder import clean, inventory

    if folder.exists() and not folder.is_dir():
        fail(ConfigError(str(folder), "is not a folder"))
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
    console = _console()
    machines = {r["machine"] for r in rows}
    one = next(iter(machines)) if len(machines) == 1 else None
    table = Table(title=f"{folder}: {len(rows)} runs" + (f" on {one}" if one else ""),
                  box=box.SIMPLE_HEAD, collapse_padding=True, pad_edge=False)
    table.add_column("run", no_wrap=True)
    table.add_column("program", overflow="fold", min_width=12)
    if one is None:
        table.add_column("machine", overflow="fold")
    table.add_column("status", no_wrap=True)
    table.add_column("cycle\n(s)", justify="right", no_wrap=True)
    table.add_column("contour\n(µm)", justify="right", no_wrap=True)
    table.add_column("record", overflow="fold")
    notes: list[str] = []
    for r in rows:
        if r["reason"]:            # the why below the table: a long reason folds nothing
            notes.append(f"{r['run_id']} {(r['status'] or '').lower()}: {r['reason']}")
        record = "ok" if r["complete"] else f"[yellow]{escape(r['problem'])}[/]"
        table.add_row(r["run_id"], escape(_program(r["program"])),
                      *([] if one else [r["machine"] or "—"]), r["status"] or "—",
                      _figure(r["cycle_time_s"]), _figure(r["max_contour_error_um"]), record)
    console.print(table)
    for note in notes:              # folded at words to the width: a few lines, not 16
        console.print(escape(note), highlight=False)
    for path in removed:
        err.print(f"removed {path}", highlight=False)
    left = len(inv.orphans)
    if left:
        err.print(f"{left} leftover files of incomplete runs; twin runs {folder} --clean "
                  "removes them", highlight=False)


def _program(program: str | None) -> str:
    """A program as the table shows it: a file by its name (the path is in --json)."""
    if not program:
        return "—"
    return Path(program).name if program.endswith((".ngc", ".nc", ".gcode", ".tap")) \
        else program


def _figure(value: float | None) -> str:
    return "—" if value is None else f"{value:.4g}"


# ----------------------------------------------------------------------------- diff
def _load(ref: str, folder: Path) -> dict[str, Any]:
    """A run's summary: a ``.json`` file, a run id in ``folder``, or the one run whose id
    starts with ``ref``. Raises ``ConfigError`` naming ``ref``."""
    from twin.session.folder import inventory

    path = Path(ref)
    if path.suffix == ".json" and path.is_file():
        candidates = [path]
    else:
        runs = inventory(folder).runs if folder.is_dir() else []
        candidates = [f for r in runs if r.summary is not None and r.run_id.startswith(ref)
                      for f in r.files if f.suffix == ".json"]
        exact = [f for f in candidates if f.stem == ref]
        candidates = exact or candidates
    if len(candidates) != 1:
        why = "no such run" if not candidates else \
            f"{len(candidates)} runs start with it ({', '.join(c.stem for c in candidates[:4])})"
        raise ConfigError(ref, f"{why} in {folder} (give a run id or a .json file)")
    import json

    try:
        doc = json.loads(candidates[0].read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ConfigError(str(candidates[0]), f"not a run summary: {exc}") from None
    if not isinstance(doc, dict) or "run_id" not in doc:
        raise ConfigError(str(candidates[0]), "not a run summary (no run_id)")
    return doc


def _flat(value: Any, prefix: str = "") -> dict[str, Any]:
    """Nested dicts as ``{"a.b.c": leaf}``."""
    if isinstance(value, dict):
        out: dict[str, Any] = {}
        for k, v in value.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: value}


def differences(a: dict[str, Any], b: dict[str, Any]) -> list[dict[str, Any]]:
    """Where two run summaries' settings differ: the run settings (``SETTINGS``), the
    ``--set`` overrides and every field of the machine files the runs used, as rows
    ``{"setting", "a", "b"}`` (a value a run lacks is None)."""
    sa, sb = a.get("spec") or {}, b.get("spec") or {}
    rows = [{"setting": k, "a": sa.get(k), "b": sb.get(k)} for k in SETTINGS
            if sa.get(k) != sb.get(k)]
    for name, fa, fb in (("overrides", sa.get("overrides") or {}, sb.get("overrides") or {}),
                         ("config", a.get("config") or {}, b.get("config") or {})):
        la, lb = _flat(fa), _flat(fb)
        rows += [{"setting": f"{name}.{k}" if name == "overrides" else k,
                  "a": la.get(k), "b": lb.get(k)}
                 for k in sorted(set(la) | set(lb)) if la.get(k) != lb.get(k)
                 and not (name == "config" and k.split(".")[0] in ("name", "source",
                                                                    "description"))]
    return rows


def _cell(value: Any) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def _diff(ref_a: str, ref_b: str, folder: Path, as_json: bool) -> None:
    try:
        a, b = _load(ref_a, folder), _load(ref_b, folder)
    except ConfigError as exc:
        fail(exc)
    rows = differences(a, b)
    if as_json:
        keep = {"config", "spec"}
        sys.stdout.write(json_text({
            "a": {k: v for k, v in a.items() if k not in keep},
            "b": {k: v for k, v in b.items() if k not in keep},
            "differences": rows}) + "\n")
        return
    console = _console()
    console.print(_figures(a, b))
    if not rows:
        console.print("the same settings and machine", highlight=False)
        return
    table = Table(title=f"{len(rows)} settings differ", box=box.SIMPLE_HEAD)
    table.add_column("setting", overflow="fold")
    table.add_column("A", justify="right", overflow="fold")
    table.add_column("B", justify="right", overflow="fold")
    for r in rows:
        table.add_row(escape(r["setting"]), escape(_cell(r["a"])), escape(_cell(r["b"])))
    console.print(table)


def _figures(a: dict[str, Any], b: dict[str, Any]) -> Table:
    """The runs' figures (``RUN_ROWS``) side by side, with B − A and its share of A."""
    table = Table(title=f"A {a['run_id']} vs B {b['run_id']}", box=box.SIMPLE_HEAD)
    for col, justify in (("quantity", "left"), ("A", "right"), ("B", "right"),
                         ("B − A", "right"), ("unit", "left")):
        table.add_column(col, justify=justify, overflow="fold")
    for label, key, unit in RUN_ROWS:
        if key == "recording":
            continue
        va, vb = _value(a, key), _value(b, key)
        if va is None and vb is None:
            continue
        change = ""
        if isinstance(va, int | float) and isinstance(vb, int | float):
            change = f"{vb - va:+.4g}" + (f" ({(vb - va) / abs(va):+.1%})" if va else "")
        elif va != vb:
            change = "differs"
        table.add_row(label, _figure_cell(va), _figure_cell(vb), change, unit)
    return table


def _value(summary: dict[str, Any], key: Any) -> Any:
    return (summary.get(key[0]) or {}).get(key[1]) if isinstance(key, tuple) \
        else summary.get(key)


def _figure_cell(value: Any) -> str:
    return _figure(value) if isinstance(value, float) else _cell(value)


def register(app: typer.Typer) -> None:
    """Add ``runs`` to the ``twin`` app."""
    app.command("runs")(runs)
