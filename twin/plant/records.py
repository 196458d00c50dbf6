"""The plant's per-period records and its switch monitor: what a step reports
(``StepStatus``), what only a twin knows (``Truth``, ``TRUTH_FIELDS``), and the debounced
limit and home switches of one axis. What I/O hardware reads is the controller's own
``Inputs`` (`twin.controller.io`): one sample type on both sides of the port."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from twin.config import SwitchConfig

__all__ = ["FINE_FIELDS", "FINE_WIDTH", "FLAGS", "TRUTH_FIELDS", "AxisMonitor", "StepStatus",
           "Truth"]

TRUTH_FIELDS = (("table_position", 2), ("table_velocity", 2), ("screw_deflection", 2),
                ("armature_current", 2), ("converter_voltage", 2))
"""The twin's truth channels of :meth:`Plant.truth_row`, for a per-tick record (m, m/s, m, A,
V; x then y)."""


FINE_FIELDS = (("table_position", 2), ("armature_current", 2), ("converter_voltage", 2),
               ("conduction", 2), ("screw_deflection", 2), ("t", 1))
"""The twin's drive-rate channels (:attr:`Plant.fine`), sampled at the end of every drive
interval (m, A, V, 1, m; x then y): the armature current at the sample, the converter
voltage averaged over the interval (the motor terminal voltage: the EMF while no current
flows), and ``conduction``, the fraction of the interval during which current flowed (below
1: discontinuous conduction), and the plant time at the sample (s)."""

FINE_WIDTH = sum(width for _, width in FINE_FIELDS)


def _frozen(pair: tuple[bool, bool]) -> np.ndarray:
    flags = np.array(pair)
    flags.setflags(write=False)
    return flags


FLAGS = tuple(_frozen((a, b)) for a in (False, True) for b in (False, True))
"""The four per-axis flag pairs, read-only and shared: ``FLAGS[2·x + y]``. The status of
every step picks from them instead of allocating arrays on the per-period path."""


class StepStatus(NamedTuple):
    """What happened during one :meth:`Plant.step` (arrays indexed by axis x, y). An
    immutable tuple: one is made every period, and a tuple is the cheapest record.

    Attributes
    ----------
    saturated : ndarray, shape (2,), bool
        The DAC command was outside its range and was clipped. (The flag arrays are
        read-only and shared between statuses.)
    limit_hit : ndarray, shape (2,), bool
        An end limit switch (min or max, debounced) was closed during the step.
    end_stop : ndarray, shape (2,), bool
        The table reached the mechanical end of its travel during the step.
    drive_fault : ndarray, shape (2,), bool
        The drive's latched overload trip at the end of the step.
    warnings : tuple of str
        MuJoCo warnings raised during the step (``mjWARN_*`` names).
    time : float
        Plant time at the end of the step (s).
    """

    saturated: np.ndarray
    limit_hit: np.ndarray
    end_stop: np.ndarray
    drive_fault: np.ndarray
    warnings: tuple[str, ...]
    time: float

    @property
    def ok(self) -> bool:
        """Nothing to report: no saturation, limit, end stop, fault or warning."""
        return not (self.saturated.any() or self.limit_hit.any() or self.end_stop.any()
                    or self.drive_fault.any() or self.warnings)


@dataclass(frozen=True, slots=True)
class Truth:
    """The twin's full state (arrays shape (2,), indexed by axis x, y).

    Attributes
    ----------
    table_position, table_velocity : ndarray
        Carriage position (m) and velocity (m/s).
    rotor_angle, rotor_speed : ndarray
        Motor shaft angle (rad) and speed (rad/s).
    screw_deflection : ndarray
        Deflection of the axial (screw) spring referred to the table (m), positive when
        the screw pushes the table forward: r·θ − x of the two-mass chain (the whole
        transmission), r_s·θ_s − x of the three-mass one (screw shaft, nut and bearing;
        the gear's twist r·θ − r_s·θ_s is not in it).
    armature_current, converter_voltage, speed_reference : ndarray
        Motor current (A), converter voltage averaged over the last drive interval (the
        motor terminal voltage, V), filtered speed reference (V).
    firing_angle, bridge : ndarray
        Thyristor firing angle (rad; NaN for PWM or blocked pulses); conducting converter
        (int64: +1 forward, −1 reverse, 0 blocked).
    time : float
        Plant time (s).
    """

    table_position: np.ndarray
    table_velocity: np.ndarray
    rotor_angle: np.ndarray
    rotor_speed: np.ndarray
    screw_deflection: np.ndarray
    armature_current: np.ndarray
    converter_voltage: np.ndarray
    firing_angle: np.ndarray
    bridge: np.ndarray
    speed_reference: np.ndarray
    time: float


class AxisMonitor:
    """Switches and end stops of one axis, from the table position sampled at the end of
    every drive interval.

    Switch channels 0, 1, 2 = limit_min, limit_max, home. A raw change must persist for
    ``debounce`` seconds of samples before the output follows it (``update``: the rule,
    sample by sample). ``quick`` answers from the samples' range alone in the common case:
    the plant's every period, far from any switch edge.
    """

    __slots__ = ("debounce", "edges", "free", "hit", "home", "limit_max", "limit_min",
                 "pending", "quiet", "state", "travel", "width")

    def __init__(self, sw: SwitchConfig, travel: tuple[float, float]):
        self.limit_min, self.limit_max = sw.limit_min, sw.limit_max
        self.home, self.width = sw.home, sw.home_width / 2.0
        # where a raw state changes (switch bounds) or an end stop begins (ends of travel)
        self.edges = (sw.limit_min, sw.limit_max, sw.home - self.width, sw.home + self.width,
                      *travel)
        self.debounce = sw.debounce - 1e-12  # absorb the float error of sample times
        self.travel = travel
        self.settle(math.inf)

    def raw(self, x: float) -> list[bool]:
        return [x <= self.limit_min, x >= self.limit_max, abs(x - self.home) <= self.width]

    def settle(self, x: float) -> None:
        """Outputs equal to the raw states at ``x``, nothing pending (after a reset)."""
        self.state = self.raw(x)
        self.pending = [math.nan, math.nan, math.nan]
        self.quiet = True  # nothing pending
        self._refresh(x)

    def _refresh(self, x: float) -> None:
        """Find ``free``: the open interval around ``x`` between two neighbouring edges
        (switch bounds, ends of travel), where the raw states are constant, if nothing is
        pending and the outputs equal those raw states (else an empty interval)."""
        self.hit = self.state[0] or self.state[1]
        edges = self.edges
        if not self.quiet or self.raw(x) != self.state or x != x or x in edges:
            self.free = (math.inf, -math.inf)
            return
        self.free = (max((e for e in edges if e < x), default=-math.inf),
                     min((e for e in edges if e > x), default=math.inf))

    def quick(self, lo: float, hi: float) -> tuple[bool, bool] | None:
        """``update``'s answer when every sample lies in [lo, hi] inside ``free`` (nothing
        can change: no switch edge, no end of travel, nothing pending), else None."""
        a, b = self.free
        if a < lo and hi < b:
            return self.hit, False
        return None

    def update(self, x: list[float], t0: float, dt: float) -> tuple[bool, bool]:
        """Feed samples ``x`` taken at t0 + dt·(1..n). Returns (an end limit switch was
        closed at the start or at any sample, the table reached an end of its travel)."""
        hit = self.state[0] or self.state[1]
        end_stop = min(x) <= self.travel[0] or max(x) >= self.travel[1]
        for i, xi in enumerate(x):
            t = t0 + dt * (i + 1)
            for ch, value in enumerate(self.raw(xi)):
                since = self.pending[ch]
                if value == self.state[ch]:
                    since = math.nan
                elif math.isnan(since):
                    since = t
                if not math.isnan(since) and t - since >= self.debounce:
                    self.state[ch], since = value, math.nan
                self.pending[ch] = since
            hit = hit or self.state[0] or self.state[1]
        self.quiet = all(math.isnan(p) for p in self.pending)
        self._refresh(x[-1])
        return hit, end_stop
