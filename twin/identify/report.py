"""What ``twin identify`` writes: the calibrated machine file, the report and the record.

- ``calibrated_toml``: BASE with the identified fields replaced, as a complete machine file
  whose header lists each identified value with its 95 % confidence interval and the
  experiment it came from, and the fields kept from BASE because the signals cannot give
  them (``fit.NOT_IDENTIFIABLE``).
- ``plot_report``: a PNG, one row per replayed experiment, measured and fitted position and
  tacho volts of both axes overlaid.
- ``record``: the experiments as a rerun recording (``.rrd``): the DAC volts written, the
  positions and tacho volts read, and the fitted twin's where the fit ran.
- ``summary``: the figures as a JSON-ready dict.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig
from twin.config.writer import machine_to_toml
from twin.identify.fit import (
    NOT_EXCITED,
    NOT_IDENTIFIABLE,
    UNSEEN_CURRENT_LOOP,
    Estimate,
    Identification,
)
from twin.identify.log import IdentLog
from twin.identify.plan import HELD_OUT, REPLAYED

__all__ = ["FIELDS", "calibrated_toml", "not_identified", "plot_report", "record", "summary"]

FIELDS = {
    "tacho_gain": ("tacho.gain", "V·s/rad", 1.0),
    "gain_error": ("dac.gain_error", "1", 1.0),
    "offset": ("dac.offset", "V", 1.0),
    "inertia": ("mechanics.rotor_inertia", "kg·m²", 1.0),
    "coulomb": ("mechanics.rotor_coulomb, slide_coulomb", "× BASE", 1.0),
    "viscous": ("mechanics.rotor_viscous, slide_viscous", "× BASE", 1.0),
    "breakaway": ("mechanics.rotor_breakaway, slide_breakaway", "× Coulomb", 1.0),
    "backlash": ("transmission.backlash", "µm", 1e6),
    "resistance": ("motor.armature_resistance", "Ω", 1.0),
    "inductance": ("motor.armature_inductance", "mH", 1e3),
    "speed_kp": ("regulators.speed_kp", "A/V", 1.0),
    "speed_ti": ("regulators.speed_ti", "ms", 1e3),
    "reference_filter": ("speed_loop.reference_filter", "ms", 1e3),
    "current_kp": ("regulators.current_kp", "V/A", 1.0),
    "current_ti": ("regulators.current_ti", "ms", 1e3),
    "brush_drop": ("motor.brush_drop", "V", 1.0),
}
"""Per fitted parameter: the machine-file field(s) it sets, the unit it is quoted in and the
factor from SI to that unit."""


def _quote(e: Estimate, scale: float) -> str:
    lo = "?" if not math.isfinite(e.low) else f"{scale * e.low:.5g}"
    hi = "?" if not math.isfinite(e.high) else f"{scale * e.high:.5g}"
    return f"{scale * e.value:.5g}  [{lo}, {hi}]"


def not_identified(e: Estimate) -> str:
    """Why a value is not identified, and what was kept (one line)."""
    if e.source == UNSEEN_CURRENT_LOOP:
        return "not fitted"
    if e.source == NOT_EXCITED or "does not replay" in e.source:
        return e.source
    if e.given:
        return (f"NOT SEPARABLE from {', '.join(e.given)}: identified given "
                f"{'its' if len(e.given) == 1 else 'their'} held value, right only "
                f"relative to it")
    if e.kept == "bound":
        return ("NOT IDENTIFIABLE from these experiments: the data reject BASE's value, "
                "the nearest one they allow kept")
    if e.kept == "base":
        return "NOT IDENTIFIABLE from these experiments: BASE's value kept"
    return "NOT IDENTIFIABLE"


def header_lines(result: Identification, base: MachineConfig, log: IdentLog,
                 log_path: str) -> list[str]:
    """The comment header of the calibrated file."""
    lines = [f"{base.name}, calibrated by `twin identify` from the experiments in {log_path}",
             f"(run on {log.driver or 'an unnamed driver'}; {log.ticks} ticks, "
             f"{log.ticks * base.controller.period:.1f} s of machine time).",
             "BASE with the identified fields replaced; every other field is BASE's.",
             "",
             "Identified (value  [95 % confidence interval]  unit  <- experiment):"]
    derived = result.derived()
    for a in AXES:
        if a not in log.axes:
            lines.append(f"axis {a}: not excited (held in position; --axes "
                         f"{''.join(log.axes)}): every value is BASE's.")
            continue
        lines.append(f"axis {a}:")
        for name, (where, unit, scale) in FIELDS.items():
            e = result.estimates[a][name]
            mark = "" if e.identifiable else "   WARNING: " + not_identified(e)
            lines.append(f"  {where} = {_quote(e, scale)} {unit}  <- {e.source}{mark}")
        if a in result.dcm:
            d = result.dcm[a]
            lines.append(f"  regulators.implementation, converter.dcm_compensation = {d.model}"
                         f"  <- steps, prbs (model selection, BIC over the best: "
                         + d.bic_text() + (")" if d.decided else "; UNDECIDED, BASE's model kept)"))
        d = derived[a]
        lines.append(f"  => K_H {1e3 * d['K_H']:.5g} mm/(s·V), Coulomb at the motor "
                     f"{d['coulomb_at_motor']:.4g} N·m, viscous at the motor "
                     f"{d['viscous_at_motor']:.4g} N·m·s/rad")
    lines.append("Not identifiable from encoder + tacho + DAC (kept from BASE):")
    lines.extend(f"  {k}: {why}" for k, why in NOT_IDENTIFIABLE.items())
    lines.append("Fit quality: held-out " + HELD_OUT + " normalised RMS error " + ", ".join(
        f"{a} position {100 * result.nrmse[a]['position']:.2f} % tacho "
        f"{100 * result.nrmse[a]['tacho']:.2f} %" for a in result.nrmse) + ".")
    lines.append("Intervals: the profile likelihood of the recorded data (each parameter "
                 "moved, the others re-fitted, replayed; F threshold on the residuals' "
                 "effective sample size); '?' is an end the data do not bound. A model "
                 "error of the twin itself is not in them.")
    return lines


def calibrated_toml(result: Identification, base: MachineConfig, log: IdentLog,
                    log_path: str) -> str:
    """The text of the calibrated machine file."""
    cfg = dataclasses.replace(result.calibrated, name=f"{base.name}_calibrated",
                              description=f"{base.description} Calibrated by twin identify "
                                          f"from {log_path}.".strip())
    return machine_to_toml(cfg, header=header_lines(result, base, log, log_path))


def summary(result: Identification, base: MachineConfig, log: IdentLog) -> dict[str, Any]:
    """The figures of an identification, JSON-ready (SI)."""
    return {
        "machine": base.name,
        "driver": log.driver,
        "axes": list(log.axes),
        "estimates": {a: {k: {"value": e.value, "low": e.low, "high": e.high,
                              "identifiable": e.identifiable, "source": e.source,
                              "kept": e.kept, "given": list(e.given)}
                          for k, e in result.estimates[a].items()} for a in AXES},
        "derived": result.derived(),
        "dcm_compensation": {a: {"present": d.present, "model": d.model, "bic": d.bic,
                                 "screened": list(d.screened),
                                 "decided": d.decided} for a, d in result.dcm.items()},
        "nrmse": result.nrmse,
        "residual": result.residual,
        "misfit": result.misfit,
        "mains_phase_rad": result.mains_phase,
        "not_identifiable": dict(NOT_IDENTIFIABLE),
        "machine_time_s": log.ticks * base.controller.period,
        "experiments_wall_time_s": log.notes.get("wall_time_s"),
        "fit_wall_time_s": result.wall_time,
        "fit_cpu_time_s": result.cpu_time,
        "replays": result.replays,
    }


def plot_report(result: Identification, log: IdentLog, path: str | Path) -> Path:
    """The PNG: per replayed experiment, measured and fitted positions (relative to the
    experiment's start, mm) and tacho volts of both axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = result.curves
    n = len(c["t"])
    fig, axes = plt.subplots(len(REPLAYED), 4, figsize=(16, 2.6 * len(REPLAYED)),
                             squeeze=False)
    for row, name in enumerate(REPLAYED):
        mask = log.experiment_mask(name)[:n]
        idx = np.flatnonzero(mask)
        if len(idx) == 0:
            continue
        t = c["t"][idx] - c["t"][idx[0]]
        for k, a in enumerate(AXES):
            ax = axes[row][k]
            meas = 1e3 * (c["pos_meas"][idx, k] - c["pos_meas"][idx[0], k])
            fit = 1e3 * (c["pos_fit"][idx, k] - c["pos_fit"][idx[0], k])
            ax.plot(t, meas, color="0.2", lw=1.4, label="measured")
            ax.plot(t, fit, color="tab:orange", lw=0.9, ls="--", label="fitted twin")
            ax.set_title(f"{name}: position {a}" + (" (held out)" if name == HELD_OUT
                                                     else ""), fontsize=9)
            ax.set_ylabel("mm")
            ax = axes[row][2 + k]
            ax.plot(t, c["tacho_meas"][idx, k], color="0.2", lw=1.0, label="measured")
            ax.plot(t, c["tacho_fit"][idx, k], color="tab:orange", lw=0.8, ls="--",
                    label="fitted twin")
            ax.set_title(f"{name}: tacho {a}", fontsize=9)
            ax.set_ylabel("V")
        for ax in axes[row]:
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time in the experiment (s)")
    axes[0][0].legend(fontsize=8)
    worst = max(max(v.values()) for v in result.nrmse.values())
    fig.suptitle(f"twin identify: measured vs fitted twin (held-out NRMSE {100 * worst:.2f} %)")
    fig.tight_layout()
    path = Path(path)
    tmp = path.with_name(path.name + ".partial.png")
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    os.replace(tmp, path)
    return path


def record(log: IdentLog, base: MachineConfig, path: str | Path,
           result: Identification | None = None) -> Path:
    """The experiments as a rerun recording: ``dac/{x,y}`` (V), ``position/{x,y}``
    (mm, relative to the first tick), ``tacho/{x,y}`` (V) measured and, with ``result``,
    fitted; an event at the start of every experiment."""
    from twin.identify.replay import measured
    from twin.telemetry.rerun_sink import RerunSink

    pos, tacho = measured(log, base)
    t = log.data["t"] - log.data["t"][0]
    with RerunSink(path, recording_id="identify", recording_name=f"identify {base.name}",
                   blueprint=False) as sink:
        cols = {}
        for k, a in enumerate(AXES):
            cols[f"dac/{a}"] = log.data[f"dac_{a}"]
            cols[f"position/{a}/measured"] = 1e3 * pos[:, k]
            cols[f"tacho/{a}/measured"] = tacho[:, k]
        if result is not None:
            n = len(result.curves["t"])
            for k, a in enumerate(AXES):
                sink.scalars(t[:n], {f"position/{a}/fitted": 1e3 * result.curves["pos_fit"][:, k],
                                     f"tacho/{a}/fitted": result.curves["tacho_fit"][:, k]})
        sink.scalars(t, cols)
        pieces = log.data["piece"].astype(int)
        seen = None
        for i in np.flatnonzero(np.diff(pieces, prepend=-1)):
            name = log.plan[pieces[i]].experiment
            if name != seen:
                sink.event(float(t[i]), f"experiment {name}")
                seen = name
    return Path(path)
