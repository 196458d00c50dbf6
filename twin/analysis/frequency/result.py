"""What a frequency-response measurement returns: ``FrequencyResponse`` with its
``Resonance``s and the position loop's ``Margins``.

SI inside (Hz for frequencies, as engineers quote them; dB and degrees only where a person
reads them: ``Resonance.peak``, ``Margins``). ``to_json`` gives the record ``twin measure``
writes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from twin.errors import ConfigError

__all__ = ["LOOPS", "SENSORS", "FrequencyResponse", "Margins", "Resonance"]

LOOPS = ("mechanics", "speed", "position")
"""What is measured: the table's acceleration per DAC volt (``mechanics``), the drive's
closed speed loop (``speed``: table speed per DAC volt), the position loop opened at the
DAC (``position``: its loop transfer function)."""
SENSORS = ("accelerometer", "motor")
"""Who sees the motion: a table accelerometer, or the motor's encoder and tacho alone."""


@dataclass(frozen=True)
class Resonance:
    """One resonance of the mechanics.

    Attributes
    ----------
    frequency : float
        Natural frequency of the pole pair, |s|/2π (Hz).
    damping : float
        Damping ratio ζ = −Re s/|s| (1).
    peak : float
        Height of the resonance over the rigid-body response at ``frequency`` (dB).
    axis : str
        ``"x"`` or ``"y"``.
    seen_by : str
        ``"accelerometer"`` or ``"motor"``.
    """

    frequency: float
    damping: float
    peak: float
    axis: str
    seen_by: str

    def __post_init__(self) -> None:
        if not (math.isfinite(self.frequency) and self.frequency > 0.0):
            raise ConfigError("frequency", f"must be > 0 Hz, got {self.frequency!r}")
        if not (math.isfinite(self.damping) and self.damping > 0.0):
            raise ConfigError("damping", f"must be > 0, got {self.damping!r}")
        if self.axis not in ("x", "y"):
            raise ConfigError("axis", f"must be x or y, got {self.axis!r}")
        if self.seen_by not in SENSORS:
            raise ConfigError("seen_by", f"must be one of {', '.join(SENSORS)}, got "
                              f"{self.seen_by!r}")

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for the JSON record (Hz, 1, dB)."""
        return {"frequency_hz": self.frequency, "damping": self.damping,
                "peak_db": self.peak, "axis": self.axis, "seen_by": self.seen_by}


@dataclass(frozen=True)
class Margins:
    """Stability margins of the position loop, from its loop transfer function L.

    Attributes
    ----------
    gain_margin : float
        −20·log10|L| where the phase of L crosses −180° (dB); ``inf`` when it does not
        below the Nyquist frequency.
    phase_margin : float
        180° + arg L where |L| = 1 (degrees).
    crossover : float
        Where |L| = 1 (Hz).
    bandwidth : float
        Where the closed loop L/(1 + L) falls 3 dB below its low-frequency gain (Hz);
        ``nan`` when it does not within the measured band.
    """

    gain_margin: float
    phase_margin: float
    crossover: float
    bandwidth: float

    def to_dict(self) -> dict[str, float | None]:
        """Plain dict for the JSON record (dB, degrees, Hz; null for a margin that is not
        there)."""
        return {k: (v if math.isfinite(v) else None) for k, v in (
            ("gain_margin_db", self.gain_margin), ("phase_margin_deg", self.phase_margin),
            ("crossover_hz", self.crossover), ("bandwidth_hz", self.bandwidth))}


def _complex_list(values: np.ndarray) -> list[list[float]]:
    return [[float(v.real), float(v.imag)] for v in np.asarray(values, dtype=complex)]


@dataclass(frozen=True, eq=False)
class FrequencyResponse:
    """A measured frequency response and what was read from it.

    Attributes
    ----------
    frequency : ndarray, shape (n,)
        The excited lines (Hz), ascending.
    response : ndarray, complex, shape (n,)
        The measurement at each line, in ``unit``.
    coherence : ndarray, shape (n,)
        γ² of each line over the averaged periods (1: no noise; 0: no signal).
    prediction : ndarray, complex, shape (n,)
        What the linearised twin of the controller's belief predicts at each line (same
        unit).
    resonances : list of Resonance
        The mechanics' resonances the sensor saw, ascending in frequency.
    margins : Margins or None
        The position loop's margins (``loop == "position"``), else None.
    unseen : list of str
        The machine's modes this measurement cannot see, each with the reason.
    loop, sensor, axis : str
        What was measured, with which sensor, on which axis.
    unit : str
        Unit of ``response`` (SI): ``m/(s²·V)`` (mechanics), ``m/(s·V)`` (speed), ``1``
        (position: the loop transfer function).
    position : float
        Where the table was, the middle of the measured travel (m): the screw's stiffness,
        hence its modes, vary with the nut's position.
    info : dict
        Everything else for the record: the excitation, the machine, the driver, the
        timing, the analytic modes compared, the paths written.
    """

    frequency: np.ndarray
    response: np.ndarray
    coherence: np.ndarray
    prediction: np.ndarray
    resonances: list[Resonance]
    margins: Margins | None
    unseen: list[str]
    loop: str
    sensor: str
    axis: str
    unit: str
    position: float
    info: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The record as plain JSON types (Hz, the response's SI unit as [re, im] pairs, dB
        and degrees where the dataclasses say)."""
        return {
            "loop": self.loop, "sensor": self.sensor, "axis": self.axis, "unit": self.unit,
            "position_mm": self.position * 1e3,
            "frequency_hz": [float(f) for f in self.frequency],
            "response": _complex_list(self.response),
            "coherence": [float(c) for c in self.coherence],
            "prediction": _complex_list(self.prediction),
            "resonances": [r.to_dict() for r in self.resonances],
            "margins": None if self.margins is None else self.margins.to_dict(),
            "unseen": list(self.unseen),
            **self.info,
        }
