"""Strict JSON everywhere: what the twin writes and prints parses with a strict parser
(RFC 8259 has no NaN or Infinity); non-finite numbers are written as null."""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from twin.system.jsonio import json_text, write_json_atomic


def _strict(text: str):
    def refuse(name: str):
        raise ValueError(f"not strict JSON: {name}")
    return json.loads(text, parse_constant=refuse)


@dataclasses.dataclass
class _Figures:
    error: float
    where: Path


def test_non_finite_numbers_become_null_and_numpy_values_plain():
    obj = {"nan": math.nan, "inf": -math.inf, "np": np.float64("inf"), "i": np.int64(3),
           "a": np.array([[1.0, np.nan]]), "t": (1, 2.5), "d": _Figures(np.nan, Path("/x")),
           7: "key"}
    assert _strict(json_text(obj)) == {"nan": None, "inf": None, "np": None, "i": 3,
                                        "a": [[1.0, None]], "t": [1, 2.5],
                                        "d": {"error": None, "where": "/x"}, "7": "key"}


def test_a_record_file_is_strict_and_atomic(tmp_path):
    path = write_json_atomic(tmp_path / "r.json", {"x": [math.nan, 1e300, 2.0]})
    assert _strict(path.read_text()) == {"x": [None, 1e300, 2.0]}
    assert not list(tmp_path.glob("*.partial"))


def test_a_json_run_summary_parses_strictly(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "twin.cli", "run", "--builtin", "spline_line",
                           "--rerun", "none", "--out", str(tmp_path), "--json"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    printed = _strict(proc.stdout)
    written = _strict((tmp_path / f"{printed['run_id']}.json").read_text())
    assert printed["status"] == written["status"] == "FINISHED"


@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_python_json_alone_would_not_be_strict(value):
    # the reason for json_text: the standard writer emits NaN/Infinity by default
    with pytest.raises(ValueError):
        _strict(json.dumps(value))
