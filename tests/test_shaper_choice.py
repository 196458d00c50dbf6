"""``twin.analysis.shaper``: the table's vibration columns against a brute-force grid, the
recommendation rule, the override file read back by the machine loader, and one cheap
closed-loop evaluation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.analysis.shaper import (
    ROBUST,
    Mode,
    ShaperRow,
    evaluate,
    model_modes,
    recommend,
    vibration,
    write_override,
)
from twin.config import load_machine
from twin.config.overrides import set_file_overrides
from twin.controller.controller import Controller
from twin.controller.shaping import SHAPERS, design
from twin.session.run import RunSpec


@pytest.mark.parametrize("seed", range(6))
def test_vibration_columns_are_the_worst_of_the_bands(seed):
    rng = np.random.default_rng(seed)
    mode = Mode("x", float(rng.uniform(5, 80)), float(rng.uniform(0.01, 0.5)), "test")
    name = str(rng.choice(SHAPERS))
    fs, zs = float(rng.uniform(0.05, 0.3)), float(rng.uniform(0.1, 0.6))
    v = vibration(name, mode, fs, zs)
    s = design(name, mode.frequency, mode.damping)
    # brute force: single evaluations on a finer grid, inside the bands
    f = mode.frequency * np.linspace(1 - fs, 1 + fs, 321)
    z = np.clip(mode.damping * np.linspace(1 - zs, 1 + zs, 41), 0, 0.95)
    brute = max(s.residual(fi, zi) for fi in f[::8] for zi in z)
    assert v["worst"] >= brute - 1e-12 and v["worst"] >= v["worst_frequency"] - 1e-12
    assert v["worst_frequency"] == pytest.approx(max(s.residual(f)), rel=0.02, abs=1e-4)
    assert v["at_mode"] == pytest.approx(s.residual(mode.frequency))


def _row(name, worst, acc, added):
    r = ShaperRow(name, {"at_mode": 0.0, "worst_frequency": worst, "worst_damping": worst,
                         "worst": worst}, 0.05, 0.01)
    r.max_acceleration, r.added_corner_error = acc, added
    return r


def test_recommend_prefers_robust_then_acceleration_then_less_added_error():
    rows = [_row("none", 1.0, 0.8, 0.0), _row("zv", 0.3, 0.8, 1e-6),
            _row("zvd", ROBUST / 2, 0.4, 5e-6), _row("ei", ROBUST / 2, 0.4, 3e-6),
            _row("2hump-ei", ROBUST / 3, 0.2, 1e-6)]
    assert recommend(rows).name == "ei"
    assert recommend([rows[0], rows[1]]).name == "zv"            # none robust: all count


def test_the_override_file_loads_into_the_machine(tmp_path):
    cfg = load_machine("laser_belt")
    modes = [Mode("x", 14.5, 0.31, "test"), Mode("y", 17.25, 0.2, "test")]
    path = write_override(tmp_path / "s.toml", _row("mzv", 0.05, 0.5, 0.0), modes, cfg,
                          ["header"])
    loaded = cfg.with_overrides(set_file_overrides(path))
    shaper = Controller.from_machine(loaded, None).shaper
    assert shaper is not None
    for s, m in zip(shaper.shapers, modes, strict=True):
        assert (s.name, s.frequency, s.damping) == ("mzv", m.frequency, m.damping)
    assert loaded.controller.limits.max_acceleration == cfg.controller.limits.max_acceleration


def test_one_closed_loop_evaluation():
    spec = RunSpec(machine="laser_belt")
    modes = model_modes(spec.machine_config())
    none, zvd = evaluate(spec, modes, ("zvd",), steps=0, side=0.01, radius=0.004)
    assert none.vibration["worst"] == 1.0 and zvd.vibration["at_mode"] < 1e-12
    assert zvd.duration == pytest.approx(design("zvd", modes[0].frequency,
                                                modes[0].damping).duration)
    assert zvd.added_corner_error == pytest.approx(zvd.corner_error - none.corner_error)
    # the shaper cancels the belt mode: far less free vibration after each move
    assert zvd.residual_vibration < 0.3 * none.residual_vibration
    assert math.isfinite(zvd.circle_error) and zvd.runs[0]["status"] == "FINISHED"
