"""HilModule on an injected clock: physics in whole drive intervals that equals a plant
stepped by hand, the process image against the plant's own reading, the watchdog at the
exact instant of expiry, the phase lock, and the pymodbus glue."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymodbus.constants import ExcCodes

from twin.config import load_machine
from twin.errors import ConfigError, SimulationError
from twin.hardware.hil import CLIENT, HilModule, Refused
from twin.hardware.hil_server import access, hil_plant
from twin.hardware.register_map import (
    dac_volts,
    dac_word,
    load_register_map,
    word_to_volts,
    words_to_counter,
)

CFG = load_machine("tomsk_xy")
RMAP = load_register_map()
WATCHDOG, FEED, DAC_X, DAC_Y, ENABLE = 0.05, 2, 0, 1, 0


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


@pytest.fixture(scope="module")
def plants():
    """Two warmed-up plants: one behind the module, one stepped by hand as the reference."""
    return hil_plant(CFG), hil_plant(CFG)


@pytest.fixture
def rig(plants):
    plant, ref = plants
    for p in plants:
        p.reset()
    clock = Clock()
    module = HilModule(plant, RMAP, watchdog=WATCHDOG, sync_phase=None, clock=clock)
    ref.enable(False)
    return module, ref, clock


def _counts(module):
    words = module.input_registers()
    return [words_to_counter(words[a], words[a + 1]) for a in (0, 2)]


def _drive(module, volts, feed=1):
    module.write_holding(FEED, feed)      # outputs are taken only once the watchdog is fed
    for addr, v in zip((DAC_X, DAC_Y), volts, strict=True):
        module.write_holding(addr, dac_word(v, 10.0, 12))
    assert module.write_coil(ENABLE, True)


def test_physics_advances_in_whole_intervals_with_the_clock(rig):
    module, _, clock = rig
    dt = module.dt
    for now, total in ((3.7 * dt, 3), (3.9 * dt, 3), (4.0 * dt, 4), (10.2 * dt, 10)):
        clock.now = now
        module.advance()
        assert module.plant.time == pytest.approx(total * dt, abs=1e-12)
    assert module.stats().max_catch_up == 6


def test_outputs_drive_the_plant_exactly_like_a_plant_stepped_by_hand(rig):
    module, ref, clock = rig
    dt, u = module.dt, np.array([2.0, -1.5])
    uq = np.array([dac_volts(dac_word(v, 10.0, 12), 10.0, 12) for v in u])
    _drive(module, u)
    ref.enable(True)
    rng = np.random.default_rng(7)
    steps = 0
    for feed in range(2, 60):   # irregular request times, fed at each
        clock.now += rng.uniform(0.1, 3.0) * dt
        steps += module.advance()
        module.write_holding(FEED, feed)
    ref.step(uq, steps * dt)
    r = ref.read()
    assert _counts(module) == r.encoder_counts.tolist()
    assert module.plant.truth().table_position.tolist() == ref.truth().table_position.tolist()
    assert r.encoder_counts[0] > 50_000 > r.encoder_counts[1]    # X forward, Y back


def test_image_is_the_plant_reading(rig):
    module, _, clock = rig
    _drive(module, [3.0, 3.0])
    clock.now = 0.8 * WATCHDOG
    module.advance()
    r = module.plant.read()
    words, bits = module.input_registers(), module.discrete_inputs()
    assert _counts(module) == r.encoder_counts.tolist()
    lsb = 10.24 / 32767
    for k, a in enumerate((4, 5)):
        assert abs(word_to_volts(words[a], 10.24) - r.tacho_volts[k]) <= 0.5 * lsb + 1e-12
    assert [bits[a] for a in range(6)] == [r.limit_min[0], r.limit_max[0], r.home[0],
                                          r.limit_min[1], r.limit_max[1], r.home[1]]
    assert bits[6] and bits[7] and not bits[8]
    assert module.holding_registers() == {0: dac_word(3.0, 10.0, 12),
                                          1: dac_word(3.0, 10.0, 12), 2: 1}
    assert module.coils() == {0: True}


def test_a_fed_or_idle_module_never_trips(rig):
    module, _, clock = rig
    for _ in range(1, 40):                # idle: outputs not live, nobody feeds
        clock.now += WATCHDOG
        module.advance()
    assert not module.tripped
    _drive(module, [1.0, 0.0])
    for feed in range(2, 200):
        clock.now += 0.9 * WATCHDOG
        module.advance()
        module.write_holding(FEED, feed)
    assert not module.tripped and module.enabled
    module.write_holding(FEED, 199)       # the same value again is no feed
    clock.now += 1.01 * WATCHDOG
    module.advance()
    assert module.tripped


@pytest.mark.parametrize("late", [1.0, 3.5])
def test_watchdog_trips_at_the_instant_of_expiry_even_when_checked_late(rig, late):
    module, ref, clock = rig
    dt, u = module.dt, np.array([2.0, 1.0])
    uq = np.array([dac_volts(dac_word(v, 10.0, 12), 10.0, 12) for v in u])
    clock.now = 3.3 * dt
    module.advance()
    _drive(module, u)                      # fed at 3.3 dt: expires at 3.3 dt + 50 ms
    clock.now += late * WATCHDOG + 0.01
    module.advance()
    assert module.tripped and not module.enabled
    k = math.ceil((3.3 * dt + WATCHDOG) / dt)         # the first boundary at/after expiry
    total = math.floor(clock.now / dt)
    ref.step(np.zeros(2), 3 * dt)
    ref.enable(True)
    ref.step(uq, (k - 3) * dt)
    ref.enable(False)
    ref.step(np.zeros(2), (total - k) * dt)
    assert _counts(module) == ref.read().encoder_counts.tolist()
    assert module.holding_registers()[DAC_X] == 0 == module.holding_registers()[DAC_Y]
    assert module.discrete_inputs()[8] and module.coils() == {0: False}
    assert module.stats().watchdog_trips == 1


def test_a_latched_trip_drops_references_and_refuses_enable_until_acknowledged(rig):
    module, _, clock = rig
    _drive(module, [1.0, 1.0])
    clock.now = 2 * WATCHDOG
    module.advance()
    assert module.write_holding(DAC_X, dac_word(4.0, 10.0, 12)) == 0
    assert not module.write_coil(ENABLE, True)
    assert module.tripped and not module.enabled
    assert module.write_coil(ENABLE, False)          # acknowledge
    assert not module.tripped
    _drive(module, [1.0, 1.0], feed=7)
    assert module.enabled and module.holding_registers()[DAC_X] == dac_word(1.0, 10.0, 12)


@pytest.mark.parametrize("phase", [0.25, 0.6])
def test_phase_lock_steers_periodic_reads_to_the_set_phase(plants, phase):
    plant = plants[0]
    plant.reset()
    clock = Clock()
    module = HilModule(plant, RMAP, sync_phase=phase, clock=clock)
    dt = module.dt
    clock.now = 0.873 * dt                     # reads every 5 intervals from an odd phase
    for _ in range(60):
        module.synchronise()
        module.advance()
        clock.now += 5 * dt
    x = module.now / dt
    assert x - math.floor(x) == pytest.approx(phase, abs=1e-4)
    assert abs(module.now - clock.now) < dt      # the grid moved by less than an interval


def test_without_phase_lock_the_grid_never_moves(rig):
    module, _, clock = rig
    clock.now = 0.873
    module.synchronise()
    assert module.now == 0.873


def test_pymodbus_glue_fills_reads_applies_writes_and_reports_faults(rig, monkeypatch):
    module, _, clock = rig

    def act(fc, start, address, registers, values=None):
        return access(module, fc, start, address, registers, values)

    regs = [0] * 7
    assert act(4, 0, 0, regs) is None
    assert [words_to_counter(regs[0], regs[1]), words_to_counter(regs[2], regs[3])] == \
        _counts(module)
    bits = [0, 0]                              # discrete inputs, 16 per entry, bit 0 first
    assert act(2, 0, 0, bits) is None
    expected = module.discrete_inputs()
    assert [(bits[0] >> a) & 1 == 1 for a in range(9)] == [expected[a] for a in range(9)]
    values = [dac_word(1.0, 10.0, 12), dac_word(-1.0, 10.0, 12), 5]
    assert act(16, 0, 0, [0] * 4, values) is None
    assert act(5, 0, 0, [0], [True]) is None
    assert module.enabled and module.holding_registers() == {0: values[0], 1: values[1], 2: 5}
    clock.now = 1.0
    module.advance()
    assert module.tripped
    values = [dac_word(2.0, 10.0, 12)]
    assert act(16, 0, 0, [0] * 4, values) is None and values == [0]   # dropped while latched
    assert act(5, 0, 0, [0], [True]) == ExcCodes.DEVICE_FAILURE

    def diverge(*_args):
        raise SimulationError("the plant state diverged")

    monkeypatch.setattr(module.plant, "step", diverge)
    clock.now = 2.0
    assert act(4, 0, 0, [0] * 7) == ExcCodes.DEVICE_FAILURE
    assert module.stats().fault == "the plant state diverged"


@pytest.mark.parametrize(("window", "from_interval", "late"), [(1.0, 3, 0), (0.4, 3, 0),
                                                               (0.0, 4, 1)])
def test_a_write_in_the_output_window_acts_from_its_reads_interval(plants, window,
                                                                    from_interval, late):
    """Counter read at 3.25 intervals, reference and enable written at 4.6: with a window of
    an interval, or of less (rounded up to one), they act from the read's boundary (3), as in
    the lock-step twin; without one, from the boundary before the write (4), counted as a
    late write."""
    plant, ref = plants
    for p in plants:
        p.reset()
    clock = Clock()
    module = HilModule(plant, RMAP, watchdog=1.0, sync_phase=None,
                       output_window=window * plant.drive_dt, clock=clock)
    dt, u = module.dt, [2.0, -1.5]
    words = [dac_word(v, 10.0, 12) for v in u]

    def act(fc, values=None):
        return access(module, fc, 0, 0, [0] * 7, values)

    clock.now = 3.25 * dt
    assert act(4) is None and plant.time == pytest.approx(3 * dt)
    clock.now = 4.6 * dt
    assert act(16, [*words, 1]) is None and act(5, [True]) is None
    clock.now = 10.25 * dt
    assert act(4) is None and plant.time == pytest.approx(10 * dt)
    ref.enable(False)
    ref.step(np.zeros(2), from_interval * dt)
    ref.enable(True)
    ref.step(np.array([dac_volts(w, 10.0, 12) for w in words]), (10 - from_interval) * dt)
    assert plant.truth().table_position.tolist() == ref.truth().table_position.tolist()
    assert (module.stats().dac_writes, module.stats().late_writes) == (1, late)


@pytest.mark.parametrize(("option", "value"), [
    ("watchdog", 0.0), ("watchdog", float("inf")), ("sync_phase", 1.0), ("sync_phase", -0.1),
    ("sync_gain", 0.0), ("sync_gain", 1.5), ("output_window", -1e-3),
    ("output_window", 0.06),
])
def test_module_options_out_of_range_name_the_option(plants, option, value):
    with pytest.raises(ConfigError) as info:
        HilModule(plants[0], RMAP, **{option: value})
    assert info.value.field == option


def test_nothing_is_driven_before_the_watchdog_is_fed(rig):
    module, _, clock = rig
    with pytest.raises(Refused) as caught:
        module.write_holding(DAC_X, dac_word(5.0, 10.0, 12))
    assert caught.value.code == ExcCodes.DEVICE_FAILURE
    assert module.write_holding(DAC_Y, 0) == 0            # a zero is always safe
    assert not module.write_coil(ENABLE, True)
    assert module.holding_registers()[DAC_X] == 0 and not module.enabled
    clock.now = 10 * WATCHDOG
    module.advance()                                      # no expiry without a feed
    assert not module.tripped and module.stats().refused == 2

    def act(fc, address, values):
        return access(module, fc, 0, address, [0] * 4, values)

    word = dac_word(1.0, 10.0, 12)
    assert act(6, DAC_X, [word]) == ExcCodes.DEVICE_FAILURE    # DAC first: refused, alive
    assert act(16, 0, [word, word, 9]) is None                 # one request that feeds
    assert act(5, ENABLE, [True]) is None and module.enabled
    assert module.holding_registers() == {DAC_X: word, DAC_Y: word, FEED: 9}


def test_one_client_owns_the_outputs_until_it_goes(rig):
    module, _, clock = rig
    first, second = object(), object()
    token = CLIENT.set(first)
    _drive(module, [1.0, -1.0])
    CLIENT.reset(token)
    assert module.owner is first
    token = CLIENT.set(second)
    try:
        for write in (lambda: module.write_holding(DAC_X, 0),
                      lambda: module.write_holding(FEED, 77),
                      lambda: module.write_coil(ENABLE, False)):
            with pytest.raises(Refused) as caught:
                write()
            assert caught.value.code == ExcCodes.DEVICE_BUSY
        assert module.input_registers() and module.discrete_inputs()   # reads stay open
        assert module.enabled and module.holding_registers()[FEED] == 1
        module.release(second)                       # not the owner: nothing changes
        assert module.enabled
        module.release(first)                        # the owner's connection closed:
        assert module.enabled and not module.tripped  # outputs guarded by the watchdog
        clock.now = 0.5 * WATCHDOG
        module.advance()
        _drive(module, [0.5, 0.5], feed=3)           # now the second may take them
        assert module.owner is second and module.enabled
        clock.now = 2 * WATCHDOG
        module.advance()                             # a trip frees them too
        assert module.tripped and module.owner is not second
        assert not module.enabled and module.holding_registers()[DAC_X] == 0
    finally:
        CLIENT.reset(token)


def test_an_access_list_lets_only_its_clients_claim_the_outputs(plants):
    """``hil.owners`` / ``--owner``: a client outside the list gets exception 1 on every
    output write and never owns the outputs; one inside claims them first come."""
    from types import SimpleNamespace

    from twin.hardware.owners import Owners

    plant, _ = plants
    plant.reset()
    owners = Owners(["10.0.0.0/24", "cell-7"], resolve=lambda host: ["192.168.5.7"])
    module = HilModule(plant, RMAP, watchdog=WATCHDOG, sync_phase=None, clock=Clock(),
                       owners=owners)
    stranger, unknown = SimpleNamespace(host="10.0.1.9"), SimpleNamespace()
    for client in (stranger, unknown, None):
        token = CLIENT.set(client)
        try:
            for write in (lambda: module.write_holding(FEED, 77),
                          lambda: module.write_registers(DAC_X, [5, 5, 9]),
                          lambda: module.write_coil(ENABLE, True)):
                with pytest.raises(Refused) as caught:
                    result = write()
                    if isinstance(result, ExcCodes):    # write_registers answers a code
                        raise Refused(result, "")
                assert caught.value.code == ExcCodes.ILLEGAL_FUNCTION
            assert module.input_registers() and module.discrete_inputs()   # reads stay open
        finally:
            CLIENT.reset(token)
    assert module.owner is not stranger and module.holding_registers()[FEED] == 0
    for host in ("10.0.0.200", "::ffff:192.168.5.7"):      # the network; the resolved host
        token = CLIENT.set(SimpleNamespace(host=host))
        try:
            assert module.write_registers(DAC_X, [0, 0, len(host)]) is None
            assert module.owner is CLIENT.get()
        finally:
            CLIENT.reset(token)
        module.release(module.owner)


def test_mask_write_and_unknown_functions_in_the_glue(rig):
    module, _, _ = rig
    regs = [0] * 3
    assert access(module, 22, 0, FEED, regs, None) is None          # function 22 reads ...
    assert regs[FEED] == 0
    assert access(module, 22, 0, FEED, regs, [41]) is None          # ... then writes
    assert module.holding_registers()[FEED] == 41 and module.owner is CLIENT.get()
    assert access(module, 7, 0, 0, regs, None) == ExcCodes.ILLEGAL_FUNCTION
