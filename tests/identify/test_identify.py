"""``twin identify`` against machines it has not seen.

Each unseen machine is BASE (tomsk_xy) with its physical parameters drawn at random
(``twin.identify.perturb``: tacho gain ±20 %, rotor inertia ×0.7-1.5, friction ×0.5-3, R and
L ±30 %, lost motion 0-20 µm, DAC errors) and, here, a speed regulator set by hand: gain
×0.5-1.5 and integral time ×0.5-2 of the design (the drive's digital current loop keeps its
DCM adaptation; the analog drives without it are in ``bench/identify.py --drive
as_built``). Here one is served by a real ``twin hil-server`` subprocess
and identified over Modbus/TCP on loopback by the ``twin identify`` command, and bad logs
are refused; the lock-step ones (``--driver sim:FILE``) are in ``test_identify_lockstep.py``,
a file of its own so that the two run on different test workers. The fitted values are
judged against the machine's own file (``unseen.assert_identified``): K_H within 1 %, lost
motion within 2 µm, and every value called identified right (rotor inertia, speed gain and
integral time within 10 %, Coulomb friction within 20 %), the others flagged; the truth
inside the 95 % intervals of ≥ 90 % of the fields called identified; where the held-out
ramps are predicted worse than 5 % NRMSE, or an axis keeps a systematic residual, nothing
replayed called identified there. Then the calibrated file
as the controller's model must do on the machine what the machine's own file does (within
1.25×).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rerun.chunk as rc

from tests.identify.unseen import BASE, assert_identified, sim_to_real, twin_cli, unseen
from twin.config import AXES, load_machine
from twin.hardware.hil_process import spawn_hil_server


@pytest.fixture(scope="module")
def over_modbus(tmp_path_factory):
    """An unseen machine served by ``twin hil-server``, identified over Modbus/TCP."""
    where = tmp_path_factory.mktemp("modbus")
    true, path = unseen(11, where, drive="mistuned")   # a hand-set speed regulator
    out = where / "calibrated.toml"
    # both ends under SCHED_FIFO where the OS grants it, as on a real-time controller
    for attempt in range(2):
        # a loaded machine may compile the kernel first: a generous start-up time
        with spawn_hil_server("--machine", str(path), "--rt-priority", "10",
                              ready_timeout=300.0) as server:
            # a request unanswered within 50 ms is sent again, twice: a 2-core machine
            # running the suite's other worker (or other jobs) beside both ends left the
            # server silent for more than the default 20 ms; a phase whose ticks were late
            # all the same is run again by the client (``experiments.disturbed``)
            proc = twin_cli("identify", "--machine", BASE, "--driver",
                            f"modbus://127.0.0.1:{server.info['port']}?timeout=0.05&retries=2",
                            "--rt-priority", "10", "-o", str(out), "--out",
                            str(where / "runs"), "--json")
        # The client repeats a phase its own loop saw disturbed; a stall of the server
        # process alone (both ends and the other test worker on two cores) it cannot see.
        # Once, on CI, that left a fit the command refused; the whole identification is
        # then run once more (a real machine's controller and I/O do not share a CPU).
        if proc.returncode == 0 or attempt or "did not converge" not in proc.stderr:
            break
        print(f"\nidentification over Modbus refused, run again: {proc.stderr}")
    assert proc.returncode == 0, proc.stderr
    return true, path, out, json.loads(proc.stdout)


# the fixture's set-up (a HIL server started, paced experiments, the fit) counts towards
# this first test's time: on a loaded machine more than the suite's 600 s
@pytest.mark.timeout(1500)
def test_an_unseen_machine_is_identified_over_modbus(over_modbus):
    true, _path, out, result = over_modbus
    assert_identified(result, true)
    print(f"\nover Modbus: machine time {result['machine_time_s']:.1f} s, experiments "
          f"{result['experiments_wall_time_s']:.1f} s wall, fit {result['fit_wall_time_s']:.1f} s")
    assert result["driver"].startswith("modbus://")
    # the calibrated file: BASE with the identified fields replaced, a header that says so
    calibrated, base = load_machine(str(out)), load_machine(BASE)
    text = out.read_text(encoding="utf-8")
    assert "95 % confidence interval" in text and "Not identifiable" in text
    assert "transmission.stiffness" in text
    for a in AXES:
        got, want = calibrated.axes[a], base.axes[a]
        assert got.transmission.stiffness == want.transmission.stiffness
        assert got.mechanics.carriage_mass == want.mechanics.carriage_mass
        assert got.motor.emf_constant == want.motor.emf_constant
        assert got.tacho.gain == pytest.approx(result["estimates"][a]["tacho_gain"]["value"])
    # the record: the log, the report and a recording with measured and fitted signals
    record = Path(result["record"])
    assert (record / "experiments.json").is_file()
    assert Path(result["report"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    entities = {c.entity_path for c in
                rc.RrdReader(record / "experiments.rrd").stream().to_chunks()}
    assert {"/position/x/measured", "/position/x/fitted", "/tacho/y/measured",
            "/dac/y"} <= entities


def test_the_calibrated_model_does_on_the_machine_what_its_own_file_does(over_modbus,
                                                                          tmp_path):
    _true, path, calibrated, _result = over_modbus
    table = sim_to_real(path, calibrated, tmp_path)
    print("\nmax coordinate error (µm), DCU 3:", json.dumps(table))
    for builtin, errors in table.items():
        assert errors["calibrated"] <= 1.25 * errors["oracle"], builtin


# a whole fit in a subprocess: on a loaded 2-core machine more than the suite's 600 s
@pytest.mark.timeout(1500)
def test_fitting_the_recorded_experiments_again_gives_the_same_machine(over_modbus,
                                                                       tmp_path):
    _true, _path, out, result = over_modbus
    again = tmp_path / "again.toml"
    proc = twin_cli("identify", "--machine", BASE, "--from-log", result["record"], "-o",
                 str(again), "--json", timeout=1400.0)
    assert proc.returncode == 0, proc.stderr
    # piped, not on a terminal: the fit still says where it is, stage by stage
    stages = [ln.split(":")[0] for ln in proc.stderr.splitlines() if ":" in ln]
    for stage in ("gains", "inertia", "lost motion", "joint fit", "held out"):
        assert stage in stages, proc.stderr
    refit = json.loads(proc.stdout)
    for a in AXES:
        for name, e in result["estimates"][a].items():
            assert refit["estimates"][a][name]["value"] == pytest.approx(e["value"],
                                                                         rel=1e-9, abs=1e-15)
    assert load_machine(str(again)).axes == load_machine(str(out)).axes


# --------------------------------------------------------------------------- bad input
def _log_doc(result: dict) -> dict:
    return json.loads((Path(result["record"]) / "experiments.json").read_text())


def test_a_log_of_another_machine_is_refused_naming_what_differs(over_modbus, tmp_path):
    doc = _log_doc(over_modbus[3])
    doc["signature"]["counts_per_metre"] = [4e6, 4e6]
    (tmp_path / "experiments.json").write_text(json.dumps(doc))
    out = tmp_path / "cal.toml"
    proc = twin_cli("identify", "--from-log", str(tmp_path), "-o", str(out))
    assert proc.returncode == 2
    assert "another machine" in proc.stderr and "counts_per_metre" in proc.stderr
    assert not out.exists()


def test_an_incomplete_log_names_the_experiments_it_lacks(over_modbus, tmp_path):
    doc = _log_doc(over_modbus[3])
    pieces = np.asarray(doc["data"]["piece"])
    first_crossing = next(i for i, p in enumerate(doc["plan"])
                          if p["experiment"] == "crossings")
    keep = int(np.argmax(pieces >= first_crossing + 2))
    doc["data"] = {k: v[:keep] for k, v in doc["data"].items()}
    (tmp_path / "experiments.json").write_text(json.dumps(doc))
    proc = twin_cli("identify", "--from-log", str(tmp_path), "-o", str(tmp_path / "c.toml"))
    assert proc.returncode == 2
    assert "incomplete" in proc.stderr and "crossings" in proc.stderr
    assert "ramps" not in proc.stderr.split("incomplete")[1]


def test_a_fit_that_does_not_converge_writes_nothing(over_modbus, tmp_path):
    doc = _log_doc(over_modbus[3])
    held = {i for i, p in enumerate(doc["plan"]) if p["experiment"] == "ramps"}
    counts = doc["data"]["counts_x"]
    ticks = [k for k, piece in enumerate(doc["data"]["piece"]) if int(piece) in held]
    c0 = counts[ticks[0]]
    for k in ticks:   # the held-out ramps: the table went the other way
        counts[k] = 2 * c0 - counts[k]
    (tmp_path / "experiments.json").write_text(json.dumps(doc))
    out = tmp_path / "cal.toml"
    proc = twin_cli("identify", "--from-log", str(tmp_path), "-o", str(out))
    assert proc.returncode == 1
    assert "did not converge" in proc.stderr and "was not written" in proc.stderr
    assert not out.exists() and not list(tmp_path.glob("cal.toml*"))
