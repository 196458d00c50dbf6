"""The modes read from a measured response: its resonances (peaks fitted with a
second-order pole), their spread by the jackknife, the modes a measurement cannot see, and
the figures that compare it with the linearised twin. Shared by the excitations of
``measure`` and the impact test (``hammer``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from twin.analysis.frequency import estimate
from twin.analysis.frequency.prediction import closed_loop_modes
from twin.analysis.frequency.result import Resonance
from twin.config import MachineConfig
from twin.plant.model import axis_mechanics

__all__ = ["USABLE", "compared", "jackknife", "resonances", "unseen"]

NEAR = 0.15
"""How far (a fraction of its frequency) a resonance may lie from a mode of the belief and
still stand for it in ``unseen``: a belief off by more has the mode unseen and an unknown
resonance found."""
USABLE = 0.5
"""Coherence from which a line enters the resonance fit (weighted by its γ²/(1 − γ²))."""


def compared(response: np.ndarray, prediction: np.ndarray, good: np.ndarray,
             belief: MachineConfig, axis: str, position: float,
             poles: list[complex] | None = None) -> dict[str, Any]:
    """The record's ``agreement`` (the measurement against the prediction on the ``good``
    lines: their count, the largest gain (dB) and phase (degrees) error) and
    ``analytic_modes`` (``poles``, default ``closed_loop_modes`` of the belief at
    ``position``: Hz, ζ)."""
    ratio = response[good] / prediction[good]
    return {
        "agreement": {
            "lines_coherent": int(good.sum()),
            "max_gain_error_db": float(np.max(np.abs(20 * np.log10(np.abs(ratio)))))
            if len(ratio) else None,
            "max_phase_error_deg": float(np.max(np.abs(np.degrees(np.angle(ratio)))))
            if len(ratio) else None},
        "analytic_modes": [{"frequency_hz": abs(s) / (2 * math.pi),
                            "damping": -s.real / abs(s)}
                           for s in (closed_loop_modes(belief, axis, position)
                                     if poles is None else poles)],
    }


def unseen(belief: MachineConfig, axis: str, position: float, sensor: str, loop: str,
            top: float, found: list[float] | None = None,
            poles: list[complex] | None = None) -> list[str]:
    """The belief's elastic modes this measurement cannot see, each with the reason; with
    ``found`` (the resonances' frequencies, Hz) also those inside the measured band that
    no resonance within ``NEAR`` of their closed-loop frequency stands for (their peak did
    not stand out of the noise; ``poles``: those closed-loop modes, if computed already)."""
    chain = axis_mechanics(belief, axis, position)
    free = chain.frequencies("free") / (2.0 * math.pi)
    locked = chain.frequencies("locked") / (2.0 * math.pi)
    motor = sensor == "motor" or loop == "position"
    if found is not None and poles is None:
        poles = closed_loop_modes(belief, axis, position)
    near = [abs(p) / (2.0 * math.pi) for p in poles] if found is not None and poles else []
    out = []
    for i, f in enumerate(free):
        if motor and i < len(locked) and 40.0 * math.log10(f / locked[i]) < 1.0:
            out.append(f"mode {i + 1} at {f:.1f} Hz: the motor barely moves in it (its "
                       f"anti-resonance at {locked[i]:.2f} Hz, "
                       f"{40.0 * math.log10(f / locked[i]):.3f} dB deep: the rotor's "
                       f"reflected mass {chain.reflected_mass:.3g} kg against "
                       f"{chain.moving_mass:.3g} kg); mount an accelerometer")
        elif top <= 0.0:
            out.append(f"mode {i + 1} at {f:.1f} Hz: no line of the measurement reached "
                       f"a coherence of {estimate.COHERENT:g} (noise or distortion)")
        elif f > top:
            out.append(f"mode {i + 1} at {f:.1f} Hz: above the measured band "
                       f"({top:.1f} Hz, the highest line with a coherence of "
                       f"{estimate.COHERENT:g})")
        elif i < len(near) and not any(abs(g - near[i]) <= NEAR * near[i] for g in found):
            out.append(f"mode {i + 1} at {near[i]:.1f} Hz (with the drive's speed loop): no "
                       f"peak near it stood out of the "
                       f"noise by three of its lines' random errors; raise --averages or "
                       f"--amplitude, or strike the table (--excitation hammer)")
    return out


def resonances(f: np.ndarray, h: np.ndarray, coherence: np.ndarray, rigid: np.ndarray,
                axis: str, seen_by: str, averages: int | None = None) -> list[Resonance]:
    """The resonances: peaks of |H/H_rigid| (dB) on the lines with γ² ≥ ``USABLE``, each
    the pole of a second-order model fitted to H/H_rigid (the measurement over the rigid
    twin's prediction: what the speed loop does to both divides out) over half to twice
    its frequency (at least its eight nearest lines), each line weighted by its
    signal-to-noise ratio γ²/(1 − γ²). With ``averages`` (P, the periods or the blows
    averaged) a peak must stand out by three of its line's random errors besides
    (20·log10(e)·√((1 − γ²)/(2·P·γ²)) dB): a noise bump is not a mode."""
    usable = coherence >= USABLE
    if usable.sum() < 8:
        return []
    fg, ratio = f[usable], h[usable] / rigid[usable]
    trust = np.sqrt(coherence[usable] / np.maximum(1.0 - coherence[usable], 1e-4))
    level = 20.0 * np.log10(np.abs(ratio))
    found = []
    noise = (None if averages is None else 20.0 * math.log10(math.e) * np.sqrt(
        (1.0 - coherence[usable]) / (2.0 * averages * coherence[usable])))
    for i in estimate.peaks(fg, level, noise=noise):
        near = (fg >= fg[i] / 2.0) & (fg <= fg[i] * 2.0)
        if near.sum() < 8:                # too coarse a grid: the eight nearest lines
            near = np.zeros(len(fg), dtype=bool)
            near[np.argsort(np.abs(fg - fg[i]))[:8]] = True
        pole = estimate.fit_mode(fg[near], ratio[near], weight=trust[near])
        if pole is None:
            continue
        freq, zeta = abs(pole) / (2.0 * math.pi), -pole.real / abs(pole)
        if not (fg[near].min() <= freq <= fg[near].max() and 0.0 < zeta < 1.0):
            continue
        found.append(Resonance(freq, zeta, float(level[i]), axis, seen_by))
    return sorted(found, key=lambda r: r.frequency)


def jackknife(spec: estimate.Spectra, found: list[Resonance], rigid: np.ndarray,
               axis: str, seen_by: str, averaged: bool = False) -> list[float | None]:
    """The standard deviation of each resonance's frequency (Hz) by the jackknife over the
    averaged periods: the fit repeated with each left out, √((P − 1)/P·Σ(f_i − f̄)²); None
    where a leave-one-out fit lost it or fewer than three periods were averaged."""
    periods = len(spec.dac)
    if periods < 3 or not found:
        return [None] * len(found)
    runs = []
    for p in range(periods):
        h, g = spec.without(p).response()
        runs.append([r.frequency for r in resonances(
            spec.frequency, h, g, rigid, axis, seen_by,
            periods - 1 if averaged else None)])
    out: list[float | None] = []
    for r in found:
        near = [min(run, key=lambda f: abs(f - r.frequency)) for run in runs if run]
        near = [f for f in near if abs(f - r.frequency) < 0.25 * r.frequency]
        if len(near) < periods:
            out.append(None)
            continue
        f = np.array(near)
        out.append(float(math.sqrt((periods - 1) / periods * np.sum((f - f.mean()) ** 2))))
    return out
