"""Welch's estimate streamed in pieces (``twin.telemetry.spectra.WelchDensity``) against
``scipy.signal.welch`` of the whole record, on many random records: random sampling
intervals, lengths (shorter and longer than a window), widths and ways of cutting them."""

from __future__ import annotations

import itertools
import os

import numpy as np
import pytest
from scipy.signal import welch

from twin.telemetry.spectra import MIN_SAMPLES, WelchDensity, level_db

CI = os.environ.get("CI") == "true"


def _pieces(rng: np.random.Generator, n: int) -> list[slice]:
    """``range(n)`` cut at random places (empty pieces and single samples included)."""
    cuts = np.sort(rng.integers(0, n + 1, int(rng.integers(0, 12))))
    edges = [0, *cuts.tolist(), n]
    return [slice(a, b) for a, b in itertools.pairwise(edges)]


@pytest.mark.parametrize("seed", range(40 if CI else 300))
def test_streamed_welch_is_scipy_welch_of_the_whole_record(seed):
    rng = np.random.default_rng(seed)
    dt = float(rng.choice([1e-3, 2.5e-4, 3.5e-3, 5e-3, rng.uniform(1e-4, 1e-2)]))
    segment = float(rng.choice([1.0, rng.uniform(0.02, 2.0)]))
    width = int(rng.integers(1, 4))
    length = max(MIN_SAMPLES, round(segment / dt))
    n = int(rng.integers(MIN_SAMPLES, 6 * length + 2))
    x = rng.normal(rng.normal(0, 5, width), 10.0 ** rng.uniform(-7, 0), (n, width))
    x += np.sin(2 * np.pi * rng.uniform(0, 0.5 / dt) * dt * np.arange(n))[:, None]
    est = WelchDensity(dt, width=width, segment=segment)
    for part in _pieces(rng, n):
        est.feed(x[part])
    f, power = est.density()
    m = min(n, length)                   # scipy: a record shorter than a window is one
    f_ref, p_ref = welch(x, fs=1.0 / dt, window="hann", nperseg=m, noverlap=m // 2,
                         nfft=length, detrend="constant", axis=0)
    np.testing.assert_allclose(f, f_ref, rtol=1e-12)
    np.testing.assert_allclose(power, p_ref, rtol=1e-9, atol=1e-12 * p_ref.max())
    assert est.segments == ((n - length) // (length - length // 2) + 1 if n >= length else 0)
    assert len(est._held) < length       # memory: less than one window of samples held


def test_too_few_samples_give_no_spectrum_and_bad_intervals_are_refused():
    est = WelchDensity(1e-3, width=2)
    est.feed(np.ones((MIN_SAMPLES - 1, 2)))
    assert est.density() is None
    est.feed(np.ones((1, 2)))
    assert est.density() is not None
    for dt in (0.0, -1e-3, float("nan")):
        with pytest.raises(ValueError, match="dt"):
            WelchDensity(dt)


def test_level_is_the_amplitude_density_in_db_re_one_micrometre():
    rng = np.random.default_rng(3)
    asd = 10.0 ** rng.uniform(-12, -2, 50)                  # m/√Hz
    np.testing.assert_allclose(level_db(asd**2), 20.0 * np.log10(asd / 1e-6), rtol=1e-12)
    assert level_db(np.array([1e-12]))[0] == pytest.approx(0.0)   # 1 µm/√Hz
    assert np.isnan(level_db(np.array([0.0]))[0])
