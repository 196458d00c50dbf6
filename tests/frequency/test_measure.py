"""``twin measure`` on the twin against the analytic linearised transfer function: the
response within 1 dB and 5° on the lines with γ² ≥ 0.9, the first elastic mode within 2 %
of the closed loop's analytic pole (``closed_loop_modes``: Muller's iteration on 1/H, not
the fit), the position loop's phase margin within 3° of the linearised design; on the
presets and on randomly perturbed machines (seeded).

The 1 dB and 5° are checked up to the controller's Nyquist frequency (the accelerometer
measures further, where the twin's physics step departs from the continuous model by a few
degrees). Under CI a short version: coarse lines (f_min 4 Hz), four realisations, one perturbed
machine. The full version measures more machines with finer lines.
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np
import pytest

from twin.analysis.frequency import measure
from twin.analysis.frequency.excitation import multisine
from twin.analysis.frequency.prediction import closed_loop_modes
from twin.config import load_machine

CI = bool(os.environ.get("CI"))
COARSE = ({"f_min": 4.0, "averages": 4, "periods": 1} if CI else
          {"f_min": 2.0, "averages": 8, "periods": 1})
"""Noise-free measurements: one period measured per realisation is enough."""


def perturbed(seed: int):
    """laser_belt with its masses and belt stiffness scaled at random, its damping ratio
    drawn from 0.1 … 0.4 (seeded). Above 0.4 a mode's frequency is ill-conditioned: on one
    machine with ζ ≈ 0.49 a response within 0.5 dB of the analytic one put the fitted mode
    2.3 % off."""
    rng = np.random.default_rng(seed)
    base = load_machine("laser_belt")
    over = {}
    for a in "xy":
        ax = base.axes[a]
        over[f"axes.{a}.mechanics.carriage_mass"] = ax.mechanics.carriage_mass * float(
            rng.uniform(0.7, 1.4))
        over[f"axes.{a}.transmission.stiffness"] = {
            "belt": ax.transmission.stiffness["belt"] * float(rng.uniform(0.6, 1.6))}
        over[f"axes.{a}.transmission.damping_ratio"] = float(rng.uniform(0.1, 0.4))
    return base.with_overrides(over)


def check_mechanics(cfg, axis: str):
    r = measure(cfg, axis=axis, loop="mechanics", sensor="accelerometer", noise=False,
                **COARSE)
    good = r.coherence >= 0.9
    assert good.sum() >= 0.8 * len(good)
    # the claim holds up to the controller's Nyquist frequency; above it the twin's own
    # physics step (ω·h ≈ 0.3 at 200 Hz) bends the phase by up to 6°
    good &= r.frequency <= 0.5 / cfg.controller.period
    ratio = r.response[good] / r.prediction[good]
    assert np.abs(20 * np.log10(np.abs(ratio))).max() < 1.0
    assert np.abs(np.degrees(np.angle(ratio))).max() < 5.0
    analytic = closed_loop_modes(cfg, axis, r.position)[0]
    first = r.resonances[0]
    assert first.frequency == pytest.approx(abs(analytic) / (2 * math.pi), rel=0.02)
    assert first.seen_by == "accelerometer" and not r.unseen
    return r


def check_position(cfg, axis: str, **options):
    r = measure(cfg, axis=axis, loop="position", noise=False, **{**COARSE, **options})
    design = r.info["design_margins"]["phase_margin_deg"]
    assert r.margins.phase_margin == pytest.approx(design, abs=3.0)
    return r


@functools.cache
def laser_belt_x():
    """laser_belt's X axis measured on ``sim`` (shared by the tests that use it)."""
    return check_mechanics(load_machine("laser_belt"), "x")


def test_laser_belt_measured_against_the_linearised_twin():
    laser_belt_x()


@pytest.mark.slow
def test_over_modbus_against_twin_hil_server_as_on_sim():
    """The same measurement through ``twin hil-server`` on loopback, paced in real time:
    the response within the noise (three standard deviations of the ratio, from both
    coherences) on 95 % of the lines. The accelerometer samples at 800 Hz here: its FIFO
    of 32 then holds 40 ms, which a loaded host's late ticks do not overrun (at 3.2 kHz,
    10 ms, they did); and the first mode within 2 % of the one on sim, or within three
    standard deviations of its jackknife over the realisations when late ticks make it
    noisier. Each read is placed
    on the sensor's clock by the module's time stamp (register +2 of the accelerometer's),
    not by the host's clock: without it a loaded host's late ticks put the mode off by up
    to 12 %."""
    from twin.hardware.hil_process import spawn_hil_server
    from twin.hardware.register_map import MAPS

    cfg = load_machine("laser_belt").with_overrides({"accelerometer.sample_rate": 800.0})
    sim = measure(cfg, axis="x", noise=False, **COARSE)
    accel = str(MAPS["accelerometer"])
    with spawn_hil_server("--machine", "laser_belt", "--map", accel, "--no-noise",
                          "--set", "accelerometer.mounted=true",
                          "--set", "accelerometer.sample_rate=800", "--rt-priority", "10"
                          ) as server:
        url = f"modbus://127.0.0.1:{server.info['port']}?map={accel}"
        # a measurement whose ticks ran late (a host loaded several times over) is done
        # again, as an engineer repeats a disturbed one, at most three times; the one with
        # the most ticks on time is compared
        tries = []
        while len(tries) < 3 and (not tries or
                                  tries[-1].info["deadlines"]["on_time_ratio"] < 0.99):
            tries.append(measure(cfg, driver=url, axis="x", noise=False, **COARSE))
        hil = max(tries, key=lambda m: m.info["deadlines"]["on_time_ratio"])
    assert hil.info["deadlines"]["paced"] and np.array_equal(hil.frequency, sim.frequency)
    good = (hil.coherence >= 0.5) & (sim.coherence >= 0.5)
    assert good.sum() >= 0.5 * len(good), hil.info["deadlines"]

    def variance(g):
        return (1 - g) / (2 * COARSE["averages"] * g)
    sigma = np.sqrt(variance(hil.coherence[good]) + variance(sim.coherence[good]))
    deviation = np.abs(hil.response[good] / sim.response[good] - 1)
    assert np.mean(deviation <= 3 * sigma + 0.02) >= 0.95, hil.info["deadlines"]
    sd = hil.info["resonance_sd_hz"][0] or 0.0   # its spread over the realisations
    assert abs(hil.resonances[0].frequency - sim.resonances[0].frequency) <= max(
        0.02 * sim.resonances[0].frequency, 3.0 * sd), (hil.resonances, sim.resonances,
                                                        hil.info["deadlines"])


@pytest.mark.parametrize("seed", [11] if CI else [11, 12, 13, 14])
def test_perturbed_belt_machines(seed):
    cfg = perturbed(seed)
    check_mechanics(cfg, "y" if seed % 2 else "x")
    if not CI:
        check_position(cfg, "x")


@pytest.mark.slow
def test_the_presets_position_loop_phase_margin_is_the_design_s():
    check_position(load_machine("laser_belt"), "y")
    if not CI:     # tomsk's position loop crosses over near 1.5 Hz: half-hertz lines
        check_position(load_machine("tomsk_xy"), "x", f_min=0.5, f_max=20.0,
                       averages=4)


def noisy(cfg, axis: str, seed: int, **options):
    """A measurement with the machine file's accelerometer noise (an ADXL345's 400 µg/√Hz)
    at the accelerometer seed ``seed``, with the default periods per realisation."""
    cfg = cfg.with_overrides({"accelerometer.seed": seed})
    r = measure(cfg, axis=axis, loop="mechanics", sensor="accelerometer", **options)
    analytic = [abs(s) / (2 * math.pi) for s in closed_loop_modes(cfg, axis, r.position)]
    # nothing the noise made up: every resonance stands for a mode of the model, and every
    # mode of the model in the band is found or said to be unseen
    for found in r.resonances:
        assert min(abs(found.frequency / f - 1) for f in analytic) <= 0.15, (
            found, analytic)
    for i, f in enumerate(analytic):
        assert (any(abs(found.frequency / f - 1) <= 0.15 for found in r.resonances)
                or any(u.startswith(f"mode {i + 1} ") for u in r.unseen)), (r.unseen, f)
    return r, analytic


@pytest.mark.parametrize("seed", [21] if CI else [21, 22, 23, 24, 25, 26])
def test_the_first_mode_through_the_accelerometers_noise(seed):
    """With the sensor's noise the first mode of laser_belt and of perturbed belt machines
    is found within 2 % of the analytic one: eight periods measured per realisation by
    default (with one, the preset's came out 1-5 % off over accelerometer seeds 0-5)."""
    cfg = load_machine("laser_belt") if seed == 21 else perturbed(seed)
    axis = "xy"[seed % 2]
    r, analytic = noisy(cfg, axis, seed, averages=4 if CI else 8)
    assert r.info["excitation"]["periods_measured"] == 8 * r.info["excitation"]["averages"]
    assert r.resonances[0].frequency == pytest.approx(analytic[0], rel=0.02)


def test_a_mode_the_drive_cannot_excite_is_said_unseen_not_made_up():
    """tomsk_xy's thyristor drive hardly moves its screw mode at feed speed: through the
    accelerometer's noise no resonance is reported that the model does not have, and the
    mode is listed unseen (the tap test finds it: test_hammer.py)."""
    r, _ = noisy(load_machine("tomsk_xy"), "x", 3, averages=2)
    assert r.unseen and r.unseen[0].startswith("mode 1 ")


def test_each_realisation_runs_the_other_way():
    """The multisine's realisations alternate the speed kept, so the travel is that of
    one realisation whatever the averaging; the measured periods follow each settling
    one."""
    from twin.analysis.frequency.measure import _schedule

    cfg = load_machine("laser_belt")
    excs = [multisine(200, cfg.controller.period, 2.0, 100.0, seed=s) for s in range(5)]
    values, speeds, measured = _schedule(excs, 5, 3, 0.02)
    assert len(values) == len(speeds) == 5 * 4 * 200
    assert measured == [1, 2, 3, 5, 6, 7, 9, 10, 11, 13, 14, 15, 17, 18, 19]
    travel = np.cumsum(speeds) * cfg.controller.period
    assert travel.max() == pytest.approx(4 * 200 * cfg.controller.period * 0.02)
    assert travel.min() >= -1e-12 and np.all(np.abs(speeds) == 0.02)
    one = _schedule(excs[:1], 6, 3, 0.02)
    assert np.all(one[1] == 0.02) and one[2] == [1, 2, 3, 4, 5, 6]
