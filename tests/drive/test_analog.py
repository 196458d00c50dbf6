"""The analog drive's regulators (``twin.drive.analog``) against a self-contained solve_ivp
model of the whole analog cascade (``tests/drive/analog_reference.py``): random settings
off their design, random drops, mains and reactor, in discontinuous and continuous
conduction, at the plant's drive interval.

With the rotor held at a speed the kernel's only approximations are its regulators'
integration (the filters' exact integrals, the trapezoidal rule on the speed integrator
over spans of one interval): they agree to 2e-9 of the peak current. With a rigid rotor the
drive also sees the speed extrapolated over each interval from the last two (the plant's
coupling), which costs up to 4e-3 of the peak at a 1 ms interval and 6e-5 at 0.1 ms (it
falls about as the interval squared).
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from twin.config import load_machine
from twin.drive import Drives, design

from .analog_reference import Cascade, simulate

TOMSK = load_machine("tomsk_xy")
CI = bool(os.environ.get("CI"))
SPAN = 0.25          # s simulated
SUB = 5              # physics sub-steps per drive interval, as the plant has them


def _cascade(ax, inertia: float, load: float) -> Cascade:
    d = design(ax)
    m, cv = ax.motor, ax.converter
    return Cascade(r=d.resistance, l=d.inductance, u_ll=cv.line_voltage, k=m.emf_constant,
                   k_c=ax.tacho.gain, t_f=ax.tacho.filter_time_constant,
                   t1=d.reference_filter, kp_w=d.speed_kp, ti_w=d.speed_ti, kp_i=d.current_kp,
                   ti_i=d.current_ti, t_fi=d.current_filter, i_th=d.bridge_threshold,
                   i_lim=d.current_limit, alpha_min=cv.min_firing_angle,
                   alpha_max=cv.max_firing_angle, inertia=inertia, load=load,
                   drop=m.brush_drop + cv.series_devices * cv.thyristor_threshold,
                   deviation=cv.mains_deviation)


def _random_drive(rng: np.random.Generator, held: bool) -> tuple:
    """A random analog tomsk_xy Y drive without DCM adaptation and its case: (axis,
    cascade, reference (V), initial speed (rad/s)); a short reference filter, so that the
    speed error starts positive (the regulators start from zero). Held: the rotor at a
    random speed, the reference a little above it, so that i* ramps up through
    discontinuous into continuous conduction. Rigid: the rotor starting at the reference's
    speed against a random load, which the drive picks up from zero current, in
    discontinuous conduction at first. (A light load at a low speed makes this drive
    limit-cycle through the reverse bridge, which the reference does not model.)"""
    d0 = design(TOMSK.axes["y"])
    o = {"axes.y.regulators.implementation": "analog",
         "axes.y.converter.dcm_compensation": False,
         "axes.y.regulators.current_kp": d0.current_kp * rng.uniform(0.5, 1.5),
         "axes.y.regulators.current_ti": d0.current_ti * rng.uniform(0.5, 2.0),
         "axes.y.regulators.speed_kp": d0.speed_kp * rng.uniform(0.5, 1.5),
         "axes.y.regulators.speed_ti": d0.speed_ti * rng.uniform(0.5, 2.0),
         "axes.y.regulators.current_filter": rng.uniform(0.3e-3, 2e-3),
         "axes.y.motor.brush_drop": rng.uniform(0.0, 2.0),
         "axes.y.converter.thyristor_threshold": rng.uniform(0.0, 1.0),
         "axes.y.converter.mains_deviation": rng.uniform(-0.05, 0.05),
         "axes.y.converter.smoothing_inductance": rng.choice([0.0, rng.uniform(0.0, 0.02)])}
    o["axes.y.speed_loop.reference_filter"] = 1e-4
    ax = TOMSK.with_overrides({k: v if isinstance(v, str | bool) else float(v)
                               for k, v in o.items()}).axes["y"]
    d = design(ax)
    if held:
        omega0 = float(rng.uniform(0.0, 30.0))
        target = rng.uniform(7.0, 9.0)    # i* at the end (A): about twice the boundary
        delta = target / (d.speed_kp * (1.0 + SPAN / d.speed_ti))
        return ax, _cascade(ax, math.inf, 0.0), ax.tacho.gain * omega0 + delta, omega0
    load = rng.uniform(0.6, 1.2) * ax.motor.emf_constant * ax.motor.rated_current
    reference = rng.uniform(0.3, 2.0)
    return (ax, _cascade(ax, d.inertia, float(load)), float(reference),
            float(reference / ax.tacho.gain))


def _kernel(ax, c: Cascade, reference: float, omega0: float, dt: float, steps: int):
    """The twin's drive coupled as the plant couples it: each sub-step's mean torque
    integrated exactly into the rotor (held: the speed stays)."""
    drives = Drives([ax], dt=dt, sub_steps=SUB)
    w, h = omega0, dt / SUB
    current, omega = np.empty(steps), np.empty(steps)
    for n in range(steps):
        drives.step(np.array([reference]), np.array([w]))
        if math.isfinite(c.inertia):
            for tau in drives.sub_torque[0]:
                w += (tau - c.load) / c.inertia * h
        current[n], omega[n] = drives.current[0], w
    return current, omega


def _compare(ax, c, reference, omega0, dt) -> tuple[float, float, set[str]] | None:
    """(RMS current error over the peak, RMS speed error over the largest speed, the modes
    the reference went through), or None if the case left the regulators' limits."""
    steps = round(SPAN / dt)
    times = dt * np.arange(1, steps + 1)
    ref = simulate(c, lambda t: reference, [], omega0, float(times[-1]), times)
    if not ref["inside"]:
        return None
    current, omega = _kernel(ax, c, reference, omega0, dt, steps)
    peak = float(np.abs(ref["current"]).max())
    err = float(np.sqrt(np.mean((current - ref["current"]) ** 2))) / peak
    top = max(float(np.abs(ref["omega"]).max()), 1e-9)
    w_err = float(np.sqrt(np.mean((omega - ref["omega"]) ** 2))) / top
    zero = ref["current"] == 0.0
    first = int(np.argmax(~zero))          # the first current
    modes = {"discontinuous"} if zero[first:].any() else set()
    if not zero[-20:].any():
        modes.add("continuous")
    return err, w_err, modes


def _cases(seed: int, held: bool, count: int, dt: float):
    """``count`` random cases that stay inside the regulators' limits (others are drawn
    again: the reference has no current limit and no reversal)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(8 * count):
        ax, c, reference, omega0 = _random_drive(rng, held)
        found = _compare(ax, c, reference, omega0, dt)
        if found is not None:
            out.append((found, (ax, c, reference, omega0)))
            if len(out) == count:
                return out
    raise AssertionError(f"only {len(out)} of {count} random drives stayed in the limits")


@pytest.mark.slow
def test_the_analog_regulators_match_the_reference_with_the_rotor_held():
    worst, modes = 0.0, set()
    for (err, _, seen), case in _cases(41, True, 1 if CI else 6, 1e-3):
        assert err < 1e-6, case
        worst = max(worst, err)
        modes |= seen
    print(f"rotor held, 1 ms intervals: worst RMS current error {worst:.1e} of the peak")
    assert modes == {"discontinuous", "continuous"}


@pytest.mark.slow
def test_the_analog_cascade_with_a_rigid_rotor_matches_the_reference():
    worst, fine, modes = 0.0, 0.0, set()
    for (err, w_err, seen), (ax, c, reference, omega0) in _cases(43, False, 2 if CI else 8,
                                                                 1e-3):
        assert err < 5e-3 and w_err < 1e-2, (err, w_err, c)
        worst = max(worst, err)
        modes |= seen
        if not CI:   # the coupling's error falls with the interval squared
            err_fine = _compare(ax, c, reference, omega0, 1e-4)[0]
            assert err_fine < max(err / 20.0, 1e-6)
            fine = max(fine, err_fine)
    print(f"rigid rotor: worst RMS current error {worst:.1e} of the peak at 1 ms intervals, "
          f"{fine:.1e} at 0.1 ms; {sorted(modes)}")
    assert "continuous" in modes     # the held rotor's test goes through both modes
