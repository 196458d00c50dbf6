"""Fit the twin's physical parameters to an identification log.

The fit simulates the twin itself — its drive kernel and MuJoCo mechanics, with candidate
parameters (``replay``) — under the DAC volts the log recorded, and compares encoder
positions and tacho volts (output error). It runs in stages, each on the experiment that
carries its parameters, then all of them together:

0. **Mains phase** (a nuisance): a thyristor drive's pulses depend on where the mains
   stood when the log began, which nothing records; a scan of one pulse period on the
   first steps picks it (the replay's floor drops a hundredfold). It is scanned again
   once the inertia is near.
1. **Gains, by regression** (``steps``): in every steady part of a speed step the speed
   loop holds ω = ((1 + g)·U + o)/K_C exactly (its integrator), and the tacho reads K_C·ω.
   Regressing the encoder's speed on the DAC volts and the tacho on the speed gives the
   tacho gain K_C, the DAC gain error g and offset o, hence K_H = r·(1 + g)/K_C.
2. **Friction over inertia** (``coast``): in the coast-downs the drive is off and
   J·dω/dt = −(T_c·sign ω + B·ω): a linear regression of the encoder's acceleration on
   [sign ω, ω] gives T_c/J and B/J.
3. **The drive as it is** (``steps``, ``prbs``; ``drive_fit``): the candidate carries the
   drive's own regulator settings (never derived again from the candidate's J, R, L), and
   the speed regulator's gain over the inertia, its integral time and the reference filter
   are fitted on the replayed steps and PRBS, for both models of the current regulator; the
   discontinuous-conduction adaptation is the model the BIC prefers.
4. **Inertia** (``steps``): the inertia, with the friction and the speed gain in
   proportion (``scale``: what the speed loop below its current limit cannot see), is
   scanned over 0.5 … 2 times the start and the current-limit estimate (the steepest tacho
   slopes of the large reversals give k·I_m/J where they reach the limit), then fitted with
   the armature resistance and the speed loop on the steps and PRBS (``lsq.solve``:
   ``scipy.optimize.least_squares``).
5. **Friction** (``coast``): Coulomb, viscous and break-away on the replayed coast-downs.
6. **Lost motion** (``crossings``): the motor positions of the home switch's edges, seen
   going up and coming down, differ by the lost motion, the screw's friction preload both
   ways (2·F/k, from the fitted friction and BASE's stiffness) and the debounce (2·v·t_d).
7. **Together** (``joint``): everything the replay carries in one last least squares on all
   replayed experiments, then each parameter's profile-likelihood interval (``profile``).
   What the data cannot separate is held at BASE's value and said so; what trades off with
   it is reported as identified only given it. Where every axis already keeps a systematic
   residual above ``MISFIT`` after the least squares, while the held-out experiment is
   predicted within ``QUALITY``, no profile is taken: those axes keep BASE's values anyway.

The axes are uncoupled, so each replay moves both: a finite-difference column of x and the
same column of y come from one simulation. The held-out experiment (``ramps``, closed loop)
is then predicted, and its normalised RMS error is the fit quality.

What the signals cannot give is never fitted (``NOT_IDENTIFIABLE``): the screw's stiffness
and damping, the screw body's geometry and the carriage masses, the split of friction
between rotor and slide, the motor's EMF constant and current limit (they scale with the
inertia), the tacho filter, the converter's mains data, the current regulator's settings
and the brush and thyristor drops.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from twin.config import AXES, MachineConfig
from twin.drive.design import design
from twin.errors import FitError
from twin.identify.direct import coast_regression, limit_inertia, lost_motion, regress_gains
from twin.identify.drive_fit import CURRENT_LOOP, SPEED_LOOP, DcmDecision, fit_speed_loop
from twin.identify.joint import TOLERANCE, joint_fit
from twin.identify.log import IdentLog
from twin.identify.lsq import (
    BOUNDS,
    Solution,
    coordinate,
    scan_mains_phase,
    solve,
    with_coordinate,
)
from twin.identify.parallel import cpu_time
from twin.identify.plan import FIT_EXPERIMENTS, HELD_OUT
from twin.identify.profile import systematic_variance
from twin.identify.replay import (
    NAMES,
    SIGMA_POSITION,
    SIGMA_TACHO,
    AxisParams,
    Problem,
    axis_figures,
    base_params,
    candidate,
)

__all__ = ["MISFIT", "NOT_EXCITED", "NOT_IDENTIFIABLE", "REPLAYED_PARAMS", "TOLERANCE", "Estimate",
           "Identification", "fit"]

QUALITY = 0.05
"""Largest held-out normalised RMS error of a fit whose replayed parameters are reported:
above it (a drive whose limit cycle the twin cannot follow tick by tick, a model the twin
lacks) the profile intervals describe a cost that is not the machine's, and every replayed
parameter keeps BASE's value, flagged."""

MISFIT = 0.015
"""Largest systematic part of an axis' residual variance (``profile.systematic_variance``,
in the scaled units of ``replay.SIGMA_POSITION`` and ``SIGMA_TACHO``: about 0.6 µm or
2.4 mV RMS in one channel alone) at the end of a fit whose replayed parameters are
reported. Above it the twin does not replay the machine to the level of its noise: the
least squares sit in a valley of the cost that is not the machine's (the mains phase and
the parameters wrong together: a full phase scan at the staged values prefers a wrong
phase), where the profile intervals, local to that valley, can be narrow and miss the truth;
every replayed parameter of that axis then keeps BASE's value, flagged. Measured (unseen
machine 11, hand-set speed loop; tomsk_xy's twin at amplitudes 1 and 0.3): the true
parameters replay their logs at 0.0003-0.0009, 0.005 on a Modbus log with one 75 ms
disturbance of x the twin cannot replay; fits whose intervals held the truth ended at
0.0004-0.0008, the fits whose intervals missed it at 0.044-3.5."""

CONVERGED = 0.25
"""Largest held-out normalised RMS error of a fit that converged at all: above it the fit
is refused (nothing is written), at the end and already after the staged fit."""

REPLAYED_PARAMS = ("inertia", "coulomb", "viscous", "breakaway", "resistance",
                   "inductance", "speed_kp", "speed_ti", "reference_filter", "current_kp",
                   "current_ti", "brush_drop")
"""The parameters the last stage fits together on the replayed experiments."""

NOT_IDENTIFIABLE = {
    "transmission.stiffness": "the motor encoder does not see the table move on the screw",
    "transmission.damping_ratio": "as the stiffness",
    "transmission screw body (screw_diameter, screw_length, screw_support, nut_start, "
    "drive_end)": "the screw's own inertia adds to the rotor's, which is fitted (with "
                  "BASE's screw); its stiffness along the travel as the stiffness",
    "mechanics.carriage_mass": "its reflected inertia is 0.1 % of the rotor's on tomsk_xy",
    "mechanics: rotor/slide split of friction": "only their sum acts on the motor",
    "motor.emf_constant, motor.current_limit_factor": "they scale with the inertia in "
                                                      "every current-limited motion",
    "tacho.filter_time_constant": "1 ms, far below the speed loop's response",
    "converter (line voltage, mains, firing limits)": "no signal of the converter's own",
    "converter thyristor drops, latching and holding currents": "they act with the brush "
        "drop, which stands for them",
}
"""Fields the encoder, tacho and DAC cannot recover, and why; kept from BASE."""

UNSEEN_CURRENT_LOOP = ("not fitted: with the DCM adaptation the current loop is linear and "
                       "ten times faster than the speed loop; the current regulator is the "
                       "modulus optimum of the fitted R and L, the brush drop BASE's")
"""The source of the current loop's values where the chosen drive model adapts."""

NOT_EXCITED = "not excited (held in position: --axes left it out); BASE's value kept"
"""The source of every value of an axis the experiments did not excite."""

_SOURCE = {"tacho_gain": "steps (steady speeds)", "gain_error": "steps (steady speeds)",
           "offset": "steps (steady speeds)",
           "inertia": "steps (current-limited reversals: k·I_m/J)",
           "coulomb": "coast (over J), with the inertia",
           "viscous": "coast (over J), steps, with the inertia",
           "breakaway": "coast (to rest), steps (starts from rest)",
           "backlash": "crossings (home switch)",
           "resistance": "steps (current rise), prbs", "inductance": "prbs",
           "speed_kp": "steps, prbs (below the limit: K_p/J), with the inertia",
           "speed_ti": "steps, prbs (the speed loop's integral response)",
           "reference_filter": "steps (the first rise of each step), prbs",
           "current_kp": "reversals, prbs (feed speeds: the current in pulses)",
           "current_ti": "reversals, prbs (feed speeds: the current in pulses)",
           "brush_drop": "reversals, prbs (feed speeds: the current in pulses)"}


@dataclass(frozen=True)
class Estimate:
    """One fitted value.

    Attributes
    ----------
    value : float
        The estimate (SI, or a multiplier of BASE for coulomb/viscous).
    low, high : float
        Its 95 % confidence interval.
    identifiable : bool
        False: the data do not pin it down (its interval is wider than ``TOLERANCE``).
    source : str
        The experiment(s) it comes from.
    kept : str
        Where the value comes from: ``"fit"``; ``"base"`` when it is not identifiable
        (BASE's value kept, the others fitted around it); ``"bound"`` when it is not
        identifiable and the data reject BASE's value: the end of its interval nearest to
        BASE's.
    given : tuple of str
        Not identifiable on its own: identified given these parameters (held), with which
        it trades off; its value is right relative to them.
    """

    value: float
    low: float
    high: float
    identifiable: bool
    source: str
    kept: str = "fit"
    given: tuple[str, ...] = ()


@dataclass
class Identification:
    """The outcome of ``fit``.

    Attributes
    ----------
    params : dict of str to AxisParams
        The identified parameters (BASE's where not identifiable).
    estimates : dict of str to dict of str to Estimate
        Per axis and parameter.
    calibrated : MachineConfig
        BASE with the identified fields replaced.
    nrmse : dict
        Held-out normalised RMS errors ``{axis: {"position": ., "tacho": .}}`` of the
        excited axes.
    residual : dict
        RMS residual of the fit experiments ``{axis: {"position_um": ., "tacho_v": .}}``
        of the excited axes.
    replays : int
        Simulations the fit ran.
    curves : dict of ndarray
        Measured and fitted positions and tacho volts of the replayed experiments.
    wall_time : float
        Wall time of the fit (s).
    """

    params: dict[str, AxisParams]
    estimates: dict[str, dict[str, Estimate]]
    calibrated: MachineConfig
    nrmse: dict[str, dict[str, float]]
    residual: dict[str, dict[str, float]]
    replays: int = 0
    wall_time: float = 0.0
    curves: dict[str, np.ndarray] = field(default_factory=dict)
    mains_phase: float | None = None
    """The log's mains phase the replays used (rad; None for PWM drives)."""
    cpu_time: float = 0.0
    """CPU time of the fit (s), its replay processes' included (``parallel``): its wall
    time on one core of its own."""
    dcm: dict[str, DcmDecision] = field(default_factory=dict)
    """Per excited axis: whether the drive's current regulator adapts to discontinuous
    conduction, as the model selection decided."""
    misfit: dict[str, float] = field(default_factory=dict)
    """Per excited axis: the systematic part of the fit experiments' residual variance at
    the end (``MISFIT``); where every axis was already above ``MISFIT`` after the joint
    least squares (no profile taken: ``joint.Joint.profiled``), the larger of that and the
    end's."""
    linear: dict[str, dict[str, float]] = field(default_factory=dict)
    """Per axis and replayed parameter: the linearised 95 % half-interval at the optimum
    (in the fitted coordinate), what the Jacobian alone would have said."""

    def derived(self) -> dict[str, dict[str, float]]:
        """K_H (m/(s·V)) and the total Coulomb and viscous friction at the motor
        (N·m, N·m·s/rad) per axis, of the calibrated machine: what the figures are quoted
        in."""
        keys = ("K_H", "coulomb_at_motor", "viscous_at_motor")
        return {a: {k: v[k] for k in keys} for a, v in axis_figures(self.calibrated).items()}


def fit(base: MachineConfig, log: IdentLog, *,
        progress: Callable[[str], None] | None = None) -> Identification:
    """Identify the twin's parameters from ``log`` (see the module docstring).

    Raises
    ------
    ConfigError
        The log does not fit ``base`` (another machine, incomplete).
    FitError
        The fit did not converge, or its parameters are not finite.
    """
    t0, cpu0 = time.perf_counter(), cpu_time()
    say = progress or (lambda _msg: None)
    log.check(base)
    problem = Problem(base, log)
    axes = problem.axes   # the others were held still: BASE's values are kept
    start = base_params(base)
    # 1. gains by regression (they do not depend on the mains phase)
    gains, gain_halfs = regress_gains(problem, base)
    params = {a: start[a].with_(**gains[a]) if a in axes else start[a] for a in AXES}
    say("gains: " + ", ".join(f"{a} K_C {gains[a]['tacho_gain']:.5g}" for a in axes))
    # 2. friction over inertia from the coast-downs (linear regression)
    ratios = coast_regression(problem, params)
    for a in axes:
        c, v = ratios[a]
        if math.isfinite(c) and c > 0.0 and math.isfinite(v) and v > 0.0:
            params[a] = params[a].with_(coulomb=c, viscous=v)
    # 3. the drive as it is: the speed loop below its current limit (gain over inertia,
    #    integral time, reference filter) for each model of the current regulator, and the
    #    model chosen; 4. then the inertia, with the friction and the gain in proportion
    #    (the current-limited reversals), and the armature resistance
    loop = log.experiment_mask(("steps", "prbs"))
    params, dcm = fit_speed_loop(problem, params, start,
                                 log.experiment_mask(("steps", "prbs", "reversals")))
    for a in axes:
        d = dcm[a]
        say(f"axis {a}: current regulator {d.model} "
            + ("" if d.decided else "UNDECIDED, BASE's kept ")
            + f"(BIC over the best: {d.bic_text()})")
    steps = log.experiment_mask("steps")
    params = _scan_scale(problem, params, start, steps, limit_inertia(problem, params))
    params = solve(problem, params, ["scale", "resistance", *SPEED_LOOP], loop, start,
                   max_nfev=6).params
    scan_mains_phase(problem, params, near=3)   # the phase moves little with the inertia
    say("inertia: " + ", ".join(f"{a} {params[a].inertia:.4g} kg·m²" for a in axes)
        + f" ({problem.replays} replays, {cpu_time() - cpu0:.0f} s CPU)")
    # 5. friction: the coast-downs (friction alone)
    coast = log.experiment_mask("coast")
    params = solve(problem, params, ["coulomb", "viscous", "breakaway"], coast, start,
                   max_nfev=4).params
    # 6. lost motion from the home switch
    lost = lost_motion(problem, params)
    for a in axes:
        if math.isfinite(lost[a][0]):
            params[a] = params[a].with_(backlash=lost[a][0])
    say("lost motion: " + ", ".join(f"{a} {1e6 * params[a].backlash:.1f} µm" for a in axes)
        + f" ({problem.replays} replays, {cpu_time() - cpu0:.0f} s CPU)")
    # the staged fit must already predict the held-out experiment roughly (within twice
    # the final bound): the last stage refines the values, it does not rescue a log the
    # twin cannot replay at all, and it is most of the fit's time
    fit_mask = log.experiment_mask(FIT_EXPERIMENTS)
    _held_out(problem, params, fit_mask, bound=2.0 * CONVERGED)
    # 7. everything the replay carries, together, with the profile intervals
    names = list(REPLAYED_PARAMS)   # quantities; fitted in profile.own_coordinate
    if all(dcm[a].present for a in axes):   # the current loop is unseen (drive_fit)
        names = [n for n in names if n not in CURRENT_LOOP]
    say("joint fit: " + ", ".join(names) + " (least squares on the replayed experiments, "
        "then each one's profile interval) …")
    joint = joint_fit(problem, params, names, fit_mask, start,
                      unprofiled=lambda sol: _declared(problem, {**params, **sol.params},
                                                       sol, fit_mask))
    params = {**params, **joint.params}
    _report_joint(joint, axes, say)
    estimates, final = _estimates(problem, params, start, names, joint, gain_halfs, lost,
                                  say)
    if not all(math.isfinite(v) for p in final.values() for v in p.to_dict().values()):
        raise FitError("the fit ran away: a parameter is not finite")
    calibrated = candidate(base, final)
    masses = calibrated.moving_masses()
    for a in axes:   # the current regulator not fitted: what the calibrated drive has
        d = design(calibrated.axes[a], moving_mass=masses[a])
        for name in ("current_kp", "current_ti"):
            if estimates[a][name].source == UNSEEN_CURRENT_LOOP:
                estimates[a][name] = dataclasses.replace(estimates[a][name],
                                                         value=getattr(d, name))
    (pos, tacho), residual, nrmse, misfit = _judge(problem, estimates, final, start, names,
                                                   joint, fit_mask, say, cpu0)
    n = len(pos)
    calibrated = candidate(base, final)
    curves = {"t": log.data["t"][:n], "pos_meas": problem.pos[:n], "pos_fit": pos,
              "tacho_meas": problem.tacho[:n], "tacho_fit": tacho}
    result = Identification(final, estimates, calibrated, nrmse, residual, problem.replays,
                            time.perf_counter() - t0, curves)
    result.mains_phase = problem.mains_phase
    result.linear = joint.linear
    result.dcm = {a: dcm[a] for a in axes}
    result.cpu_time = cpu_time() - cpu0
    result.misfit = misfit
    return result


def _report_joint(joint, axes: tuple[str, ...], say: Callable[[str], None]) -> None:
    """Say what the joint fit could not pin down: no profiles (every axis above the misfit
    limit), the values held and how, the values identified only given others."""
    if not joint.profiled:
        say("no profile intervals: every axis stays above the misfit limit after the "
            "least squares (" + ", ".join(f"{a} {_misfit_text(joint.misfit[a])}"
                                          for a in axes) + ")")
    if any(joint.held[a] for a in axes):
        say("not pinned down by these experiments: " + "; ".join(
            f"{a} {', '.join(sorted(joint.held[a]))}" for a in axes if joint.held[a])
            + "; the others fitted again around them")
    for a in axes:
        for n, how in joint.held[a].items():
            say(f"warning: axis {a}: {n} is not identifiable from these experiments "
                f"(amplitude too low, or not excited); "
                + ("BASE's value kept" if how == "base" else
                   "the value nearest BASE's the data allow kept"))
        for n, held in joint.given[a].items():
            say(f"warning: axis {a}: {n} is identified only given {', '.join(held)} "
                f"(held): its value is right relative to it, not on its own")


def _estimates(problem: Problem, params: dict[str, AxisParams],
               start: dict[str, AxisParams], names: list[str], joint, gain_halfs: dict,
               lost: dict, say: Callable[[str], None]
               ) -> tuple[dict[str, dict[str, Estimate]], dict[str, AxisParams]]:
    """Per axis the estimates of a fit (the regressions' halves, the joint fit's profile
    intervals, the lost motion's) and its final parameters: an axis held still keeps
    BASE's, a lost motion the home switch does not pin down keeps BASE's (and says so)."""
    axes = problem.axes
    estimates: dict[str, dict[str, Estimate]] = {}
    final = {}
    for a in AXES:
        if a not in axes:
            estimates[a] = {name: Estimate(getattr(start[a], name), math.nan, math.nan,
                                           False, NOT_EXCITED, "base") for name in NAMES}
            final[a] = start[a]
            continue
        est: dict[str, Estimate] = {}
        p = params[a]
        for name in ("tacho_gain", "gain_error", "offset"):
            v, h = getattr(p, name), gain_halfs[a][name]
            est[name] = Estimate(v, v - h, v + h, True, _SOURCE[name])
        for name in names:
            lo, hi = joint.intervals[a][name]
            x = coordinate(p, start[a], name)
            held = joint.held[a].get(name)
            if held is None:   # the interval of a re-fitted value: widened to hold it
                lo = min(lo, x) if math.isfinite(lo) else lo
                hi = max(hi, x) if math.isfinite(hi) else hi
            est[name] = Estimate(getattr(p, name), _value(p, start[a], name, lo),
                                 _value(p, start[a], name, hi),
                                 held is None and name not in joint.given[a]
                                 and joint.profiled, _SOURCE[name],
                                 held or "fit", joint.given[a].get(name, ()))
        for name in REPLAYED_PARAMS:
            if name not in names:   # not fitted: the chosen drive model does not show it
                est[name] = Estimate(getattr(p, name), math.nan, math.nan, False,
                                     UNSEEN_CURRENT_LOOP, "base")
        if not est["coulomb"].identifiable:   # the preload is then uncertain as a whole
            again = lost_motion(problem, {**params, a: p}, {a: False})
            b, h = lost[a][0], again[a][1]
        else:
            b, h = lost[a]
        ok = math.isfinite(b) and h <= TOLERANCE["backlash"]
        if not ok:
            p = p.with_(backlash=start[a].backlash)
            say(f"warning: axis {a}: the lost motion is not identifiable from the home "
                f"switch's edges; BASE's value kept")
        est["backlash"] = Estimate(p.backlash, max(b - h, 0.0) if ok else math.nan,
                                   b + h if ok else math.nan, ok, _SOURCE["backlash"],
                                   "fit" if ok else "base")
        estimates[a] = est
        final[a] = p
    return estimates, final


def _judge(problem: Problem, estimates: dict[str, dict[str, Estimate]],
           final: dict[str, AxisParams], start: dict[str, AxisParams], names: list[str],
           joint, fit_mask: np.ndarray, say: Callable[[str], None], cpu0: float):
    """The fit's quality: the held-out prediction and each axis' misfit; every replayed
    parameter keeps BASE's value, flagged, where the twin does not replay the machine
    (``QUALITY``) or an axis of it (``MISFIT``). Returns the held-out replay (position,
    tacho), the fit experiments' residual, the NRMSE and the misfit per axis."""
    axes = problem.axes
    # fit quality: the fit experiments' residual, and the held-out prediction
    (pos, tacho), residual, nrmse = _held_out(problem, final, fit_mask)
    worst = max(max(v.values()) for v in nrmse.values())
    say(f"held out: NRMSE {100 * worst:.2f} % ({problem.replays} replays, "
        f"{cpu_time() - cpu0:.0f} s CPU)")
    res = problem.residuals(final, fit_mask)   # the replay just run: kept, not re-run
    misfit = {a: systematic_variance(res[a]) for a in axes}
    if not joint.profiled:   # above the limit already after the least squares, unprofiled
        misfit = {a: max(misfit[a], joint.misfit[a]) for a in axes}
    if worst > QUALITY:   # the twin does not replay this machine: no value to trust
        why = (f"the fitted twin predicts the held-out {HELD_OUT} with a normalised RMS "
               f"error of {100 * worst:.1f} % (above {100 * QUALITY:.0f} %): it does not "
               f"replay this machine; BASE's value kept")
        say(f"warning: {why}, for every replayed parameter")
        _keep_base(estimates, final, start, axes, names, why)
    for a in (a for a in axes if worst <= QUALITY and misfit[a] > MISFIT):
        why = (f"the fitted twin does not replay axis {a} to the level of its noise: it "
               f"stays {_misfit_text(misfit[a])} from the recorded signals (limit "
               f"{_misfit_text(MISFIT)}), a valley of the cost that is not the machine's, "
               "where an interval would not hold the truth; BASE's value kept")
        say(f"warning: axis {a}: {why}, for every replayed parameter")
        _keep_base(estimates, final, start, [a], names, why)
    return (pos, tacho), residual, nrmse, misfit


def _declared(problem: Problem, params: dict[str, AxisParams], sol: Solution,
              fit_mask: np.ndarray) -> bool:
    """Every excited axis of the joint least squares' solution ``sol`` (``params``) would
    keep BASE's values for its residual's systematic part (above ``MISFIT``), while the
    held-out experiment is predicted within ``QUALITY``: profiles would be thrown away.
    (A prediction worse than that is given the profiles: a point of theirs below the
    optimum restarts the fit.) The held-out replay is the one the fit's end reuses."""
    if not all(systematic_variance(sol.res[a]) > MISFIT for a in problem.axes):
        return False
    try:
        _, _, nrmse = _held_out(problem, params, fit_mask)
    except FitError:
        return False
    return max(max(v.values()) for v in nrmse.values()) <= QUALITY


def _keep_base(estimates: dict[str, dict[str, Estimate]], final: dict[str, AxisParams],
               start: dict[str, AxisParams], axes: Sequence[str], names: Sequence[str],
               why: str) -> None:
    """Every replayed parameter of ``axes`` back to BASE's value, flagged not identifiable
    for the reason ``why``, without an interval (the cost it came from is not the
    machine's) (in place)."""
    for a in axes:
        for name in names:
            estimates[a][name] = dataclasses.replace(
                estimates[a][name], value=getattr(start[a], name), low=math.nan,
                high=math.nan, identifiable=False, source=why, kept="base", given=())
        final[a] = final[a].with_(**{n: getattr(start[a], n) for n in REPLAYED_PARAMS})


def _misfit_text(variance: float) -> str:
    """A systematic residual variance (scaled units) as the RMS of position and tacho it
    stands for, each channel alone (µm, mV)."""
    r = math.sqrt(2.0 * variance)
    return f"{1e6 * r * SIGMA_POSITION:.2g} µm or {1e3 * r * SIGMA_TACHO:.2g} mV RMS"


SCALE_GRID = tuple(2.0 ** (k / 3.0) for k in range(-3, 4))
"""Inertia factors (friction in proportion) tried before the local fit: 0.5 … 2."""


def _scan_scale(problem: Problem, params: dict[str, AxisParams],
                start: dict[str, AxisParams], mask: np.ndarray,
                limit: dict[str, float]) -> dict[str, AxisParams]:
    """The inertia (friction in proportion) that best replays ``mask`` of ``SCALE_GRID``
    times the present one and the current-limit estimate (``direct.limit_inertia``), per
    axis. The local fit starts from it: started from the current-limit estimate alone it
    stayed, at amplitude 0.3 (the limit never reached), in a valley where the armature
    resistance made up for an inertia twice the truth."""
    tries = [{a: p.inertia * f for a, p in params.items()} for f in SCALE_GRID]
    if any(math.isfinite(v) and v > 0.0 for v in limit.values()):
        tries.append({a: limit[a] if math.isfinite(limit.get(a, math.nan))
                      and limit[a] > 0.0 else params[a].inertia for a in params})
    best = {a: (math.inf, params[a]) for a in problem.axes}
    for j in tries:
        trial = {a: with_coordinate(p, start[a], "scale", math.log(j[a] / start[a].inertia))
                 if a in problem.axes else p for a, p in params.items()}
        res = problem.residuals(trial, mask)
        for a in problem.axes:
            cost = float(res[a] @ res[a])
            if cost < best[a][0]:
                best[a] = (cost, trial[a])
    return {**params, **{a: b[1] for a, b in best.items()}}


def _held_out(problem: Problem, params: dict[str, AxisParams], fit_mask: np.ndarray, *,
              bound: float = CONVERGED):
    """Replay ``params`` through the held-out experiment: ((positions, tacho volts), the
    fit experiments' RMS residual and the held-out normalised RMS errors, per excited axis).

    Raises
    ------
    FitError
        The held-out prediction is worse than ``bound``."""
    held = problem.log.experiment_mask(HELD_OUT)
    pos, tacho = problem.simulate(params, int(np.flatnonzero(held)[-1]) + 1)
    n = len(pos)
    residual, nrmse = {}, {}
    fm, hm = fit_mask[:n], held[:n]
    for k, a in problem.excited:
        residual[a] = {
            "position_um": float(np.sqrt(np.mean((pos[fm, k] - problem.pos[:n][fm, k]) ** 2))
                                 * 1e6),
            "tacho_v": float(np.sqrt(np.mean((tacho[fm, k] - problem.tacho[:n][fm, k]) ** 2)))}
        nrmse[a] = {"position": _nrmse(pos[hm, k], problem.pos[:n][hm, k]),
                    "tacho": _nrmse(tacho[hm, k], problem.tacho[:n][hm, k])}
    worst = max(max(v.values()) for v in nrmse.values())
    if not math.isfinite(worst) or worst > bound:
        raise FitError(f"the fit did not converge: the held-out experiment is predicted "
                       f"with a normalised RMS error of {100 * worst:.1f} %")
    return (pos, tacho), residual, nrmse


def _value(p: AxisParams, base: AxisParams, name: str, x: float) -> float:
    """The parameter value at coordinate ``x`` (NaN stays NaN: an open end)."""
    if not math.isfinite(x):
        return math.nan
    lo, hi = BOUNDS[name]
    return getattr(with_coordinate(p, base, name, min(max(x, lo), hi)), name)


def _nrmse(pred: np.ndarray, meas: np.ndarray) -> float:
    """RMS(pred − meas) over the measurement's range (1)."""
    span = float(np.ptp(meas))
    if span == 0.0:
        return math.inf
    return float(np.sqrt(np.mean((pred - meas) ** 2))) / span
