"""The telemetry port: a small ``Sink`` protocol and the do-nothing ``NullSink``.

A run hands a sink batches of columns on the ``sim_time`` timeline; a sink never sees the
controller or the plant. Entity paths are rerun-style (``axes/x/position/actual``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["PROGRAMMED", "NullSink", "Sink"]

PROGRAMMED = "path/programmed"
"""The entity of the programmed path: a static polyline (mm), logged by `Sink.static_path`."""


@runtime_checkable
class Sink(Protocol):
    """Where a run's signals go.

    ``t`` is simulated time (s), shape (n,), increasing; values come in the units the
    recording shows them in (``twin.telemetry.channels.SERIES``: mm, mm/min, µm, V, A, rpm),
    2-D points in mm.
    """

    def static_path(self, entity: str, points: np.ndarray, *,
                    color: tuple[int, int, int] = (160, 160, 160)) -> None:
        """A time-independent polyline, e.g. the programmed path; points (n, 2) (mm)."""
        ...

    def scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Scalar series: each value array has shape (n,), or (n, k) for k series."""
        ...

    def points(self, t: np.ndarray, columns: Mapping[str, np.ndarray], *,
               colors: Mapping[str, np.ndarray] | None = None) -> None:
        """One 2-D point per sample: each value array has shape (n, 2) (mm); ``colors``
        optionally gives some entities one RGB colour (uint8, (n, 3)) per point."""
        ...

    def event(self, t: float, text: str, *, level: str = "INFO") -> None:
        """A discrete event (block start, limit switch, trip) at time t (s)."""
        ...

    def close(self) -> None:
        """Flush everything; the recording is complete and readable afterwards.

        A sink that writes a file may also have ``finish()``: complete the recording
        without publishing it under its final name. A run calls it, writes its summary,
        then calls ``close()``, so that a recording never stands without its summary.
        A sink that records spectra has ``spectrum(frequency, columns)`` (whole hertz;
        ``twin.telemetry.spectra``): a run sends its spectra there before ``finish()``."""
        ...


class NullSink:
    """A sink that drops everything (the default when telemetry is off)."""

    def static_path(self, entity: str, points: np.ndarray, *,
                    color: tuple[int, int, int] = (160, 160, 160)) -> None:
        """Drop it."""

    def scalars(self, t: np.ndarray, columns: Mapping[str, np.ndarray]) -> None:
        """Drop it."""

    def points(self, t: np.ndarray, columns: Mapping[str, np.ndarray], *,
               colors: Mapping[str, np.ndarray] | None = None) -> None:
        """Drop it."""

    def event(self, t: float, text: str, *, level: str = "INFO") -> None:
        """Drop it."""

    def close(self) -> None:
        """Nothing to flush."""
