"""The cyclic controller against a simulated linear plant behind a tiny MachineIO.

The plant is the seed's continuous part K_H/(p·(T·p + 1)) per axis, discretised exactly
under a zero-order hold over the period after each write (like the lock-step twin), quantised
encoders on wrapping counters, limit and home switches. The one period of delay that the
regulator's models assume is the controller's own (it computes ahead).
"""

import itertools
import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.controller.controller import RECORD_FIELDS, Controller, ControllerStatus
from twin.controller.gains import RegulatorGains, default_gains
from twin.controller.gcode import parse
from twin.controller.io import Inputs, MachineIO, Outputs
from twin.controller.linear import LinearAxisModel
from twin.controller.loop_defaults import estimated_axis_model, servo_lag
from twin.controller.metrics import contour_error
from twin.controller.planner import MotionBlock, segments_from_program
from twin.controller.record import Record
from twin.errors import PlanningError

CFG = load_machine("tomsk_xy")
AXES = [CFG.axes["x"], CFG.axes["y"]]
PROGRAM = ("G21 G90\nG1 X60 Y50 F600\nG1 X60 Y60\nG3 X50 Y70 I-10 J0\nG4 P0.1\n"
           "G1 X40 Y65 F900\nG2 X40 Y55 I0 J-5\nM2")


class LinearPlant(MachineIO):
    """K_H/(p(Tp+1)) per axis, exact ZOH, 32-bit wrapping counters."""

    def __init__(self, *, start=(0.05, 0.05), time_constant=0.0173, count_offset=(0, 0)):
        self.kh = [1.0 / ax.volts_per_speed for ax in AXES]
        self.cpm = [ax.counts_per_metre for ax in AXES]
        self.decay = math.exp(-CFG.controller.period / time_constant)
        self.tc = time_constant
        self.x, self.v = list(start), [0.0, 0.0]
        self.offset = list(count_offset)
        self.applied = Outputs()
        self.inputs = Inputs()
        self.forced_limit: tuple[int, str] | None = None
        self.jammed = False
        self.drive_ready = True
        self.ticks = 0

    def read(self) -> Inputs:
        inp = self.inputs
        for k, ax in enumerate(AXES):
            inp.encoder_counts[k] = (math.floor(self.x[k] * self.cpm[k]) + self.offset[k]) \
                % 2**32
            inp.tacho_volts[k] = self.v[k] / self.kh[k]
            sw = ax.switches
            inp.limit_min[k] = self.x[k] <= sw.limit_min or self.forced_limit == (k, "min")
            inp.limit_max[k] = self.x[k] >= sw.limit_max or self.forced_limit == (k, "max")
            inp.home[k] = sw.home - sw.home_width <= self.x[k] <= sw.home
        inp.drive_ready = self.drive_ready
        inp.time = self.ticks * CFG.controller.period
        return inp

    def write(self, outputs: Outputs) -> None:
        period = CFG.controller.period
        self.applied = Outputs(outputs.dac_volts.copy(), outputs.enable)
        for k in range(2):
            u = self.applied.dac_volts[k] if self.applied.enable else 0.0
            target = self.kh[k] * u
            dv = self.v[k] - target
            if not self.jammed:
                self.x[k] += target * period + dv * self.tc * (1.0 - self.decay)
                self.v[k] = target + dv * self.decay
        self.ticks += 1

    def close(self) -> None:
        self.applied = Outputs()


def controller(program=PROGRAM, *, start=(0.05, 0.05), **options):
    prog = parse(program, start=start) if isinstance(program, str) else program
    return Controller.from_machine(CFG, prog, start=start, **options)


def run_until(ctrl, plant, predicate, limit=20_000):
    for _ in range(limit):
        out = ctrl.tick(plant.read())
        plant.write(out)
        if predicate(ctrl):
            return out
    raise AssertionError(f"condition not reached, status {ctrl.status.name}")


# ------------------------------------------------------------------------ following
def test_follows_a_program_and_ends_disabled_on_the_end_point():
    ctrl, plant = controller(), LinearPlant()
    status = ctrl.run(plant, max_time=60.0)
    assert status == ControllerStatus.FINISHED
    rec = ctrl.record.as_arrays()
    assert set(rec) == {name for name, _ in RECORD_FIELDS}
    n = len(rec["t"])
    np.testing.assert_allclose(np.diff(rec["t"]), CFG.controller.period, rtol=1e-9)
    assert rec["terms"].shape == (n, 2, 5) and rec["position"].shape == (n, 2)
    # the programmed end, exactly, in the reference; the table within 2 counts of it
    assert rec["ref_position"][-1].tolist() == [0.04, 0.055]
    np.testing.assert_allclose(plant.x, [0.04, 0.055], atol=2 / 5e6)
    # finished: outputs zero, drives disabled; the settling lasted settle_time
    assert not ctrl.outputs.enable and np.all(ctrl.outputs.dac_volts == 0.0)
    settling = rec["status"] == ControllerStatus.SETTLING
    assert settling.sum() == round(ctrl.settle_time / CFG.controller.period)
    assert rec["enable"][-1] == 0 and rec["enable"][settling].all()
    # a P loop without feed-forward lags by v/K_v (K_v = kp·K_H): the seed's velocity error
    k_v = ctrl.gains.kp[0] / AXES[0].volts_per_speed
    lag = np.hypot(*rec["following_error"].T).max()
    assert 0.5 * 0.015 / k_v < lag < 1.3 * 0.015 / k_v
    np.testing.assert_allclose(rec["following_error"], rec["ref_position"] - rec["position"])
    statuses = [k for k, _ in itertools.groupby(rec["status"].tolist())]
    assert statuses == [ControllerStatus.RUNNING, ControllerStatus.DWELLING,
                        ControllerStatus.RUNNING, ControllerStatus.SETTLING,
                        ControllerStatus.FINISHED]


def test_feed_forward_of_the_float_channels_cuts_the_contour_error():
    """FF1..FF3 fed by the interpolator's v, a, j channels (seed 004's extended interface).

    Compared on the 90th percentile: the largest errors sit at the corners, where the node
    speed (the corner model) rather than the regulator sets them."""
    models = [estimated_axis_model(ax) for ax in AXES]
    errors = {}
    for ff in (False, True):
        gains = default_gains(models, CFG.controller.period, ff=ff)
        ctrl, plant = controller(gains=gains), LinearPlant()
        assert ctrl.run(plant, max_time=60.0) == ControllerStatus.FINISHED
        rec = ctrl.record.as_arrays()
        path = [b.segment for b in segments_from_program(parse(PROGRAM, start=(0.05, 0.05)))
                if isinstance(b, MotionBlock)]
        errors[ff] = np.percentile(contour_error(path, rec["position"]), 90)
    assert errors[True] < 0.1 * errors[False]


@pytest.mark.parametrize(("ff1_times_kh", "expected"), [
    (0.0, lambda kv, t, T: 1.0 / kv),            # P loop: the ramp lag 1/K_v
    (0.5, lambda kv, t, T: 0.5 / kv),
    (1.0, lambda kv, t, T: t + T),               # full FF: the drive's lag and the delay
])
def test_servo_lag_for_the_corner_model(ff1_times_kh, expected):
    model = LinearAxisModel.servo(2e-3, 0.02)
    gains = RegulatorGains(kp=5000.0, ff1=ff1_times_kh / 2e-3)
    kv = 5000.0 * 2e-3
    assert servo_lag(gains, [model, model], 5e-3) == pytest.approx(
        max(expected(kv, 0.02, 5e-3), 0.025), rel=1e-12)


def test_traditional_interface_runs_the_same_program():
    ctrl, plant = controller(mode="traditional"), LinearPlant()
    assert ctrl.run(plant, max_time=60.0) == ControllerStatus.FINISHED
    ref = ctrl.record.as_arrays()["ref_position"]
    np.testing.assert_allclose(ref * 5e6, np.round(ref * 5e6), atol=1e-6)


# ------------------------------------------------------------------------ trips
@pytest.mark.parametrize("switch", [(0, "max"), (1, "min")])
def test_limit_switch_trips_with_outputs_zero_and_latches(switch):
    ctrl, plant = controller(), LinearPlant()
    run_until(ctrl, plant, lambda c: len(c.record) == 200)
    plant.forced_limit = switch
    out = run_until(ctrl, plant, lambda c: True)
    assert ctrl.status == ControllerStatus.LIMIT_TRIP
    assert not out.enable and np.all(out.dac_volts == 0.0)
    plant.forced_limit = None                    # released: still latched
    for _ in range(20):
        out = ctrl.tick(plant.read())
        assert ctrl.status == ControllerStatus.LIMIT_TRIP and not out.enable
    ctrl.reset()
    assert ctrl.status == ControllerStatus.IDLE


def test_following_error_trips_with_outputs_zero():
    ctrl, plant = controller(), LinearPlant()
    run_until(ctrl, plant, lambda c: len(c.record) == 100)
    plant.jammed = True
    out = run_until(ctrl, plant, lambda c: c.status == ControllerStatus.FOLLOWING_ERROR)
    assert not out.enable and np.all(out.dac_volts == 0.0)
    err = ctrl.record.as_arrays()["following_error"][-1]
    assert np.abs(err).max() > CFG.controller.regulator.following_error_limit
    ctrl.tick(plant.read())
    assert ctrl.status == ControllerStatus.FOLLOWING_ERROR and not ctrl.outputs.enable


def test_drive_fault_disables_the_outputs():
    ctrl, plant = controller(), LinearPlant()
    run_until(ctrl, plant, lambda c: len(c.record) == 50)
    plant.drive_ready = False
    out = run_until(ctrl, plant, lambda c: True)
    assert ctrl.status == ControllerStatus.DRIVE_FAULT and not out.enable


def test_record_grows_in_chunks_without_changing_a_value():
    runs = []
    for capacity in (97, 65536):
        ctrl, plant = controller(record_capacity=capacity), LinearPlant()
        ctrl.run(plant, max_time=60.0)
        runs.append(ctrl.record.as_arrays())
    assert len(runs[0]["t"]) > 10 * 97
    for name, values in runs[1].items():
        np.testing.assert_array_equal(runs[0][name], values)


@pytest.mark.parametrize("capacity", [1, 3, 7, 64])
def test_record_reads_any_tail_across_chunks(capacity):
    rec = Record([("t", 1), ("terms", (2, 2)), ("status", 1)], integer=("status",),
                 capacity=capacity)
    rows = np.arange(50 * 6, dtype=float).reshape(50, 6)
    for row in rows:
        rec.append(row)
    assert len(rec) == 50
    for start in range(0, 55):
        np.testing.assert_array_equal(rec.table(start), rows[start:].reshape(-1, 6))
        arrays = rec.as_arrays(start)
        np.testing.assert_array_equal(arrays["terms"], rows[start:, 1:5].reshape(-1, 2, 2))
        assert arrays["status"].dtype == np.int64


def test_a_released_record_keeps_its_row_numbers_and_frees_whole_chunks():
    rec = Record([("t", 1), ("v", 2)], capacity=8)
    rows = np.arange(100 * 3, dtype=float).reshape(100, 3)
    read = 0
    for k, row in enumerate(rows):
        rec.append(row)
        if k % 13 == 12:           # a reader that consumes the tail, then releases it
            np.testing.assert_array_equal(rec.table(read), rows[read:k + 1])
            read = k + 1
            rec.release(read)
            assert rec.first <= read < rec.first + 2 * 8
            assert len(rec._chunks) <= 2
        if k == 50:
            rec.capacity = 3       # later chunks are smaller; row numbers stay
    assert len(rec) == 100
    np.testing.assert_array_equal(rec.table(read), rows[read:])
    with pytest.raises(ValueError, match="released"):
        rec.table(0)
    chunk, i = rec.slot()          # the in-place writer continues after the released rows
    chunk[i] = -1.0
    rec.advance()
    assert len(rec) == 101 and rec.table(100).tolist() == [[-1.0, -1.0, -1.0]]


def test_encoder_wrap_mid_run_is_harmless():
    runs = []
    for offset in ((0, 0), (2**32 - 250_010, 2**32 - 300)):   # x wraps after 50 mm of travel
        ctrl, plant = controller(), LinearPlant(count_offset=offset)
        assert ctrl.run(plant, max_time=60.0) == ControllerStatus.FINISHED
        runs.append(ctrl.record.as_arrays())
    for name in ("position", "dac_volts", "following_error", "status"):
        np.testing.assert_array_equal(runs[0][name], runs[1][name])


# ------------------------------------------------------------------------ soft limits
def test_program_leaving_the_work_zone_is_refused_before_motion():
    bad = "G21 G90\nG1 X60 Y50 F600\nG1 X60 Y250\nM2"
    with pytest.raises(PlanningError, match="line 3"):
        controller(bad)


def test_program_that_does_not_start_at_the_table_is_refused():
    prog = parse(PROGRAM, start=(0.05, 0.05))
    with pytest.raises(PlanningError, match="line 2: the program starts at"):
        Controller.from_machine(CFG, prog, start=(0.05, 0.06))


def test_streamed_program_stops_at_rest_before_the_bad_block():
    items = parse("G21 G90\nG1 X60 Y50 F600\nG1 X60 Y250\nM2", start=(0.05, 0.05)).items
    ctrl, plant = Controller.from_machine(CFG, iter(items), start=(0.05, 0.05)), LinearPlant()
    assert ctrl.run(plant, max_time=30.0) == ControllerStatus.PROGRAM_ERROR
    assert isinstance(ctrl.error, PlanningError) and "line 3" in str(ctrl.error)
    np.testing.assert_allclose(plant.x, [0.06, 0.05], atol=1e-6)      # the rig's 1 µm
    assert not ctrl.outputs.enable


# ------------------------------------------------------------------------ manual mode
def test_idle_controller_keeps_the_drives_disabled():
    ctrl = Controller.from_machine(CFG, None, start=(0.1, 0.1))
    out = ctrl.tick(LinearPlant(start=(0.1, 0.1)).read())
    assert ctrl.status == ControllerStatus.IDLE and not out.enable


def test_home_then_jog_in_machine_coordinates():
    plant = LinearPlant(start=(0.05, 0.04))
    ctrl = Controller.from_machine(CFG, None, start=(0.1, 0.1))      # coordinates unknown
    ctrl.home("x")
    run_until(ctrl, plant, lambda c: c.done)
    assert ctrl.status == ControllerStatus.FINISHED
    search = 0.25 * AXES[0].limits.max_velocity
    x_ctrl = ctrl.encoder.position[0]
    assert abs(x_ctrl - plant.x[0]) <= search * CFG.controller.period + 2 / 5e6
    assert plant.x[0] < CFG.axes["x"].switches.home                  # braked past the edge
    with pytest.raises(PlanningError):
        ctrl.jog((0.5, 0.1))                                          # outside the zone
    ctrl.jog((0.03, ctrl.position_reference[1]))
    with pytest.raises(PlanningError):
        ctrl.jog((0.04, 0.1))                                         # busy
    run_until(ctrl, plant, lambda c: c.done)
    assert ctrl.status == ControllerStatus.FINISHED
    assert plant.x[0] == pytest.approx(0.03, abs=search * CFG.controller.period + 4 / 5e6)


def test_homing_toward_a_limit_trips_and_without_switches_fails_cleanly():
    plant = LinearPlant(start=(0.05, 0.04))
    ctrl = Controller.from_machine(CFG, None, start=(0.1, 0.1))
    ctrl.home("y", direction=1)                          # away from the home switch
    run_until(ctrl, plant, lambda c: c.done)
    assert ctrl.status == ControllerStatus.LIMIT_TRIP
    assert plant.x[1] >= CFG.axes["y"].switches.limit_max

    class NoSwitches(LinearPlant):
        def read(self):
            inp = super().read()
            inp.home[:] = inp.limit_min[:] = inp.limit_max[:] = False
            return inp

    plant = NoSwitches(start=(0.05, 0.15))
    ctrl = Controller.from_machine(CFG, None, start=(0.1, 0.1))
    ctrl.home("y")
    run_until(ctrl, plant, lambda c: c.done, limit=40_000)
    assert ctrl.status == ControllerStatus.HOMING_FAILED and not ctrl.outputs.enable
