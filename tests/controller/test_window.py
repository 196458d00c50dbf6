"""The compiled look-ahead passes (`twin.controller.window`) against the plain Python ones
they replace: the rows' reach floor and reach of every law equal to
`twin.controller.reach`'s, and whole plans identical with `PythonWindow` in the planner."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.controller.gcode import parse
from twin.controller.planner import PlannedBlock, Planner
from twin.controller.profiles import LAWS, Limits
from twin.controller.profiles.laws import law_code
from twin.controller.reach import reach_floor, reach_function
from twin.controller.window import (
    ACC,
    COLUMNS,
    JERK,
    LEN,
    VMAX,
    PythonWindow,
    Window,
    _floor,
    _reach,
)
from twin.errors import PlanningError


def _cases(rng: np.random.Generator, n: int):
    """Blocks from 1 µm to 1 m, limits over four decades, speeds from 0 past the cap."""
    for _ in range(n):
        d = 10.0 ** rng.uniform(-6, 0)
        limits = Limits(10.0 ** rng.uniform(-3, 0), 10.0 ** rng.uniform(-1, 1.5),
                        10.0 ** rng.uniform(0, 3))
        v = 0.0 if rng.random() < 0.2 else rng.uniform(0, 1.2) * limits.max_velocity
        yield d, limits, v


@pytest.mark.parametrize("law", LAWS)
def test_floor_and_reach_are_the_python_ones_bit_for_bit(law):
    kind, ka, kj = law_code(law)
    reach = reach_function(law)
    row = np.zeros((1, len(COLUMNS)))
    for d, limits, v in _cases(np.random.default_rng(LAWS.index(law)), 4000):
        row[0, LEN], row[0, VMAX] = d, limits.max_velocity
        row[0, ACC], row[0, JERK] = limits.max_acceleration, limits.max_jerk
        _floor(row, 0, kind, ka, kj)
        floor = reach_floor(law, d, limits)
        assert tuple(row[0, 6:10]) == floor, (law, d, limits)
        got, want = _reach(row, 0, v, kind, ka, kj), reach(v, d, limits, floor)
        assert got == want, (law, d, limits, v, got, want)


def _chords(rng: np.random.Generator, n: int) -> str:
    """A CAM-like program: short chords of a meandering path, arcs, feed changes, a rapid,
    a G61.1 stretch (every block to rest) and a G61 stretch (no rounding)."""
    lines = ["G21 G90 G64 P0.01 F1500", "G0 X10 Y10"]
    x = y = 10.0
    heading = 0.0
    for k in range(n):
        if k % 97 == 0:
            lines.append(f"F{rng.integers(300, 4000)}")
        if k == n // 3:
            lines.append("G61.1")
        if k == n // 3 + 20:
            lines.append("G61")
        if k == n // 3 + 40:
            lines.append("G64 P0.01")
        if k % 53 == 0:
            lines.append(f"G0 X{x + 1:.3f} Y{y:.3f}")
            x += 1
        heading += rng.normal(0.0, 0.3)
        step = rng.choice([0.05, 0.2, 1.0, 5.0])
        x = min(max(x + step * math.cos(heading), 5.0), 95.0)
        y = min(max(y + step * math.sin(heading), 5.0), 95.0)
        lines.append(f"G1 X{x:.3f} Y{y:.3f}")
    return "\n".join([*lines, "M2"]) + "\n"


def _speeds(planner: Planner, text: str) -> list[tuple]:
    return [(b.index, b._v_start, b._v_end, b.v_nominal) for b in
            planner.plan(parse(text, start=(0.01, 0.01))) if isinstance(b, PlannedBlock)]


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("lookahead", [1, 7, 64])
def test_plans_are_those_of_the_python_passes(law, lookahead):
    cfg = load_machine("laser_belt")
    text = _chords(np.random.default_rng(7), 600)
    for mode in ("lookahead", "stop"):
        compiled = Planner.from_settings(cfg.controller, cfg.axes, law=law, mode=mode,
                                         lookahead=lookahead, work_zone=None)
        python = Planner.from_settings(cfg.controller, cfg.axes, law=law, mode=mode,
                                       lookahead=lookahead, work_zone=None)
        python._window = PythonWindow
        got, want = _speeds(compiled, text), _speeds(python, text)
        assert len(got) > 500
        assert got == want, (law, lookahead, mode)


def test_the_window_holds_what_the_python_window_holds():
    """Row for row after every step, for a ring that wraps many times."""
    rng = np.random.default_rng(3)
    limits = Limits(0.05, 1.0, 20.0)
    compiled, python = Window("jerk-limited", 9), PythonWindow("jerk-limited", 9)
    for k in range(400):
        d = 10.0 ** rng.uniform(-5, -1)
        emax, linked = (0.0, False) if k % 31 == 0 else (rng.uniform(0, 0.06), True)
        for w in (compiled, python):
            w.append(d, limits, emax, linked and len(w) > 0)
        if len(compiled) >= 9 or rng.random() < 0.4:
            assert compiled.commit() == python.commit()
        np.testing.assert_array_equal(compiled.rows(), python.rows())


def test_a_length_that_is_not_a_number_is_refused_naming_it():
    with pytest.raises(PlanningError, match="distance"):
        Window("cubic", 4).append(math.nan, Limits(0.1, 1.0, 10.0), 0.0, False)
