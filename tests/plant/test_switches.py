"""Limit and home switches: they close at the configured positions, with the debounce."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import load_machine
from twin.plant import Plant

# tomsk_xy, X axis: limit_min 2 mm, home 10 mm (width 0.5 mm), limit_max 298 mm; travel 0-300
STATIC = [
    (0.0015, (True, False, False)),
    (0.0020, (True, False, False)),
    (0.0021, (False, False, False)),
    (0.00974, (False, False, False)),
    (0.00976, (False, False, True)),
    (0.0100, (False, False, True)),
    (0.01024, (False, False, True)),
    (0.01026, (False, False, False)),
    (0.2979, (False, False, False)),
    (0.2980, (False, True, False)),
    (0.3000, (False, True, False)),
]


@pytest.mark.parametrize(("x", "closed"), STATIC)
def test_switch_states_at_rest(x, closed):
    plant = Plant.from_machine("tomsk_xy")
    plant.reset(positions=np.array([x, 0.1]))
    r = plant.read()
    assert (r.limit_min[0], r.limit_max[0], r.home[0]) == closed
    assert (r.limit_min[1], r.limit_max[1], r.home[1]) == (False, False, False)


def _crossing(plant: Plant, start: float, volts: float, channel: str, duration: float):
    """Drive X from ``start`` at constant reference; per drive interval (time, x, state)."""
    plant.reset(positions=np.array([start, 0.1]))
    log = []
    for _ in range(round(duration / plant.drive_dt)):
        plant.step(np.array([volts, 0.0]), plant.drive_dt)
        log.append((plant.time, plant.truth().table_position[0],
                    bool(getattr(plant.read(), channel)[0])))
    return log


@pytest.mark.parametrize("debounce", [0.0, 0.002, 0.005])
def test_home_switch_closes_one_debounce_after_the_edge(debounce):
    cfg = load_machine("tomsk_xy").with_overrides({"axes.*.switches.debounce": debounce})
    plant = Plant(cfg)
    edge = cfg.axes["x"].switches.home - cfg.axes["x"].switches.home_width / 2
    log = _crossing(plant, 0.0085, 6.0, "home", 0.3)  # 10 mm/s towards the home cam
    t_edge = next(t for t, x, _ in log if x >= edge)  # first sample past the edge
    t_closed = next(t for t, _, closed in log if closed)
    assert t_closed - t_edge == pytest.approx(debounce, abs=1e-9)
    x_closed = next(x for _, x, closed in log if closed)
    speed = 6.0 / cfg.axes["x"].volts_per_speed
    assert edge <= x_closed <= edge + speed * (debounce + plant.drive_dt) + 1e-6


def test_a_pulse_shorter_than_the_debounce_is_ignored():
    # Crossing the 0.5 mm home cam at 10 mm/s keeps it closed for 50 ms: a 60 ms debounce
    # must swallow it, a 40 ms one must not.
    for debounce, seen in ((0.06, False), (0.04, True)):
        cfg = load_machine("tomsk_xy").with_overrides({"axes.*.switches.debounce": debounce})
        log = _crossing(Plant(cfg), 0.0085, 6.0, "home", 0.4)
        assert log[-1][1] > 0.0105  # the table passed the whole cam
        assert any(closed for *_, closed in log) is seen


def test_limit_switch_then_end_stop_are_reported_in_the_status():
    plant = Plant.from_machine("tomsk_xy")
    plant.reset(positions=np.array([0.004, 0.1]))
    statuses = [plant.step(np.array([-6.0, 0.0]), 5e-3) for _ in range(120)]
    first_limit = next(i for i, s in enumerate(statuses) if s.limit_hit[0])
    first_stop = next(i for i, s in enumerate(statuses) if s.end_stop[0])
    assert first_limit < first_stop  # 2 mm of switch travel before the stop at 0
    assert plant.read().limit_min[0]
    assert not any(s.limit_hit[1] or s.end_stop[1] for s in statuses)
    assert plant.truth().table_position[0] == pytest.approx(0.0, abs=2e-4)


def test_quick_path_agrees_with_the_sample_rule_over_random_walks():
    """The plant's per-period shortcut (``quick`` on the samples' range, ``update`` only when
    an edge or a pending change is near) gives the same outputs as applying the debounce
    rule (``update``) to every period's samples, on random walks that cross every switch
    edge and both ends of travel."""
    from twin.plant.records import AxisMonitor

    sw = load_machine("tomsk_xy").axes["x"].switches
    rng = np.random.default_rng(7)
    dt = 1e-3
    for walk in range(40):
        fast, ref = AxisMonitor(sw, (0.0, 0.3)), AxisMonitor(sw, (0.0, 0.3))
        start = rng.choice([0.001, 0.0021, 0.0098, 0.0102, 0.15, 0.2979])
        fast.settle(start)
        ref.settle(start)
        x, t = start, 0.0
        for _ in range(400):
            steps = rng.normal(0.0, rng.choice([2e-6, 2e-5, 2e-4]), size=5)
            xs = np.clip(x + np.cumsum(steps), 0.0, 0.3).tolist()
            got = fast.quick(min(xs), max(xs)) or fast.update(xs, t, dt)
            want = ref.update(xs, t, dt)
            assert got == want and fast.state == ref.state, (walk, t)
            x, t = xs[-1], t + 5 * dt
