"""Issue 2, test 6: 1 mm of table travel is 5000 ± 1 counts (seed 000: LIR-128A, 2500 p/rev
on the motor, i = 12, 6 mm lead → 5 counts per µm), and the 32-bit counters wrap."""

from __future__ import annotations

import numpy as np
import pytest

from twin.plant import Plant

COUNTS_PER_MM = 5000  # seed 000
WRAP = 2**32  # seed 000: 32-bit hardware counters


def _delta(after: np.ndarray, before: np.ndarray) -> np.ndarray:
    """Counter difference as a reader must compute it: modulo the counter width, signed."""
    return (after - before + WRAP // 2) % WRAP - WRAP // 2


@pytest.mark.parametrize("start", [0.0123456, 0.1, 0.2876543])
def test_one_millimetre_of_relaxed_travel_is_5000_counts(start):
    plant = Plant.from_machine("tomsk_xy")
    plant.reset(positions=np.array([start, start / 2]))
    before = plant.read().encoder_counts
    plant.reset(positions=np.array([start + 1e-3, start / 2 - 1e-3]))
    after = plant.read().encoder_counts
    assert abs(_delta(after[0], before[0]) - COUNTS_PER_MM) <= 1
    assert abs(_delta(after[1], before[1]) + COUNTS_PER_MM) <= 1


def test_counts_follow_the_rotor_while_the_table_moves():
    # At constant speed the screw deflection is nearly constant; the counts measure the rotor,
    # i.e. table travel plus the change of deflection: Δcounts = 5/µm · (Δx + Δδ) ± 1.
    plant = Plant.from_machine("tomsk_xy")
    plant.reset(positions=np.array([0.05, 0.05]))
    u = np.array([6.0, -6.0])  # 10 mm/s
    plant.step(u, 0.1)  # past the start transient
    c0, t0 = plant.read().encoder_counts, plant.truth()
    travelled = 0.0
    while travelled < 1e-3:
        plant.step(u, 1e-3)
        travelled = abs(plant.truth().table_position[0] - t0.table_position[0])
    c1, t1 = plant.read().encoder_counts, plant.truth()
    rotor_side = (t1.table_position - t0.table_position
                  + t1.screw_deflection - t0.screw_deflection)
    expected = rotor_side * 1e3 * COUNTS_PER_MM
    assert np.all(np.abs(_delta(c1, c0) - expected) <= 1)
    assert np.all(np.abs(_delta(c1, c0)) >= COUNTS_PER_MM - 1)


@pytest.mark.parametrize(("preset", "volts"), [(WRAP - 2000, 6.0), (1500, -6.0)])
def test_counter_wraps_and_differences_survive_it(preset, volts):
    plant = Plant.from_machine("tomsk_xy")
    plant.reset(positions=np.array([0.1, 0.1]), encoder_preset=np.array([preset, preset]))
    assert plant.read().encoder_counts.tolist() == [preset, preset]
    plant.step(np.array([volts, 0.0]), 0.25)
    counts = plant.read().encoder_counts
    assert 0 <= counts[0] < WRAP
    crossed = counts[0] < preset if volts > 0 else counts[0] > preset
    assert crossed, "the counter must have wrapped"
    x = plant.truth()
    moved = (x.table_position[0] - 0.1 + x.screw_deflection[0]) * 1e3 * COUNTS_PER_MM
    assert abs(_delta(counts[0], preset) - moved) <= 1
    assert counts[1] == preset


def test_counts_are_int64_in_the_counter_range():
    plant = Plant.from_machine("laser_belt")
    plant.reset(positions=np.array([0.0, 0.0]))
    plant.step(np.array([-1.0, -1.0]), 0.05)  # into the end stop: rotor angle below zero
    counts = plant.read().encoder_counts
    assert counts.dtype == np.int64
    assert np.all((counts >= 0) & (counts < WRAP))
