"""The machine-file fuzz (issue 19): every leaf of every shipped machine file × {wrong type,
negative, 0, nan, inf, 1e300, 1e-300, 2^62, missing, unknown sibling}, loaded and run
through ``twin run`` (the real command line, in a long-lived helper process).

Each case either loads and runs (exit 0 or 1 with a summary in a final status, or exit 2 for
a program the machine cannot run, never a traceback), or is refused on load with a
``ConfigError`` naming the dotted field (for a per-axis default, the field of one axis), and
the command line exits 2 with the same message. No case may take longer than its limit: a
value in range must not hang a run. CI runs a seeded quarter of the cases, the full run
all of them.
"""

from __future__ import annotations

import json
import os
import random
import re
import select
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from tests.config_fuzz import cases
from twin.config.loader import MACHINES_DIR

ROOT = Path(__file__).resolve().parent.parent
CASE_LIMIT = 120.0
"""Longest a case may take (s): a short program, which runs in well under a second and in
13 s at worst (the slowest feed the schema allows); a hang runs past any limit."""
START_LIMIT = 300.0
"""Longest the helper may take to start and compile (s): a cold numba cache on a loaded
2-core machine."""

FINAL = {"FINISHED", "ABORTED", "FAULT", "TIMEOUT"}


class _Lines:
    """Lines from a pipe with a deadline (unbuffered: a line read ahead into a buffer would
    hide from ``select``)."""

    def __init__(self, fd: int):
        self.fd, self.buf = fd, b""

    def next(self, deadline: float) -> str | None:
        """The next line ("" at the end of the stream), None at the deadline."""
        while b"\n" not in self.buf:
            ready, _, _ = select.select([self.fd], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                return None
            data = os.read(self.fd, 65536)
            if not data:
                rest, self.buf = self.buf, b""
                return rest.decode()
            self.buf += data
        line, _, self.buf = self.buf.partition(b"\n")
        return line.decode() + "\n"


def run_cases(todo: list[dict]) -> tuple[dict[int, dict], list[dict]]:
    """Answers by case number, and the cases that ran over the limit (the helper is
    restarted after each)."""
    answers: dict[int, dict] = {}
    hung: list[dict] = []
    pending = list(todo)
    env = {**os.environ, "RERUN_ANALYTICS": "0", "PYTHONPATH": str(ROOT)}
    while pending:
        with tempfile.TemporaryFile("w+") as feed:   # a file: a pipe would fill and block
            feed.writelines(json.dumps(case) + "\n" for case in pending)
            feed.seek(0)
            proc = subprocess.Popen([sys.executable, "-m", "tests.config_fuzz"], cwd=ROOT,
                                    env=env, stdin=feed, stdout=subprocess.PIPE,
                                    stderr=subprocess.DEVNULL, bufsize=0)
        assert proc.stdout is not None
        lines = _Lines(proc.stdout.fileno())
        current, deadline = None, time.monotonic() + START_LIMIT   # imports, compiles
        by_number = {c["i"]: c for c in pending}
        while True:
            line = lines.next(deadline)
            if line is None:                    # the case in hand ran over its limit
                proc.kill()
                proc.wait()
                if current is None:
                    raise AssertionError(f"the fuzz helper did not start within "
                                         f"{START_LIMIT:g} s")
                hung.append(by_number[current])
                break
            if not line:
                proc.wait()
                if current is not None and current not in answers:
                    raise AssertionError(f"the fuzz helper died in case {by_number[current]}")
                break
            msg = json.loads(line)
            if msg.get("start"):
                current, deadline = msg["i"], time.monotonic() + CASE_LIMIT
            else:
                answers[msg["i"]] = msg
        pending = [c for c in pending if c["i"] not in answers and c not in hung]
    return answers, hung


def _named_across(mutated: str, field: str, message: str) -> bool:
    """A check across fields names this one: by its path from the table it shares with the
    field in error, or its whole table (a quantity derived from the table: a ratio)."""
    parts = mutated.split(".")
    table = ".".join(parts[:-1])
    if len(parts) > 3 and re.search(rf"{re.escape(table)}(?![\w.])", message):
        return True
    for k in range(1, len(parts)):
        prefix, rel = ".".join(parts[:-k]), ".".join(parts[-k:])
        if field.startswith(prefix + ".") and rel in message:
            return True
    return False


def judge(case: dict, answer: dict) -> str | None:
    """What is wrong with one case's outcome, or None."""
    where = f"{case['file']} {case['leaf']} = {case['kind']}"
    if answer["traceback"]:
        return f"{where}: traceback\n{answer['traceback']}"
    if answer["load"].startswith("TRACEBACK"):
        return f"{where}: load raised\n{answer['load']}"
    if answer["load"] != "ok":
        field, _, message = answer["load"].partition(": ")
        # the field itself; the table that holds it (a table it empties); or, for a check
        # across fields, a field whose message names this one by its path from their
        # common table
        named = any(f in answer["load"] or f.startswith(field + ".") or
                    _named_across(f, field, message) for f in case["fields"])
        if case["kind"] == "unknown sibling":
            named = any(f.rsplit(".", 1)[0] + ".bogus_key" in answer["load"] or
                        "bogus_key" in answer["load"] for f in case["fields"])
        if not named:
            return f"{where}: refused without naming {case['fields']}: {answer['load']}"
        if answer["exit"] != 2:
            return f"{where}: refused on load but the command exited {answer['exit']}"
        return None
    if case["kind"] == "unknown sibling":
        return f"{where}: an unknown key was accepted"
    if answer["exit"] not in (0, 1, 2):
        return f"{where}: exit {answer['exit']}\n{answer['output']}"
    if answer["exit"] in (0, 1) and answer["status"] not in FINAL:
        return f"{where}: exit {answer['exit']} with status {answer['status']}"
    return None


@pytest.mark.slow
def test_every_leaf_of_every_machine_file(record_property):
    every = cases(sorted(MACHINES_DIR.glob("*.toml")))
    todo = random.Random(19).sample(every, len(every) // 4) if os.environ.get("CI") else every
    _fuzz(todo, record_property)


def _fuzz(todo: list[dict], record_property) -> None:
    t0 = time.perf_counter()
    answers, hung = run_cases(todo)
    wall = time.perf_counter() - t0
    problems = [f"{c['file']} {c['leaf']} = {c['kind']}: over {CASE_LIMIT:g} s" for c in hung]
    outcomes: dict[str, int] = {}
    for case in todo:
        answer = answers.get(case["i"])
        if answer is None:
            continue
        problem = judge(case, answer)
        if problem:
            problems.append(problem)
        key = ("refused" if answer["load"] != "ok" else
               f"ran {answer['status']}" if answer["status"] else f"exit {answer['exit']}")
        outcomes[key] = outcomes.get(key, 0) + 1
    slowest = max((a["seconds"] for a in answers.values()), default=0.0)
    record_property("fuzz", json.dumps({"cases": len(todo), "outcomes": outcomes,
                                        "wall_s": round(wall, 1), "slowest_s": slowest}))
    print(f"\nconfig fuzz: {len(todo)} cases in {wall:.1f} s, slowest {slowest:.2f} s: "
          f"{outcomes}")
    assert not problems, f"{len(problems)} of {len(todo)} cases:\n" + "\n\n".join(problems[:20])
