"""design(): modulus and symmetric optimum reproduced from the textbook closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from twin.config import load_machine
from twin.drive import DriveDesign, axis_inertia, design
from twin.errors import ConfigError

PRESETS = ["tomsk_xy", "laser_belt"]


def _axis(preset: str, name: str = "y", **overrides):
    cfg = load_machine(preset)
    if overrides:
        cfg = cfg.with_overrides({f"axes.{name}.{k}": v for k, v in overrides.items()})
    return cfg.axes[name]


@pytest.mark.parametrize("preset", PRESETS)
def test_current_loop_is_the_modulus_optimum(preset):
    ax = _axis(preset)
    d = design(ax)
    conv = ax.converter
    t_p = 1.0 / (6 * conv.mains_frequency) if conv.kind == "thyristor" else 1.0 / conv.pwm_frequency
    # half a period of hold; the pulse-level drive's pulse-mean current adds another half
    t_mu = t_p if conv.kind == "thyristor" and conv.model == "pulse" else t_p / 2.0
    r, l_a = ax.motor.armature_resistance, ax.motor.armature_inductance
    assert d.sampling_period == pytest.approx(t_p)
    assert d.converter_time_constant == pytest.approx(t_mu)
    assert d.current_ti == pytest.approx(l_a / r)
    assert d.current_kp == pytest.approx(r * (l_a / r) / (2.0 * t_mu))
    assert d.current_loop_time_constant == pytest.approx(2.0 * t_mu)
    # the MO open loop K_pi·(T_ii s+1)/(T_ii s) · (1/R)/(T_a s+1) · 1/(T_μ s+1) must reduce to
    # 1/(2 T_μ s (T_μ s + 1)): closed loop 1/(2 T_μ² s² + 2 T_μ s + 1), ζ = 1/√2
    w = np.logspace(0, 5, 200) * 1j
    open_loop = (d.current_kp * (d.current_ti * w + 1) / (d.current_ti * w) / r
                 / (d.armature_time_constant * w + 1) / (t_mu * w + 1))
    np.testing.assert_allclose(open_loop, 1.0 / (2 * t_mu * w * (t_mu * w + 1)), rtol=1e-12)


@pytest.mark.parametrize("preset", PRESETS)
def test_converter_limits(preset):
    ax = _axis(preset)
    d = design(ax)
    conv = ax.converter
    if conv.kind == "thyristor":
        u_d0 = 1.35 * conv.line_voltage  # 3·√2/π = 1.3505
        assert d.max_voltage == pytest.approx(u_d0, rel=1e-3)
        assert d.voltage_range == pytest.approx(
            (d.max_voltage * math.cos(conv.max_firing_angle),
             d.max_voltage * math.cos(conv.min_firing_angle)))
    else:
        assert d.max_voltage == conv.dc_link_voltage
        assert d.voltage_range == (-conv.dc_link_voltage, conv.dc_link_voltage)


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("a", [2.0, 3.0])
def test_speed_loop_is_the_symmetric_optimum(preset, a):
    ax = _axis(preset, **{"speed_loop.symmetric_optimum_a": a})
    d = design(ax)
    t_sigma = 2.0 * d.converter_time_constant + ax.tacho.filter_time_constant
    j = ax.mechanics.rotor_inertia + ax.mechanics.carriage_mass * ax.transmission.ratio ** 2
    k, k_c = ax.motor.emf_constant, ax.tacho.gain
    assert d.small_time_constant == pytest.approx(t_sigma)
    assert d.speed_ti == pytest.approx(a * a * t_sigma)
    assert d.speed_kp == pytest.approx(j / (a * t_sigma * k_c * k))
    assert d.reference_filter == pytest.approx(a * a * t_sigma)
    # SO property: |L(jω_c)| = 1 at ω_c = 1/(a T_σ), the phase maximum, margin atan a − atan 1/a
    w_c = 1.0 / (a * t_sigma)

    def open_loop(w):
        s = 1j * w
        return (d.speed_kp * (d.speed_ti * s + 1) / (d.speed_ti * s) * k * k_c / (j * s)
                / (t_sigma * s + 1))
    assert abs(open_loop(w_c)) == pytest.approx(1.0, rel=1e-12)
    margin = math.pi + np.angle(open_loop(w_c))
    assert margin == pytest.approx(math.atan(a) - math.atan(1.0 / a), rel=1e-12)
    assert d.phase_margin == pytest.approx(margin)
    assert d.crossover == pytest.approx(w_c)
    w = w_c * np.array([0.9, 1.1])
    assert np.all(np.angle(open_loop(w)) < np.angle(open_loop(w_c)))


@pytest.mark.parametrize(("use_filter", "overshoot"), [(True, 0.081), (False, 0.434)])
def test_lumped_so_loop_gives_the_textbook_overshoot(use_filter, overshoot):
    """The classic SO figures for a = 2: 8.1 % with the reference filter, 43.4 % without."""
    d = design(_axis("tomsk_xy"))
    t_s, k, k_c, j = d.small_time_constant, d.emf_constant, d.tacho_gain, d.inertia
    # forward PI · k/(J s) · 1/(T_σ s + 1), unity feedback in tacho volts
    num = d.speed_kp * k * k_c * np.array([d.speed_ti, 1.0])
    den = np.polymul([d.speed_ti, 0.0], np.polymul([j, 0.0], [t_s, 1.0]))
    closed_den = np.polyadd(den, num)
    closed_num = num
    if use_filter:
        closed_den = np.polymul(closed_den, [d.reference_filter, 1.0])
    t = np.linspace(0.0, 40 * t_s, 20001)
    _, y = signal.step((closed_num, closed_den), T=t)
    assert y.max() - 1.0 == pytest.approx(overshoot, abs=0.002)


def test_reference_filter_from_config_wins():
    d = design(_axis("tomsk_xy", **{"speed_loop.reference_filter": 0.0}))
    assert d.reference_filter == 0.0
    d = design(_axis("tomsk_xy", **{"speed_loop.reference_filter": 0.05}))
    assert d.reference_filter == 0.05


def test_inertia_reflects_the_moving_mass():
    cfg = load_machine("laser_belt")
    masses = cfg.moving_masses()
    ax, ay = cfg.axes["x"], cfg.axes["y"]
    assert masses == {"x": ax.mechanics.carriage_mass + ay.mechanics.carriage_mass,
                      "y": ay.mechanics.carriage_mass}
    r = ax.transmission.ratio
    assert axis_inertia(ax, masses["x"]) == pytest.approx(
        ax.mechanics.rotor_inertia + masses["x"] * r * r)
    assert design(ax, moving_mass=masses["x"]).inertia == axis_inertia(ax, masses["x"])
    assert design(ax).inertia == axis_inertia(ax)
    with pytest.raises(ConfigError, match="moving_mass"):
        design(ax, moving_mass=-1.0)


def test_bridge_that_cannot_rectify_is_rejected():
    ax = _axis("tomsk_xy", **{"converter.min_firing_angle": math.radians(95.0)})
    with pytest.raises(ConfigError, match="min_firing_angle"):
        design(ax)


def test_design_is_frozen_and_validated():
    d = design(_axis("tomsk_xy"))
    with pytest.raises(AttributeError):
        d.speed_kp = 1.0  # type: ignore[misc]
    fields = {f: getattr(d, f) for f in d.__dataclass_fields__}
    with pytest.raises(ConfigError, match="converter"):
        DriveDesign(**{**fields, "converter": "diesel"})
    with pytest.raises(ConfigError, match="voltage_range"):
        DriveDesign(**{**fields, "voltage_range": (10.0, -10.0)})
