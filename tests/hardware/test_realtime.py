"""RealTimeLoop: absolute deadlines, overrun handling and the deadline report."""

import numpy as np
import pytest

from twin.hardware.realtime import RealTimeLoop, TickStats


class FakeClock:
    """A clock that only moves when slept on or when a tick 'works'."""

    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now

    def sleep(self, dt):
        self.now += dt


def _fake_loop(period, work):
    clock = FakeClock()

    def busy_clock():
        # The spin-wait polls the clock: advance a microsecond per poll.
        clock.now += 1e-6
        return clock.now

    loop = RealTimeLoop(period, clock=busy_clock, sleep=clock.sleep, spin=1e-4)

    def tick(k, t):
        clock.now += work(k)
        return True

    return loop, tick


def test_no_drift_and_all_on_time_when_work_fits():
    loop, tick = _fake_loop(5e-3, lambda k: 1e-3)
    stats = loop.run(tick, max_ticks=1000)
    assert stats.due == 1000
    assert stats.on_time == 1000 and stats.late == 0 and stats.skipped == 0
    assert stats.jitter_max_us < 0.1 * 5e-3 * 1e6


def test_overrun_skips_slots_and_counts_them_due():
    # Tick 10 takes 3.5 periods: slots 11 and 12 are wholly overrun and skipped; slot 13 is
    # still open (half a period left) and runs, late.
    period = 1e-3
    loop, tick = _fake_loop(period, lambda k: 3.5e-3 if k == 10 else 1e-4)
    seen = []

    def recording_tick(k, t):
        seen.append(k)
        return tick(k, t)

    stats = loop.run(recording_tick, max_ticks=50)
    assert 11 not in seen and 12 not in seen
    assert seen[seen.index(10) + 1] == 13
    assert stats.skipped == 2
    assert stats.late == 1
    assert stats.due == stats.on_time + stats.late + stats.skipped


def test_an_overrun_at_the_end_counts_only_the_slots_within_the_duration():
    # 10 slots of 1 ms; tick 8 takes 3.5 periods, past the end: only slot 9 was skipped
    # (slots 10 and 11 lie beyond the duration and were never due). Found under load in CI.
    loop, tick = _fake_loop(1e-3, lambda k: 3.5e-3 if k == 8 else 1e-4)
    stats = loop.run(tick, duration=0.01)
    assert (stats.due, stats.on_time, stats.late, stats.skipped) == (10, 9, 0, 1)


def test_tick_returning_false_stops_and_is_not_counted():
    loop, _ = _fake_loop(1e-3, lambda k: 0.0)
    stats = loop.run(lambda k, t: k < 4)
    assert stats.due == 4


def test_report_percentiles_match_numpy():
    lat = np.array([0.0, 1e-5, 2e-5, 5e-4, 3e-3])
    s = TickStats.from_lateness(5e-3, lat, 2, tolerance=5e-4)
    assert s.due == 7 and s.on_time == 4 and s.late == 1 and s.skipped == 2
    assert s.jitter_p99_us == pytest.approx(np.percentile(lat, 99) * 1e6)
    assert s.jitter_max_us == pytest.approx(3000.0)
    assert s.to_dict()["on_time_ratio"] == pytest.approx(4 / 7)


def test_lockstep_report():
    s = TickStats.lockstep(5e-3, 200)
    assert s.due == s.on_time == 200 and not s.paced


@pytest.mark.parametrize("period", [5e-3, 1e-3])
def test_real_clock_loop_runs_and_accounts_every_tick(period):
    stats = RealTimeLoop(period).run(lambda k, t: True, duration=0.2)
    assert stats.due == pytest.approx(0.2 / period, abs=1)
    assert stats.due == stats.on_time + stats.late + stats.skipped


def test_bad_period():
    with pytest.raises(ValueError, match="period"):
        RealTimeLoop(0.0)


def test_a_tick_that_raises_is_counted_and_the_error_propagates():
    loop, _ = _fake_loop(1e-3, lambda k: 0.0)

    def tick(k, t):
        if k == 3:
            raise RuntimeError("I/O failed")
        return True

    with pytest.raises(RuntimeError, match="I/O failed"):
        loop.run(tick)
    assert loop.last_stats().due == 4
