"""The compiled cyclic path against the plain Python path it transcribes.

The Python tick stays the reference. Every test runs the same thing twice, once with the
compiled kernel off (``Controller._tick_compiled`` answering "not this tick") and once as
shipped, and compares the records bit for bit: no tolerance, because the kernel repeats the
reference's operations in the same order (``twin.controller.cyclic``). On the twin the
whole closed loop must then agree as well: the plant's truth is compared too.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.controller import controller as controller_module
from twin.controller.compensation import NO_COMPENSATION
from twin.controller.controller import Controller, ControllerStatus
from twin.controller.cyclic import steady_tick
from twin.controller.geometry import Line
from twin.controller.io import Inputs
from twin.controller.planner import MotionBlock
from twin.controller.shaping import NO_TAPS
from twin.session.run import RunSpec, run

LAWS = ("trapezoid", "parabolic", "cosine", "cubic", "jerk-limited")

# lines, both arc directions, a dwell and a full circle, relative to where the table stands
GCODE = """G21 G91 G17 F1500
G1 X6 Y2.5
G2 X10 Y0 I5 J0
G4 P0.2
G3 X-10 Y0 I-5 J0
G1 X-4 Y-6 F900
G2 X0 Y0 I3 J1
G1 X-2 Y3.5
M30
"""


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view(np.int64) if a.dtype == np.float64 else a


def _same(reference: dict[str, np.ndarray], compiled: dict[str, np.ndarray]) -> None:
    assert reference.keys() == compiled.keys()
    for name, ref in reference.items():
        got = compiled[name]
        assert ref.shape == got.shape, name
        diff = np.flatnonzero((_bits(ref) != _bits(got)).reshape(len(ref), -1).any(axis=1))
        assert diff.size == 0, (f"{name} differs first at row {diff[0]} of {len(ref)}: "
                                f"{ref[diff[0]]!r} against {got[diff[0]]!r}")


@pytest.fixture
def both(monkeypatch):
    """Run a spec with the kernel off, then on; returns the two results and the share of
    ticks the kernel took in the second run."""
    real = Controller._tick_compiled

    def go(spec: RunSpec, tmp_path, **options):
        monkeypatch.setattr(Controller, "_tick_compiled", lambda self, inputs: False)
        reference = run(spec, out_dir=tmp_path, rerun="none", **options)
        taken = [0, 0]

        def counted(self, inputs):
            done = real(self, inputs)
            taken[done] += 1
            return done

        monkeypatch.setattr(Controller, "_tick_compiled", counted)
        compiled = run(spec, out_dir=tmp_path, rerun="none", **options)
        monkeypatch.setattr(Controller, "_tick_compiled", real)
        return reference, compiled, taken[1] / max(1, sum(taken))

    return go


@pytest.mark.parametrize("law", LAWS)
def test_lines_arcs_and_dwells_give_the_same_bits(law, both, tmp_path):
    program = tmp_path / "shapes.ngc"
    program.write_text(GCODE)
    reference, compiled, share = both(RunSpec(program=str(program), profile=law), tmp_path)
    assert reference.summary["status"] == "FINISHED"
    _same(reference.record, compiled.record)
    assert share > 0.85, f"the kernel took only {share:.0%} of the ticks"


@pytest.mark.parametrize("shaper", ["zv", "ei"])
def test_shaped_and_compensated_runs_give_the_same_bits(shaper, both, tmp_path):
    """Both ticks call the one compensation and shaper cores: the records agree bit for
    bit with the reference offsets on (laser_belt: its belt mode, friction and stretch)."""
    program = tmp_path / "shapes.ngc"
    program.write_text(GCODE)
    spec = RunSpec(machine="laser_belt", program=str(program), profile=f"trapezoid+{shaper}",
                   overrides={"controller.compensation.smoothing": True,
                              "controller.compensation.stretch": True})
    reference, compiled, share = both(spec, tmp_path)
    assert reference.summary["status"] == "FINISHED"
    _same(reference.record, compiled.record)
    # the settling after the end (the shaper's delay, then in position) is Python's
    assert share > 0.5, f"the kernel took only {share:.0%} of the ticks"


@pytest.mark.parametrize("law", LAWS)
def test_chords_planned_as_runs_give_the_same_bits(law, both, tmp_path):
    """A circle of 4 mm sent as 0.5 mm chords: blends between them and, for the smooth laws,
    runs of blocks sharing one speed change (``BlendPart`` pieces in the kernel)."""
    n = 50
    lines = ["G21 G91 G17 F1200"]
    for k in range(n):
        a0, a1 = 2 * math.pi * k / n, 2 * math.pi * (k + 1) / n
        lines.append(f"G1 X{4.0 * (math.cos(a1) - math.cos(a0)):.6f} "
                     f"Y{4.0 * (math.sin(a1) - math.sin(a0)):.6f}")
    program = tmp_path / "chords.ngc"
    program.write_text("\n".join([*lines, "M30", ""]))
    spec = RunSpec(program=str(program), profile=law)
    reference, compiled, share = both(spec, tmp_path)
    assert reference.summary["status"] == "FINISHED"
    _same(reference.record, compiled.record)
    assert share > 0.5


@pytest.mark.parametrize("law", LAWS)
def test_a_spline_gives_the_same_bits(law, both, tmp_path):
    reference, compiled, share = both(RunSpec(builtin="spline_line", profile=law), tmp_path)
    assert reference.summary["status"] == "FINISHED"
    _same(reference.record, compiled.record)
    assert share > 0.85


def test_the_default_program_gives_the_same_bits(both, tmp_path):
    reference, compiled, share = both(RunSpec(), tmp_path)
    _same(reference.record, compiled.record)
    assert reference.summary == {**compiled.summary, "run_id": reference.summary["run_id"],
                                 "wall_time_s": reference.summary["wall_time_s"],
                                 "real_time_factor": reference.summary["real_time_factor"],
                                 "telemetry_wall_s": reference.summary["telemetry_wall_s"],
                                 "recording": reference.summary["recording"]}
    assert share > 0.95


def test_a_following_error_trip_inside_the_kernel_gives_the_same_bits(both, tmp_path):
    spec = RunSpec(builtin="spline_line",
                   overrides={"controller.regulator.following_error_limit": 20e-6})
    reference, compiled, _ = both(spec, tmp_path)
    assert reference.status == ControllerStatus.FOLLOWING_ERROR
    assert compiled.status == ControllerStatus.FOLLOWING_ERROR
    _same(reference.record, compiled.record)


def test_homing_and_jogs_give_the_same_bits(both, tmp_path):
    spec = RunSpec(builtin="none", commands=("home x", "jog y 0.004", "goto 0.05 0.04"))
    reference, compiled, share = both(spec, tmp_path)
    assert reference.summary["status"] == "FINISHED"
    _same(reference.record, compiled.record)
    assert share > 0.5          # the jogs; homing itself runs in Python


# --------------------------------------------------------------------------- block changes
def _chord_run(compiled: bool, read_ahead_in_tick: bool, law: str) -> tuple[Controller, int]:
    """A controller on 400 random chords of 0.02–0.1 mm (several block changes in some
    periods), fed a servo that follows its DAC; returns it and the number of ticks whose
    block change the kernel made."""
    cfg = load_machine("tomsk_xy")
    rng = np.random.default_rng(7)
    start = np.array((0.05, 0.04))
    heading, points = 0.0, [start]
    for _ in range(400):
        heading += rng.uniform(-0.5, 0.5)
        step = rng.uniform(0.02e-3, 0.1e-3)
        points.append(points[-1] + step * np.array((math.cos(heading), math.sin(heading))))
    blocks = [MotionBlock(Line(tuple(a), tuple(b)), 0.01) for a, b in
              itertools.pairwise(points)]
    ctrl = Controller.from_machine(cfg, blocks, start=tuple(start), compiled=compiled,
                                   profile=law)
    ctrl.read_ahead_in_tick = read_ahead_in_tick
    cpm = np.array([cfg.axes[a].counts_per_metre for a in ("x", "y")])
    kh = np.array([1.0 / cfg.axes[a].volts_per_speed for a in ("x", "y")])
    x = start.copy()
    inputs = Inputs()
    changes = 0
    while not ctrl.done:
        inputs.encoder_counts[:] = np.floor(x * cpm).astype(np.int64) % (1 << 32)
        block = ctrl.interpolator._cur
        kernel = ctrl.compiled and ctrl._tick_compiled(inputs)
        out = ctrl.outputs if kernel else ctrl._tick_python(inputs)
        changes += kernel and ctrl.interpolator._cur is not block
        if not read_ahead_in_tick:
            ctrl.read_ahead()
        x = x + kh * out.dac_volts * ctrl.period
    return ctrl, changes


@pytest.mark.parametrize("law", ("trapezoid", "jerk-limited"))
def test_block_changes_in_the_kernel_and_the_read_ahead_after_the_write(law):
    """The kernel makes the block changes to blocks read ahead (``Interpolator.landing``),
    also past blocks shorter than a period; reading ahead after the write instead of
    inside the tick changes no bit."""
    reference, _ = _chord_run(False, True, law)
    in_tick, _ = _chord_run(True, True, law)
    after_write, changes = _chord_run(True, False, law)
    assert reference.status == ControllerStatus.FINISHED
    blocks_run = int(reference.record.as_arrays()["block"].max()) + 1
    assert blocks_run >= 400                         # the chords and the blends between
    _same(reference.record.as_arrays(), in_tick.record.as_arrays())
    _same(reference.record.as_arrays(), after_write.record.as_arrays())
    # each tick whose block change the kernel made passed one block or more
    passes = np.diff(after_write.record.as_arrays()["block"])
    assert passes.max() >= 2, "no period passed a whole block: the test lost its point"
    assert changes >= 0.95 * np.count_nonzero(passes), (changes, np.count_nonzero(passes))


# --------------------------------------------------------------------------- without a plant
def _synthetic(compiled: bool, events: dict[int, str]) -> tuple[list, Controller]:
    """A controller on a line and an arc, fed inputs that follow its own reference with a
    lag and a ripple, and the events ``{tick: "limit"|"ready"|"hold"}``; returns every
    tick's outputs (dac, enable, status) and the controller."""
    cfg = load_machine("tomsk_xy")
    start = (0.05, 0.04)
    blocks = [MotionBlock(Line(start, (0.07, 0.05)), 0.02),
              MotionBlock(Line((0.07, 0.05), (0.06, 0.03)), 0.015)]
    ctrl = Controller.from_machine(cfg, blocks, start=start, compiled=compiled)
    cpm = np.array([cfg.axes[a].counts_per_metre for a in ("x", "y")])
    inputs = Inputs()
    inputs.encoder_counts[:] = np.rint(np.array(start) * cpm).astype(np.int64) + (1 << 31)
    out, lagged = [], np.array(start)
    for k in range(400):
        event = events.get(k)
        if event == "limit":
            inputs.limit_max[1] = True
        if event == "ready":
            inputs.drive_ready = False
        if event == "hold":
            ctrl.interpolator.stop()
        o = ctrl.tick(inputs)
        out.append((o.dac_volts.copy(), o.enable, ctrl.status))
        ref = ctrl.interpolator.reference.position
        lagged = lagged + 0.6 * (ref - lagged)
        ripple = np.array([math.sin(0.7 * k), math.cos(1.3 * k)]) * 3
        inputs.encoder_counts[:] = (np.rint(lagged * cpm + ripple).astype(np.int64)
                                    + (1 << 31)) % (1 << 32)
        inputs.tacho_volts[:] = (ref - lagged) * 1e3
    return out, ctrl


@pytest.mark.parametrize("events", [{}, {150: "limit"}, {60: "ready"}, {90: "hold"}],
                         ids=["clean", "limit-switch", "drive-fault", "feed-hold"])
def test_synthetic_inputs_give_the_same_outputs_tick_for_tick(events):
    reference, ctrl_ref = _synthetic(False, events)
    compiled, ctrl = _synthetic(True, events)
    for k, ((dac_r, en_r, st_r), (dac_c, en_c, st_c)) in enumerate(
            zip(reference, compiled, strict=True)):
        assert (_bits(dac_r) == _bits(dac_c)).all() and en_r == en_c and st_r == st_c, k
    _same(ctrl_ref.record.as_arrays(), ctrl.record.as_arrays())
    expected = {"limit-switch": ControllerStatus.LIMIT_TRIP,
                "drive-fault": ControllerStatus.DRIVE_FAULT}
    if events:
        kind = {"limit": "limit-switch", "ready": "drive-fault", "hold": "feed-hold"}[
            next(iter(events.values()))]
        assert ctrl.status == expected.get(kind, ControllerStatus.FINISHED)


def test_the_kernel_is_off_where_it_does_not_apply():
    cfg = load_machine("tomsk_xy")
    assert Controller.from_machine(cfg, None).compiled
    assert not Controller.from_machine(cfg, None, compiled=False).compiled
    assert not Controller.from_machine(cfg, None, mode="traditional").compiled
    wide = cfg.with_overrides({"axes.x.encoder.bits": 64})
    assert not Controller.from_machine(wide, None).compiled   # int64 unwrap: up to 62 bit


def test_a_closed_switch_leaves_the_state_untouched():
    """FALLBACK means nothing was written: the Python path then does the whole tick."""
    cfg = load_machine("tomsk_xy")
    ctrl = Controller.from_machine(cfg, [MotionBlock(Line((0.05, 0.04), (0.06, 0.04)), 0.01)],
                                   start=(0.05, 0.04))
    ctrl.tick(Inputs())
    ctrl.tick(Inputs())
    enc, reg, interp = ctrl.encoder, ctrl.regulator, ctrl.interpolator
    before = [a.copy() for a in (enc.state_int, enc.position, reg._st, reg.output,
                                 interp.reference.position)]
    closed = Inputs()
    closed.limit_min[0] = True
    geo, pieces, starts, table, coef = interp._cur.tables
    chunk, row = ctrl.record.slot()
    code = steady_tick(closed.encoder_counts, closed.tacho_volts, closed.limit_min,
                       closed.limit_max, True, ctrl._limits_prev, enc.state_int,
                       enc.state_float, enc.position, geo, pieces, starts, table, coef,
                       interp._tau + interp.period, 3, ctrl.period, *(
                           getattr(interp.reference, f) for f in
                           ("position", "velocity", "acceleration", "jerk")),
                       *NO_COMPENSATION, *NO_TAPS, reg._par, reg._st, reg.output, reg.error,
                       reg.terms, reg._code_min, reg._code_max, ctrl._held,
                       ctrl.outputs.dac_volts, chunk, row, 0, 0)
    assert code == controller_module.FALLBACK
    after = (enc.state_int, enc.position, reg._st, reg.output, interp.reference.position)
    for b, a in zip(before, after, strict=True):
        assert (_bits(b) == _bits(a)).all()
