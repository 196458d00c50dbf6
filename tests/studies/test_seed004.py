"""Seed 004: the traditional integer-difference interface against the float channel."""

from __future__ import annotations

import math

import pytest

from twin.analysis.studies.seed004_feed import COUNTS_PER_METRE, RATE, feed_errors


@pytest.mark.parametrize("feed", [10.0, 100.0, 1000.0, 5000.0])
def test_differenced_speed_alternates_between_floor_and_ceil_of_the_feed_per_tick(feed):
    row = feed_errors(feed)
    f_t = feed / 60e3 * COUNTS_PER_METRE / RATE           # F·k/(60·f), counts per tick
    assert row["feed_per_tick_counts"] == pytest.approx(f_t, rel=1e-12)
    assert row["max_pct"] == pytest.approx(100.0 * (math.ceil(f_t) - f_t) / f_t, abs=1e-6)
    assert row["min_pct"] == pytest.approx(100.0 * (math.floor(f_t) - f_t) / f_t, abs=1e-6)
    assert row["float_channel_max_rel"] <= 1e-6
    # one count per tick at 1 kHz and 1000 counts/mm: 1 m/s² (0.1 g) and its jerk
    assert row["acceleration_spike"] == pytest.approx(1.0, rel=1e-6)


def test_seed_figures_at_10_and_5000_mm_per_min():
    slow, fast = feed_errors(10.0), feed_errors(5000.0)
    assert slow["max_pct"] >= 100.0 and slow["max_pct"] == pytest.approx(500.0)
    assert slow["min_pct"] == pytest.approx(-100.0)
    assert max(abs(fast["max_pct"]), abs(fast["min_pct"])) <= 1.2
