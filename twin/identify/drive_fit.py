"""The drive as it is: its speed regulator, its reference filter, and whether its current
regulator adapts to discontinuous conduction.

The candidate machine carries the drive's settings (``replay.candidate``); these stages
fit them on the replayed speed steps and PRBS, where the speed loop works below its current
limit. There the loop sees its gain only over the inertia (K_p·k·K_C/J: the current
reference a speed error asks for, over the inertia it accelerates), its integral time and
the reference filter; the inertia on its own comes from the current-limited reversals
(``fit._scan_scale``), where the drive gives k·I_m whatever its gain.

How the current regulator is built — digital with the adaptation to discontinuous
conduction, digital without it, or analog (continuous PI, no adaptation) — is a property of
the drive, so it is chosen, not fitted: the speed-loop stage is run for each model
(``MODELS``), and the one whose replay is better by a margin (a difference in BIC over
both axes, (SSE_1 − SSE_0)/(s²·τ) with the residuals' variance ``profile.noise_variance``
and autocorrelation time τ, above ``DECISIVE``) is taken;
the models have the same fitted parameters, so the BIC difference is the likelihood ratio.
Each model is first replayed with the staged speed loop at the best of a coarse mains-phase
scan (``_screen``); one that is ``SCREEN`` worse there is not fitted (its screen's BIC is
reported, marked): the speed loop the fit would adjust is the same in every model.
The adaptation is decided first (the best model with it against the best without); below
the margin BASE's choice is kept and reported as undecided.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twin.config import MachineConfig
from twin.drive.design import design
from twin.identify.lsq import scan_mains_phase, solve
from twin.identify.parallel import split_map
from twin.identify.profile import autocorrelation_time, noise_variance
from twin.identify.replay import AxisParams, Problem

__all__ = ["CURRENT_LOOP", "DECISIVE", "MODELS", "SPEED_LOOP", "DcmDecision", "fit_speed_loop",
           "model_of"]

SPEED_LOOP = ["speed_kp_rel", "speed_ti", "reference_filter"]
"""The coordinates of the speed-loop stage: the gain over the inertia, the integral time,
the reference filter."""

CURRENT_LOOP = ["current_kp", "current_ti", "brush_drop"]
"""What a drive without the adaptation to discontinuous conduction also shows at feed
speeds, where the current flows in pulses: the current regulator's gain and integral
time and the brush drop (fitted after the choice, where the chosen model has no
adaptation; with it the current loop is linearised and ten times faster than the speed
loop, and they are kept from BASE)."""

DECISIVE = 6.0
"""BIC difference above which the data decide between models of the current regulator
(``strong`` evidence on the usual scale)."""


MODELS = {"digital, DCM adaptation": (0.0, 1.0), "digital, no DCM adaptation": (0.0, 0.0),
          "analog": (1.0, 0.0)}
"""The current regulator's models the fit chooses among: name → (analog, dcm_compensation).
An analog drive's firing unit has no adaptation (arccos firing)."""


def model_of(p: AxisParams) -> str:
    """The name of the current regulator's model ``p`` carries."""
    if p.analog > 0.5:
        return "analog"
    return "digital, DCM adaptation" if p.dcm_compensation > 0.5 else \
        "digital, no DCM adaptation"


@dataclass(frozen=True)
class DcmDecision:
    """The current regulator's model chosen for one axis.

    Attributes
    ----------
    model : str
        The chosen model (``MODELS``).
    bic : dict of str to float
        Per model: its BIC less the chosen one's (0 for the chosen; n_eff·ln(SSE/SSE_min)).
    decided : bool
        Whether the data decide the adaptation (with it, or without): the BIC of the best
        model of one kind is ``DECISIVE`` below the other kind's. Undecided, BASE's kind
        is kept. Within the kind, BASE's model is kept unless another is ``DECISIVE``
        better.
    screened : tuple of str
        Models not fitted: replayed with the staged speed loop, their BIC was ``SCREEN``
        above the best's (their ``bic`` is that screen's).
    """

    model: str
    bic: dict[str, float]
    decided: bool
    screened: tuple[str, ...] = ()

    def bic_text(self) -> str:
        """The BIC of each model over the chosen one's, for people (the models screened
        out marked as such)."""
        return ", ".join(f"{m} {b:+.1f}" + (" (screened out, not fitted)"
                                            if m in self.screened else "")
                         for m, b in self.bic.items())

    @property
    def present(self) -> bool:
        """The chosen model adapts to discontinuous conduction."""
        return MODELS[self.model][1] > 0.5


def fit_speed_loop(problem: Problem, params: dict[str, AxisParams],
                   start: dict[str, AxisParams], mask: np.ndarray, *, max_nfev: int = 4
                   ) -> tuple[dict[str, AxisParams], dict[str, DcmDecision]]:
    """The speed-loop settings for each model of the current regulator (``MODELS``) on the
    ticks of ``mask``, each with its own mains phase (``lsq.scan_mains_phase``: a drive
    without the adaptation replays well only near its phase); the model is chosen for the
    machine (the axes share the mains and, on one machine, the kind of drive) by the summed
    BIC; a model without the adaptation is fitted with its current-loop settings and brush
    drop too (``CURRENT_LOOP``), so that it is compared at its best. Returns the
    parameters per axis and the decisions; the problem's mains phase is the chosen
    model's.

    Every model is first replayed as it stands (``_screen``: the staged speed loop, a
    coarse mains-phase scan); one whose BIC there is ``SCREEN`` above the best's is not
    fitted: fitting the speed loop, which every model shares, does not close such a gap
    (on tomsk_xy it is 2700-6400, where the choice is made with 6)."""
    screened = _screen(problem, params, mask)
    fits = {}
    for name, (analog, dcm) in MODELS.items():
        if name not in screened.kept:
            continue
        trial = {a: _as_model(p, problem.base, a, analog, dcm) for a, p in params.items()}
        scan_mains_phase(problem, trial)   # the full scan: as if no model were screened
        coords = SPEED_LOOP if dcm > 0.5 else SPEED_LOOP + CURRENT_LOOP
        sol = solve(problem, trial, coords, mask, start, max_nfev=max_nfev)
        fits[name] = (sol, problem.mains_phase)
    axes = problem.axes
    total = {m: sum(f[0].sse(a) for a in axes) for m, f in fits.items()}
    best = min(total, key=total.get)
    res = np.concatenate([fits[best][0].res[a] for a in axes])
    scale = noise_variance(res, 0) * autocorrelation_time(res, channels=2 * len(axes))
    bic = {m: (v - total[best]) / scale for m, v in total.items()}
    # first the adaptation (present or not), then, without it, how the drive is built
    base_model = model_of(params[axes[0]])
    adapted = [m for m in fits if MODELS[m][1] > 0.5]
    bare = [m for m in fits if MODELS[m][1] <= 0.5]
    if not adapted or not bare:   # the screen dropped a whole kind: decided there
        group, decided = adapted or bare, True
    else:
        with_, without = min(bic[m] for m in adapted), min(bic[m] for m in bare)
        if abs(with_ - without) >= DECISIVE:
            group = adapted if with_ < without else bare
            decided = True
        else:
            group = adapted if MODELS[base_model][1] > 0.5 else bare
            decided = False
    chosen = min(group, key=bic.get)
    if base_model in group and bic[base_model] - bic[chosen] < DECISIVE:
        chosen = base_model
    sol, problem.mains_phase = fits[chosen]
    bic.update({m: b for m, b in screened.bic.items() if m not in fits})
    decisions = {a: DcmDecision(chosen, bic, decided, screened.dropped) for a in axes}
    return {**params, **sol.params}, decisions


SCREEN = 20.0 * DECISIVE
"""BIC above the best model's, all replayed with the staged speed loop, beyond which a
model of the current regulator is not fitted (``fit_speed_loop``)."""

SCREEN_GRID = 12
"""Mains phases per pulse period of the screen's scan (the models fitted are scanned again
in full, as ``fit_speed_loop`` scans them)."""


@dataclass(frozen=True)
class _Screened:
    kept: tuple[str, ...]
    dropped: tuple[str, ...]
    bic: dict[str, float]


def _screen(problem: Problem, params: dict[str, AxisParams], mask: np.ndarray) -> _Screened:
    """Each model of ``MODELS`` replayed with the speed loop as staged, at the best mains
    phase of a coarse scan (``SCREEN_GRID``), on the ticks of ``mask``: its BIC over the
    best's, and the models within ``SCREEN`` of it."""
    def one(name: str) -> tuple[float, np.ndarray]:
        analog, dcm = MODELS[name]
        trial = {a: _as_model(p, problem.base, a, analog, dcm) for a, p in params.items()}
        problem.mains_phase = None
        scan_mains_phase(problem, trial, steps=SCREEN_GRID, golden=0)
        r = problem.residuals(trial, mask)
        return (sum(float(v @ v) for v in r.values()),
                np.concatenate([r[a] for a in problem.axes]))

    # the models are independent: side by side where two processes may run (their scans
    # are then one after the other in each)
    sse = dict(zip(MODELS, split_map(problem, one, list(MODELS)), strict=True))
    best = min(sse, key=lambda m: sse[m][0])
    res = sse[best][1]
    scale = noise_variance(res, 0) * autocorrelation_time(res, channels=2 * len(problem.axes))
    bic = {m: (v[0] - sse[best][0]) / scale for m, v in sse.items()}
    kept = tuple(m for m in MODELS if bic[m] <= SCREEN)
    return _Screened(kept, tuple(m for m in MODELS if m not in kept), bic)


def _as_model(p: AxisParams, base: MachineConfig, axis: str, analog: float, dcm: float
              ) -> AxisParams:
    """``p`` with the current regulator's model (analog, DCM adaptation) and, where the model
    changes, the current loop's settings that BASE's drive built that way would have
    (``design``: an analog drive's converter lag differs), the speed loop's as fitted."""
    if (p.analog, p.dcm_compensation) == (analog, dcm):
        return p
    kind = "analog" if analog > 0.5 else "digital"
    built = base.with_overrides({f"axes.{axis}.regulators.implementation": kind,
                                 f"axes.{axis}.converter.dcm_compensation": dcm > 0.5})
    d = design(built.axes[axis], moving_mass=built.moving_masses()[axis])
    return p.with_(analog=analog, dcm_compensation=dcm, current_kp=d.current_kp,
                   current_ti=d.current_ti, current_designed=1.0 if dcm > 0.5 else 0.0)
