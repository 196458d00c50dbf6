"""The test signals: a periodic multisine with Schroeder phases, or a periodic PRBS, one
value per controller period, normalised to a peak of 1.

Both repeat every ``N`` periods, so every period of the record has the same spectrum and
the lines fall on the bins of a period's DFT (no leakage, no window); ``N`` is chosen so
that a period spans a whole number of accelerometer samples as well. The multisine puts
equal power on every bin from ``f_min`` to ``f_max``; Schroeder's phases
φ_k = −π·k·(k − 1)/K keep its crest factor near 1.7 instead of √(2K); random phases make
realisations whose nonlinear distortions differ (the measurement averages several, so that
distortions lower the coherence instead of biasing the response unseen). The PRBS is a
maximal-length sequence held ``hold`` periods per bit: its power falls off as sinc² towards
1/(hold·T).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.errors import ConfigError

__all__ = ["Excitation", "mls", "multisine", "period_length", "prbs"]

_TAPS = {5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5), 10: (10, 7),
         11: (11, 9), 12: (12, 11, 10, 4)}
"""Feedback taps of maximal-length Fibonacci LFSRs (bits → taps)."""


@dataclass(frozen=True)
class Excitation:
    """One period of a test signal.

    Attributes
    ----------
    kind : str
        ``"multisine"`` or ``"prbs"``.
    values : ndarray, shape (N,)
        The signal at each controller period, peak |value| = 1.
    period : float
        The controller period T (s).
    lines : ndarray of int
        The bins (multiples of 1/(N·T)) that carry the signal's power below the Nyquist
        frequency.
    """

    kind: str
    values: np.ndarray
    period: float
    lines: np.ndarray

    @property
    def length(self) -> int:
        """N, the periods of the controller in one period of the signal."""
        return len(self.values)

    @property
    def resolution(self) -> float:
        """Line spacing 1/(N·T) (Hz)."""
        return 1.0 / (self.length * self.period)


def period_length(minimum: int, period: float, sample_rate: float | None) -> int:
    """The smallest N ≥ ``minimum`` for which N controller periods hold a whole number of
    accelerometer samples (N·T·f_s an integer to 1e-6), or ``minimum`` without one.

    Raises
    ------
    ConfigError
        ``accelerometer.sample_rate``: no N up to 64·minimum fits.
    """
    if sample_rate is None:
        return minimum
    for n in range(minimum, 64 * minimum + 1):
        samples = n * period * sample_rate
        if abs(samples - round(samples)) < 1e-6:
            return n
    raise ConfigError("accelerometer.sample_rate", f"{sample_rate:g} Hz and the controller "
                      f"period {period * 1e3:g} ms have no common multiple of a test period "
                      "near the one asked for")


def multisine(length: int, period: float, f_min: float, f_max: float, *,
              seed: int | None = None) -> Excitation:
    """A multisine over the bins of an N = ``length`` period from the one at or below
    ``f_min`` to ``f_max`` (Hz):
    Schroeder's phases, or with ``seed`` random phases (uniform, of that seed's stream): a
    new realisation whose nonlinear distortions differ from another's, so that they show
    as noise in the coherence over several realisations."""
    df = 1.0 / (length * period)
    first = max(1, math.floor(f_min / df + 1e-9))
    last = min(length // 2 - (1 if length % 2 == 0 else 0), math.floor(f_max / df + 1e-9))
    if last < first:
        raise ConfigError("f_min", f"no line of the {df:.3g} Hz grid lies in [{f_min:g}, "
                          f"{f_max:g}] Hz")
    lines = np.arange(first, last + 1)
    count = len(lines)
    phases = (-math.pi * np.arange(count) * np.arange(1, count + 1) / count if seed is None
              else np.random.default_rng([seed, 0x5105]).uniform(0.0, 2.0 * math.pi, count))
    spectrum = np.zeros(length // 2 + 1, dtype=complex)
    spectrum[lines] = np.exp(1j * phases)
    values = np.fft.irfft(spectrum, n=length)          # Σ cos(2πkn/N + φ_k), scaled
    return Excitation("multisine", values / np.abs(values).max(), period, lines)


def mls(bits: int) -> np.ndarray:
    """A maximal-length sequence of 2^bits − 1 values ±1 (Fibonacci LFSR, ``_TAPS``)."""
    if bits not in _TAPS:
        raise ConfigError("bits", f"must be one of {sorted(_TAPS)}, got {bits}")
    taps = _TAPS[bits]
    state = 1
    out = np.empty((1 << bits) - 1)
    for i in range(len(out)):
        out[i] = 1.0 if state & 1 else -1.0
        feedback = 0
        for t in taps:
            feedback ^= (state >> (t - 1)) & 1
        state = ((state << 1) | feedback) & ((1 << bits) - 1)
    return out


def prbs(minimum: int, period: float, f_min: float, f_max: float) -> Excitation:
    """A periodic PRBS whose period is at least ``minimum`` controller periods and
    1/f_min, with bits held so that its power stays within 3 dB up to ``f_max`` (Hz)
    (sinc²(f·hold·T) ≥ 1/2: hold ≤ 0.44/(f_max·T))."""
    hold = max(1, math.floor(0.443 / (f_max * period)))
    need = max(minimum, math.ceil(1.0 / (f_min * period)))
    bits = next((b for b in sorted(_TAPS) if ((1 << b) - 1) * hold >= need), max(_TAPS))
    values = np.repeat(mls(bits), hold)
    length = len(values)
    df = 1.0 / (length * period)
    lines = np.arange(max(1, math.floor(f_min / df + 1e-9)),
                      min((length - 1) // 2, math.floor(f_max / df + 1e-9)) + 1)
    lines = lines[lines % ((1 << bits) - 1) != 0] if hold > 1 else lines
    return Excitation("prbs", values, period, lines)
