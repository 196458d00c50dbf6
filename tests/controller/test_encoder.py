"""Encoder counter unwrapping and counts ↔ metres, against brute-force references."""

import random

import numpy as np
import pytest

from twin.config import load_machine
from twin.controller.encoder import (
    EncoderUnwrapper,
    counts_to_metres,
    metres_to_counts,
    unwrap_delta,
)
from twin.errors import ConfigError


@pytest.mark.parametrize("bits", [8, 12, 16, 32, 64])
def test_unwrap_delta_recovers_every_delta_within_half_range(bits):
    rng = random.Random(bits)
    modulus, half = 1 << bits, 1 << (bits - 1)
    for _ in range(2000):
        last = rng.randrange(modulus)
        delta = rng.randrange(-half, half)
        raw = (last + delta) % modulus
        assert unwrap_delta(raw, last, bits) == delta


@pytest.mark.parametrize(("raw", "last", "bits", "expected"), [
    (0, 255, 8, 1),              # wrap upward
    (255, 0, 8, -1),             # wrap downward
    (128, 0, 8, -128),           # exactly half range: the negative side
    (127, 0, 8, 127),
    (0, 2**32 - 5, 32, 5),
    (2**32 - 3, 2, 32, -5),
])
def test_unwrap_delta_edge_cases(raw, last, bits, expected):
    assert unwrap_delta(raw, last, bits) == expected


def test_unwrapper_follows_a_trajectory_through_many_wraps():
    # 8-bit counters wrap every 256 counts; the true count walks far beyond that.
    cpm = (1000.0, 250.0)
    enc = EncoderUnwrapper(cpm, bits=8)
    rng = np.random.default_rng(1)
    true = np.cumsum(rng.integers(-100, 101, size=(5000, 2)), axis=0) + 17
    enc.reset(true[0] % 256, position=(true[0, 0] / cpm[0], true[0, 1] / cpm[1]))
    for counts in true[1:]:
        pos = enc.update(counts % 256)
        np.testing.assert_allclose(pos, counts / np.array(cpm), rtol=0, atol=1e-12)
    assert enc.counts == tuple(int(c) for c in true[-1] - true[0])


def test_first_update_without_reset_is_the_zero():
    enc = EncoderUnwrapper((5e6, 5e6))
    assert not enc.ready
    np.testing.assert_array_equal(enc.update([123, 2**32 - 1]), [0.0, 0.0])
    np.testing.assert_allclose(enc.update([128, 4]), [5 / 5e6, 5 / 5e6], rtol=1e-15)


def test_rebase_shifts_every_later_position():
    enc = EncoderUnwrapper((1e6, 1e6))
    enc.reset([0, 0], position=(0.5, 0.25))
    enc.rebase((0.01, -0.02))
    np.testing.assert_allclose(enc.update([1000, 0]), [0.511, 0.23], rtol=1e-14)


def test_tomsk_rig_resolution_is_five_counts_per_micrometre():
    cfg = load_machine("tomsk_xy")
    cpm = cfg.axes["x"].counts_per_metre
    assert cpm == pytest.approx(5e6, rel=1e-12)
    np.testing.assert_array_equal(metres_to_counts([1e-6, -2e-6, 0.2], cpm), [5, -10, 1_000_000])
    np.testing.assert_allclose(counts_to_metres(np.array([5, 1_000_000]), cpm), [1e-6, 0.2],
                               rtol=1e-12)


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"counts_per_metre": (0.0, 1.0)}, "counts_per_metre"),
    ({"counts_per_metre": (float("nan"), 1.0)}, "counts_per_metre"),
    ({"counts_per_metre": (1.0, 1.0), "bits": 4}, "bits"),
    ({"counts_per_metre": (1.0, 1.0), "bits": (32,)}, "bits"),
])
def test_invalid_configuration_names_the_field(kwargs, field):
    with pytest.raises(ConfigError) as err:
        EncoderUnwrapper(**kwargs)
    assert err.value.field == field
