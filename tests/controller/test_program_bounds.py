"""Numbers that mean nothing are refused at their line: a feed below the machine's minimum
(a typing slip, or a number that underflowed to a denormal) and a program longer than the
machine's maximum (a dwell or an arc of a billion turns), both set in the machine file."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from twin.config import load_machine
from twin.controller.gcode import parse
from twin.controller.planner import Planner
from twin.errors import ConfigError, PlanningError

CFG = load_machine("tomsk_xy")
HERE = (0.01, 0.01)   # tomsk_xy's home (m)


def _check(text: str, cfg=CFG) -> None:
    planner = Planner.from_settings(cfg.controller, cfg.axes)
    planner.check(parse(text, start=HERE))


@pytest.mark.parametrize(("text", "line"), [
    ("G21 G91\nG1 X1 F0.00001\nM30", 2),                        # 1e-5 mm/min
    ("G21 G91\nG1 X1 F60\nG1 Y1 F0." + "0" * 318 + "3\nM30", 3),   # a denormal
])
def test_a_feed_below_the_minimum_is_refused_at_its_line(text, line):
    with pytest.raises(PlanningError, match=rf"line {line}: feed .* is below the "
                                            r"machine's minimum 0\.06 mm/min"):
        _check(text)


@pytest.mark.parametrize(("text", "line"), [
    ("G21 G91\nG1 X1 F60\nG4 P999999999\nM30", 3),
    ("G21 G91\nG2 X0 Y0 I1 J0 P999999999 F600\nM30", 2),
])
def test_a_program_beyond_the_longest_is_refused_at_its_line(text, line):
    with pytest.raises(PlanningError, match=rf"line {line}: the program takes at least .* "
                                            r"beyond the machine's 86400 s"):
        _check(text)


def test_the_bounds_come_from_the_machine_file():
    short = CFG.with_overrides({"controller.max_program_time": 5.0,
                                "controller.min_feed": 1e-3})
    _check("G21 G91\nG1 X1 F600\nM30", short)                     # 0.1 s: fine
    with pytest.raises(PlanningError, match="line 2: the program takes at least 6 s"):
        _check("G21 G91\nG4 P6\nM30", short)
    with pytest.raises(PlanningError, match="line 2: feed 30 mm/min is below"):
        _check("G21 G91\nG1 X1 F30\nM30", short)                  # 0.5 mm/s < 1 mm/s
    with pytest.raises(ConfigError, match=r"controller\.min_feed"):
        CFG.with_overrides({"controller.min_feed": 0.0})


def test_a_streamed_program_stops_at_the_line_it_reaches():
    planner = Planner.from_settings(CFG.controller, CFG.axes)
    items = parse("G21 G91\nG1 X1 F600\nG1 X1 F0.000001\nM30", start=HERE)
    planned = []
    with pytest.raises(PlanningError, match="line 3: feed"):
        for block in planner.plan(iter(list(items))):
            planned.append(block)
    assert len(planned) == 1 and planned[0].line == 2     # what came before was planned


def test_twin_run_refuses_a_denormal_feed_naming_the_line(tmp_path):
    program = tmp_path / "tiny_feed.ngc"
    program.write_text("G21 G91\nG1 X1 F0." + "0" * 318 + "3\nM30\n")
    proc = subprocess.run([sys.executable, "-m", "twin.cli", "run", str(program), "--rerun",
                           "none", "--out", str(tmp_path), "--json"], capture_output=True,
                          text=True, timeout=120, env={**os.environ, "RERUN_ANALYTICS": "0"})
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "line 2: feed" in proc.stderr and "controller.min_feed" in proc.stderr
    refusal = json.loads(proc.stdout)   # --json: its one object, and no run record
    assert refusal["status"] == "REFUSED" and refusal["error"].startswith("line 2: feed")
    assert proc.stdout.count("\n") == 1 and not list(tmp_path.glob("*.json"))
