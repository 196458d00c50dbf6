"""The reference compensations of a machine (``[controller.compensation]``).

A machine file::

    [controller.compensation]
    smoothing = true        # undo the shapers' and the position loop's curve shrink
    stretch = true          # lead the motor by the transmission's believed stretch
    reversal_band = 2.0e-3  # m/s: the speed over which the friction part flips

Both act on the interpolated reference before the input shapers, from the controller's
belief only (``twin.controller.compensation``); both are off by default.
"""

from __future__ import annotations

from dataclasses import dataclass

from twin.config.fields import Validated, flag, num

__all__ = ["CompensationSettings"]


@dataclass(frozen=True, kw_only=True)
class CompensationSettings(Validated):
    """Feed-forward offsets of the position reference (``twin.controller.compensation``)."""

    smoothing: bool = flag(False, "offset the reference by −(σ²/2)·a_n on curves: the "
                           "shapers' and the believed position loop's shrink of a curve "
                           "(σ² the variance of their impulse responses, a_n the reference's "
                           "normal acceleration)")
    stretch: bool = flag(False, "lead the motor by the believed transmission's stretch "
                         "(m·a_n + b·v + F_c·sign v)/k per axis: the quasi-static stretch on "
                         "curves and the friction's, which flips where an axis reverses")
    reversal_band: float = num(2e-3, "m/s", display="mm/s", gt=0.0, le=1.0,
                               doc="axis speed over which the friction part of the "
                               "stretch compensation ramps from one sign to the other")
