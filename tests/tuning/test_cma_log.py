"""A resumed CMA trial log is read line by line, and a line that holds no whole trial — torn,
of the wrong type anywhere, nested to any depth — is skipped with a warning naming its line,
never a traceback (issue 33: ``"x": "hostile"`` was a ValueError)."""

from __future__ import annotations

import copy
import json
import math
import os
import random

import pytest

from tests.test_cli_hostile_input import PEAK_BOUND_MIB, twin_cli
from tuning.cma_job import WARNED_LINES, TrialLog
from tuning.evaluator import Trial

CI = bool(os.environ.get("CI"))
DIM = 11


def _trial(rng: random.Random) -> tuple[list[float], Trial]:
    x = [rng.uniform(-1, 1) for _ in range(DIM)]
    trial = Trial(tuple(x), rng.uniform(0, 9), {"max_coordinate_error": rng.uniform(0, 2)},
                  {"max_coordinate_error": rng.uniform(0, 1e-4), "cycle_time": math.nan},
                  rng.choice(["FINISHED", "FAULT"]),
                  {"kp": [rng.uniform(1, 9), rng.uniform(1, 9)], "ki": [0.5, 0.25],
                   "dcu_alpha": [[0.1, 0.2, 0.3], [0.3, 0.2, 0.1]], "max_jerk": 5.0},
                  rng.uniform(0, 1), rng.uniform(0, 9))
    return x, trial


def _same(a: Trial, b: Trial) -> bool:
    """Field by field, NaN equal to NaN (a failed run's metrics)."""
    def norm(t: Trial):
        return json.dumps(t.to_dict(), sort_keys=True)
    return norm(a) == norm(b)


def _written(tmp_path, n: int, rng: random.Random) -> tuple[list[str], list[Trial]]:
    path = tmp_path / "log.jsonl"
    log = TrialLog(path, resume=False)
    trials = []
    for k in range(n):
        x, trial = _trial(rng)
        log.append(k // 4, k % 4, x, trial)
        trials.append(trial)
    log.close()
    return path.read_text().splitlines(), trials


def _read(tmp_path, lines: list[str]) -> tuple[TrialLog, list[str]]:
    path = tmp_path / "log.jsonl"
    path.write_text("\n".join(lines) + "\n")
    said: list[str] = []
    log = TrialLog(path, resume=True, dim=DIM, warn=said.append)
    log.close()
    return log, said


def test_a_log_reads_back_every_trial_it_wrote(tmp_path):
    lines, trials = _written(tmp_path, 8, random.Random(0))
    log, said = _read(tmp_path, lines)
    assert said == []
    assert sorted(log.done) == [(k // 4, k % 4) for k in range(8)]
    for k, trial in enumerate(trials):
        x, got = log.done[(k // 4, k % 4)]
        assert x == trial.x and _same(got, trial)


HOSTILE = ["hostile", None, [], {}, True, -1, 2**70, 1.5, "NaN", [["deep"]], {"a": 1}]


def _paths(node, prefix=()):
    """Every place in a JSON document: (path, value)."""
    yield prefix, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


def _replace(doc, path, value):
    doc = copy.deepcopy(doc)
    if not path:
        return value
    node = doc
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    return doc


def test_a_line_with_a_wrong_type_anywhere_is_skipped_naming_its_line(tmp_path):
    rng = random.Random(1)
    lines, _ = _written(tmp_path, 6, rng)
    doc = json.loads(lines[2])
    places = [p for p, _ in _paths(doc) if "terms" not in p and "metrics" not in p[:2]]
    cases = rng.sample([(p, h) for p in places for h in HOSTILE], 40 if CI else 400)
    kept = skipped = 0
    for path, hostile in cases:
        bad = _replace(doc, path, hostile)
        log, said = _read(tmp_path, [*lines[:2], json.dumps(bad), *lines[3:]])
        others = {(k // 4, k % 4) for k in (0, 1, 3, 4, 5)}
        assert others <= set(log.done), (path, hostile)          # the other lines stand
        if (0, 2) in log.done:
            # the change left a whole trial (an int for a float, a value in a free table):
            # read as it is written now, the same as its own reading of that document
            kept += 1
            assert said == []
            continue
        skipped += 1
        assert len(said) == 1 and "skipped 1 line " in said[0] and "line 3 (" in said[0], \
            (path, hostile, said)
    assert skipped > kept


def test_a_line_nested_to_any_depth_is_skipped(tmp_path):
    rng = random.Random(2)
    lines, _ = _written(tmp_path, 3, rng)
    for depth in [63, 64, 65, 200_000, *(int(10 ** rng.uniform(0, 5)) for _ in
                                           range(3 if CI else 20))]:
        deep = "[" * depth + "]" * depth
        log, said = _read(tmp_path, [lines[0], f'{{"generation": 0, "index": 1, "x": {deep}}}',
                                     lines[2]])
        assert set(log.done) == {(0, 0), (0, 2)}
        assert len(said) == 1 and "line 2" in said[0]
        if depth + 1 > 64:
            assert "nested deeper than 64 levels" in said[0]


def test_many_bad_lines_are_counted_not_listed(tmp_path):
    lines, _ = _written(tmp_path, 2, random.Random(3))
    log, said = _read(tmp_path, [lines[0], *(["{torn"] * 50), lines[1]])
    assert len(log.done) == 2 and len(said) == 1
    assert "skipped 50 lines" in said[0] and f"and {50 - WARNED_LINES} more" in said[0]
    assert said[0].count("line ") == WARNED_LINES          # each of the first named
    assert "line 2 (not JSON: Expecting property name" in said[0]


HOSTILE_LOG = ('{"generation": 0, "index": 0, "x": "hostile", "trial": {}}\n'
               '{"generation": 0, "index": 1, "x": ' + "[" * 200_000 + "]" * 200_000 + "}\n")


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_hostile_cma_resume_log_is_skipped_with_one_warning(tmp_path):
    """``"x": "hostile"`` and a line nested 200 000 deep: both skipped with one warning
    naming them, the job runs them again and ends as it would have (exit 0), through the
    command line (``tests/test_cli_hostile_input.py``). CI reads the same log with the
    job's own ``TrialLog`` instead of running a whole job."""
    out = tmp_path / "job"
    out.mkdir()
    (out / "cma_trials.jsonl").write_text(HOSTILE_LOG)
    if CI:
        said: list[str] = []
        TrialLog(out / "cma_trials.jsonl", resume=True, dim=11, warn=said.append).close()
        warnings = [f"warning: {s}" for s in said]
    else:
        done, peak = twin_cli(tmp_path, "tune", "--method", "cma", "--program", "tiny",
                           "--workers", "1", "--seed", "3", "--max-runs", "2", "--budget-s",
                           "300", "--out", str(out), "--resume", "--json")
        assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr[-2000:]
        assert json.loads(done.stdout)["runs"] == 2 and peak < PEAK_BOUND_MIB
        warnings = [ln for ln in done.stderr.splitlines() if ln.startswith("warning:")]
    assert len(warnings) == 1 and "skipped 2 lines" in warnings[0]
    assert "line 1 (" in warnings[0] and "line 2, column" in warnings[0]
