"""What a recording spans: each entity's value range, the 2-D bounds of its points and the
time span, gathered as batches pass through a sink; and the axis ranges a layout draws them
in.

rerun's time-series views fit their y axis to the first data they see and keep it (the
viewer writes that range into the blueprint), so a recording read from a file shows its
later data running off the panels. A layout built from a ``Extents`` states every range.

rerun's plots (egui_plot) label only multiples of powers of ten, and only those at least
about 20 screen points apart: a range of 0 … 7600 in a 150-point panel labels nothing but
0. ``tick_range`` widens a data range to whole multiples of a power of ten, at most
``MAX_STEPS`` of them, so that every panel shows at least two labelled ticks.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np

__all__ = ["MAX_STEPS", "Extents", "tick_range"]

MAX_STEPS = 5
"""Most labelled steps a panel's y range spans: 150 screen points per panel (a 1100-point
window with five panels a tab) give 30 points per step, where egui_plot draws labels at
full strength."""

MARGIN = 0.04
"""Share of the range added beyond each labelled end, so that a trace lying on it stays
inside the panel."""


def tick_range(lo: float, hi: float, *, max_steps: int = MAX_STEPS
               ) -> tuple[float, float] | None:
    """A y range holding ``[lo, hi]`` whose ends are multiples of one power of ten ``s``,
    at most ``max_steps`` steps of ``s`` apart (the smallest such ``s``), plus
    ``MARGIN`` of the range on each side. None for non-finite data.

    At least two labelled values (multiples of ``s``) lie inside it; a constant ``v`` gets
    ``v ± s`` (``-1 … 1`` for zero)."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return None
    lo, hi = min(lo, hi), max(lo, hi)
    span = hi - lo
    if span <= 1e-12 * max(abs(lo), abs(hi), 1e-300):
        s = 10.0 ** math.floor(math.log10(abs(lo))) if lo != 0.0 else 1.0
        a, b = lo - s, hi + s
    else:
        s = 10.0 ** math.floor(math.log10(span / max_steps))
        while True:
            a, b = math.floor(lo / s) * s, math.ceil(hi / s) * s
            if b - a <= max_steps * s * (1 + 1e-9):
                break
            s *= 10.0
        if b - a < s * (1 - 1e-9):            # never: lo < hi spans at least one cell
            b = a + s
    pad = MARGIN * (b - a)
    return (a - pad, b + pad)


class Extents:
    """Ranges of what a sink was given (in the recorded units), in bounded memory.

    ``values[entity]``: (min, max) of its scalars (all series of an entity together; NaN
    ignored). ``bounds[entity]``: ((x min, y min), (x max, y max)) of its 2-D points and
    polylines. ``time``: (first, last) sample time (s) of anything with a time.
    ``band[entity]``: (lowest, highest) frequency (Hz) of a spectrum.
    """

    def __init__(self) -> None:
        self.values: dict[str, tuple[float, float]] = {}
        self.bounds: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.time: tuple[float, float] | None = None
        self.band: dict[str, tuple[float, float]] = {}

    def add_time(self, t: np.ndarray) -> None:
        """Widen the time span by the sample times ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        if t.size:
            lo, hi = float(t.min()), float(t.max())
            self.time = (lo, hi) if self.time is None else (min(self.time[0], lo),
                                                            max(self.time[1], hi))

    def add_scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Widen the time span by ``t`` and each entity's value range by its column."""
        self.add_time(t)
        self.add_values(columns)

    def add_spectrum(self, frequency: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Widen each entity's band by the frequencies ``frequency`` (Hz) and its value
        range by its column (a spectrum: no time)."""
        f = np.asarray(frequency, dtype=np.float64)
        if f.size:
            lo, hi = float(f.min()), float(f.max())
            for entity in columns:
                old = self.band.get(entity)
                self.band[entity] = (lo, hi) if old is None else (min(old[0], lo),
                                                                  max(old[1], hi))
        self.add_values(columns)

    def add_values(self, columns: Mapping[str, np.ndarray]) -> None:
        """Widen each entity's value range by its column (any shape; NaN ignored)."""
        for entity, values in columns.items():
            v = np.asarray(values, dtype=np.float64)
            v = v[np.isfinite(v)]
            if not v.size:
                continue
            lo, hi = float(v.min()), float(v.max())
            old = self.values.get(entity)
            self.values[entity] = (lo, hi) if old is None else (min(old[0], lo),
                                                                max(old[1], hi))

    def add_points(self, entity: str, points: np.ndarray) -> None:
        """Widen ``entity``'s 2-D bounds by ``points`` ((n, 2); non-finite rows ignored)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        p = p[np.all(np.isfinite(p), axis=1)]
        if not len(p):
            return
        lo, hi = p.min(axis=0), p.max(axis=0)
        old = self.bounds.get(entity)
        self.bounds[entity] = (lo, hi) if old is None else (np.minimum(old[0], lo),
                                                            np.maximum(old[1], hi))

    @staticmethod
    def _matches(entity: str, patterns: Iterable[str]) -> bool:
        """``entity`` is one of ``patterns``, or below one ending in ``/**``."""
        for p in patterns:
            p = p.lstrip("/")
            if p.endswith("/**") and (entity == p[:-3] or entity.startswith(p[:-2])):
                return True
            if entity == p:
                return True
        return False

    def value_range(self, *patterns: str) -> tuple[float, float] | None:
        """(min, max) over the entities matching ``patterns``; None if none has data."""
        found = [r for e, r in self.values.items() if self._matches(e, patterns)]
        if not found:
            return None
        return (min(r[0] for r in found), max(r[1] for r in found))

    def band_range(self, *patterns: str) -> tuple[float, float] | None:
        """(lowest, highest) frequency (Hz) over the spectra matching ``patterns``; None if
        none has data."""
        found = [b for e, b in self.band.items() if self._matches(e, patterns)]
        if not found:
            return None
        return (min(b[0] for b in found), max(b[1] for b in found))

    def point_bounds(self, *patterns: str) -> tuple[np.ndarray, np.ndarray] | None:
        """((x, y) min, (x, y) max) over the entities matching ``patterns``; None if none."""
        found = [b for e, b in self.bounds.items() if self._matches(e, patterns)]
        if not found:
            return None
        return (np.min([b[0] for b in found], axis=0), np.max([b[1] for b in found], axis=0))
