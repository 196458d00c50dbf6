"""CAM-like programs (twin.analysis.studies.cam) as the twin runs them: what they are, and the
accuracy of the look-ahead on them (issue 12)."""

from __future__ import annotations

import itertools
import math
import os

import pytest

from twin.analysis.studies import cam
from twin.controller.gcode import parse
from twin.controller.gcode.items import Move
from twin.session.run import RunSpec, run

FULL = not os.environ.get("CI")
FRICTIONLESS = {"axes.*.mechanics.slide_coulomb": 0.0, "axes.*.mechanics.rotor_coulomb": 0.0}


def moves(text):
    return [m for m in parse(text, start=(0.01, 0.01)) if isinstance(m, Move)]


def test_the_programs_are_what_cam_sends():
    nest = moves(cam.chorded_nest())
    cut = [m for m in nest if m.kind != "rapid"]
    assert {m.kind for m in cut} == {"line"}                      # no arcs: chords
    assert sum(math.dist(m.start, m.end) for m in cut) == pytest.approx(32.6, rel=0.01)
    assert len(cut) > 7000
    letters = moves(cam.lettering())
    assert sum(m.kind == "rapid" for m in letters) >= 12          # one per outline
    pocket = moves(cam.pocket())
    assert max(math.dist(m.start, m.end) for m in pocket) > 0.09  # long passes
    chords = moves(cam.chords(5000))
    assert len([m for m in chords if m.kind == "line"]) == 5000


def test_a_circle_as_chords_keeps_its_radius():
    for chord in (0.5, 0.01):
        pts = [m.end for m in moves(cam.circle(2.0, chord=chord)) if m.kind == "line"]
        r = [math.dist(p, (0.2, 0.2)) for p in pts]
        assert max(r) == pytest.approx(2e-3, abs=1e-12) and min(r) == pytest.approx(2e-3, abs=1e-12)
        assert max(itertools.starmap(math.dist, itertools.pairwise(pts))) <= chord * 1e-3 * (
            1 + 1e-9)


@pytest.mark.slow
def test_the_lookahead_keeps_the_contour_within_tolerance_of_the_stop_run(tmp_path):
    """Issue 12: on the frictionless twin the look-ahead's contour error stays within the
    contour tolerance (50 µm on laser_belt) plus the stop-at-every-node run's own error,
    on a chorded nest (CI one part, the full run four)."""
    program = tmp_path / "nest.ngc"
    program.write_text(cam.chorded_nest(*((2, 2) if FULL else (1, 1))))
    errors = {}
    for planner in ("lookahead", "stop"):
        r = run(RunSpec(machine="laser_belt", program=str(program), planner=planner,
                        overrides=FRICTIONLESS), out_dir=tmp_path, rerun="none")
        assert r.summary["status"] == "FINISHED"
        errors[planner] = r.summary["max_contour_error_um"]
    assert errors["lookahead"] <= 50.0 + errors["stop"], errors
