"""Speed loop of the thyristor drive on a rigid rotor: step response and speed range.

What is asserted and why
------------------------
- A 1 V step from standstill (preset rotor friction) settles to ω = 1/K_C within 2 %.
- Overshoot: the symmetric optimum with a = 2 gives 8.1 % with the reference filter and
  43.4 % without it when the small lags are lumped into one T_σ and sampling is ignored.
  Mean-value bridge: the regulators sample at 300 Hz, every 0.77·T_σ, and that extra phase
  lag raises the overshoot (measured 9.2 % and 50 %). Pulse-level bridge (the default):
  T_σ holds T_ie = 2·T_p for a current loop in continuous conduction, but a 1 V step stays
  below the boundary current (2.9 A of pulse mean against 4.2 A·sin α), where the
  compensated current loop settles within about one pulse: the speed loop sees less lag
  than designed and overshoots less (measured 4.0 % and 28 %). We assert the SO character
  with bands that hold the measured value and exclude the neighbouring designs on the same
  drive: mean 5-13 % / 35-58 % (a = 1.5: 36 % / 82 %; a = 3: 0 % / 26 %); pulse 2-9 % /
  20-45 % (a = 1.5: 14 % / 78 %; a = 3: 0.7 % / 17 %).
- Settling time (2 % band): textbook 13.3·T_σ with the filter; we assert < 20·T_σ
  (measured 18.5·T_σ mean-value, 17.2·T_σ pulse-level).
- Speed range ≥ 2000:1: 10 V/2000 (one 12-bit DAC step) with the preset rotor Coulomb
  friction gives motion at the proportional mean speed within 20 % (within 0.1 %
  mean-value, 1 % pulse-level). The mean-value drive holds it steady within ±20 %; the
  pulse-level one moves the 1e-3 kg·m² rotor in current pulses of 300 Hz, ±35 % about the
  mean at 1 rpm, but never stops (no stick-slip).
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import load_machine
from twin.drive import Drives

from .rig import simulate

TOMSK = load_machine("tomsk_xy")


def step_metrics(t: np.ndarray, y: np.ndarray, band: float = 0.02) -> tuple[float, float]:
    """Overshoot (fraction) and settling time (s; inf if never) of a unit-final response."""
    outside = np.nonzero(np.abs(y - 1.0) > band)[0]
    if not outside.size:
        return float(y.max() - 1.0), float(t[0])
    settle = t[outside[-1] + 1] if outside[-1] + 1 < t.size else np.inf
    return float(y.max() - 1.0), float(settle)


@pytest.mark.parametrize(("model", "reference_filter", "overshoot_band"), [
    ("mean", None, (0.05, 0.13)),
    ("mean", 0.0, (0.35, 0.58)),
    ("pulse", None, (0.02, 0.09)),
    ("pulse", 0.0, (0.20, 0.45)),
])
def test_step_response_is_the_symmetric_optimum(model, reference_filter, overshoot_band):
    cfg = TOMSK.with_overrides({"axes.*.speed_loop.reference_filter": reference_filter,
                                "axes.*.converter.model": model})
    ax = cfg.axes["y"]
    drives = Drives([ax], dt=1e-3)
    run = simulate(drives, 1.0, 0.4, coulomb=ax.mechanics.rotor_coulomb,
                   viscous=ax.mechanics.rotor_viscous)
    y = run.omega[:, 0] * ax.tacho.gain  # in units of the 1 V target 1/K_C
    overshoot, settle = step_metrics(run.time, y)
    t_sigma = drives.designs[0].small_time_constant
    print(f"SO step (T1 = {drives.designs[0].reference_filter * 1e3:.1f} ms): overshoot "
          f"{overshoot:.1%}, 2 % settling {settle * 1e3:.1f} ms = {settle / t_sigma:.1f} T_σ")
    assert y[-100:] == pytest.approx(1.0, abs=0.02)
    assert overshoot_band[0] <= overshoot <= overshoot_band[1]
    if reference_filter is None:
        assert settle < 20 * t_sigma
    assert np.abs(run.current).max() < drives.designs[0].current_limit  # linear regime


@pytest.mark.parametrize("model", ["mean", "pulse"])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_speed_range_2000_to_1_with_coulomb_friction(sign, model):
    ax = TOMSK.with_overrides({"axes.*.converter.model": model}).axes["x"]
    full_scale = ax.dac.full_scale
    lsb = 2 * full_scale / 2 ** ax.dac.bits
    u = sign * round(full_scale / 2000 / lsb) * lsb  # 10 V/2000 as the 12-bit DAC gives it
    drives = Drives([ax], dt=1e-3)
    run = simulate(drives, u, 3.0, coulomb=ax.mechanics.rotor_coulomb,
                   viscous=ax.mechanics.rotor_viscous)
    target = u / ax.tacho.gain
    late = run.time > 1.0
    mean_speed = (run.angle[-1, 0] - run.angle[late][0, 0]) / (run.time[-1] - run.time[late][0])
    print(f"2000:1: reference {u * 1e3:.2f} mV, mean speed {mean_speed / target:.4f} of "
          f"U/K_C = {target:.4f} rad/s")
    assert mean_speed == pytest.approx(target, rel=0.2)
    spread = 0.2 if model == "mean" else 0.5
    assert np.all(run.omega[late, 0] * sign > (1 - spread) * abs(target))  # no stick-slip
    assert np.all(run.omega[late, 0] * sign < (1 + spread) * abs(target))


def test_full_speed_and_both_axes_at_once():
    """Both axes in one Drives object run independently: ±10 V give ±U/K_C."""
    drives = Drives.from_machine(TOMSK, dt=1e-3)
    u = np.array([10.0, -5.0])
    run = simulate(drives, u, 0.6, coulomb=0.03, viscous=2e-4)
    k_c = np.array([TOMSK.axes[a].tacho.gain for a in ("x", "y")])
    np.testing.assert_allclose(run.omega[-1], u / k_c, rtol=0.02)
    # the regulator limits the current it measures, the pulse mean; the instantaneous
    # current, and its mean over a 1 ms interval, ride above it by the converter's ripple.
    # Over three pulses (10 intervals) the mean current holds the limit within the MO
    # loop's own overshoot (4.3 %) and its lag behind the EMF ramp of the acceleration
    # (measured 5.5 %)
    mean_current = np.abs(run.torque) / TOMSK.axes["x"].motor.emf_constant
    window = np.ones(10) / 10
    for k in range(2):
        smooth = np.convolve(mean_current[:, k], window, mode="valid")
        assert np.all(smooth <= drives.designs[0].current_limit * 1.1)
