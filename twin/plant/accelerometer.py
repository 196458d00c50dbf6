"""The table accelerometer (``[accelerometer]`` of a machine file): what an ADXL345 clamped
on the table gives.

The sensor runs on its own clock: sample i is taken at t_i = i/f_s (plant time, f_s =
``sample_rate``) and is the mean acceleration of the table over its sample interval, the
sensor's own averaging (an anti-alias filter of one sample's width)::

    a_i = (v(t_i) − v(t_{i−1}))·f_s

with v the table velocity of each channel (x: the X slide, y: the Y slide; the sensor sits
on the Y carriage, which the X carriage carries). The plant hands it the velocity after
every physics step; between steps the integrator's velocity is linear in time, so v(t_i) is
interpolated exactly. To each sample it adds white noise of ``noise_density`` over the
sensor's Nyquist band, rounds it to whole counts of ``resolution`` and clips it to
``±range`` (in whole counts). Samples go into a FIFO of ``block`` entries; when it is full
the oldest sample is dropped and the overrun is flagged (an ADXL345 in stream mode). A read
(:meth:`Accelerometer.pop`) empties it, as one SPI burst of the I/O does each period.

Its noise is a generator of its own (``accelerometer.seed``): mounting the sensor changes no
other noise of the twin.
"""

from __future__ import annotations

import math

import numpy as np

from twin.config import AccelerometerConfig

__all__ = ["Accelerometer"]


class Accelerometer:
    """The sensor model (see the module docstring).

    Parameters
    ----------
    config : AccelerometerConfig
    noise : bool
        Add the sensor's noise (False: the quantisation and clipping alone).

    Attributes
    ----------
    config : AccelerometerConfig
    produced : int
        Samples taken since the reset (the sequence number of the next one, minus one).
    lost : int
        Samples dropped by a full FIFO since the reset.
    """

    def __init__(self, config: AccelerometerConfig, *, noise: bool = True):
        self.config = config
        self.noise = bool(noise)
        self.period = 1.0 / config.sample_rate
        self._counts = math.floor(config.range / config.resolution)
        self._fifo = np.zeros((config.block, 2))
        self.reset(0.0, np.zeros(2))

    def reset(self, time: float, velocity: np.ndarray) -> None:
        """Start again at plant ``time`` (s) with the table at ``velocity`` (m/s, (2,)): the
        FIFO empty, the sample clock at zero (the next sample at the first multiple of the
        sample period after ``time``), the noise stream at its seed."""
        self._rng = np.random.default_rng([self.config.seed, 0xACCE1])
        self._t = float(time)
        self._v = np.asarray(velocity, dtype=float).copy()
        self.produced = math.floor(self._t / self.period + 1e-9)
        self._v_sample = self._v.copy()   # velocity at the last sample instant
        self._count = 0
        self._first = self.produced + 1
        self.lost = 0
        self._overrun = False

    def feed(self, t0: float, step: float, velocity: np.ndarray) -> None:
        """Take the velocities after physics steps of length ``step`` (s) that began at plant
        time ``t0`` (s): ``velocity[j]`` (m/s, shape (n, 2)) at ``t0 + (j + 1)·step``."""
        n = len(velocity)
        if n == 0:
            return
        t_end = t0 + n * step
        first = self.produced + 1
        last = math.floor(t_end / self.period + 1e-9)
        if last >= first:
            times = np.concatenate(([self._t], t0 + step * np.arange(1, n + 1)))
            instants = self.period * np.arange(first, last + 1)
            v = np.empty((len(instants) + 1, 2))
            v[0] = self._v_sample
            for k in range(2):
                values = np.concatenate(([self._v[k]], velocity[:, k]))
                v[1:, k] = np.interp(instants, times, values)
            self._push(np.diff(v, axis=0) * self.config.sample_rate, first)
            self._v_sample = v[-1].copy()
            self.produced = last
        self._t = t_end
        self._v = np.asarray(velocity[-1], dtype=float).copy()

    def _push(self, accel: np.ndarray, first: int) -> None:
        """Noise, quantisation and clipping of new samples, into the FIFO."""
        cfg = self.config
        if self.noise and cfg.noise_density > 0.0:
            accel = accel + self._rng.standard_normal(accel.shape) * cfg.noise_rms
        codes = np.clip(np.floor(accel / cfg.resolution + 0.5), -self._counts, self._counts)
        samples = codes * cfg.resolution
        block = len(self._fifo)
        if len(samples) > block:           # more than the FIFO holds: only the newest stay
            drop = len(samples) - block
            samples, first = samples[drop:], first + drop
            self.lost += drop
            self._overrun = True
        room = block - self._count
        if len(samples) > room:            # a full FIFO drops its oldest
            drop = len(samples) - room
            self._fifo[:self._count - drop] = self._fifo[drop:self._count]
            self._count -= drop
            self._first += drop
            self.lost += drop
            self._overrun = True
        if self._count == 0:
            self._first = first
        self._fifo[self._count:self._count + len(samples)] = samples
        self._count += len(samples)

    def pop(self, out: np.ndarray) -> tuple[int, int, bool]:
        """Empty the FIFO into ``out`` (shape (block, 2), m/s²; rows past the count are
        left as they were): (samples read, sequence number of the first of them, whether
        samples were lost since the last read)."""
        n, first, overrun = self._count, self._first, self._overrun
        out[:n] = self._fifo[:n]
        self._count = 0
        self._first = self.produced + 1
        self._overrun = False
        return n, first, overrun
