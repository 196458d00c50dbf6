"""Stop signals at random instants of ``twin run`` over Modbus/TCP to ``twin hil-server``
(issue 19): whatever the instant (while Python starts, while the driver connects, in the
paced loop, while the record is written), each trial leaves either nothing under a final
name or a recording that passes ``rerun rrd verify``, with its summary, whose status is
never a state in progress; and the module's outputs are zero and its drives disabled as
soon as the process has exited, with a watchdog far too slow to have done it (5 s), so the
driver did.

CI runs 6 trials; the full run (``slow``) 30.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time

import pytest

from tests.hardware.test_hil_server import UNIT, client, hil_server
from tests.rrd import assert_verified

PROGRAM = "G91 G1 X4 Y3 F600\nG4 P60\nM30\n"   # a move, then a long dwell under control
SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
FINAL = ("FINISHED", "ABORTED", "FAULT", "TIMEOUT")


@pytest.mark.slow
def test_stop_signals_at_random_instants_over_modbus(tmp_path):
    trials = 6 if os.environ.get("CI") else 30
    rng = random.Random(1919)
    program = tmp_path / "long.ngc"
    program.write_text(PROGRAM)
    outcomes: dict[str, int] = {}
    with hil_server("--from", "50,20", watchdog_ms=5000.0) as server:
        port = server.info["port"]
        for trial in range(trials):
            signum = rng.choice(SIGNALS)
            delay = rng.uniform(0.0, 6.0)
            out = tmp_path / f"trial{trial}"
            proc = subprocess.Popen(
                [sys.executable, "-m", "twin.cli", "run", str(program), "--driver", server.url,
                 "--out", str(out), "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                text=True, env={**os.environ, "RERUN_ANALYTICS": "0"})
            time.sleep(delay)
            proc.send_signal(signum)
            try:
                stdout, _ = proc.communicate(timeout=60.0)
            finally:
                if proc.poll() is None:
                    proc.kill()
            where = f"trial {trial}: {signal.Signals(signum).name} after {delay:.2f} s"
            # the module, at once: references zero, drives disabled, the watchdog idle
            with client(port) as c:
                dac = c.read_holding_registers(0, count=2, device_id=UNIT).registers
                enable = c.read_coils(0, count=1, device_id=UNIT).bits[0]
                tripped = c.read_discrete_inputs(8, count=1, device_id=UNIT).bits[0]
            assert dac == [0, 0] and enable is False and tripped is False, where
            # the files: a final name only with a whole record
            recordings = sorted(out.glob("*.rrd")) if out.exists() else []
            summaries = sorted(out.glob("*.json")) if out.exists() else []
            assert [p.stem for p in recordings] == [p.stem for p in summaries], where
            for rrd, js in zip(recordings, summaries, strict=True):
                summary = json.loads(js.read_text())
                assert summary["status"] in FINAL, where
                assert_verified(rrd, where)
                outcomes[summary["status"]] = outcomes.get(summary["status"], 0) + 1
            if not recordings:
                outcomes["nothing"] = outcomes.get("nothing", 0) + 1
            if recordings and stdout.strip():
                assert json.loads(stdout)["status"] in FINAL, where
    print(f"{trials} trials: {outcomes}")
    assert sum(outcomes.values()) == trials
