"""Unseen machines for the ``twin identify`` tests: BASE (tomsk_xy) with its physical
parameters drawn at random (``twin.identify.perturb``), the check of what was identified
against the machine's own file, and the sim-to-real table."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from twin.config import load_machine
from twin.config.writer import machine_to_toml
from twin.identify.perturb import perturbed_machine, true_params
from twin.identify.replay import axis_figures
from twin.session.run import RunSpec, run

CI = os.environ.get("CI") == "true"
BASE = "tomsk_xy"


def unseen(seed: int, where: Path, *, drive: str | None = None):
    """An unseen machine (``drive``: a hand-set drive, ``perturb.DRIVES``) and its file."""
    cfg = perturbed_machine(load_machine(BASE), np.random.default_rng(seed),
                            name=f"unseen_{seed}", drive=drive)
    path = where / f"unseen_{seed}.toml"
    path.write_text(machine_to_toml(cfg), encoding="utf-8")
    return cfg, path


def twin_cli(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True,
                          text=True, timeout=timeout,
                          env={**os.environ, "RERUN_ANALYTICS": "0"})


def assert_identified(result: dict, true) -> None:
    """A value called identified is right: K_H within 1 %, the rotor inertia and the speed
    regulator's gain and integral time within 10 %, the Coulomb friction at the motor
    within 20 %, the lost motion within 2 µm; a value not identified is flagged (BASE's
    kept, or identified only given one held). The regressions' values (K_H, tacho gain) are
    always identified; the truth lies inside ≥ 90 % of the intervals
    (``assert_covered``); where the fitted twin does not replay the machine (held-out NRMSE
    above ``fit.QUALITY``) or an axis of it (a systematic residual above ``fit.MISFIT``),
    nothing it replays is called identified there: a confident wrong value is the failure,
    an honest "not identified" is not; a decided model of the current regulator is the
    machine's."""
    from twin.identify.fit import MISFIT, QUALITY, REPLAYED_PARAMS

    truth, own = axis_figures(true), true_params(load_machine(BASE), true)
    for a in result["axes"]:   # an axis held (``--axes``) keeps BASE's values
        d, e, t = result["derived"][a], result["estimates"][a], truth[a]
        where = f"axis {a} of {true.name}"
        assert d["K_H"] == pytest.approx(t["K_H"], rel=0.01), where
        for name in ("tacho_gain", "gain_error"):
            assert e[name]["identifiable"], (where, name)
        if e["backlash"]["identifiable"]:   # its preload is uncertain with the friction
            assert abs(e["backlash"]["value"] - t["backlash"]) <= 2e-6, where
        checks = {"inertia": (e["inertia"]["value"], t["inertia"], 0.10),
                  "coulomb": (d["coulomb_at_motor"], t["coulomb_at_motor"], 0.20),
                  "speed_kp": (e["speed_kp"]["value"], own[a].speed_kp, 0.10),
                  "speed_ti": (e["speed_ti"]["value"], own[a].speed_ti, 0.10)}
        for name, (got, want, rel) in checks.items():
            if e[name]["identifiable"]:
                assert got == pytest.approx(want, rel=rel), (where, name)
            else:
                assert e[name]["kept"] in ("base", "bound") or e[name]["given"], \
                    (where, name)
        dcm = result["dcm_compensation"][a]
        if dcm["decided"]:
            assert dcm["present"] == bool(own[a].dcm_compensation), where
    assert_covered(result, true)
    worst = max(max(v.values()) for v in result["nrmse"].values())
    for a in result["axes"]:
        if worst > QUALITY or result["misfit"][a] > MISFIT:
            called = [n for n in REPLAYED_PARAMS
                      if result["estimates"][a][n]["identifiable"]]
            assert not called, (f"axis {a} of {true.name}", worst, result["misfit"][a], called)


COVERED = ("tacho_gain", "gain_error", "offset", "inertia", "coulomb", "viscous",
           "breakaway", "backlash", "resistance", "inductance", "speed_kp", "speed_ti",
           "reference_filter")


def assert_covered(result: dict, true, share: float = 0.9) -> None:
    """The truth lies inside the reported 95 % interval of at least ``share`` of the
    identified fields; the others are declared not identifiable (a field declared is never
    a confident wrong value)."""
    own = true_params(load_machine(BASE), true)
    marks = []
    for a in result["axes"]:
        for name in COVERED:
            e = result["estimates"][a][name]
            if not e["identifiable"]:
                continue
            t = getattr(own[a], name)
            lo = -np.inf if e["low"] is None else e["low"]
            hi = np.inf if e["high"] is None else e["high"]
            marks.append((f"{a}.{name}", bool(lo - 1e-12 * abs(t) <= t <= hi + 1e-12 * abs(t)),
                          t, e["value"], lo, hi))
    inside = sum(m[1] for m in marks)
    assert inside >= share * len(marks), [m for m in marks if not m[1]]


def _max_coordinate_error(machine: Path, model: str, builtin: str, out: Path) -> float:
    spec = RunSpec(machine=str(machine), controller_model=model, builtin=builtin, dcu_order=3)
    summary = run(spec, out_dir=out, rerun="none").summary
    assert summary["status"] == "FINISHED"
    return max(summary["max_coordinate_error_um"].values())


def sim_to_real(true_path: Path, calibrated: Path, out: Path) -> dict[str, dict[str, float]]:
    """Max coordinate error (µm) of the machine run with the calibrated model, its own file
    (the oracle) and the nominal BASE as the controller's model: on the Table-2 move and
    the default program (in CI the Table-2 move alone)."""
    table = {}
    for builtin in ("spline_line",) if CI else ("spline_line", "default"):
        table[builtin] = {name: _max_coordinate_error(true_path, model, builtin, out)
                          for name, model in (("calibrated", str(calibrated)),
                                              ("oracle", str(true_path)), ("nominal", BASE))}
    return table
