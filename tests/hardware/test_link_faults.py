"""Faults of the link to the machine's I/O: the deadline policy of paced runs
(``controller.deadlines``: exact slot sequences for its rules, and a real run through a
latency proxy between the driver and the HIL server), and a counter answer corrupted in
transit (the driver's plausibility check)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest

from tests.hardware.link_proxy import LinkProxy
from twin.errors import DeadlineFault
from twin.hardware.hil_process import spawn_hil_server
from twin.hardware.realtime import DeadlinePolicy, RealTimeLoop

PERIOD = 5e-3


def _policy(**kw):
    seen: list[str] = []
    return DeadlinePolicy(PERIOD, window=0.1, on_warning=seen.append, **kw), seen   # 20 slots


def test_more_lost_periods_in_a_row_than_allowed_stop_the_run():
    policy, seen = _policy(max_skipped_in_a_row=4)
    for _ in range(5):
        policy.observe(True, 0)
    policy.observe(True, 2)                      # two lost: a warning, no fault
    assert len(seen) == 1 and "2 periods lost in a row" in seen[0]
    with pytest.raises(DeadlineFault, match=r"5 periods of 5 ms lost in a row, more than "
                                            r"controller\.deadlines\.max_skipped_in_a_row = 4"):
        policy.observe(True, 5)


def test_a_falling_on_time_share_is_warned_about_then_stops_the_run():
    policy, seen = _policy(min_on_time=0.9, warn_on_time=0.97)
    for _ in range(20):
        policy.observe(True, 0)
    for _ in range(2):                           # down to 18 of 20 on time: warned at 95 %
        policy.observe(False, 0)
    assert len(seen) == 1 and "95.0 % of the last 20 periods" in seen[0]
    with pytest.raises(DeadlineFault, match=r"85\.0 % of the last 20 periods started on "
                                            r"time, below controller\.deadlines\.min_on_time"):
        policy.observe(False, 0)


def test_the_first_ticks_are_not_judged_by_the_share():
    policy, seen = _policy()
    policy.observe(False, 0)                     # a slow first tick: nothing yet
    assert not seen


def test_the_loop_applies_the_policy_slot_by_slot():
    clock = [0.0]
    policy, _ = _policy(max_skipped_in_a_row=4)

    def tick(k, _t):
        clock[0] += PERIOD * (7.5 if k == 3 else 0.2)   # the fourth, from 3 T to 10.5 T:
        return True

    loop = RealTimeLoop(PERIOD, spin=0.0, clock=lambda: clock[0],
                        sleep=lambda dt: clock.__setitem__(0, clock[0] + dt))
    with pytest.raises(DeadlineFault, match="6 periods"):   # slots 4 … 9 lost
        loop.run(tick, max_ticks=100, policy=policy)
    assert loop.last_stats().due == 4 + 6


def test_five_ms_of_latency_ends_a_run_in_a_deadline_fault(tmp_path):
    with spawn_hil_server("--rt-priority", "10") as server:
        proxy = LinkProxy(server.info["port"], delay=5e-3)
        try:
            proc = subprocess.run(
                [sys.executable, "-m", "twin.cli", "run", "--builtin", "spline_line",
                 "--driver", f"modbus://127.0.0.1:{proxy.port}?timeout=0.1", "--rerun",
                 "none", "--out", str(tmp_path), "--json"], capture_output=True, text=True,
                timeout=300, env={**os.environ, "RERUN_ANALYTICS": "0"})
        finally:
            proxy.close()
    assert proc.returncode == 1, proc.stderr
    s = json.loads(proc.stdout)
    assert s["status"] == "FAULT" and s["fault"] == "DEADLINE", s.get("error")
    assert "controller.deadlines" in s["error"] and s["aborted"] is None
    assert s["ticks"]["on_time_ratio"] < 0.5


def test_a_corrupted_counter_answer_ends_the_run_in_a_fault_naming_the_axis(tmp_path):
    """One flipped bit in the high word of X's counter, in one answer of the module to a
    counter read (function 4) well into the run: the driver's plausibility check stops the
    run (Modbus/TCP has no checksum to catch it)."""
    answers = [0]

    def spoil(data: bytes) -> bytes:
        # MBAP (7 bytes), then function 4, byte count, X counter high word, low word, ...
        if len(data) >= 11 and data[7] == 4:
            answers[0] += 1
            if answers[0] == 300:
                data = data[:9] + bytes([data[9] ^ 0x01]) + data[10:]
        return data

    with spawn_hil_server("--rt-priority", "10") as server:
        proxy = LinkProxy(server.info["port"], spoil=spoil)
        try:
            proc = subprocess.run(
                [sys.executable, "-m", "twin.cli", "run", "--builtin", "spline_line",
                 "--driver", f"modbus://127.0.0.1:{proxy.port}?timeout=0.1", "--rerun",
                 "none", "--out", str(tmp_path), "--json", "--rt-priority", "10"],
                capture_output=True, text=True, timeout=300,
                env={**os.environ, "RERUN_ANALYTICS": "0"})
        finally:
            proxy.close()
    assert proc.returncode == 1, proc.stderr
    s = json.loads(proc.stdout)
    assert s["status"] == "FAULT" and s["fault"] == "DRIVER", s
    found = re.search(r"axis x: implausible counter step of (-?\d+) counts", s["error"])
    assert found and abs(int(found.group(1)) - (1 << 24)) < 1000   # the flip, plus motion
    assert answers[0] >= 300
    # and the reason is said in words, not only in the record (or a library's log line)
    assert re.search(r"^fault: driver fault: modbus://\S+: axis x: implausible counter step",
                     proc.stderr, re.M), proc.stderr
