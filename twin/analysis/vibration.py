"""Residual vibration of a run: the elastic oscillation left once the reference stops
accelerating (what an input shaper cancels; Singer & Seering's residual vibration, measured
on the twin).

A run summary's ``elastic_oscillation_um`` (``twin.analysis.compare.elastic_oscillation``) is
the deflection minus its moving average over one mode period: when an acceleration lasts
about one period, as the corners of a laser job do on laser_belt (0.8 m/s² for 60 ms against
a 63 ms mode), it measures the quasi-static deflection ``m·a/k`` itself, which no shaper can
remove. The residual vibration separates the two: on each interval during which an axis'
(shaped) reference acceleration is zero for at least ``MIN_PERIODS`` periods of that axis'
mode, the deflection should stand at its settled value (friction and the loop's own lag);
what it does instead is the free vibration the move left behind::

    residual = max over such intervals, over both axes, of
               max |d(t) − d_settled|   for t from the interval's start to half a period
                                        before its end,
    d_settled = mean of d over that last half period.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["MIN_PERIODS", "QUIET", "quiet_intervals", "residual_vibration"]

MIN_PERIODS = 1.5
"""Shortest quiet interval that is judged (mode periods): its last half period is the
settled value, the first period the vibration."""

QUIET = 1e-6
"""A reference acceleration at or below this counts as none (m/s²)."""


def quiet_intervals(t, acceleration, shortest: float) -> list[tuple[float, float]]:
    """The intervals ``(start, end)`` (s) during which ``|acceleration| ≤ QUIET`` for at
    least ``shortest`` (s); ``t`` (n,) the sample times, ``acceleration`` (n,)."""
    t = np.asarray(t, dtype=float)
    quiet = np.abs(np.asarray(acceleration, dtype=float)) <= QUIET
    if not quiet.any():
        return []
    edges = np.diff(np.concatenate(([0], quiet.view(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends, strict=True)
            if t[b] - t[a] >= shortest]


def residual_vibration(t, acceleration, fine_t, deflection, periods: Sequence[float]
                       ) -> float:
    """Largest residual vibration of the deflection (m; see the module docstring).

    Parameters
    ----------
    t : array_like, shape (n,)
        Controller ticks (s).
    acceleration : array_like, shape (n, 2)
        The reference acceleration of x and y the regulator followed (m/s²), after the
        shapers.
    fine_t : array_like, shape (m,)
        Times of the deflection samples (s), increasing.
    deflection : array_like, shape (m, 2)
        Screw or belt deflection of x and y (m).
    periods : sequence of 2 float
        Period of each axis' first elastic mode (s).

    Returns
    -------
    float
        0 when no interval is long enough.
    """
    acc = np.asarray(acceleration, dtype=float).reshape(-1, 2)
    ft = np.asarray(fine_t, dtype=float)
    d = np.asarray(deflection, dtype=float).reshape(-1, 2)
    worst = 0.0
    for k in range(2):
        half = 0.5 * periods[k]
        for start, end in quiet_intervals(t, acc[:, k], MIN_PERIODS * periods[k]):
            i0, i1, i2 = np.searchsorted(ft, (start, end - half, end))
            if i2 - i1 < 1 or i1 <= i0:
                continue
            settled = float(np.mean(d[i1:i2, k]))
            worst = max(worst, float(np.max(np.abs(d[i0:i1, k] - settled))))
    return worst
