"""Spectra of a run's signals: the following error and the screw deflection, as drive
engineers read them (an amplitude spectral density in µm/√Hz against frequency).

``amplitude_density`` is Welch's estimate (Hann windows of ``segment`` seconds, half
overlapping, the mean removed), the one a run records (``twin.telemetry.spectra.
WelchDensity``): ``√PSD`` of each column, summed over the columns in power
(``√(PSD_x + PSD_y)``), so that its square integrates to the signals' total variance
(Parseval). ``peak`` names the frequency where it is largest above a lower bound (the
slow part of a move is not a resonance).
"""

from __future__ import annotations

import numpy as np

from twin.telemetry.spectra import MIN_SAMPLES, WelchDensity

__all__ = ["amplitude_density", "peak"]


def amplitude_density(t, values, *, segment: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Welch amplitude spectral density of ``values`` (n,) or (n, k) sampled at ``t`` (s,
    equally spaced).

    Parameters
    ----------
    segment : float
        Window length (s); a record shorter than it is one window, zero-padded to it.

    Returns
    -------
    frequency : ndarray
        (Hz), from 0 to the Nyquist rate.
    density : ndarray
        (unit of ``values`` per √Hz), the columns summed in power.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(values, dtype=float).reshape(t.size, -1)
    if t.size < MIN_SAMPLES:
        return np.zeros(1), np.zeros(1)
    estimate = WelchDensity(float(np.median(np.diff(t))), width=x.shape[1], segment=segment)
    estimate.feed(x)
    f, p = estimate.density()
    return f, np.sqrt(np.sum(p, axis=1))


def peak(frequency, density, *, above: float = 1.0) -> tuple[float, float]:
    """(frequency (Hz), density) of the largest ``density`` above ``above`` Hz; (nan, 0)
    when there is none."""
    f, d = np.asarray(frequency), np.asarray(density)
    keep = f > above
    if not keep.any():
        return float("nan"), 0.0
    i = int(np.argmax(np.where(keep, d, -np.inf)))
    return float(f[i]), float(d[i])
