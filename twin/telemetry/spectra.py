"""The spectra a run records: the amplitude spectral density of each axis's following error
(per controller period) and screw deflection (per drive interval), estimated as the run goes
in memory that does not grow with it, and sent once at the end on a timeline of their own,
``FREQUENCY`` (whole hertz).

The estimate is Welch's (``WelchDensity``): Hann windows of ``SEGMENT`` (1 s: 1 Hz bins),
half overlapping, each window's mean removed, the periodograms averaged, scaled as
``scipy.signal.welch``'s one-sided density. A record shorter than one window is one window
of all of it, zero-padded to the window's length (the same 1 Hz grid; the resolution is then
1/its duration). Fewer than ``MIN_SAMPLES`` samples give no spectrum: a run stopped at once
records none.

The recording shows each density as a level in dB re 1 µm/√Hz (0 dB = 1 µm/√Hz, −20 dB =
0.1 µm/√Hz, −60 dB = 1 nm/√Hz): rerun's plots have no logarithmic axis, and a density
spans many decades (a move's own following error near 1 Hz, a resonance three decades
below it). The DC bin holds no level (NaN: each window's mean is removed). Beside each
axis's curve
a single point marks the model's first elastic mode (``RunSpectra.modes``) where it lies in
the band.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from twin.config import AXES
from twin.telemetry.sink import Sink

__all__ = ["DB_SPAN", "FREQUENCY", "MIN_SAMPLES", "QUANTITIES", "SEGMENT", "RunSpectra",
           "WelchDensity", "level_db", "spectrum_entity"]

FREQUENCY = "frequency_hz"
"""The spectra's timeline: a sequence timeline whose values are frequencies in whole hertz
(rerun's timelines hold integers or times; the name carries the unit)."""

SEGMENT = 1.0
"""Welch window of a run's spectra (s): bins 1 Hz apart, each logged at its whole hertz."""

MIN_SAMPLES = 8
"""Fewest samples that make a spectrum."""

DB_SPAN = 120.0
"""Levels a spectrum plot shows below its highest (dB): six decades of µm/√Hz. Lower bins
(the numerical floor of a signal that is nearly constant) run off the bottom."""

QUANTITIES = {"following_error": "following error", "screw_deflection": "screw deflection"}
"""The signals a run records spectra of: entity name and the name a reader reads."""


def spectrum_entity(quantity: str, axis: str, *, mode: bool = False) -> str:
    """The entity of ``axis``'s spectrum of ``quantity`` (``spectra/following_error/x``), or
    of its elastic-mode marker (``spectra/following_error/x_mode``)."""
    return f"spectra/{quantity}/{axis}" + ("_mode" if mode else "")


def level_db(power: np.ndarray) -> np.ndarray:
    """Power spectral density (m²/Hz) as an amplitude density level in dB re 1 µm/√Hz:
    ``20·log10(√power / 1 µm)``; NaN where the power is zero."""
    p = np.asarray(power, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.where(p > 0.0, 10.0 * np.log10(np.where(p > 0.0, p, 1.0)) + 120.0, np.nan)


class WelchDensity:
    """Welch's power spectral density of ``width`` signals sampled every ``dt`` seconds,
    fed in pieces of any size.

    Equal to ``scipy.signal.welch(x, fs=1/dt, window="hann", nperseg=L, noverlap=L // 2,
    detrend="constant")`` of everything fed, ``L = round(segment/dt)`` (at least
    ``MIN_SAMPLES``); for a record of ``m < L`` samples, to ``welch`` with ``nperseg=m,
    nfft=L``. It holds less than one window of samples and one sum of periodograms.

    Parameters
    ----------
    dt : float
        Sampling interval (s); the samples are taken as equally spaced.
    width : int
        Number of signals (columns).
    segment : float
        Window length (s).
    """

    BLOCK = 64
    """Windows transformed at a time (bounds the memory of a large piece)."""

    def __init__(self, dt: float, *, width: int = 1, segment: float = SEGMENT):
        if not (np.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        self.dt = float(dt)
        self.length = max(MIN_SAMPLES, round(segment / dt))
        """int: samples per window (and the transform's length)."""
        self.step = self.length - self.length // 2
        self.width = int(width)
        self.window = _hann(self.length)
        self.segments = 0
        """int: full windows averaged so far."""
        self.samples = 0
        """int: samples fed so far."""
        self._held = np.zeros((0, self.width))
        self._sum = np.zeros((self.length // 2 + 1, self.width))

    def feed(self, values: np.ndarray) -> None:
        """Add samples: shape (n,) for one signal or (n, width)."""
        x = np.asarray(values, dtype=np.float64).reshape(-1, self.width)
        if not len(x):
            return
        self.samples += len(x)
        held = np.concatenate((self._held, x)) if len(self._held) else x
        count = (len(held) - self.length) // self.step + 1 if len(held) >= self.length else 0
        if count:
            windows = np.lib.stride_tricks.sliding_window_view(held, self.length, axis=0)
            windows = windows[: (count - 1) * self.step + 1: self.step]  # (count, width, L)
            for k in range(0, count, self.BLOCK):
                self._sum += _periodograms(windows[k:k + self.BLOCK], self.window,
                                           self.length).sum(axis=0)
            self.segments += count
        self._held = held[count * self.step:].copy()

    def density(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(frequency (Hz), shape (L//2 + 1,); power spectral density (unit²/Hz), shape
        (L//2 + 1, width)), or None with fewer than ``MIN_SAMPLES`` samples."""
        if self.segments:
            power, window = self._sum / self.segments, self.window
        elif self.samples >= MIN_SAMPLES:
            window = _hann(len(self._held))
            power = _periodograms(self._held.T[None], window, self.length)[0]
        else:
            return None
        power = power / (np.sum(window**2) / self.dt)           # scipy's "density"
        power[1:-1 if self.length % 2 == 0 else None] *= 2.0     # one-sided
        return np.fft.rfftfreq(self.length, self.dt), power


def _hann(n: int) -> np.ndarray:
    """The periodic Hann window of ``n`` samples (scipy's ``get_window("hann", n)``)."""
    return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / n)


def _periodograms(windows: np.ndarray, window: np.ndarray, n: int) -> np.ndarray:
    """|FFT|² of each window's samples, mean removed, Hann-weighted, zero-padded to ``n``:
    ``windows`` (count, width, m) → (count, n//2 + 1, width)."""
    x = windows - windows.mean(axis=-1, keepdims=True)
    spectrum = np.fft.rfft(x * window, n=n, axis=-1)
    return np.swapaxes(spectrum.real**2 + spectrum.imag**2, 1, 2)


class RunSpectra:
    """The spectra of one run: each axis's following error and (on the twin) screw
    deflection, fed as the run's records go to the telemetry, sent at its end.

    Parameters
    ----------
    period : float
        Controller period (s): the following error's sampling interval.
    drive_dt : float or None
        The twin's drive interval (s): the screw deflection's; None behind real I/O (no
        deflection is known).
    modes : sequence of float, optional
        The model's first elastic mode per axis (Hz), marked on the curves.
    """

    def __init__(self, period: float, drive_dt: float | None = None,
                 modes: Sequence[float] | None = None):
        self.modes = None if modes is None else [float(f) for f in modes]
        self.welch = {"following_error": WelchDensity(period, width=len(AXES))}
        if drive_dt is not None:
            self.welch["screw_deflection"] = WelchDensity(drive_dt, width=len(AXES))

    def feed(self, quantity: str, values: np.ndarray) -> None:
        """Add samples of ``quantity`` (a key of ``QUANTITIES``; m), shape (n, axes)."""
        estimate = self.welch.get(quantity)
        if estimate is not None:
            estimate.feed(values)

    def columns(self, quantity: str
                ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, tuple[int, float]]]:
        """What the recording holds of ``quantity``: the frequencies (Hz, whole numbers:
        the nearest to each bin, within a quarter hertz), each axis's level (dB re 1
        µm/√Hz) by entity, and each marker's (frequency, level) by entity. Empty without
        a spectrum."""
        estimate = self.welch.get(quantity)
        found = estimate.density() if estimate is not None else None
        if found is None:
            return np.zeros(0, dtype=np.int64), {}, {}
        f, power = found
        hz = np.rint(f).astype(np.int64)
        levels = level_db(power)
        levels[0] = np.nan            # DC: each window's mean is removed (kept as a gap so
        #                               that the frequency axis starts, and is labelled, at 0)
        curves = {spectrum_entity(quantity, a): levels[:, k] for k, a in enumerate(AXES)}
        marks = {}
        for k, a in enumerate(AXES):
            mode = self.modes[k] if self.modes is not None else np.nan
            if len(f) and f[0] - 0.5 <= mode <= f[-1] + 0.5:
                i = int(np.argmin(np.abs(f - mode)))
                marks[spectrum_entity(quantity, a, mode=True)] = (int(hz[i]),
                                                                  float(levels[i, k]))
        return hz, curves, marks

    def send(self, sink: Sink, *, colours: Mapping[str, tuple[int, int, int]]) -> None:
        """Send the spectra to a sink that records them (``spectrum``; styled where it has
        ``style``): per quantity each axis's curve in ``colours[axis]``, and a diamond at
        the model's first elastic mode of each axis within the band."""
        send, style = (getattr(sink, name, None) for name in ("spectrum", "style"))
        if send is None:
            return
        for quantity, what in QUANTITIES.items():
            hz, curves, marks = self.columns(quantity)
            for entity, level in curves.items():
                axis = entity.rsplit("/", 1)[1]
                if style is not None:
                    style(entity, name=f"{axis} {what}", color=colours[axis])
                send(hz, {entity: level})
            for entity, (f, level) in marks.items():
                axis = entity.rsplit("/", 1)[1].removesuffix("_mode")
                mode = self.modes[AXES.index(axis)]
                if style is not None:
                    style(entity, name=f"{axis} first elastic mode of the model, "
                          f"{mode:.1f} Hz", color=colours[axis], marker="diamond")
                send(np.array([f]), {entity: np.array([level])})
