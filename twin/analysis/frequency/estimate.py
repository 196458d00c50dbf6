"""From a recording to a frequency response: spectra of whole periods, averaging and
coherence, the position loop's margins and the resonances.

Every period of the excitation is a period of the steady response, so each signal's DFT
over one period has the response on the excited lines only (no window, no leakage). With
the per-period spectra Y_p, U_p and D_p of the output, the DAC and the excitation, the
response is S_YD/S_UD, their cross spectra with the excitation summed over the periods
(the noise falls as 1/√P), and the coherence of each line is γ² = γ²_YD·γ²_UD, the
coherence of each with the excitation D over the periods. The periods are of several
realisations of a random-phase multisine: a nonlinear distortion differs from one to the
next and lowers the coherence as noise does, where with one realisation it would repeat
every period and pass for the response.

The DAC is held for a controller period T, the accelerometer averages over its sample
interval T_s: its spectrum is compared with the held input's continuous spectrum,
U(ω)·(1 − e^(−jωT))/(jωT), after its own averaging (1 − e^(−jωT_s))/(jωT_s) is divided
out. The held input has power at the images f ± n/T of each line as well, so the
accelerometer measures the mechanics up to its own Nyquist frequency although the
excitation is computed at the controller's rate.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import find_peaks

from twin.analysis.frequency.excitation import Excitation
from twin.analysis.frequency.record import Recording
from twin.analysis.frequency.result import Margins

__all__ = ["COHERENT", "Spectra", "fit_mode", "margins", "peaks", "spectra"]

COHERENT = 0.9
"""Coherence from which a line is trusted (the figures and the margins use only those)."""


def _hold(w: np.ndarray, width: float) -> np.ndarray:
    """(1 − e^(−jωτ))/(jωτ): a signal held (or averaged) over τ = ``width``."""
    x = w * width
    return np.where(np.abs(x) < 1e-12, 1.0, (1.0 - np.exp(-1j * x)) / (1j * x + 1e-300))


class Spectra:
    """Per-period spectra of a recording on the measured lines.

    Attributes
    ----------
    frequency : ndarray
        The lines (Hz).
    excitation, dac, output : ndarray, complex, shape (periods, lines)
        The excitation (V) and the DAC's held input (V), and the output, per period.
    """

    def __init__(self, frequency: np.ndarray, excitation: np.ndarray, dac: np.ndarray,
                 output: np.ndarray):
        self.frequency, self.excitation = frequency, excitation
        self.dac, self.output = dac, output

    def response(self) -> tuple[np.ndarray, np.ndarray]:
        """The response H = S_YD/S_UD of the output Y and the DAC's input U, both against
        the excitation D (cross spectra summed over the periods: noise in the loop does
        not bias it), and its coherence γ²_YD·γ²_UD at each line, γ²_XD =
        |S_XD|²/(S_XX·S_DD)."""
        d = self.excitation
        s_dd = np.sum(np.abs(d) ** 2, axis=0)

        def cross(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            s_xd = np.sum(x * np.conj(d), axis=0)
            s_xx = np.sum(np.abs(x) ** 2, axis=0)
            return s_xd, np.abs(s_xd) ** 2 / np.where(s_xx * s_dd > 0, s_xx * s_dd, np.inf)

        s_yd, g_y = cross(self.output)
        s_ud, g_u = cross(self.dac)
        return s_yd / s_ud, g_y * g_u

    def without(self, period: int) -> Spectra:
        """The spectra with one period left out (for a jackknife)."""
        keep = np.arange(len(self.dac)) != period
        return Spectra(self.frequency, self.excitation[keep], self.dac[keep],
                       self.output[keep])


def _periods(rec: Recording, length: int, measured: list[int]) -> list[np.ndarray]:
    """Indices into the recording of each complete period of ``measured`` (the numbers of
    the periods to use)."""
    where = {int(s): i for i, s in enumerate(rec.slot)}
    out = []
    for p in measured:
        idx = [where.get(p * length + n) for n in range(length)]
        if all(i is not None for i in idx):
            out.append(np.array(idx))
    return out


def spectra(rec: Recording, exc: Excitation, *, loop: str, sensor: str,
            measured: list[int], ratio: float, tacho_gain: float, sample_rate: float | None,
            f_max: float) -> Spectra:
    """The per-period spectra of the measured output (``twin.analysis.frequency.LOOPS``):
    the accelerometer's table acceleration (``mechanics``) or speed (``speed``, A/(jω)),
    the tacho's r·ω (``speed``; differenced over T for ``mechanics``), or the position
    loop's feedback −U_c against the DAC (``position``), on the excited lines up to
    ``f_max`` (Hz; with the accelerometer their images up to its Nyquist frequency too),
    of the periods numbered ``measured`` (each ``exc.length`` slots; the excitation of a
    period is the DAC's volts less the regulator's).

    Raises
    ------
    ValueError
        No complete period was recorded, or the accelerometer lost samples in every one.
    """
    n, period = exc.length, exc.period
    if sensor == "accelerometer" and loop != "position":
        return _accel_spectra(rec, exc, measured, loop, sample_rate, f_max)
    chunks = _periods(rec, n, measured)
    if not chunks:
        raise ValueError("no complete period of the excitation was recorded")
    lines = exc.lines[exc.lines * exc.resolution <= f_max + 1e-9]
    f = lines * exc.resolution
    w = 2.0 * math.pi * f
    exc_, dac, out = [], [], []
    for idx in chunks:
        u = np.fft.fft(rec.dac[idx])[lines] / n
        exc_.append(np.fft.fft(rec.dac[idx] - rec.regulator[idx])[lines] / n)
        if loop == "position":
            y = -np.fft.fft(rec.regulator[idx])[lines] / n
        else:
            y = np.fft.fft(rec.tacho[idx] * ratio / tacho_gain)[lines] / n
            if loop == "mechanics":
                y = y * (1.0 - np.exp(-1j * w * period)) / period
        dac.append(u)
        out.append(y)
    return Spectra(f, np.array(exc_), np.array(dac), np.array(out))


def _accel_spectra(rec: Recording, exc: Excitation, measured: list[int], loop: str,
                   sample_rate: float | None, f_max: float) -> Spectra:
    """The accelerometer's spectra against the DAC's held volts as they were applied:
    each tick's value from its tick to the next (its read's time on the lock-step twin; on
    real I/O its place on the sensor's clock, ``_tick_times``), so that a late or a lost
    tick enters the input as it happened."""
    if sample_rate is None or not len(rec.accel):
        raise ValueError("the accelerometer returned no samples")
    n, period = exc.length, exc.period
    m = round(n * period * sample_rate)
    ts = 1.0 / sample_rate
    first_seq = int(rec.accel_sequence[0])
    by_seq = np.full(int(rec.accel_sequence[-1]) - first_seq + 1, np.nan)
    by_seq[rec.accel_sequence - first_seq] = rec.accel
    bins = np.arange(1, m // 2)
    excited = np.zeros(n, dtype=bool)
    excited[exc.lines] = True
    excited[(n - exc.lines) % n] = True
    keep = excited[bins % n] & (bins / (n * period) <= f_max + 1e-9)
    hold = _hold(2.0 * math.pi * bins / (n * period), period)
    keep &= np.abs(hold) >= 0.2           # near the multiples of 1/T the input has no power
    bins = bins[keep]
    f = bins / (n * period)
    w = 2.0 * math.pi * f
    hold = hold[keep]
    average = _hold(w, ts)
    times, origin = _tick_times(rec, period, sample_rate)
    ends = np.append(times[1:], times[-1] + period)
    exc_, dac, out = [], [], []
    for p in measured:
        tau = origin + p * n * period
        i0 = math.floor(tau * sample_rate + 1e-6) + 1      # first sample after tau
        j = i0 - first_seq
        span = (ends > tau) & (times < tau + n * period)
        if j < 0 or j + m > len(by_seq) or not span.any() or times[span][0] > tau + 1e-9:
            continue
        a = by_seq[j:j + m]
        if not np.all(np.isfinite(a)):    # samples lost in this period
            continue
        lo = np.maximum(times[span], tau) - tau
        hi = np.minimum(ends[span], tau + n * period) - tau
        pieces = (np.exp(-1j * np.outer(w, lo)) - np.exp(-1j * np.outer(w, hi))) / (
            1j * w[:, None])
        u = pieces @ rec.dac[span] / (n * period)
        d = np.fft.fft(rec.excitation[p * n:(p + 1) * n])[bins % n] / n * hold
        y = np.fft.fft(a)[bins] / m * np.exp(-1j * w * (i0 * ts - tau)) / average
        if loop == "speed":
            y = y / (1j * w)
        exc_.append(d)
        dac.append(u)
        out.append(y)
    if not dac:
        raise ValueError("the accelerometer lost samples in every period")
    return Spectra(f, np.array(exc_), np.array(dac), np.array(out))


def _tick_times(rec: Recording, period: float, sample_rate: float
                ) -> tuple[np.ndarray, float]:
    """When each tick wrote the DAC, and where slot 0 lies, on the clock of the
    accelerometer's samples (s): the driver's time stamps on the lock-step twin (the plant's
    clock); on real I/O (a paced recording, whose time stamps are the host's) each tick
    where its read fell on the sensor's clock (``Inputs.accel_clock``), slot 0 where
    ``_sensor_clock`` puts it."""
    if rec.stats is None:
        return rec.time, float(rec.time[0] - rec.slot[0] * period)
    origin = _sensor_clock(rec, period, sample_rate)
    seen = rec.accel_clock / sample_rate
    return np.where(np.isfinite(seen), seen, origin + rec.slot * period), origin


def _sensor_clock(rec: Recording, period: float, sample_rate: float) -> float:
    """Where slot 0 lies on the accelerometer's clock (s), for a paced recording whose
    driver time stamps are another clock: the median over the ticks of their reads' time
    on the sensor's clock less slot·T (a late tick does not move it)."""
    ok = np.isfinite(rec.accel_clock)
    if not ok.any():
        raise ValueError("the accelerometer returned no samples")
    return float(np.median(rec.accel_clock[ok] / sample_rate - rec.slot[ok] * period))


def _crossing(f: np.ndarray, values: np.ndarray, level: float) -> float:
    """First frequency where ``values`` falls through ``level`` (log-f interpolation);
    nan if never."""
    below = np.nonzero((values[:-1] >= level) & (values[1:] < level))[0]
    if not len(below):
        return math.nan
    i = below[0]
    x = (level - values[i]) / (values[i + 1] - values[i])
    return float(np.exp(np.log(f[i]) + x * (np.log(f[i + 1]) - np.log(f[i]))))


def _at(f: np.ndarray, values: np.ndarray, where: float) -> float:
    return float(np.interp(np.log(where), np.log(f), values))


def margins(frequency: np.ndarray, loop: np.ndarray) -> Margins:
    """Gain and phase margin, crossover and closed-loop bandwidth of the position loop from
    its loop transfer function L at ``frequency`` (Hz, ascending; ``Margins``)."""
    f = np.asarray(frequency, dtype=float)
    el = np.asarray(loop, dtype=complex)
    gain = 20.0 * np.log10(np.abs(el))
    phase = np.degrees(np.unwrap(np.angle(el)))
    phase -= 360.0 * round(float(phase[0]) / 360.0 + 0.25)   # start in (−90° − 360°, −90°]
    crossover = _crossing(f, gain, 0.0)
    pm = 180.0 + _at(f, phase, crossover) if math.isfinite(crossover) else math.nan
    cross180 = _crossing(f, phase, -180.0)
    gm = -_at(f, gain, cross180) if math.isfinite(cross180) else math.inf
    closed = 20.0 * np.log10(np.abs(el / (1.0 + el)))
    bandwidth = _crossing(f, closed, float(closed[0]) - 3.0)
    return Margins(gain_margin=gm, phase_margin=pm, crossover=crossover, bandwidth=bandwidth)


def fit_mode(frequency: np.ndarray, response: np.ndarray, *, iterations: int = 8,
             weight: np.ndarray | None = None) -> complex | None:
    """The pole s (1/s, Im s > 0) of a second-order fit H ≈ (b₂s² + b₁s + b₀)/(s² + a₁s +
    a₀) to ``response`` at ``frequency`` (Hz), by Sanathanan-Koerner iterations of the
    linearised least squares (each line weighted by ``weight``, default 1); None when the
    fit has no oscillating pole."""
    f = np.asarray(frequency, dtype=float)
    h = np.asarray(response, dtype=complex)
    scale = 2.0 * math.pi * float(np.median(f))
    s = 2j * math.pi * f / scale
    trust = np.ones(len(f)) if weight is None else np.asarray(weight, dtype=float)
    weight = trust.copy()
    a1 = a0 = math.nan
    for _ in range(iterations):
        cols = np.stack([s**2, s, np.ones_like(s), -h * s, -h], axis=1) * weight[:, None]
        rhs = h * s**2 * weight
        a = np.concatenate([cols.real, cols.imag])
        b = np.concatenate([rhs.real, rhs.imag])
        x = np.linalg.lstsq(a, b, rcond=None)[0]
        a1, a0 = x[3], x[4]
        weight = trust / np.maximum(np.abs(s**2 + a1 * s + a0), 1e-12)
    roots = np.roots([1.0, a1, a0])
    roots = roots[roots.imag > 0]
    if not len(roots) or roots[0].real >= 0:
        return None
    return complex(roots[0] * scale)


def peaks(frequency: np.ndarray, ratio_db: np.ndarray, *, prominence: float = 1.0,
          noise: np.ndarray | None = None) -> list[int]:
    """Indices of the lines where the response over the rigid twin's (dB) has a peak at
    least ``prominence`` dB above its surroundings; with ``noise`` (each line's random
    error, dB) at least ``prominence`` plus three of its own line's."""
    found, props = find_peaks(np.asarray(ratio_db, dtype=float), prominence=prominence)
    if noise is not None:
        found = found[props["prominences"] >= prominence + 3.0 * np.asarray(noise)[found]]
    return [int(i) for i in found]
