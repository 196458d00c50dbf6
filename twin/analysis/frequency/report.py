"""What ``twin measure`` writes into ``measure-<id>/``: ``measurement.json`` (the record,
``FrequencyResponse.to_json``), ``bode.png`` (the measurement against the linearised twin of
the controller's belief, so that a wrong model stands out) and ``measurement.rrd`` (the
run's signals for the rerun viewer)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from twin.analysis.frequency.estimate import COHERENT
from twin.analysis.frequency.record import Recording
from twin.analysis.frequency.result import FrequencyResponse
from twin.system.jsonio import record_id, write_json_atomic

__all__ = ["plot_bode", "record_signals", "write_record"]

_SHOWN = {"mechanics": ("table acceleration per DAC volt", "dB re 1 (m/s²)/V", 1.0),
          "speed": ("table speed per DAC volt", "dB re 1 (mm/s)/V", 1e3),
          "position": ("position loop opened at the DAC, L", "dB", 1.0)}
"""What a Bode plot's magnitude shows: its title, axis label, and the scale from SI."""
_ACCELERANCE = ("accelerance, table acceleration per hammer force", "dB re 1 (m/s²)/N", 1.0)
"""The same for an impact test (its unit ``m/(s²·N)``)."""


def plot_bode(result: FrequencyResponse, path: str | Path) -> Path:
    """Magnitude (dB), phase (degrees) and coherence against frequency (Hz): the measured
    lines (faint where γ² < ``COHERENT``), the prediction, the resonances and the margins."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    title, label, scale = _ACCELERANCE if result.unit == "m/(s²·N)" else _SHOWN[result.loop]
    f = result.frequency
    good = result.coherence >= COHERENT
    mag = 20.0 * np.log10(np.abs(result.response) * scale)
    pred = 20.0 * np.log10(np.abs(result.prediction) * scale)
    phase = np.degrees(np.angle(result.response))
    pred_phase = np.degrees(np.angle(result.prediction))
    fig, axes = plt.subplots(3, 1, figsize=(9, 9), sharex=True,
                             gridspec_kw={"height_ratios": [3, 2, 1]})
    for ax, y, yp, name in ((axes[0], mag, pred, label), (axes[1], phase, pred_phase,
                                                           "phase (°)")):
        ax.semilogx(f, yp, "-", color="tab:orange", label="linearised twin (belief)")
        ax.semilogx(f[good], y[good], ".", color="tab:blue", ms=4,
                    label=f"measured, γ² ≥ {COHERENT:g}")
        ax.semilogx(f[~good], y[~good], ".", color="tab:blue", alpha=0.2, ms=3,
                    label=f"measured, γ² < {COHERENT:g}")
        ax.set_ylabel(name)
        ax.grid(True, which="both", alpha=0.3)
    axes[1].set_ylim(-190, 190)
    axes[1].set_yticks(range(-180, 181, 90))
    for r in result.resonances:
        for ax in axes[:2]:
            ax.axvline(r.frequency, color="tab:red", lw=0.8, ls="--")
        axes[0].annotate(f"{r.frequency:.1f} Hz, ζ {r.damping:.3f}, {r.peak:+.1f} dB",
                         (r.frequency, float(np.nanmax(mag))), fontsize=8, color="tab:red",
                         rotation=90, va="top", ha="right")
    axes[0].legend(loc="lower left", fontsize=8)
    axes[2].semilogx(f, result.coherence, ".", ms=3, color="tab:green")
    axes[2].axhline(COHERENT, color="grey", lw=0.8, ls=":")
    axes[2].set_ylim(0, 1.05)
    axes[2].set_ylabel("coherence γ²")
    axes[2].set_xlabel("frequency (Hz)")
    axes[2].grid(True, which="both", alpha=0.3)
    head = f"{result.info.get('machine', '')} axis {result.axis}: {title} " \
           f"({result.sensor}; at {1e3 * result.position:.1f} mm)"
    if result.margins is not None:
        m = result.margins
        gm = "∞" if not math.isfinite(m.gain_margin) else f"{m.gain_margin:.1f} dB"
        head += (f"\ngain margin {gm}, phase margin {m.phase_margin:.1f}° at "
                 f"{m.crossover:.2f} Hz, bandwidth {m.bandwidth:.2f} Hz")
    if result.unseen:
        head += "\nnot seen: " + "; ".join(u.split(":")[0] for u in result.unseen)
    axes[0].set_title(head, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def record_signals(rec: Recording, result: FrequencyResponse, path: str | Path) -> Path:
    """The run as a rerun recording: the DAC (V), the regulator's share (V), the encoder
    position (mm, from the first tick), the tacho (V) and the accelerometer (m/s²); of an
    impact test the hammer's force sensor (N) as well."""
    from twin.telemetry.rerun_sink import RerunSink

    exc = result.info["excitation"]
    period = result.info.get("controller_period_s") or (
        1.0 / (exc["resolution_hz"] * exc["ticks_per_period"]))
    t = rec.slot * period
    a = result.axis
    with RerunSink(path, recording_id="measure", recording_name=f"measure axis {a}",
                   blueprint=False) as sink:
        sink.scalars(t, {f"dac/{a}": rec.dac, f"regulator/{a}": rec.regulator,
                         f"position/{a}": 1e3 * (rec.position - rec.position[0]),
                         f"tacho/{a}": rec.tacho})
        if len(rec.accel):
            rate = result.info.get("accelerometer_rate_hz")
            if rate:
                ta = rec.accel_sequence / rate - float(rec.time[0])
                sink.scalars(ta, {f"accelerometer/{a}": rec.accel})
                if exc["kind"] == "hammer":     # the force sensor, on the same clock
                    sink.scalars(ta, {f"hammer_force/{a}": rec.excitation})
        sink.event(0.0, f"{result.loop} loop, {exc['kind']}")
    return Path(path)


def write_record(result: FrequencyResponse, rec: Recording, out_dir: Path
                 ) -> FrequencyResponse:
    """Write ``measure-<id>/`` under ``out_dir`` and return the result with its paths in
    ``info["paths"]``."""
    where = Path(out_dir) / record_id("measure-")
    where.mkdir(parents=True, exist_ok=False)
    paths = {"record": str(where), "json": str(where / "measurement.json"),
             "bode": str(plot_bode(result, where / "bode.png")),
             "rrd": str(record_signals(rec, result, where / "measurement.rrd"))}
    result = dataclasses.replace(result, info={**result.info, "paths": paths})
    write_json_atomic(where / "measurement.json", result.to_json())
    return result
