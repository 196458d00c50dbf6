"""A modal hammer on the twin: the blows on the table and the hammer's force sensor.

An impact test strikes the table with a hammer whose tip carries a force sensor, while the
drives hold position; a table accelerometer records the response. On the twin each blow is
a half-sine pulse of force on the table body (``Plant.set_table_force``), of peak ``peak``
(N) and length ``duration`` (s): a hard tip is short and reaches high frequencies, a soft
one is long (the pulse's spectrum falls to its first zero at 1.5/``duration``). MuJoCo holds
an applied force over a drive interval (``Plant.drive_dt``), so ``HammerSimDriver`` steps a
period in which a blow falls interval by interval, each with the pulse's mean over it: the
force the table feels is that staircase, and the force sensor reports exactly it.

The force sensor samples on the accelerometer's clock (a data-acquisition front end that
samples both channels together): sample i is the mean force over ((i − 1)/f_s, i/f_s], as
the accelerometer's sample i is the mean acceleration over it, plus white noise of
``noise`` (N rms per sample).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from twin.hardware.sim import SimDriver

__all__ = ["HammerSimDriver", "force_samples", "pulse_mean"]


def pulse_mean(t0: float, t1: float, start: float, duration: float, peak: float) -> float:
    """Mean over [t0, t1] (s) of the half-sine ``peak``·sin(π(t − start)/duration) on
    [start, start + duration] (zero elsewhere) (N)."""
    a, b = max(t0, start), min(t1, start + duration)
    if b <= a or t1 <= t0:
        return 0.0
    w = math.pi / duration
    return peak * (math.cos(w * (a - start)) - math.cos(w * (b - start))) / (w * (t1 - t0))


class HammerSimDriver(SimDriver):
    """The lock-step twin with a hammer striking its table along one axis.

    Parameters
    ----------
    plant, period
        As ``SimDriver``.
    axis : int
        The slide struck along (0: X, 1: Y).
    duration : float
        Length of each blow (s).

    Attributes
    ----------
    blows : list of (float, float)
        Each blow's start (plant time, s) and peak (N), set by :meth:`strike_at`.
    segments : list of (float, float, float)
        The force applied, piecewise constant: (from, to (s), force (N)).
    """

    def __init__(self, plant, period: float, *, axis: int, duration: float):
        super().__init__(plant, period)
        self.axis, self.duration = axis, duration
        self.blows: list[tuple[float, float]] = []
        self.segments: list[tuple[float, float, float]] = []
        self._force = np.zeros(2)

    def strike_at(self, blows: Sequence[tuple[float, float]]) -> None:
        """Strike at these (start (plant time, s), peak (N)) from now on."""
        self.blows = sorted((float(t), float(p)) for t, p in blows)

    def _advance(self, dac_volts: np.ndarray, duration: float) -> None:
        t = self.plant.time
        hits = [(s, p) for s, p in self.blows if s < t + duration and s + self.duration > t]
        if not hits:
            self.plant.step(dac_volts, duration)
            return
        dt = self.plant.drive_dt
        n = max(1, round(duration / dt))
        for i in range(n):
            a = t + i * dt
            f = sum(pulse_mean(a, a + dt, s, self.duration, p) for s, p in hits)
            self._force[self.axis] = f
            self.plant.set_table_force(self._force)
            self.plant.step(dac_volts, dt)
            if f:
                self.segments.append((a, a + dt, f))
        self._force[self.axis] = 0.0
        self.plant.set_table_force(self._force)


def force_samples(segments: Sequence[tuple[float, float, float]], sequence: np.ndarray,
                  sample_rate: float, noise: float, rng: np.random.Generator) -> np.ndarray:
    """The force sensor's samples numbered ``sequence`` (on the accelerometer's clock):
    each the mean of the piecewise constant ``segments`` ((from, to (s), force (N))) over
    ((i − 1)/f_s, i/f_s], plus white noise of ``noise`` (N rms) (N)."""
    seq = np.asarray(sequence, dtype=np.int64)
    out = np.zeros(len(seq))
    if len(seq):
        first = int(seq[0])
        where = {int(s): j for j, s in enumerate(seq)}
        ts = 1.0 / sample_rate
        for a, b, f in segments:
            for i in range(math.floor(a * sample_rate) + 1, math.ceil(b * sample_rate) + 1):
                j = where.get(i) if i >= first else None
                if j is None:
                    continue
                lo, hi = max(a, (i - 1) * ts), min(b, i * ts)
                if hi > lo:
                    out[j] += f * (hi - lo) / ts
    return out + noise * rng.standard_normal(len(out))
