"""The identification plan (its sequence, its room), the log's checks and the machine-file
writer that ``twin identify`` writes its calibrated file with."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pytest

from twin.config import AXES, available_machines, load_machine
from twin.config.writer import machine_to_toml
from twin.errors import ConfigError, ExperimentAborted
from twin.hardware.realtime import TickStats
from twin.hardware.sim import SimDriver
from twin.identify.experiments import disturbed, run_plan, timing
from twin.identify.plan import (
    EXPERIMENTS,
    Piece,
    default_plan,
    excursion,
    parse_axes,
    phases,
    prbs,
)
from twin.plant import Plant


@pytest.mark.parametrize("name", available_machines())
def test_a_machine_written_back_loads_to_the_same_configuration(name, tmp_path):
    cfg = load_machine(name)
    path = tmp_path / f"{name}.toml"
    path.write_text(machine_to_toml(cfg, header=["a header", "of two lines"]))
    again = load_machine(str(path))
    assert dataclasses.replace(again, source="") == dataclasses.replace(cfg, source="")
    assert path.read_text().startswith("# a header\n# of two lines\n")


def test_the_prbs_is_a_maximal_length_sequence():
    seq = prbs()
    assert len(seq) == 127 and set(seq) == {-1, 1}
    assert seq.count(1) == 64                       # m-sequence balance: one more 1
    # its periodic autocorrelation is 127 at lag 0 and -1 at every other lag
    s = np.array(seq)
    for lag in range(1, 127):
        assert int(s @ np.roll(s, lag)) == -1


def test_the_default_plan_runs_every_experiment_within_a_minute():
    plan = default_plan(0.015, home_width=0.5e-3)
    assert {p.experiment for p in plan} == set(EXPERIMENTS)
    assert math.fsum(p.duration for p in plan) <= 60.0
    assert len(phases(plan)) == 2 and phases(plan)[1][0].kind == "home"
    with pytest.raises(ConfigError, match="amplitude"):
        default_plan(0.015, amplitude=1.5)


def test_the_excursion_bounds_the_positions_including_a_coast():
    plan = [Piece("s", "speed", 1.0, 0.01), Piece("c", "coast", 2.0, 0.0),
            Piece("s", "speed", 0.5, -0.01)]
    lo, hi = excursion(plan, overshoot=1.0)
    assert (lo, hi) == (0.0, pytest.approx(0.01))          # the coast taken as a stop
    lo, hi = excursion(plan, overshoot=1.0, coast_travel=lambda v: 0.5 * v)
    assert hi == pytest.approx(0.015) and lo == 0.0


@pytest.mark.parametrize("seed", range(8))
def test_the_coast_bound_holds_a_machine_with_less_friction_and_more_inertia(seed):
    """The room a coast-down is given (``experiments._coast_bound``) bounds the coast of
    any machine within ``SPREAD`` of the model's inertia and frictions: against a
    solve_ivp integration of J·dω/dt = −(T_c + B·ω) to rest, for random such machines
    (and equals it at the envelope's corner)."""
    from scipy.integrate import solve_ivp

    from twin.drive.design import axis_inertia
    from twin.identify.experiments import SPREAD, _coast_bound

    rng = np.random.default_rng(seed)
    base = load_machine("tomsk_xy")
    a = AXES[seed % 2]
    # a model with friction and inertia of its own: viscous-heavy, Coulomb-heavy or none
    f = {"rotor_coulomb": rng.uniform(0.2, 3.0), "slide_coulomb": rng.uniform(0.2, 3.0),
         "rotor_viscous": rng.choice([0.0, rng.uniform(0.2, 5.0)]),
         "slide_viscous": rng.uniform(0.2, 5.0), "rotor_inertia": rng.uniform(0.5, 2.0)}
    m = base.axes[a].mechanics
    model = base.with_overrides({f"axes.{a}.mechanics.{k}": v * getattr(m, k)
                                 for k, v in f.items()})
    ax = model.axes[a]
    r = ax.transmission.ratio
    bound = _coast_bound(model, a)
    v = rng.uniform(1e-3, 0.02)

    def coast(j: float, tc: float, b: float) -> float:
        def rhs(_t, y):
            return [y[1], -(tc + b * y[1]) / j if y[1] > 0.0 else 0.0]

        stop = lambda _t, y: y[1]   # noqa: E731 (at rest)
        stop.terminal = True
        sol = solve_ivp(rhs, (0.0, 1e3), [0.0, v / r], events=stop, rtol=1e-10,
                        atol=1e-12)
        return r * float(sol.y[0, -1])

    j0 = axis_inertia(ax, model.moving_masses()[a])
    tc0 = ax.mechanics.rotor_coulomb + r * ax.mechanics.slide_coulomb
    b0 = ax.mechanics.rotor_viscous + r * r * ax.mechanics.slide_viscous
    corner = coast(SPREAD * j0, tc0 / SPREAD, b0 / SPREAD)
    assert bound(v) == pytest.approx(corner, rel=1e-6)
    for _ in range(5):   # machines inside the envelope coast less
        j = j0 * rng.uniform(1.0, SPREAD)
        tc, b = tc0 / rng.uniform(1.0, SPREAD), b0 / rng.uniform(1.0, SPREAD)
        assert coast(j, tc, b) <= bound(v) * (1.0 + 1e-6)
    # BASE's own machine coasts less than half the bound
    assert coast(j0, tc0, b0) < 0.5 * bound(v)


class _Recording(SimDriver):
    """The lock-step twin, keeping what was last written."""

    last = None

    def write(self, outputs):
        self.last = (outputs.dac_volts.copy(), outputs.enable)
        super().write(outputs)


def test_an_experiment_that_leaves_its_room_stops_the_machine_safely():
    base = load_machine("tomsk_xy")
    # the real drive is three times faster than the model: the steps overrun their room
    fast = base.with_overrides({f"axes.{a}.tacho.gain": base.axes[a].tacho.gain / 3.0
                                for a in AXES})
    plant = Plant(fast, noise=False)
    plant.reset()
    driver = _Recording(plant, base.controller.period)
    with pytest.raises(ExperimentAborted, match="left the room") as info:
        run_plan(driver, base, [Piece("steps", "speed", 2.0, 1e-3),
                                Piece("steps", "speed", 0.5, 0.0)])
    dac, enable = driver.last
    assert not enable and np.all(dac == 0.0)
    assert info.value.log.ticks > 0 and "aborted" in info.value.log.notes


@pytest.mark.parametrize(("text", "axes"), [("x", ("x",)), ("Y", ("y",)), ("xy", ("x", "y")),
                                            ("yx", ("x", "y")), (" y ", ("y",))])
def test_the_axes_option_names_the_axes_in_machine_order(text, axes):
    assert parse_axes(text) == axes


@pytest.mark.parametrize("text", ["", "z", "xx", "xyz", "x,y"])
def test_a_bad_axes_option_names_the_option(text):
    with pytest.raises(ConfigError, match="axes"):
        parse_axes(text)


class _Stalling(SimDriver):
    """The twin behind a loop that stalls once, 15 ms (three periods) inside one read."""

    reads = 0

    def read(self):
        self.reads += 1
        if self.reads == 30:
            time.sleep(0.015)
        return super().read()


def _paced_steps(driver):
    """Two speed steps of tomsk_xy's twin run paced through ``driver`` (a SimDriver class)."""
    base = load_machine("tomsk_xy")
    plant = Plant(base, noise=False)
    plant.reset()
    plan = [Piece("steps", "speed", 0.3, 1e-3), Piece("steps", "speed", 0.1, 0.0)]
    return run_plan(driver(plant, base.controller.period), base, plan, paced=True)


def test_a_paced_phase_disturbed_by_a_stall_is_measured_again():
    period = load_machine("tomsk_xy").controller.period
    log = _paced_steps(_Stalling)
    reports = log.notes["deadlines"]
    first = reports[0]
    assert first["attempt"] == 0 and first["skipped"] >= 2   # the stall lost its slots
    assert log.notes["repeated"][0].startswith("phase 0: ")
    assert [r["attempt"] for r in reports] == list(range(len(reports)))
    # the log holds one attempt, the least disturbed: every due slot of it that ran
    kept = min(reports, key=lambda r: (r["skipped"], r["jitter_max_us"]))
    assert log.ticks == kept["due"] - kept["skipped"] and kept["due"] >= round(0.4 / period)
    assert "repeated for timing: phase 0" in timing(log.notes)


@pytest.mark.parametrize(("skipped", "late_us", "want"), [(0, 2400.0, False), (0, 2500.0, True),
                                                          (1, 10.0, True), (0, 0.0, False)])
def test_a_phase_is_disturbed_by_a_lost_slot_or_a_tick_half_a_period_late(skipped, late_us,
                                                                           want):
    stats = TickStats(5e-3, 100, 100 - skipped, 0, skipped, 1.0, 2.0, late_us, 5e-4)
    assert disturbed(stats) is want


class _SlowWrite(SimDriver):
    """The twin behind a loop whose every 25th write takes 6.5 ms (1.3 periods): the next
    tick reads the machine about 1.5 ms after its slot's deadline (a tick late by less
    than half a period: the phase is not measured again for it)."""

    writes = 0

    def write(self, outputs):
        self.writes += 1
        super().write(outputs)
        if self.writes % 25 == 12:
            time.sleep(0.0065)


def test_a_paced_log_holds_when_each_tick_read_the_machine():
    """A tick that ran late read the machine late, and its volts took over late: the log's
    time is when its read went out, not its slot's deadline (a replay on the deadlines
    applied the previous volts for a period too short). A loaded host makes more ticks late,
    never early, so both checks hold under load."""
    period = load_machine("tomsk_xy").controller.period
    log = _paced_steps(_SlowWrite)
    t = log.data["t"]
    late = (t - t[0]) - np.arange(len(t)) * period     # after its slot (the first on time)
    assert late.min() >= -1e-4     # no read logged before its slot (a loaded host: later)
    assert late.max() >= 1e-3      # a tick after a slow write, at its own time (was 0)
