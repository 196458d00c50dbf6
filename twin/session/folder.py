"""What a folder of run records holds: the runs, which are complete, and what is left over.

A finished run leaves a pair, ``<id>.json`` (the summary, written first) and ``<id>.rrd``
(the recording, renamed from ``<id>.rrd.partial`` once the summary is written), or the
summary alone when the run recorded nothing. Anything else is incomplete: a recording
without its summary, a ``.partial`` that was never renamed (a killed process, a full disk),
a summary whose recording is missing. ``inventory`` sorts a folder into runs and orphans;
``clean`` removes the orphans. A ``.partial`` written to within ``LIVE_S`` seconds belongs
to a run still going and is left alone.

Light on purpose (the standard library only): ``twin runs`` lists a folder without loading
the twin.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twin.errors import ConfigError
from twin.system.jsonio import load_json

__all__ = ["LIVE_S", "Inventory", "RunEntry", "clean", "inventory"]

LIVE_S = 60.0
"""A ``.partial`` modified this recently (s) is taken as a run in progress."""


@dataclass
class RunEntry:
    """One run of the folder.

    Attributes
    ----------
    run_id : str
    summary : dict or None
        The summary, if it was written (and reads as one).
    files : list of Path
        Every file of the run.
    problem : str
        Empty for a complete run; else what is wrong (shown, and the reason to clean).
    live : bool
        Its recording is still being written (a run in progress).
    """

    run_id: str
    summary: dict[str, Any] | None = None
    files: list[Path] = field(default_factory=list)
    problem: str = ""
    live: bool = False

    @property
    def complete(self) -> bool:
        """The pair is whole."""
        return not self.problem

    def row(self) -> dict[str, Any]:
        """The figures ``twin runs`` shows (JSON-ready)."""
        s = self.summary or {}
        spec = s.get("spec") or {}
        program = spec.get("program") or spec.get("experiment") or (
            " then ".join(spec["commands"]) if spec.get("commands") else None) or (
            f"builtin {spec['builtin']}" if spec.get("builtin") else None)
        return {"run_id": self.run_id, "program": program, "machine": s.get("machine"),
                "status": s.get("status"), "reason": s.get("fault") or s.get("aborted")
                or s.get("timeout"), "cycle_time_s": s.get("cycle_time_s"),
                "max_contour_error_um": s.get("max_contour_error_um"),
                "complete": self.complete, "problem": self.problem or None,
                "live": self.live, "files": [str(f) for f in self.files]}


@dataclass
class Inventory:
    """A folder sorted: its runs (oldest first) and the files ``clean`` would remove."""

    folder: Path
    runs: list[RunEntry]

    @property
    def orphans(self) -> list[Path]:
        """Files of incomplete runs that no run in progress writes: a recording without its
        summary, a ``.partial``."""
        out: list[Path] = []
        for run in self.runs:
            if run.complete or run.live:
                continue
            for f in run.files:
                if f.suffix == ".partial" or (run.summary is None and f.suffix == ".rrd"):
                    out.append(f)
        return out


def _run_summary(path: Path) -> dict[str, Any] | None:
    """The file's summary if it is a run summary (other JSON files are not runs)."""
    try:
        doc = load_json(path.read_text(encoding="utf-8"), str(path))   # nesting bounded
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, ConfigError):
        return None
    if isinstance(doc, dict) and "run_id" in doc and "status" in doc and "spec" in doc:
        return doc
    return None


def _run_id(name: str) -> tuple[str, str] | None:
    """(run id, kind) of a run record's file name, or None."""
    for suffix, kind in ((".rrd.partial", "rrd.partial"), (".json.partial", "json.partial"),
                         (".rrd", "rrd"), (".json", "json")):
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[:-len(suffix)], kind
    return None


def inventory(folder: str | Path, *, now: float | None = None) -> Inventory:
    """Sort ``folder``'s run records into runs (see the module docstring)."""
    root = Path(folder)
    now = time.time() if now is None else now
    found: dict[str, dict[str, Path]] = {}
    for path in sorted(root.iterdir()) if root.is_dir() else ():
        parsed = _run_id(path.name) if path.is_file() else None
        if parsed is not None:
            found.setdefault(parsed[0], {})[parsed[1]] = path
    runs = []
    for run_id, kinds in found.items():
        summary = _run_summary(kinds["json"]) if "json" in kinds else None
        if "json" in kinds and summary is None and "rrd" not in kinds \
                and "rrd.partial" not in kinds:
            continue   # some other JSON file (a tuning result, a comparison)
        entry = RunEntry(run_id, summary, sorted(kinds.values()))
        entry.live = any(k.endswith("partial") and now - _mtime(p) < LIVE_S
                         for k, p in kinds.items())
        if summary is None:
            entry.problem = ("recording without its summary" if "rrd" in kinds
                             else "recording never finished (.partial), no summary")
        elif "rrd.partial" in kinds or "json.partial" in kinds:
            entry.problem = "a .partial was left behind"
        elif summary.get("recording") and "rrd" not in kinds \
                and not Path(summary["recording"]).is_file():
            entry.problem = "its recording is missing"
        if entry.live:
            entry.problem = entry.problem or "in progress"
        runs.append(entry)
    runs.sort(key=lambda r: min(_mtime(p) for p in r.files))
    return Inventory(root, runs)


def _mtime(path: Path) -> float:
    """Modification time, or −inf for a file gone meanwhile (a live run renames its
    ``.partial``)."""
    try:
        return path.stat().st_mtime
    except OSError:
        return -float("inf")


def clean(inv: Inventory) -> list[Path]:
    """Remove ``inv.orphans``; returns what was removed."""
    removed = []
    for path in inv.orphans:
        try:
            path.unlink()
        except FileNotFoundError:
            continue
        removed.append(path)
    return removed
