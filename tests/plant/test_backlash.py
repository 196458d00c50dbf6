"""Lost motion and break-away friction in the mechanics.

Lost motion b: the table is driven through a dead band of width b in series with the screw
spring, so it sits ±b/2 from the motor's position, on the side the forces on it push it
to. On a circle those forces flip where an axis reverses (at the quadrants: friction and
damping change sign with the velocity), the motor then travels b before the table follows,
and the table's true path bulges in by b/2 there: the quadrant spike of the contour error,
which the motor encoder does not see. Without lost motion there is none.

Break-away friction F_s > F_c: a standing slide holds until the screw pushes with F_s.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import load_machine
from twin.plant import FINE_FIELDS, Plant
from twin.plant.model import axis_mechanics
from twin.session.run import RunSpec, run

CIRCLE = """G21 G90 G17
G1 X10 Y20 F300
G1 X20 Y20
G3 X20 Y20 I0 J10
G1 X30 Y20
M2
"""
"""A 10 mm circle at 300 mm/min about (20, 30) mm, entered and left along its tangent at
its lowest point, so that the quadrants at 0°, 90° and 180° are clean."""

NO_COULOMB = {"axes.*.mechanics.slide_coulomb": 0.0, "axes.*.mechanics.rotor_coulomb": 0.0}


def _quadrant_spikes(tmp_path, backlash: float, extra: dict | None = None):
    """(peak radial error of the table near the quadrants 0°, 90°, 180° (m), largest
    radial error away from every quadrant (m)) on the circle, DCU order 3."""
    prog = tmp_path / "circle.ngc"
    prog.write_text(CIRCLE, encoding="utf-8")
    spec = RunSpec(machine="tomsk_xy", program=str(prog), dcu_order=3,
                   overrides={"axes.*.transmission.backlash": backlash, **(extra or {})})
    result = run(spec, out_dir=tmp_path, rerun="none")
    assert result.summary["status"] == "FINISHED"
    rec = result.record
    arc = next(s for s in result.path if type(s).__name__ == "Arc")
    pos = rec["table_position"]
    angle = np.degrees(np.arctan2(pos[:, 1] - arc.center[1], pos[:, 0] - arc.center[0]))
    radial = np.abs(np.hypot(*(pos - arc.center).T) - arc.radius)
    on_arc = rec["line"] == 4                          # the G3 block

    def near(q, width):
        return np.abs((angle - q + 180.0) % 360.0 - 180.0) < width

    peaks = [radial[on_arc & near(q, 10.0)].max() for q in (0.0, 90.0, 180.0)]
    away = on_arc & ~near(0, 20) & ~near(90, 20) & ~near(180, 20) & ~near(-90, 20)
    encoder = np.abs(np.hypot(*(rec["position"] - arc.center).T) - arc.radius)
    seen = max(encoder[on_arc & near(q, 10.0)].max() for q in (0.0, 90.0, 180.0))
    return np.array(peaks), radial[away].max(), seen


def test_lost_motion_makes_the_quadrant_spike_half_its_width(tmp_path):
    b = 10e-6
    clean, clean_away, _ = _quadrant_spikes(tmp_path, 0.0, NO_COULOMB)
    lashed, lashed_away, seen = _quadrant_spikes(tmp_path, b, NO_COULOMB)
    assert clean.max() < 0.5e-6 and clean_away < 0.5e-6  # no spike without lost motion
    np.testing.assert_allclose(lashed, b / 2, rtol=0.25)  # the table stops b/2 short
    assert lashed_away < lashed.min()                      # a spike, not a shifted circle
    # the motor encoder sees none of it: the controller's own view has no spike
    assert seen < 1e-6


def test_lost_motion_adds_to_the_friction_spike(tmp_path):
    """With Coulomb friction a quadrant spike exists already (stiction at the reversal);
    lost motion adds b/2 to it."""
    b = 20e-6
    friction, _, _ = _quadrant_spikes(tmp_path, 0.0)
    both, _, _ = _quadrant_spikes(tmp_path, b)
    assert friction.min() > 1e-6
    np.testing.assert_allclose(both - friction, b / 2, rtol=0.25)


def _deflection_at_breakaway(breakaway: float) -> float:
    """A slow speed-reference ramp on X: the screw winds up against the standing slide until
    the slide breaks away; returns the largest screw deflection before the table moved."""
    cfg = load_machine("tomsk_xy").with_overrides(
        {"axes.x.mechanics.slide_breakaway": breakaway})
    plant = Plant(cfg)
    plant.reset()
    col = {name: k for k, (name, _) in enumerate(FINE_FIELDS)}
    x0 = plant.truth().table_position[0]
    deflection = []
    for k in range(400):
        plant.step(np.array([0.002 * k, 0.0]), cfg.controller.period)
        fine = plant.fine
        x = fine[:, 2 * col["table_position"]]
        d = fine[:, 2 * col["screw_deflection"]]
        moved = np.abs(x - x0) > 0.2e-6
        if moved.any():
            deflection.extend(d[:np.argmax(moved)])
            break
        deflection.extend(d)
    return max(deflection)


@pytest.mark.parametrize("breakaway", [0.0, 40.0])
def test_a_standing_slide_holds_until_the_screw_pushes_with_the_breakaway_force(breakaway):
    cfg = load_machine("tomsk_xy")
    ax = cfg.axes["x"]
    # the screw deflection is the axial spring's (screw, nut, bearing), here at home
    k = axis_mechanics(cfg, "x", ax.switches.home).stiffness
    f_s = max(breakaway, ax.mechanics.slide_coulomb)
    assert _deflection_at_breakaway(breakaway) == pytest.approx(f_s / k, rel=0.15)
