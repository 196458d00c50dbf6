"""The MJCF and its parameterisation: one XML for every machine, parameters where they
belong, bad parameters rejected with the field named (issue 2, test 8, model parts)."""

from __future__ import annotations

import math
import tomllib

import mujoco
import numpy as np
import pytest

from twin.config import MACHINES_DIR, load_machine, machine_from_toml_dict
from twin.errors import ConfigError
from twin.plant import Plant
from twin.plant.model import MODEL_XML, build_spec, load_model, main

MACHINES = ["tomsk_xy", "laser_belt"]


def test_names_follow_the_model_convention():
    m = mujoco.MjModel.from_xml_path(str(MODEL_XML))
    joints = [m.joint(i).name for i in range(m.njnt)]
    assert joints == ["x", "y", "x_rotor", "y_rotor", "x_shaft", "y_shaft"]
    assert [m.tendon(i).name for i in range(m.ntendon)] == ["x_screw", "y_screw", "x_gear",
                                                            "y_gear"]
    assert m.body("y_carriage").parentid == m.body("x_carriage").id  # Y rides on X
    assert m.key("home").id == 0 and m.nu == 0
    # a machine without screw bodies has the two-mass structure, in the same order
    two = load_model("laser_belt")
    assert [two.joint(i).name for i in range(two.njnt)] == ["x", "y", "x_rotor", "y_rotor"]
    assert [two.tendon(i).name for i in range(two.ntendon)] == ["x_screw", "y_screw"]


TWO_MASS = {"axes.*.transmission.screw_diameter": 0.0, "axes.*.transmission.nut_start": 0.0}
"""tomsk_xy as it was before the screw body: the two-mass model with a constant spring."""


@pytest.mark.parametrize("machine", [*MACHINES, "tomsk_two_mass"])
def test_machine_parameters_land_in_the_compiled_model(machine):
    cfg = load_machine("tomsk_xy").with_overrides(TWO_MASS) if machine == "tomsk_two_mass" \
        else load_machine(machine)
    m = load_model(cfg)
    assert m.opt.timestep == cfg.simulation.timestep
    for axis in ("x", "y"):
        ax = cfg.axes[axis]
        mech, tr = ax.mechanics, ax.transmission
        slide, rotor = m.joint(axis), m.joint(f"{axis}_rotor")
        carried = ("x", "y") if axis == "x" else ("y",)
        assert m.body_subtreemass[m.body(f"{axis}_carriage").id] == pytest.approx(
            sum(cfg.axes[a].mechanics.carriage_mass for a in carried))
        np.testing.assert_allclose(slide.range, mech.travel)
        assert slide.frictionloss[0] == mech.slide_coulomb
        assert m.dof_damping[slide.dofadr[0]] == mech.slide_viscous
        assert m.body_inertia[m.body(f"{axis}_motor").id][0] == mech.rotor_inertia
        assert rotor.frictionloss[0] == mech.rotor_coulomb
        assert m.dof_damping[rotor.dofadr[0]] == mech.rotor_viscous
        lead_per_rad = (tr.lead / (2 * math.pi) if tr.kind == "screw" else tr.pulley_radius)
        mass = m.body_subtreemass[m.body(f"{axis}_carriage").id]
        if tr.screw_diameter == 0.0:
            # the two-mass model: one tendon r·θ − x with the series stiffness of the chain
            coef = _wraps(m, f"{axis}_screw")
            assert coef == pytest.approx({f"{axis}_rotor": lead_per_rad / tr.gear_ratio,
                                          axis: -1.0})
            series = 1.0 / sum(1.0 / k for k in tr.stiffness.values())
            assert m.tendon_stiffness[m.tendon(f"{axis}_screw").id] == pytest.approx(series)
            damping = 2 * tr.damping_ratio * math.sqrt(series * mass)
            assert m.tendon_damping[m.tendon(f"{axis}_screw").id] == pytest.approx(damping)
            continue
        # three masses: the screw's inertia ρ·π·d⁴·L/32, computed here as MuJoCo computes a
        # steel cylinder's; the gear spring r·θ − r_s·θ_s, the axial one r_s·θ_s − x
        steel = mujoco.MjSpec()
        steel.worldbody.add_body().add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                                            size=[tr.screw_diameter / 2, tr.screw_length / 2,
                                                  0], density=7850.0)
        axial_inertia = steel.compile().body_inertia[1][2]
        assert m.body_inertia[m.body(f"{axis}_shaft").id][0] == pytest.approx(axial_inertia,
                                                                             rel=1e-9)
        assert _wraps(m, f"{axis}_gear") == pytest.approx(
            {f"{axis}_rotor": lead_per_rad / tr.gear_ratio, f"{axis}_shaft": -lead_per_rad})
        assert _wraps(m, f"{axis}_screw") == pytest.approx({f"{axis}_shaft": lead_per_rad,
                                                            axis: -1.0})
        assert m.tendon_stiffness[m.tendon(f"{axis}_gear").id] == pytest.approx(
            1.0 / sum(1.0 / k for n, k in tr.stiffness.items() if n in ("gear", "coupling")))
        # the axial spring as at the home keyframe: the screw's E·A/a from its value at the
        # far end of travel (fixed-free, tomsk_xy)
        far = tr.nut_start + mech.travel[1] - mech.travel[0]
        home = tr.nut_start + ax.switches.home - mech.travel[0]
        parts = {**tr.stiffness, "screw": tr.stiffness["screw"] * far / home}
        axial = 1.0 / sum(1.0 / k for n, k in parts.items() if n not in ("gear", "coupling"))
        assert m.tendon_stiffness[m.tendon(f"{axis}_screw").id] == pytest.approx(axial,
                                                                                rel=1e-12)


def _wraps(m: mujoco.MjModel, tendon: str) -> dict[str, float]:
    """Joint name → coefficient of a fixed tendon."""
    t = m.tendon(tendon)
    first = m.tendon_adr[t.id]
    return {m.joint(m.wrap_objid[w]).name: m.wrap_prm[w]
            for w in range(first, first + m.tendon_num[t.id])}


@pytest.mark.parametrize("machine", MACHINES)
def test_home_keyframe_puts_the_tables_on_the_home_switches_with_relaxed_screws(machine):
    cfg = load_machine(machine)
    m = load_model(cfg)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(d.qpos[:2], [cfg.axes[a].switches.home for a in ("x", "y")])
    np.testing.assert_allclose(d.ten_length, 0.0, atol=1e-15)


def test_exported_mjcf_reproduces_the_machine(tmp_path):
    out = tmp_path / "laser.xml"
    main(["laser_belt", "-o", str(out), "--scene"])
    exported = mujoco.MjModel.from_xml_path(str(out))
    direct = load_model("laser_belt", scene=True)
    for field in ("body_mass", "tendon_stiffness", "tendon_damping", "wrap_prm", "jnt_range",
                  "dof_frictionloss", "dof_damping", "key_qpos"):
        np.testing.assert_allclose(getattr(exported, field), getattr(direct, field),
                                   err_msg=field)
    assert exported.ncam == direct.ncam == 2


BAD_VALUES = [
    ("axes.x.mechanics.carriage_mass", -40.0),
    ("axes.y.mechanics.carriage_mass", 0.0),
    ("axes.x.mechanics.rotor_inertia", -1e-3),
    ("axes.y.mechanics.slide_coulomb", -1.0),
    ("axes.x.mechanics.rotor_viscous", -1e-4),
    ("axes.y.transmission.damping_ratio", -0.05),
    ("axes.x.transmission.stiffness.nut", -1e8),
    ("axes.x.transmission.lead", -6e-3),
    ("axes.y.mechanics.travel", [0.2, 0.0]),
    ("simulation.timestep", -2e-4),
    ("axes.x.mechanics.carriage_mass", None),
]


@pytest.mark.parametrize(("field", "value"), BAD_VALUES)
def test_negative_or_invalid_parameter_names_the_field(field, value):
    cfg = load_machine("tomsk_xy")
    with pytest.raises(ConfigError) as err:
        Plant(cfg.with_overrides({field: value}))
    assert err.value.field.endswith(field.split(".")[-1])
    assert field.rsplit(".", 1)[0].split(".")[-1] in str(err.value)


@pytest.mark.parametrize(("section", "key"), [
    ("axis_defaults.mechanics", "carriage_mass"), ("axis_defaults.mechanics", "rotor_inertia"),
    ("axis_defaults.transmission", "damping_ratio"), ("axis_defaults.switches", "home"),
])
def test_missing_parameter_names_the_field(tmp_path, section, key):
    doc = tomllib.loads((MACHINES_DIR / "tomsk_xy.toml").read_text(encoding="utf-8"))
    table = doc
    for part in section.split("."):
        table = table[part]
    del table[key]
    if key == "carriage_mass":
        for axis in doc["axes"].values():  # the preset also sets it per axis
            axis.get("mechanics", {}).pop(key, None)
    with pytest.raises(ConfigError, match=key) as err:
        machine_from_toml_dict(doc)
    assert err.value.field.endswith(key) and "missing" in err.value.message


@pytest.mark.parametrize("switch", ["limit_min", "limit_max"])
def test_switch_outside_the_travel_is_rejected_by_the_machine_file(switch):
    # (the config itself keeps home between the limits, so home cannot leave the travel alone)
    with pytest.raises(ConfigError, match=rf"axes\.y\.switches\.{switch}: must lie within "
                       r"mechanics\.travel \[0\.02, 0\.15\] m"):
        load_machine("tomsk_xy").with_overrides({
            "axes.y.mechanics.travel": [0.02, 0.15],
            "axes.y.switches.limit_min": 0.01 if switch == "limit_min" else 0.03,
            "axes.y.switches.home": 0.04,
            "axes.y.switches.limit_max": 0.19 if switch == "limit_max" else 0.14,
        })


@pytest.mark.parametrize("timestep", [0.0, -1e-4, math.nan])
def test_bad_timestep_override_is_rejected(timestep):
    with pytest.raises(ConfigError, match=r"simulation\.timestep"):
        build_spec("tomsk_xy", timestep=timestep)


def test_python_m_twin_plant_exports_a_machine_without_a_warning(tmp_path):
    """``python -m twin.plant`` (the MJCF export for MuJoCo's viewer) runs clean: no
    runpy warning about a module imported twice, the same file as ``main``."""
    import subprocess
    import sys

    out = tmp_path / "cli.xml"
    done = subprocess.run([sys.executable, "-m", "twin.plant", "tomsk_xy", "-o", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    main(["tomsk_xy", "-o", str(tmp_path / "direct.xml")])
    assert out.read_text() == (tmp_path / "direct.xml").read_text()
