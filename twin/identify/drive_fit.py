"""The drive as it is: its speed regulator, its reference filter, and whether its current
regulator adapts to discontinuous conduction.

The candidate machine carries the drive's settings (``replay.candidate``); these stages
fit them on the replayed speed steps and PRBS, where the speed loop works below its current
limit. There the loop sees its gain only over the inertia (K_p·k·K_C/J: the current
reference a speed error asks for, over the inertia it accelerates), its integral time and
the reference filter; the inertia on its own comes from the current-limited reversals
(``fit._scan_scale``), where the drive gives k·I_m whatever its gain.

The adaptation to discontinuous conduction is a yes-or-no property of the drive, so it is
chosen, not fitted: the speed-loop stage is run for both models, and the one whose replay
is better by a margin (a difference in BIC, n_eff·ln(SSE_1/SSE_0) with the effective number
of samples, above ``DECISIVE``) is taken; the two have the same fitted parameters, so the
BIC difference is the likelihood ratio. Below the margin BASE's choice is kept and the
decision is reported as undecided.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.identify.lsq import solve
from twin.identify.profile import autocorrelation_time
from twin.identify.replay import AxisParams, Problem

__all__ = ["DECISIVE", "SPEED_LOOP", "DcmDecision", "fit_speed_loop"]

SPEED_LOOP = ["speed_kp_rel", "speed_ti", "reference_filter"]
"""The coordinates of the speed-loop stage: the gain over the inertia, the integral time,
the reference filter."""

DECISIVE = 10.0
"""BIC difference above which the data decide between the two models of the current
regulator (``very strong`` evidence on the usual scale)."""


@dataclass(frozen=True)
class DcmDecision:
    """The model choice for one axis.

    Attributes
    ----------
    present : bool
        The chosen model: the adaptation present.
    bic : float
        BIC(without) − BIC(with): positive favours the adaptation.
    decided : bool
        False: the difference is below ``DECISIVE`` (BASE's choice kept).
    """

    present: bool
    bic: float
    decided: bool


def fit_speed_loop(problem: Problem, params: dict[str, AxisParams],
                   start: dict[str, AxisParams], mask: np.ndarray, *, max_nfev: int = 6
                   ) -> tuple[dict[str, AxisParams], dict[str, DcmDecision]]:
    """The speed-loop settings for both current-regulator models on the ticks of ``mask``;
    returns the parameters of the chosen model per axis and the decisions."""
    fits, costs = {}, {}
    for present in (True, False):
        trial = {a: p.with_(dcm_compensation=1.0 if present else 0.0)
                 for a, p in params.items()}
        sol = solve(problem, trial, SPEED_LOOP, mask, start, max_nfev=max_nfev)
        fits[present] = sol
        costs[present] = {a: sol.sse(a) for a in problem.axes}
    out, decisions = dict(params), {}
    for a in problem.axes:
        res = fits[True].res[a]
        n_eff = len(res) / autocorrelation_time(res)
        with_, without = costs[True][a], costs[False][a]
        bic = n_eff * math.log(max(without, 1e-300) / max(with_, 1e-300))
        decided = abs(bic) >= DECISIVE
        present = bic > 0.0 if decided else params[a].dcm_compensation > 0.5
        decisions[a] = DcmDecision(present, bic, decided)
        out[a] = fits[present].params[a]
    return out, decisions
