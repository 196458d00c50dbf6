"""The measurement's parts against independent references: the excitation signals, the
sensor model, the mode fit, the margins, the elastic speed loop and the visibility of the
modes. All cheap (no twin runs)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from twin.analysis.frequency import estimate
from twin.analysis.frequency.excitation import mls, multisine, period_length, prbs
from twin.analysis.frequency.measure import plan_room
from twin.analysis.frequency.modes import unseen as _unseen
from twin.config import AccelerometerConfig, load_machine
from twin.drive.design import axis_inertia
from twin.drive.linear import speed_response, speed_transfer_function
from twin.errors import ConfigError
from twin.plant.accelerometer import Accelerometer

SEEDS = range(3) if __import__("os").environ.get("CI") else range(12)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_multisine_has_power_on_its_lines_only(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(64, 600))
    period = float(rng.uniform(1e-3, 6e-3))
    f_min = float(rng.uniform(1, 4)) / (n * period)
    f_max = float(rng.uniform(0.2, 0.49)) / period
    exc = multisine(n, period, f_min, f_max, seed=seed if seed % 2 else None)
    spectrum = np.abs(np.fft.rfft(exc.values))
    on = np.zeros(len(spectrum), dtype=bool)
    on[exc.lines] = True
    assert np.max(np.abs(exc.values)) == pytest.approx(1.0)
    assert spectrum[~on].max() < 1e-9 * spectrum[on].min()
    assert np.ptp(spectrum[on]) < 1e-9 * spectrum[on].max()     # flat amplitude spectrum
    assert exc.lines[0] * exc.resolution <= f_min + 1e-9
    assert exc.lines[-1] * exc.resolution <= f_max + 1e-9


@pytest.mark.parametrize("bits", [5, 7, 9, 11])
def test_a_maximal_length_sequence_repeats_only_after_its_length(bits):
    seq = mls(bits)
    assert len(seq) == 2**bits - 1 and seq.sum() == 1.0            # balanced: one more +1
    circular = np.real(np.fft.ifft(np.abs(np.fft.fft(seq)) ** 2))   # autocorrelation
    assert circular[0] == pytest.approx(len(seq))
    assert np.allclose(circular[1:], -1.0)


def test_a_prbs_period_holds_whole_bits_and_reaches_f_min():
    exc = prbs(100, 5e-3, 1.0, 40.0)
    assert exc.length * 5e-3 >= 1.0 and exc.lines[-1] * exc.resolution <= 40.0 + 1e-9


@pytest.mark.parametrize("period,rate", [(5e-3, 3200.0), (3.5e-3, 3200.0), (1e-3, 1600.0),
                                         (2.5e-3, 800.0)])
def test_a_period_spans_whole_accelerometer_samples(period, rate):
    n = period_length(97, period, rate)
    assert n >= 97 and abs(n * period * rate - round(n * period * rate)) < 1e-6


@pytest.mark.parametrize("seed", SEEDS)
def test_the_accelerometer_gives_the_mean_acceleration_of_each_interval(seed):
    rng = np.random.default_rng(seed)
    cfg = AccelerometerConfig(mounted=True, sample_rate=float(rng.choice([800, 1600, 3200])),
                              resolution=1e-4, range=1e3, block=32)
    sensor = Accelerometer(cfg, noise=False)
    f, amp, h = float(rng.uniform(5, 200)), float(rng.uniform(0.01, 1)), 2e-4
    w = 2 * math.pi * f
    sensor.reset(0.0, np.zeros(2))
    got, seq = [], []
    out = np.zeros((32, 2))
    t = 0.0
    for _ in range(40):                    # 40 reads of 25 steps of h
        steps = t + h * np.arange(1, 26)
        v = np.stack([amp * np.sin(w * steps), -amp * np.sin(w * steps)], axis=1)
        sensor.feed(t, h, v)
        t = steps[-1]
        n, first, lost = sensor.pop(out)
        assert not lost
        got.append(out[:n].copy())
        seq.append(first + np.arange(n))
    a, i = np.concatenate(got), np.concatenate(seq)
    ts = 1.0 / cfg.sample_rate
    # the mean acceleration (v(t_i) − v(t_i − T_s))/T_s, the velocity interpolated linearly
    # between the steps: each end off by at most amp·(ωh)²/8
    exact = amp * (np.sin(w * i * ts) - np.sin(w * (i - 1) * ts)) / ts
    assert np.abs(a[:, 0] - exact).max() < amp * (w * h) ** 2 / 4 / ts + cfg.resolution
    assert np.allclose(a[:, 1], -a[:, 0], atol=cfg.resolution)
    assert np.all(np.diff(i) == 1)


def test_a_full_fifo_drops_its_oldest_and_says_so():
    cfg = AccelerometerConfig(mounted=True, sample_rate=1000.0, block=8)
    sensor = Accelerometer(cfg, noise=False)
    sensor.feed(0.0, 1e-3, np.zeros((20, 2)))
    out = np.zeros((8, 2))
    n, first, lost = sensor.pop(out)
    assert (n, first, lost) == (8, 13, True) and sensor.lost == 12
    assert sensor.pop(out)[0] == 0


@pytest.mark.parametrize("seed", SEEDS)
def test_the_mode_fit_recovers_a_random_pole(seed):
    rng = np.random.default_rng(seed)
    fn, zeta = float(rng.uniform(5, 500)), float(rng.uniform(0.01, 0.7))
    w = 2 * math.pi * fn
    b = rng.normal(size=3) * [1 / w**2, 1 / w, 1]
    f = np.linspace(fn / 1.5, fn * 1.5, int(rng.integers(8, 60)))
    s = 2j * math.pi * f
    h = (b[0] * s**2 + b[1] * s + b[2] + w**2) / (s**2 + 2 * zeta * w * s + w**2)
    pole = estimate.fit_mode(f, h)
    assert abs(pole) / (2 * math.pi) == pytest.approx(fn, rel=1e-6)
    assert -pole.real / abs(pole) == pytest.approx(zeta, rel=1e-5)


@pytest.mark.parametrize("seed", SEEDS)
def test_margins_of_an_integrator_lag_and_delay(seed):
    # L = K·e^(−sτ_d)/(s·(τs + 1)): |L| = 1 where K = ω·√(1 + ω²τ²) (brentq); the phase
    # there −90° − atan(ωτ) − ωτ_d; −180° where atan(ωτ) + ωτ_d = 90°
    from scipy.optimize import brentq

    rng = np.random.default_rng(seed)
    k, tau, delay = float(rng.uniform(5, 60)), float(rng.uniform(1e-3, 2e-2)), \
        float(rng.uniform(1e-4, 5e-3))
    f = np.geomspace(0.05, 2000, 20000)
    s = 2j * math.pi * f
    el = k * np.exp(-s * delay) / (s * (tau * s + 1))
    m = estimate.margins(f, el)
    wc = brentq(lambda w: w * math.sqrt(1 + (w * tau) ** 2) - k, 1e-6, 1e6)
    pm = 90.0 - math.degrees(math.atan(wc * tau) + wc * delay)
    w180 = brentq(lambda w: math.atan(w * tau) + w * delay - math.pi / 2, 1e-6, 1e6)
    gm = -20 * math.log10(k / (w180 * math.sqrt(1 + (w180 * tau) ** 2)))
    assert m.crossover == pytest.approx(wc / (2 * math.pi), rel=1e-3)
    assert m.phase_margin == pytest.approx(pm, abs=0.05)
    assert m.gain_margin == pytest.approx(gm, abs=0.05)


@pytest.mark.parametrize("name", ["tomsk_xy", "laser_belt"])
def test_the_elastic_speed_loop_with_a_rigid_rotor_is_the_drive_s_own(name):
    cfg = load_machine(name)
    for axis in "xy":
        ax = cfg.axes[axis]
        mass = cfg.moving_masses()[axis]
        f = np.geomspace(0.5, 2000, 200)
        s = 2j * math.pi * f
        num, den = speed_transfer_function(ax, moving_mass=mass)
        _, ref = signal.freqs(num, den, worN=2 * math.pi * f)
        got = speed_response(ax, s, 1.0 / (axis_inertia(ax, mass) * s), moving_mass=mass)
        assert np.allclose(got, ref, rtol=1e-8)


def test_a_motor_sensor_says_it_cannot_see_tomsk_s_screw_mode():
    cfg = load_machine("tomsk_xy")
    unseen = _unseen(cfg, "x", 0.15, "motor", "mechanics", 99.0)
    assert len(unseen) == 2 and all("mount an accelerometer" in u for u in unseen)
    above = _unseen(cfg, "x", 0.15, "accelerometer", "mechanics", 200.0)
    assert len(above) == 1 and "mode 2" in above[0] and "above the measured band" in above[0]
    assert _unseen(cfg, "x", 0.15, "accelerometer", "mechanics", 400.0) == []
    assert "no line" in _unseen(cfg, "x", 0.15, "accelerometer", "mechanics", 0.0)[0]
    belt = load_machine("laser_belt")        # its light rotor: the belt mode shows
    assert _unseen(belt, "x", 0.6, "motor", "speed", 140.0) == []


def test_no_room_for_the_excursion_names_the_amplitude():
    cfg = load_machine("tomsk_xy")
    with pytest.raises(ConfigError) as caught:
        plan_room(cfg, "x", (-0.01, 0.4), np.array([0.1, 0.1]))
    assert caught.value.field == "amplitude"
    target, window = plan_room(cfg, "x", (-0.01, 0.05), np.array([0.005, 0.1]))
    assert window[0][0] >= cfg.axes["x"].switches.limit_min
    assert target[0] - 0.01 >= cfg.axes["x"].switches.limit_min


@pytest.mark.parametrize("seed", SEEDS)
def test_the_accelerometer_registers_carry_the_fifo_as_it_was(seed):
    from twin.hardware.register_map import accelerometer_samples, accelerometer_words

    rng = np.random.default_rng(seed)
    block = int(rng.integers(1, 57))
    lsb = float(rng.uniform(0.001, 0.1))
    count = int(rng.integers(0, block + 1))
    first = int(rng.integers(0, 10**7))
    lost, phase = bool(rng.integers(2)), float(rng.uniform(0, 1))
    samples = rng.uniform(-1000 * lsb, 1000 * lsb, (block, 2))
    words = accelerometer_words(count, first, lost, samples, lsb, block, phase)
    assert len(words) == 3 + 2 * block and all(0 <= w <= 0xFFFF for w in words)
    n, low, flag, got_phase, got = accelerometer_samples(words, lsb, block)
    assert (n, low, flag) == (count, first & 0xFFFF, lost)
    assert got_phase == pytest.approx(phase, abs=1 / 65536)
    assert np.abs(got[:count] - samples[:count]).max(initial=0.0) <= 0.5 * lsb + 1e-12
    assert not got[count:].any()
