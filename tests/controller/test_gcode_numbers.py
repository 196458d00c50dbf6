"""Numbers that mean nothing, in every word: the valid program of ``test_gcode_fuzz`` with
one to three of its numbers replaced by denormal, huge, tiny, overflowing or malformed ones.

Each program must either be refused with an error placed in the text (``GCodeError`` with
its line and column; ``PlanningError`` naming the line), or read and plan into moves and
profiles that are all finite. CI runs 5 000 programs; the full run (``slow``) 100 000.
"""

from __future__ import annotations

import math
import os
import random
import re
import time

import pytest

from tests.controller.test_gcode_fuzz import VALID, check_outcome
from twin.config import load_machine
from twin.controller.gcode import parse
from twin.controller.planner import Planner
from twin.errors import GCodeError, PlanningError

NUMBER = re.compile(r"(?<=[GMNXYZIJKRFPST])[-+]?[0-9.]+")
"""The number of every word of the valid program (the letter stays)."""

EXTREMES = [
    "0." + "0" * 320 + "3",                 # a denormal after parsing (~3e-321)
    "0." + "0" * 400 + "1",                 # underflows to 0
    "0." + "0" * 307 + "22250738585072014",  # the smallest normal double
    "1" + "0" * 308,                        # 1e308
    "1" + "0" * 309,                        # overflows to inf
    "9" * 400,                              # overflows to inf
    "0.000000001", "0.0000000000001", "1e5", "1E-300", "4.9406564584124654e-324",
    "4611686018427387904",                  # 2^62
    "9223372036854775808",                  # 2^63
    "9007199254740993",                     # 2^53 + 1
    "0", "0.", ".0", ".", "-", "+", "--1", "1..2", "0x10", "1_000", "nan", "inf",
    "00000000000000000000000000000000001", "999999999", "0.5", "12.7",
]

PLANNER_CFG = load_machine("tomsk_xy")


def _program(rng: random.Random) -> str:
    spots = list(NUMBER.finditer(VALID))
    chosen = sorted(rng.sample(spots, rng.randint(1, 3)), key=lambda m: m.start(),
                    reverse=True)
    text = VALID
    for m in chosen:
        value = rng.choice(EXTREMES)
        if rng.random() < 0.3 and value[:1] not in "+-":
            value = "-" + value
        text = text[:m.start()] + value + text[m.end():]
    return text


def _check(text: str, planner: Planner) -> str:
    """The outcome of reading and planning ``text``: "refused", "planning" or "ran"."""
    check_outcome(text)                            # a GCodeError is placed, moves finite
    try:
        program = parse(text)
    except GCodeError:
        return "refused"
    try:
        blocks = list(planner.plan(program))
    except PlanningError as exc:
        assert re.search(r"\bline \d+", str(exc)), f"unplaced: {exc}"
        return "planning"
    for b in blocks:
        profile = getattr(b, "profile", None)
        if profile is None:
            continue
        prof = profile()
        assert math.isfinite(prof.duration) and prof.duration >= 0.0, text
        assert all(math.isfinite(v) for v in (prof.distance, prof.v_start, prof.v_end,
                                              prof.v_peak)), text
    return "ran"


@pytest.mark.slow
def test_extreme_numbers_in_every_word_are_refused_in_place_or_run_finite():
    count = 5_000 if os.environ.get("CI") else 100_000
    rng = random.Random(20261125)
    planner = Planner.from_settings(PLANNER_CFG.controller, PLANNER_CFG.axes, work_zone=None)
    outcomes = {"refused": 0, "planning": 0, "ran": 0}
    start = time.perf_counter()
    for _ in range(count):
        outcomes[_check(_program(rng), planner)] += 1
    wall = time.perf_counter() - start
    print(f"{count} programs in {wall:.1f} s: {outcomes}")
    assert sum(outcomes.values()) == count
    assert outcomes["refused"] > 0 and outcomes["ran"] > 0   # both sides were reached
