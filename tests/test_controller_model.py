"""The controller's model of the machine, separate from the plant (``--controller-model``):
every model-based setting comes from it, the physics from ``--machine``, and the run record
names and hashes both."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from twin.config import diff_machines, field_unit, load_machine, machine_identity
from twin.session.run import RunSpec, prepare, run

TOMSK = load_machine("tomsk_xy")


@pytest.fixture(scope="module")
def believed(tmp_path_factory):
    """tomsk_xy whose drives the controller believes 30 % faster (tacho gain / 1.3)."""
    path = tmp_path_factory.mktemp("model") / "believed.toml"
    text = (TOMSK.source and open(TOMSK.source, encoding="utf-8").read())
    path.write_text(text.replace("gain = 0.04775 ", "gain = 0.036731 "), encoding="utf-8")
    return path


def test_by_default_the_controller_believes_the_machine_itself():
    p = prepare(RunSpec(builtin="none"))
    assert p.belief is p.cfg


def test_the_gains_dcu_and_corner_model_come_from_the_controller_model(believed):
    own = prepare(RunSpec(builtin="none", dcu_order=3))
    other = prepare(RunSpec(builtin="none", dcu_order=3, controller_model=str(believed)))
    from_model = prepare(RunSpec(machine=str(believed), builtin="none", dcu_order=3))
    # the plant is the same machine ...
    assert other.cfg == own.cfg
    assert other.plant.config.axes["x"].tacho.gain == TOMSK.axes["x"].tacho.gain
    # ... the controller is the one derived from the model
    assert other.controller.gains == from_model.controller.gains
    assert other.controller.gains != own.controller.gains
    alpha1 = [a[0] for a in other.controller.gains.dcu_alpha]
    own_alpha1 = [a[0] for a in own.controller.gains.dcu_alpha]
    assert alpha1 == pytest.approx([a / 1.3 for a in own_alpha1], rel=1e-3)  # 1/(K_H·T)


def test_the_run_record_names_and_hashes_both_machines(believed, tmp_path):
    s = run(RunSpec(builtin="spline_line", dcu_order=1, controller_model=str(believed)),
            out_dir=tmp_path, rerun="none").summary
    assert s["machine"] == "tomsk_xy" and s["controller_model"] == "tomsk_xy"
    assert s["machine_file"]["file_sha256"] == machine_identity(TOMSK)["file_sha256"]
    assert s["controller_model_file"]["file"] == str(believed)
    assert s["controller_model_file"]["file_sha256"] != s["machine_file"]["file_sha256"]
    assert s["controller_model_file"]["config_sha256"] != s["machine_file"]["config_sha256"]
    saved = json.loads((tmp_path / f"{s['run_id']}.json").read_text(encoding="utf-8"))
    assert saved["spec"]["controller_model"] == str(believed)
    assert saved["controller_model_config"]["axes"]["x"]["tacho"]["gain"] == 0.036731


def test_a_mistuned_dcu_leaves_the_error_it_was_not_derived_for(believed, tmp_path):
    """What the engineer asks the CLI: the DCU derived for a drive 30 % off the real one."""
    matched = run(RunSpec(builtin="spline_line", dcu_order=1), out_dir=tmp_path,
                  rerun="none").summary
    mistuned = run(RunSpec(builtin="spline_line", dcu_order=1,
                           controller_model=str(believed)), out_dir=tmp_path,
                   rerun="none").summary
    assert mistuned["max_coordinate_error_um"]["x"] > \
        1.15 * matched["max_coordinate_error_um"]["x"]


def test_machines_diff_lists_the_differing_fields_with_units(believed):
    rows = diff_machines(TOMSK, load_machine(believed))
    assert [r[0] for r in rows] == ["axes.x.tacho.gain", "axes.y.tacho.gain"]
    assert field_unit("axes.x.tacho.gain") == "V·s/rad"
    out = subprocess.run([sys.executable, "-m", "twin.cli", "machines", "--diff", "tomsk_xy",
                          str(believed), "--json"], capture_output=True, text=True,
                         check=True, timeout=120)
    doc = json.loads(out.stdout)
    assert [d["field"] for d in doc["differences"]] == ["axes.x.tacho.gain",
                                                        "axes.y.tacho.gain"]
    assert doc["differences"][0]["unit"] == "V·s/rad"


def test_the_belief_of_the_x_axis_moves_the_y_carriage_too():
    """The X axis carries the Y carriage: its linear model is that of an axis whose own
    carriage weighs both (random masses on a light rotor, so that they matter), not of the
    X carriage alone."""
    import numpy as np

    from twin.drive import axis_transfer_function
    from twin.session.run import axis_models

    rng = np.random.default_rng(3)
    for _ in range(3):
        mx, my = (float(m) for m in rng.uniform(500.0, 3000.0, 2))
        cfg = TOMSK.with_overrides({"axes.x.mechanics.carriage_mass": mx,
                                    "axes.y.mechanics.carriage_mass": my,
                                    "axes.*.mechanics.rotor_inertia": 2e-4})
        both = cfg.with_overrides({"axes.x.mechanics.carriage_mass": mx + my})
        model_x, model_y = axis_models(cfg)
        num, den = axis_transfer_function(both.axes["x"])
        np.testing.assert_allclose(model_x.den, den / den[0], rtol=1e-12)
        np.testing.assert_allclose(model_x.num, num / den[0], rtol=1e-12)
        alone = axis_transfer_function(cfg.axes["x"])[1]
        assert not np.allclose(model_x.den, alone / alone[0], rtol=1e-3)
        num, den = axis_transfer_function(cfg.axes["y"])
        np.testing.assert_allclose(model_y.den, den / den[0], rtol=1e-12)
