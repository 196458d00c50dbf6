"""``twin identify`` in lock-step (``--driver sim:FILE``) on unseen machines: more of them
than the Modbus one, one axis at a time, and whether tuning on the calibrated file transfers
to the machine (at least half of what tuning on the machine itself gains). Split from
``test_identify.py`` so that the two halves can run on different test workers.

Slow parts run a shorter version in CI (CI=true): one identification serves the file, the
one-axis one at amplitude 1 of a machine whose y is BASE's own: it is the machine judged in
place of four at 0.3, 0.5 and 1, and, its calibrated file then standing for the whole
machine, the one tuning is transferred from (one identification in this file instead of
six; ``bench/identify.py`` runs the coverage study at 0.3, 0.5 and 1).
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from tests.identify.unseen import BASE, CI, assert_identified, sim_to_real, unseen
from twin.config import load_machine
from twin.config.writer import machine_to_toml
from twin.errors import ConfigError
from twin.identify import identify
from twin.identify.replay import axis_figures


@pytest.fixture(scope="module")
def in_lockstep(tmp_path_factory, request):
    """The same unseen machine as ``over_modbus``, identified in lock-step: no timing of a
    loaded machine in its experiments, so what is tuned on it does not depend on the load.
    In CI the one-axis identification (``x_alone``: y is BASE's there, so its calibrated
    file stands for the whole machine)."""
    if CI:
        return request.getfixturevalue("x_alone")[:3]
    where = tmp_path_factory.mktemp("lockstep")
    true, path = unseen(11, where, drive="mistuned")
    out = where / "calibrated.toml"
    identify(BASE, out, driver=f"sim:{path}", out_dir=where / "runs")
    return true, path, out


@pytest.fixture(scope="module")
def x_alone(tmp_path_factory):
    """Axis x of an unseen machine with a hand-set speed regulator identified while y is
    held (``--axes x``); y without a DAC offset: with one, the position loop holds it a few
    counts off (offset·K_H/K_v), which is not what this is about. In CI, where it stands
    for ``test_more_unseen_machines_lock_step`` and ``in_lockstep`` too (one
    identification instead of three), y is BASE's own axis: the calibrated file, x
    identified and y BASE's, is then a model of the whole machine."""
    where = tmp_path_factory.mktemp("x_alone")
    true, path = unseen(21, where, drive="mistuned")
    true = true.with_overrides({"axes.y.dac.offset": 0.0})
    if CI:
        true = dataclasses.replace(true, axes={**true.axes, "y": load_machine(BASE).axes["y"]})
    path.write_text(machine_to_toml(true), encoding="utf-8")
    out = where / "calibrated.toml"
    result = identify(BASE, out, driver=f"sim:{path}", out_dir=where / "runs", axes="x")
    return true, path, out, result


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "amplitude"),
                         [(21, 1.0)] if CI else [(21, 0.3), (37, 0.5), (37, 1.0), (21, 1.0)])
def test_more_unseen_machines_lock_step(seed, amplitude, tmp_path, request):
    """Hand-set speed regulators, identified at reduced amplitude too: the truth inside the
    intervals or the field declared (``bench/identify.py`` runs the coverage study on
    many machines at 0.3, 0.5 and 1). In CI the one-axis identification (``x_alone``,
    the same machine's x) is the one judged."""
    if CI:
        true, path, out, result = request.getfixturevalue("x_alone")
    else:
        true, path = unseen(seed, tmp_path, drive="mistuned")
        out = tmp_path / "calibrated.toml"
        result = identify(BASE, out, driver=f"sim:{path}", out_dir=tmp_path / "runs",
                          amplitude=amplitude)
    assert_identified(result, true)
    if not CI:
        table = sim_to_real(path, out, tmp_path)
        print("\nmax coordinate error (µm), DCU 3:", json.dumps(table))
        for builtin, errors in table.items():
            assert errors["calibrated"] <= 1.25 * errors["oracle"], builtin


def test_one_axis_is_identified_while_the_other_is_held(x_alone, tmp_path):
    """``--axes x``: only x is excited and fitted; y is held still by the position loop and
    keeps BASE's values, which the header and the JSON say."""
    from twin.identify.fit import NOT_EXCITED, QUALITY
    from twin.identify.log import IdentLog

    true, path, out, result = x_alone
    assert result["axes"] == ["x"] and set(result["nrmse"]) == {"x"}
    truth, base = axis_figures(true)["x"], load_machine(BASE)
    assert result["derived"]["x"]["K_H"] == pytest.approx(truth["K_H"], rel=0.01)
    inertia = result["estimates"]["x"]["inertia"]
    if inertia["identifiable"]:   # else flagged, which the header and the JSON say
        assert inertia["value"] == pytest.approx(truth["inertia"], rel=0.10)
    if result["estimates"]["x"]["coulomb"]["identifiable"]:
        assert result["derived"]["x"]["coulomb_at_motor"] == pytest.approx(
            truth["coulomb_at_motor"], rel=0.20)
    assert max(result["nrmse"]["x"].values()) <= QUALITY
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
        outcome = there.tuning.run(there.tuning.space.decode(np.asarray(found.x)))
    with Evaluator.create(true, "compact") as on_truth:
        direct = run_cma(on_truth, budget_s=600.0, max_evals=runs, seed=3)
        analytic = on_truth.baseline.cost
        # costed as the other two are, against the machine's own analytic design (an
        # evaluator believing the calibrated file scales each figure by the baseline it
        # believes, up to 5 % off the machine's)
        transferred = math.fsum(on_truth.tuning.terms(outcome).values())
    assert direct.cost < 0.98 * analytic, "the budget must let tuning improve on the design"
    print(f"\ntuning cost on the machine: analytic {analytic:.4f}, transferred "
          f"{transferred:.4f}, tuned on it "
          f"directly {direct.cost:.4f} ({runs} runs each)")
    # what the settings tuned on the calibrated twin keep, on the machine, of the improvement
    # over the analytic design that tuning on the machine itself achieves
    assert analytic - transferred >= 0.5 * (analytic - direct.cost)
