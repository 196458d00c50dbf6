"""The reproducers of issue 33 through the real command line: each ends in exit 2 and one
``error:`` line naming the place (a G-code error adds its line's excerpt and caret), no
traceback, in bounded time (the subprocess timeout) and memory (its peak, VmHWM, read by a
wrapper as it exits). With ``--json``, stdout holds exactly one JSON object. CI runs a
cheap subset; the whole table without CI."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

CI = bool(os.environ.get("CI"))
PEAK_BOUND_MIB = 1024
"""Far above what any command takes (a dry run peaks at a few hundred MiB)."""

WRAPPER = """
import atexit, os, runpy, sys

def _peak():
    with open("/proc/self/status") as f:
        kib = next(row.split()[1] for row in f if row.startswith("VmHWM:"))
    with open(os.environ["TWIN_PEAK_FILE"], "w") as f:
        f.write(kib)

atexit.register(_peak)
sys.argv = ["twin", *sys.argv[1:]]
runpy.run_module("twin.cli", run_name="__main__")
"""


def twin_cli(tmp_path: Path, *args: str) -> tuple[subprocess.CompletedProcess, float]:
    """Run ``twin ARGS`` in ``tmp_path``: what it did, and its peak memory (MiB)."""
    peak = tmp_path / "peak"
    done = subprocess.run([sys.executable, "-c", WRAPPER, *args], capture_output=True,
                          text=True, timeout=240, cwd=tmp_path,
                          env={**os.environ, "RERUN_ANALYTICS": "0",
                               "TWIN_PEAK_FILE": str(peak), "COLUMNS": "200"})
    return done, int(peak.read_text()) / 1024 if peak.exists() else float("nan")


def _files(tmp_path: Path) -> None:
    """Every hostile input of the issue, in ``tmp_path``."""
    def write(name: str, text: str) -> None:
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)

    write("brackets.ngc", "G21 G1 F100 X" + "[" * 5000 + "1" + "]" * 5000 + "\nM2\n")
    write("hashes.ngc", "#1=1\nG21 G1 F100 X" + "#" * 350 + "1\nM2\n")
    write("abs.ngc", "G21 G1 F100 X" + "ABS[" * 400 + "1" + "]" * 400 + "\nM2\n")
    write("oword.ngc", "O" + "1" * 5000 + " sub\nO1 endsub\nM2\n")
    write("nword.ngc", "G21 G1 F100\nN" + "1" * 5000 + " X1\nM2\n")
    write("secret.ngc", "o<secret> sub\nG1 X5 F100\no<secret> endsub\n")
    write("c/sub/up.ngc", "G21 G90\no<../../secret> call\nM2\n")
    write("c/sub/abs.ngc", f"G21 G90\no<{tmp_path / 'secret'}> call\nM2\n")
    os.symlink(tmp_path / "secret.ngc", tmp_path / "c" / "sub" / "secret.ngc")
    write("c/sub/link.ngc", "G21 G90\no<secret> call\nM2\n")
    write("arrays.toml", "[controller.regulator]\nkp = " + "[" * 3000 + "]" * 3000 + "\n")
    write("tables.toml", "[" + ".".join(["a"] * 5000) + "]\nx = 1\n")
    write("inline.toml", "[controller]\nx = " + "{a=" * 2000 + "1" + "}" * 2000 + "\n")
    write("log/experiments.json", '{"format": 1, "x": ' + "[" * 100_000 + "]" * 100_000 + "}")
    os.symlink(tmp_path / "nowhere" / "deeper", tmp_path / "dangling")


DRY = ("--dry-run", "--rerun", "none", "--out", "runs")
CASES = [
    # (name, arguments, what the error line must hold, lines of excerpt after it)
    ("brackets", ("run", "brackets.ngc", *DRY), "line 1, col 114: brackets, functions and "
     "'#' nest deeper than 100 levels", 2),
    ("hashes", ("run", "hashes.ngc", *DRY), "line 2, col 114: brackets", 2),
    ("abs", ("run", "abs.ngc", *DRY), "line 1, col 417: brackets", 2),
    ("oword", ("run", "oword.ngc", *DRY), "line 1, col 2: O-word number of 5000 digits", 2),
    ("nword", ("run", "nword.ngc", *DRY), "line 2, col 1: N value 111111111111… (5000 "
     "characters) is out of range", 2),
    ("traversal", ("run", "c/sub/up.ngc", *DRY), "line 2, col 1: O<../../secret> call: a "
     "subroutine name is a file name", 2),
    ("absolute", ("run", "c/sub/abs.ngc", *DRY), "may not hold '/'", 2),
    ("symlink", ("run", "c/sub/link.ngc", *DRY), "line 2, col 1: O<secret> call: no "
     "subroutine <secret> in the program and no secret.ngc in", 2),
    ("set-file", ("run", "--set-file", "arrays.toml", *DRY), "arrays.toml: line 2, "
     "controller.regulator.kp: nested deeper than 64 levels", 0),
    ("machine", ("machines", "--fields", "tables.toml", "--json"), "tables.toml: line 1, "
     "a.a.a.a", 0),
    ("inline", ("run", "--machine", "inline.toml", *DRY), "inline.toml: line 2, "
     "controller.x: nested deeper than 64 levels", 0),
    ("set", ("run", "--set", "kp=" + "[" * 3000, *DRY), "kp: the value nests deeper", 0),
    ("log", ("identify", "-o", "cal.toml", "--from-log", "log", "--out", "runs", "--json"),
     "log/experiments.json: line 1, column 83: nested deeper than 64 levels", 0),
    ("out", ("run", "--builtin", "tiny", "--dry-run", "--rerun", "none", "--out", "dangling",
             "--json"), "out: dangling is a symlink to", 0),
]
CI_CASES = ("brackets", "machine")


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_each_hostile_input_is_one_line_and_exit_2(tmp_path):
    _files(tmp_path)
    wrong = []
    for name, args, words, excerpt in CASES:
        if CI and name not in CI_CASES:
            continue
        done, peak = twin_cli(tmp_path, *args)
        lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
        ok = (done.returncode == 2 and "Traceback" not in done.stderr
              and len(lines) == 1 + excerpt and lines[0].startswith("error: ")
              and words in lines[0] and len(done.stderr) < 1500 and peak < PEAK_BOUND_MIB)
        if ok and "--json" in args:     # the one object --json promises, a refusal's too
            answer = json.loads(done.stdout)
            ok = answer["status"] == "REFUSED" and answer["error"] in lines[0]
        elif ok:
            ok = done.stdout == ""
        if not ok:
            wrong.append((name, done.returncode, peak, done.stdout[-300:],
                          done.stderr[-600:]))
    assert wrong == []
