"""``twin identify`` against machines it has not seen.

Each unseen machine is BASE (tomsk_xy) with its physical parameters drawn at random
(``twin.identify.perturb``: tacho gain ±20 %, rotor inertia ×0.7-1.5, friction ×0.5-3, R and
L ±30 %, lost motion 0-20 µm). One is served by a real ``twin hil-server`` subprocess and
identified over Modbus/TCP on loopback by the ``twin identify`` command; the others run
lock-step (``--driver sim:FILE``). The fitted values are judged against the machine's own
file: K_H within 1 %, rotor inertia within 10 %, Coulomb friction within 20 %, lost motion
within 2 µm, the held-out ramps predicted within 2 % NRMSE. Then the calibrated file as the
controller's model must do on the machine what the machine's own file does (within 1.25×),
and tuning on it must transfer (keep at least half of what tuning on the machine gains; for
this figure the same machine is identified in lock-step, whose file does not depend on how
loaded the machine running the tests is).

Slow parts run a shorter version in CI (CI=true): one lock-step machine instead of two.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rerun.chunk as rc

from twin.config import AXES, load_machine
from twin.config.writer import machine_to_toml
from twin.errors import ConfigError
from twin.hardware.hil_process import spawn_hil_server
from twin.identify import identify
from twin.identify.perturb import perturbed_machine
from twin.identify.replay import axis_figures
from twin.session.run import RunSpec, run

CI = os.environ.get("CI") == "true"
BASE = "tomsk_xy"


def _unseen(seed: int, where: Path):
    cfg = perturbed_machine(load_machine(BASE), np.random.default_rng(seed),
                            name=f"unseen_{seed}")
    path = where / f"unseen_{seed}.toml"
    path.write_text(machine_to_toml(cfg), encoding="utf-8")
    return cfg, path


def _twin(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True,
                          text=True, timeout=timeout,
                          env={**os.environ, "RERUN_ANALYTICS": "0"})


def _assert_identified(result: dict, true) -> None:
    truth = axis_figures(true)
    for a in AXES:
        d, e, t = result["derived"][a], result["estimates"][a], truth[a]
        where = f"axis {a} of {true.name}"
        assert d["K_H"] == pytest.approx(t["K_H"], rel=0.01), where
        assert e["inertia"]["value"] == pytest.approx(t["inertia"], rel=0.10), where
        assert d["coulomb_at_motor"] == pytest.approx(t["coulomb_at_motor"], rel=0.20), where
        assert abs(e["backlash"]["value"] - t["backlash"]) <= 2e-6, where
        for name in ("tacho_gain", "inertia", "coulomb", "backlash"):
            assert e[name]["identifiable"], (where, name)
    assert max(max(v.values()) for v in result["nrmse"].values()) <= 0.02


def _max_coordinate_error(machine: Path, model: str, builtin: str, out: Path) -> float:
    spec = RunSpec(machine=str(machine), controller_model=model, builtin=builtin, dcu_order=3)
    summary = run(spec, out_dir=out, rerun="none").summary
    assert summary["status"] == "FINISHED"
    return max(summary["max_coordinate_error_um"].values())


def _sim_to_real(true_path: Path, calibrated: Path, out: Path) -> dict[str, dict[str, float]]:
    """Max coordinate error (µm) of the machine run with the calibrated model, its own file
    (the oracle) and the nominal BASE as the controller's model."""
    table = {}
    for builtin in ("spline_line", "default"):
        table[builtin] = {name: _max_coordinate_error(true_path, model, builtin, out)
                          for name, model in (("calibrated", str(calibrated)),
                                              ("oracle", str(true_path)), ("nominal", BASE))}
    return table


@pytest.fixture(scope="module")
def over_modbus(tmp_path_factory):
    """An unseen machine served by ``twin hil-server``, identified over Modbus/TCP."""
    where = tmp_path_factory.mktemp("modbus")
    true, path = _unseen(11, where)
    out = where / "calibrated.toml"
    # both ends under SCHED_FIFO where the OS grants it, as on a real-time controller
    with spawn_hil_server("--machine", str(path), "--rt-priority", "10") as server:
        # one re-send of a request unanswered within its 20 ms: a 2-core CI machine running
        # the suite's other worker beside both ends once left the server silent that long
        proc = _twin("identify", "--machine", BASE, "--driver",
                     f"modbus://127.0.0.1:{server.info['port']}?retries=1", "--rt-priority", "10",
                     "-o", str(out),
                     "--out", str(where / "runs"), "--json")
    assert proc.returncode == 0, proc.stderr
    return true, path, out, json.loads(proc.stdout)


@pytest.fixture(scope="module")
def in_lockstep(tmp_path_factory):
    """The same unseen machine as ``over_modbus``, identified in lock-step: no timing of a
    loaded machine in its experiments, so what is tuned on it does not depend on the load."""
    where = tmp_path_factory.mktemp("lockstep")
    true, path = _unseen(11, where)
    out = where / "calibrated.toml"
    identify(BASE, out, driver=f"sim:{path}", out_dir=where / "runs")
    return true, path, out


def test_an_unseen_machine_is_identified_over_modbus(over_modbus):
    true, _path, out, result = over_modbus
    _assert_identified(result, true)
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
    table = _sim_to_real(path, calibrated, tmp_path)
    print("\nmax coordinate error (µm), DCU 3:", json.dumps(table))
    for builtin, errors in table.items():
        assert errors["calibrated"] <= 1.25 * errors["oracle"], builtin


def test_fitting_the_recorded_experiments_again_gives_the_same_machine(over_modbus,
                                                                       tmp_path):
    _true, _path, out, result = over_modbus
    again = tmp_path / "again.toml"
    proc = _twin("identify", "--machine", BASE, "--from-log", result["record"], "-o",
                 str(again), "--json")
    assert proc.returncode == 0, proc.stderr
    refit = json.loads(proc.stdout)
    for a in AXES:
        for name, e in result["estimates"][a].items():
            assert refit["estimates"][a][name]["value"] == pytest.approx(e["value"],
                                                                         rel=1e-9, abs=1e-15)
    assert load_machine(str(again)).axes == load_machine(str(out)).axes


@pytest.mark.slow
@pytest.mark.parametrize("seed", [21] if CI else [21, 37])
def test_more_unseen_machines_lock_step(seed, tmp_path):
    true, path = _unseen(seed, tmp_path)
    out = tmp_path / "calibrated.toml"
    result = identify(BASE, out, driver=f"sim:{path}", out_dir=tmp_path / "runs")
    _assert_identified(result, true)
    if not CI:
        table = _sim_to_real(path, out, tmp_path)
        print("\nmax coordinate error (µm), DCU 3:", json.dumps(table))
        for builtin, errors in table.items():
            assert errors["calibrated"] <= 1.25 * errors["oracle"], builtin


def test_one_axis_is_identified_while_the_other_is_held(tmp_path):
    """``--axes x``: only x is excited and fitted; y is held still by the position loop and
    keeps BASE's values, which the header and the JSON say."""
    from twin.identify.fit import NOT_EXCITED
    from twin.identify.log import IdentLog

    true, path = _unseen(21, tmp_path)
    out = tmp_path / "calibrated.toml"
    result = identify(BASE, out, driver=f"sim:{path}", out_dir=tmp_path / "runs", axes="x")
    assert result["axes"] == ["x"] and set(result["nrmse"]) == {"x"}
    truth, base = axis_figures(true)["x"], load_machine(BASE)
    assert result["derived"]["x"]["K_H"] == pytest.approx(truth["K_H"], rel=0.01)
    assert result["estimates"]["x"]["inertia"]["value"] == pytest.approx(truth["inertia"],
                                                                          rel=0.10)
    assert result["derived"]["x"]["coulomb_at_motor"] == pytest.approx(
        truth["coulomb_at_motor"], rel=0.20)
    assert max(result["nrmse"]["x"].values()) <= 0.02
    log = IdentLog.load(result["record"])
    assert log.axes == ["x"]
    assert np.ptp(log.data["counts_y"]) <= 2       # held: a count or two at most
    assert np.ptp(log.data["counts_x"]) > 1e4      # while x travelled
    assert all(not e["identifiable"] and e["source"] == NOT_EXCITED
               for e in result["estimates"]["y"].values())
    assert load_machine(str(out)).axes["y"] == base.axes["y"]
    assert "axis y: not excited" in out.read_text()
    with pytest.raises(ConfigError, match="did not excite axis y"):
        identify(BASE, tmp_path / "again.toml", from_log=result["record"], axes="y")
    with pytest.raises(ConfigError, match="axes"):
        identify(BASE, tmp_path / "again.toml", driver=f"sim:{path}", axes="xz")
    assert not (tmp_path / "again.toml").exists()


@pytest.mark.slow
def test_tuning_on_the_calibrated_file_transfers_to_the_machine(in_lockstep):
    from tuning.cma_job import run_cma
    from tuning.evaluator import Evaluator

    # identified in lock-step: over paced real I/O the file depends on the machine's load,
    # and so did this figure (beside the suite transferred 3.46 and 3.64, alone 2.84, against
    # 3.11 tuned directly and 4.0 analytic)
    true, _path, calibrated = in_lockstep
    # fewer than about 20 runs do not beat the analytic design at all, and 24 were marginal
    # once the planner rounded the compact program's corners (transferred within 9 % of
    # direct alone, 25 % under the suite's load): 48 everywhere
    runs = 48
    with Evaluator.create(load_machine(str(calibrated)), "compact") as on_model:
        found = run_cma(on_model, budget_s=600.0, max_evals=runs, seed=3)
    # the settings found on the calibrated twin, run on the machine (whose controller
    # believes the calibrated file, as it would after identification)
    with Evaluator.create(true, "compact", belief=load_machine(str(calibrated))) as there:
        transferred = there.evaluate([found.x])[0]
    with Evaluator.create(true, "compact") as on_truth:
        direct = run_cma(on_truth, budget_s=600.0, max_evals=runs, seed=3)
        analytic = on_truth.baseline.cost
    assert direct.cost < 0.98 * analytic, "the budget must let tuning improve on the design"
    print(f"\ntuning cost on the machine: analytic {analytic:.4f}, transferred "
          f"{transferred.cost:.4f}, tuned on it "
          f"directly {direct.cost:.4f} ({runs} runs each)")
    # what the settings tuned on the calibrated twin keep, on the machine, of the improvement
    # over the analytic design that tuning on the machine itself achieves
    assert analytic - transferred.cost >= 0.5 * (analytic - direct.cost)


# --------------------------------------------------------------------------- bad input
def _log_doc(result: dict) -> dict:
    return json.loads((Path(result["record"]) / "experiments.json").read_text())


def test_a_log_of_another_machine_is_refused_naming_what_differs(over_modbus, tmp_path):
    doc = _log_doc(over_modbus[3])
    doc["signature"]["counts_per_metre"] = [4e6, 4e6]
    (tmp_path / "experiments.json").write_text(json.dumps(doc))
    out = tmp_path / "cal.toml"
    proc = _twin("identify", "--from-log", str(tmp_path), "-o", str(out))
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
    proc = _twin("identify", "--from-log", str(tmp_path), "-o", str(tmp_path / "c.toml"))
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
    proc = _twin("identify", "--from-log", str(tmp_path), "-o", str(out))
    assert proc.returncode == 1
    assert "did not converge" in proc.stderr and "was not written" in proc.stderr
    assert not out.exists() and not list(tmp_path.glob("cal.toml*"))
