"""Scaled test programs and the machine randomiser."""

import math

import numpy as np
import pytest

from envs.programs import COMPACT_SCALE, PROGRAMS, scaled_program, tuning_program
from envs.randomize import RANGES, MachineRandomizer
from twin.config import load_machine
from twin.controller.geometry import Arc, Line
from twin.controller.library import build_program, program_path
from twin.controller.planner import MotionBlock
from twin.controller.spline_path import SplinePath
from twin.errors import ConfigError

START = (0.01, 0.01)


@pytest.fixture(scope="module")
def cfg():
    return load_machine("tomsk_xy")


def test_compact_is_the_default_program_scaled(cfg):
    full = program_path(build_program("default", cfg, START))
    small = program_path(tuning_program("compact", cfg, START))
    assert [type(s) for s in small] == [type(s) for s in full]
    for a, b in zip(full, small, strict=True):
        # lengths scale exactly (a natural spline through scaled points is the scaled one)
        assert b.length == pytest.approx(COMPACT_SCALE * a.length, rel=1e-9)
        np.testing.assert_allclose(b.start - START, COMPACT_SCALE * (a.start - START),
                                   atol=1e-15)
    assert small[0].start.tolist() == list(START)


@pytest.mark.parametrize("segment", [
    Line((0.0, 0.0), (0.02, 0.01)),
    Arc((0.02, 0.0), (0.0, 0.02), (0.0, 0.0), ccw=True),
    SplinePath([(0.0, 0.0), (0.01, 0.004), (0.02, 0.0), (0.03, 0.01)]),
])
def test_scaled_segments_keep_their_shape(segment):
    factor, origin = 0.3, np.array([0.005, -0.002])
    (scaled,) = program_path(scaled_program([MotionBlock(segment, 0.01)], origin, factor))
    assert scaled.length == pytest.approx(factor * segment.length, rel=1e-9)
    for s in np.linspace(0.0, 1.0, 7):
        p = segment.point(s * segment.length)
        q = scaled.point(s * scaled.length)
        np.testing.assert_allclose(q, origin + factor * (p - origin), atol=1e-12)


def test_program_names(cfg):
    assert {"compact", "tiny", "default"} <= set(PROGRAMS)
    with pytest.raises(ConfigError, match="unknown tuning program"):
        tuning_program("nope", cfg, START)
    with pytest.raises(ConfigError, match="factor"):
        scaled_program([], START, 0.0)


def test_randomiser_is_seeded_and_within_ranges(cfg):
    r = MachineRandomizer(cfg)
    a = r.overrides(np.random.default_rng(7))
    b = r.overrides(np.random.default_rng(7))
    c = r.overrides(np.random.default_rng(8))
    assert a == b
    assert a != c
    for key, value in a.items():
        _, axis, *rest = key.split(".")
        path = ".".join(rest[:2])
        low, high = RANGES[path]
        nominal = cfg.axes[axis]
        for part in rest:
            nominal = getattr(nominal, part) if not isinstance(nominal, dict) else \
                nominal[part]
        factor = value / nominal
        upper = high if path != "transmission.damping_ratio" else min(high, 2.0 / nominal)
        assert low * (1 - 1e-12) <= factor <= upper * (1 + 1e-12), key
    machine = r.sample(np.random.default_rng(7))
    assert machine.axes["x"].mechanics.carriage_mass == pytest.approx(
        a["axes.x.mechanics.carriage_mass"])
    assert machine.name.endswith("~random")


def test_factors_are_log_uniform(cfg):
    r = MachineRandomizer(cfg, ranges={"mechanics.carriage_mass": (0.5, 2.0)})
    rng = np.random.default_rng(0)
    logs = [math.log(r.overrides(rng)["axes.y.mechanics.carriage_mass"] / 40.0)
            for _ in range(2000)]
    # log-uniform on [ln 0.5, ln 2]: mean 0, std (2 ln 2)/sqrt(12)
    assert abs(np.mean(logs)) < 0.03
    assert np.std(logs) == pytest.approx(2 * math.log(2) / math.sqrt(12), rel=0.05)


@pytest.mark.parametrize("ranges, field", [
    ({"mechanics.carriage_mass": (2.0, 1.0)}, "ranges.mechanics.carriage_mass"),
    ({"mechanics.carriage_mass": (0.0, 1.0)}, "ranges.mechanics.carriage_mass"),
    ({"mechanics.carriage_mass": "x"}, "ranges.mechanics.carriage_mass"),
])
def test_bad_ranges(cfg, ranges, field):
    with pytest.raises(ConfigError) as info:
        MachineRandomizer(cfg, ranges=ranges)
    assert info.value.field == field
