"""Spectra (``twin.analysis.spectrum``) against Parseval and known sinusoids."""

from __future__ import annotations

import numpy as np
import pytest

from twin.analysis.spectrum import amplitude_density, peak


@pytest.mark.parametrize("seed", range(8))
def test_the_peak_is_the_sinusoid_and_parseval_holds(seed):
    rng = np.random.default_rng(seed)
    dt = float(rng.uniform(2.5e-4, 5e-3))
    t = np.arange(0.0, float(rng.uniform(4.0, 12.0)), dt)
    f0 = float(rng.uniform(3.0, 0.3 / dt))
    amp = rng.uniform(1e-6, 1e-4, 2)
    x = np.column_stack([a * np.sin(2 * np.pi * f0 * t + rng.uniform(0, 6)) for a in amp])
    x += rng.normal(scale=1e-7, size=x.shape)
    f, d = amplitude_density(t, x, segment=1.0)
    fp, _ = peak(f, d)
    assert abs(fp - f0) <= 1.0 + 1e-9                   # 1 s windows: 1 Hz bins
    # Parseval: the density's square integrates to the total variance of the columns
    total = float(np.sum(d**2) * (f[1] - f[0]))
    assert total == pytest.approx(float(np.sum(np.var(x, axis=0))), rel=0.08)


def test_short_records_and_no_band_are_quiet():
    f, d = amplitude_density(np.arange(4) * 1e-3, np.zeros(4))
    assert d.tolist() == [0.0]
    assert np.isnan(peak(f, d)[0])
