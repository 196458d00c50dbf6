"""The impact (tap) test: ``twin measure --excitation hammer``.

Where the drive cannot excite a mode coherently (a thyristor drive's current loop far slower
than a screw mode), a machine-tool engineer strikes the table with a modal hammer while the
drives hold position, and reads the modes off the accelerance A/F: the table accelerometer's
response per the hammer's measured force. Each blow is a half-sine of settable peak and
length (``twin.session.hammer``), the blows spaced one analysis window apart plus a random
pause (a hand's), each peak within ±10 % of the one asked for; the position regulator holds
both axes meanwhile (``run_excitation`` with the position loop closed and no excitation).

Each blow gives one window of N = f_s/f_min samples of force and acceleration from just
before it; the force is windowed to the blow (a force window: the sensor's noise outside it
is dropped), and the H1 estimate over the blows, H = S_AF/S_FF, with its coherence
γ² = |S_AF|²/(S_AA·S_FF), is ``Spectra`` with the force as the excitation and the input.
Both channels are means over the same sample intervals, so the ratio needs no correction.

A hammer is a physical instrument: the twin strikes only its own table (``sim``,
``sim:FILE``); over Modbus the measurement is refused.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.analysis.frequency import estimate, modes
from twin.analysis.frequency.estimate import Spectra
from twin.analysis.frequency.prediction import accelerance
from twin.analysis.frequency.record import Recording, run_excitation
from twin.analysis.frequency.result import FrequencyResponse
from twin.config import AXES, MachineConfig
from twin.errors import ConfigError, ExperimentAborted
from twin.session.hammer import HammerSimDriver, force_samples
from twin.session.machine_io import open_experiment_driver

__all__ = ["ACCELERANCE", "DURATION", "FORCE", "REACH", "HammerOptions", "band", "check", "strike",
           "tap_spectra", "tap_test"]

FORCE = 2000.0
"""Default peak force of a blow (N): a one-kilogram modal hammer on a machine table (lighter
blows leave the guideways' friction sticking: the response is then less linear)."""
DURATION = 2.0e-3
"""Default length of a blow (s): a hard plastic tip on steel, usable to ~600 Hz."""
FORCE_NOISE = 0.05
"""The force sensor's noise (N rms per sample)."""
PRE = 4
"""Samples of each window before its blow."""
SETTLE = 0.3
"""Time before the first blow (s): the hold settles after the enable edge."""
REACH = (-2e-3, 2e-3)
"""How far the held axis may move (m): a blow moves a held table by micrometres."""
ACCELERANCE = "m/(s²·N)"
"""Unit of a tap test's response (the accelerance A/F)."""


@dataclass(frozen=True)
class HammerOptions:
    """A tap test's settings.

    Attributes
    ----------
    force : float
        Peak force of a blow (N).
    duration : float
        Length of a blow (s).
    taps : int
        Blows averaged.
    f_min, f_max : float
        Line spacing (the window is 1/f_min) and highest line (Hz).
    """

    force: float
    duration: float
    taps: int
    f_min: float
    f_max: float


def band(duration: float) -> float:
    """Where a half-sine blow of ``duration`` (s) has fallen 20 dB below its low-frequency
    level (Hz): the tip's usable band. Its spectrum is ∝ cos(πfT)/(1 − (2fT)²)."""
    x = np.linspace(0.0, 1.5, 15001)               # f·T up to the first zero
    level = np.abs(np.cos(np.pi * x) / np.where(np.abs(1 - 4 * x * x) < 1e-9, 1e-9,
                                                  1 - 4 * x * x))
    level[np.abs(1 - 4 * x * x) < 1e-9] = math.pi / 4
    return float(x[np.argmax(level < 0.1)] / duration)


def check(driver: str, loop: str, sensor: str, force: float | None, duration: float | None,
          f_min: float | None, f_max: float | None, taps: int, sample_rate: float
          ) -> HammerOptions:
    """The tap test's options checked, defaults filled in.

    Raises
    ------
    ConfigError
        Naming the option: a hammer over Modbus, a loop or sensor it does not measure, a
        non-positive force or duration, a band outside the accelerometer's.
    """
    if not (driver == "sim" or driver.startswith("sim:")):
        raise ConfigError("excitation", "hammer: a modal hammer is a physical instrument "
                          "the twin cannot strike through " + driver.split("?")[0]
                          + "; tap the machine by hand or use --driver sim or sim:FILE")
    if loop != "mechanics":
        raise ConfigError("loop", f"the hammer measures the mechanics (accelerance), not "
                          f"the {loop} loop; use --loop mechanics")
    if sensor != "accelerometer":
        raise ConfigError("sensor", "the hammer's response is the table accelerometer's; "
                          "use --sensor accelerometer")
    force = FORCE if force is None else float(force)
    duration = DURATION if duration is None else float(duration)
    if not (math.isfinite(force) and 0.0 < force <= 1e5):
        raise ConfigError("hammer_force", f"must lie in (0, 100000] N, got {force:g} N")
    if not (math.isfinite(duration) and 0.05e-3 <= duration <= 50e-3):
        raise ConfigError("hammer_duration", f"must lie in [0.05, 50] ms, got "
                          f"{1e3 * duration:g} ms")
    nyq = 0.5 * sample_rate
    f_max = min(band(duration), nyq) if f_max is None else float(f_max)
    if not (math.isfinite(f_max) and 0.0 < f_max <= nyq):
        raise ConfigError("f_max", f"must lie in (0, {nyq:g}] Hz, the Nyquist frequency of "
                          f"the accelerometer, got {f_max:g} Hz")
    f_min = 2.0 if f_min is None else float(f_min)
    if not (math.isfinite(f_min) and 0.1 <= f_min < f_max):
        raise ConfigError("f_min", f"must lie in [0.1, {f_max:g}) Hz, got {f_min:g} Hz")
    return HammerOptions(force, duration, taps, f_min, f_max)


def strike(io: HammerSimDriver, base: MachineConfig, belief: MachineConfig, axis: str,
           opts: HammerOptions, window: list[tuple[float, float]], *, noise: bool,
           seed: int = 0) -> tuple[Spectra, Recording]:
    """Hold position and strike the table ``opts.taps`` times along ``axis``; return the
    per-blow spectra (force as excitation and input, acceleration as output) and the
    recording (its ``excitation`` the force sensor's samples on the accelerometer's clock).

    Raises
    ------
    ExperimentAborted
        A safety stop (the table left ``window``, a following error, a drive fault).
    ValueError
        The accelerometer lost the samples of every blow.
    """
    rng = np.random.default_rng([seed, 0x4A33E])
    rate = base.accelerometer.sample_rate
    n = round(rate / opts.f_min)
    span = n / rate
    start = io.plant.time + SETTLE
    blows, t = [], start
    for _ in range(opts.taps):
        blows.append((t, opts.force * float(rng.uniform(0.9, 1.1))))
        t += span + opts.duration + float(rng.uniform(0.05, 0.15))
    io.strike_at(blows)
    period = base.controller.period
    ticks = math.ceil((t - io.plant.time) / period) + 2
    rec = run_excitation(io, base, belief, axis=axis, loop="position", volts=np.zeros(ticks),
                         offset=0.0, window=window, accelerometer=True, paced=False)
    force = force_samples(io.segments, rec.accel_sequence, rate,
                          FORCE_NOISE if noise else 0.0, rng)
    starts = [math.floor(s * rate) + 1 for s, _ in blows]
    spec = tap_spectra(force, rec.accel, rec.accel_sequence, starts, n, rate, opts)
    rec.excitation = force
    return spec, rec


def tap_spectra(force: np.ndarray, accel: np.ndarray, sequence: np.ndarray,
                starts: list[int], n: int, rate: float, opts: HammerOptions) -> Spectra:
    """The H1 spectra of the blows: for each blow (``starts``: the sample number in which
    it begins) a window of ``n`` samples from ``PRE`` before it of the force (N; windowed to
    the blow) and the acceleration (m/s²), both numbered ``sequence`` at ``rate`` (Hz); the
    lines from ``opts.f_min`` to ``opts.f_max``. A blow whose window lost samples is left
    out.

    Raises
    ------
    ValueError
        Every blow's window lost samples.
    """
    by_seq = {int(s): j for j, s in enumerate(sequence)}
    bins = np.arange(1, n // 2 + 1)
    f = bins * rate / n
    keep = (f >= opts.f_min - 1e-9) & (f <= opts.f_max + 1e-9)
    bins, f = bins[keep], f[keep]
    forces, outputs = [], []
    for start in starts:
        idx = [by_seq.get(i) for i in range(start - PRE, start - PRE + n)]
        if any(j is None for j in idx):
            continue
        rows = np.array(idx)
        fw = force[rows].copy()
        fw[PRE + math.ceil(opts.duration * rate) + 2:] = 0.0   # the force window
        fw[:max(PRE - 2, 0)] = 0.0
        forces.append(np.fft.fft(fw)[bins] / n)
        outputs.append(np.fft.fft(accel[rows])[bins] / n)
    if not forces:
        raise ValueError("the accelerometer lost samples in every blow's window")
    spec_f = np.array(forces)
    return Spectra(f, spec_f, spec_f, np.array(outputs))


def tap_test(base: MachineConfig, belief: MachineConfig, driver: str, axis: str,
             opts: HammerOptions, target: np.ndarray, window: list[tuple[float, float]],
             *, out_dir, noise: bool, say: Callable[[str], None]) -> FrequencyResponse:
    """The impact test (the module docstring) on the twin ``driver`` names: its table set
    at ``target`` (m; the middle of the travel: the jog there is of no interest to the
    test), held within ``window``, struck; the accelerance, its resonances and the analytic
    modes; ``measure-<id>/`` written under ``out_dir`` (None: nothing).

    Raises
    ------
    ExperimentAborted
        A safety stop, or every blow's window lost samples.
    """
    if out_dir is not None:
        from twin.system.jsonio import output_dir
        output_dir(out_dir)
    io, _ = open_experiment_driver(driver, base, noise=noise, accelerometer=True)
    k = AXES.index(axis)
    striker = HammerSimDriver(io.plant, io.period, axis=k,  # type: ignore[attr-defined]
                              duration=opts.duration)
    try:
        say(f"{driver}: the table at x {1e3 * target[0]:.2f} mm, y {1e3 * target[1]:.2f} mm")
        io.plant.reset(positions=target)   # type: ignore[attr-defined]
        say(f"hammer: {opts.taps} blows of {opts.force:g} N, {1e3 * opts.duration:g} ms, "
            f"along {axis}; windows of {1.0 / opts.f_min:.2f} s")
        spec, rec = strike(striker, base, belief, axis, opts, window, noise=noise)
    except ValueError as exc_:
        raise ExperimentAborted(f"the measurement is incomplete: {exc_}") from None
    finally:
        striker.close()
    position = min(max(float(np.mean(rec.position)), belief.axes[axis].mechanics.travel[0]),
                   belief.axes[axis].mechanics.travel[1])
    response, coherence = spec.response()
    f = spec.frequency
    prediction = accelerance(belief, axis, position, f)
    rigid = accelerance(belief, axis, position, f, rigid=True)
    good = coherence >= estimate.COHERENT
    found = modes.resonances(f, response, coherence, rigid, axis, "accelerometer", len(spec.dac))
    # a pole whose half-power width 2ζf is narrower than the lines is not resolved by them:
    # on the twin a friction nonlinearity's or the drive's ripple, never the structure's
    resonances = [r for r in found if 2.0 * r.damping * r.frequency >= opts.f_min]
    narrow = [f"a peak at {r.frequency:.1f} Hz, {2.0 * r.damping * r.frequency:.2f} Hz "
              f"wide, narrower than the {opts.f_min:g} Hz lines: not resolved (lower "
              "--f-min to resolve it)" for r in found if r not in resonances]
    info: dict[str, Any] = {
        "machine": base.name, "controller_model": belief.name, "driver": driver,
        "excitation": {"kind": "hammer", "peak_force_n": opts.force,
                       "duration_ms": 1e3 * opts.duration, "taps": len(spec.dac),
                       "resolution_hz": opts.f_min, "f_max_hz": opts.f_max},
        "controller_period_s": base.controller.period,
        "machine_time_s": len(rec.slot) * base.controller.period,
        "accelerometer_rate_hz": base.accelerometer.sample_rate,
        "accelerometer_samples_lost": int(rec.lost),
        "resonance_sd_hz": modes.jackknife(spec, resonances, rigid, axis, "accelerometer",
                                      averaged=True),
        **modes.compared(response, prediction, good, belief, axis, position),
        "deadlines": None,
    }
    top = float(f[good].max()) if good.any() else 0.0
    unseen = modes.unseen(belief, axis, position, "accelerometer", "mechanics", top) + narrow
    result = FrequencyResponse(f, response, coherence, prediction, resonances, None,
                               unseen, "mechanics", "accelerometer", axis, ACCELERANCE,
                               position, info)
    if out_dir is not None:
        from twin.analysis.frequency.report import write_record
        result = write_record(result, rec, Path(out_dir))
    return result
