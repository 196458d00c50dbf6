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
2. **Friction over inertia, then inertia** (``coast``, ``steps``): in the coast-downs the
   drive is off and J·dω/dt = −(T_c·sign ω + B·ω): a linear regression of the encoder's
   acceleration on [sign ω, ω] gives T_c/J and B/J. The steepest tacho slopes of the large
   reversals, where the drive holds its current limit, give k·I_m/J (k, I_m BASE's), hence a
   first J. Then Levenberg-Marquardt on the replayed steps moves J with the friction in
   proportion, together with the armature resistance (which shapes how fast the current
   reaches its limit, and so trades off against J when left out).
3. **Friction** (``coast``): Coulomb, viscous and break-away on the replayed coast-downs.
4. **Lost motion** (``crossings``): the motor positions of the home switch's edges, seen
   going up and coming down, differ by the lost motion, the screw's friction preload both
   ways (2·F/k, from the fitted friction and BASE's stiffness) and the debounce (2·v·t_d).
5. **Together**: inertia, friction, armature R and L (which enter only through the current
   loop the drive's own design compensates) in one last Levenberg-Marquardt on all replayed
   experiments, whose Jacobian gives the 95 % confidence intervals, widened for the
   residuals' correlation in time. A parameter whose interval is too wide (``TOLERANCE``)
   is reported as not identifiable: it is set back to BASE's value and the others are
   fitted again around it.

The axes are uncoupled, so each replay moves both: a finite-difference column of x and the
same column of y come from one simulation. The held-out experiment (``ramps``, closed loop)
is then predicted, and its normalised RMS error is the fit quality.

What the signals cannot give is never fitted: the screw's stiffness and damping and the
carriage masses (a motor encoder does not see the table's motion, and the reflected rotor
inertia swamps the table's), the split of friction between rotor and slide (only their sum
acts on the motor), the motor's EMF constant and current limit (they scale with the
inertia), the tacho filter and the converter's mains data.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import savgol_filter

from twin.config import AXES, MachineConfig
from twin.drive.design import moving_masses
from twin.errors import FitError
from twin.identify.log import IdentLog
from twin.identify.plan import FIT_EXPERIMENTS, HELD_OUT
from twin.identify.replay import AxisParams, base_params, candidate, measured, replay

__all__ = ["NOT_IDENTIFIABLE", "TOLERANCE", "Estimate", "Identification", "fit"]

SIGMA_POSITION = 5e-6
"""Position residual scale (m): the replay's own floor (unknown mains phase)."""
SIGMA_TACHO = 0.02
"""Tacho residual scale (V)."""

TOLERANCE = {"inertia": math.log(1.25), "coulomb": math.log(1.25),
             "viscous": math.log(1.5), "breakaway": 0.5, "backlash": 3e-6,
             "resistance": math.log(1.25), "inductance": math.log(1.25)}
"""Largest 95 % half-interval (in the fitted coordinate: log for the multiplicative ones,
1 for the break-away ratio, m for the lost motion) of a parameter called identifiable."""

NOT_IDENTIFIABLE = {
    "transmission.stiffness": "the motor encoder does not see the table move on the screw",
    "transmission.damping_ratio": "as the stiffness",
    "mechanics.carriage_mass": "its reflected inertia is 0.1 % of the rotor's on tomsk_xy",
    "mechanics: rotor/slide split of friction": "only their sum acts on the motor",
    "motor.emf_constant, motor.current_limit_factor": "they scale with the inertia in "
                                                      "every current-limited motion",
    "tacho.filter_time_constant": "1 ms, far below the speed loop's response",
    "converter (line voltage, mains, firing limits)": "no signal of the converter's own",
}
"""Fields the encoder, tacho and DAC cannot recover, and why; kept from BASE."""

_COORDS = (("scale", "log", 0.01), ("inertia", "log", 0.01), ("coulomb", "log", 0.02),
           ("viscous", "log", 0.05), ("breakaway", "lin", 0.2), ("backlash", "lin", 2e-6),
           ("resistance", "log", 0.03), ("inductance", "log", 0.03))
"""The fitted coordinates: name, transform (log of the ratio to BASE, or linear) and
finite-difference step. ``scale`` moves the inertia with the friction in proportion (the
coast-downs fix friction over inertia)."""
_SOURCE = {"tacho_gain": "steps (steady speeds)", "gain_error": "steps (steady speeds)",
           "offset": "steps (steady speeds)", "inertia": "steps (current limit), prbs",
           "coulomb": "coast, steps (current limit)", "viscous": "coast, steps, prbs",
           "breakaway": "coast (to rest), steps (starts from rest)",
           "backlash": "crossings (home switch)",
           "resistance": "prbs", "inductance": "prbs"}


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
        False: the data do not pin it down; BASE's value is kept.
    source : str
        The experiment(s) it comes from.
    """

    value: float
    low: float
    high: float
    identifiable: bool
    source: str


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
        Held-out normalised RMS errors ``{axis: {"position": ., "tacho": .}}``.
    residual : dict
        RMS residual of the fit experiments ``{axis: {"position_um": ., "tacho_v": .}}``.
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

    def derived(self, base: MachineConfig) -> dict[str, dict[str, float]]:
        """K_H (m/(s·V)) and the total Coulomb and viscous friction at the motor
        (N·m, N·m·s/rad) per axis: what the figures are quoted in."""
        out = {}
        for a in AXES:
            p, ax = self.params[a], base.axes[a]
            m, r = ax.mechanics, ax.transmission.ratio
            out[a] = {"K_H": r * (1.0 + p.gain_error) / p.tacho_gain,
                      "coulomb_at_motor": p.coulomb * (m.rotor_coulomb + r * m.slide_coulomb),
                      "viscous_at_motor": p.viscous * (m.rotor_viscous
                                                       + r * r * m.slide_viscous)}
        return out


class _Problem:
    """Residuals of the log against replays of candidate parameters."""

    def __init__(self, base: MachineConfig, log: IdentLog):
        self.base, self.log = base, log
        self.pos, self.tacho = measured(log, base)
        self.replays = 0
        self.mains_phase: float | None = None

    def simulate(self, params: dict[str, AxisParams], until: int
                 ) -> tuple[np.ndarray, np.ndarray]:
        self.replays += 1
        return replay(candidate(self.base, params), self.log, until=until,
                      mains_phase=self.mains_phase)

    def residuals(self, params: dict[str, AxisParams], mask: np.ndarray
                  ) -> dict[str, np.ndarray]:
        """Per axis: scaled position and tacho residuals over the ticks of ``mask``."""
        until = int(np.flatnonzero(mask)[-1]) + 1
        pos, tacho = self.simulate(params, until)
        m = mask[:until]
        out = {}
        for k, a in enumerate(AXES):
            dp = (pos[m, k] - self.pos[:until][m, k]) / SIGMA_POSITION
            dt = (tacho[m, k] - self.tacho[:until][m, k]) / SIGMA_TACHO
            out[a] = np.concatenate([dp, dt])
        return out


def _get(p: AxisParams, base: AxisParams, name: str, kind: str) -> float:
    if name == "scale":  # inertia with the friction scaled along (their ratios held)
        return math.log(p.inertia / base.inertia)
    v = getattr(p, name)
    if kind == "log":
        ref = getattr(base, name)
        return math.log(v / ref) if name in ("inertia", "resistance", "inductance") \
            else math.log(v)
    return v - 1.0 if name == "breakaway" else v


def _set(p: AxisParams, base: AxisParams, name: str, kind: str, x: float) -> AxisParams:
    if name == "scale":
        f = base.inertia * math.exp(x) / p.inertia
        return p.with_(inertia=p.inertia * f, coulomb=p.coulomb * f, viscous=p.viscous * f)
    if kind == "log":
        ref = getattr(base, name) if name in ("inertia", "resistance", "inductance") else 1.0
        return p.with_(**{name: ref * math.exp(x)})
    if name == "breakaway":
        return p.with_(breakaway=1.0 + max(x, 0.0))
    return p.with_(**{name: max(x, 0.0)})


_BOUNDS = {"scale": (math.log(0.2), math.log(5.0)), "inertia": (math.log(0.2), math.log(5.0)),
           "coulomb": (math.log(0.05), math.log(20.0)),
           "viscous": (math.log(0.01), math.log(100.0)),
           "breakaway": (0.0, 4.0), "backlash": (0.0, 200e-6),
           "resistance": (math.log(0.3), math.log(3.0)),
           "inductance": (math.log(0.3), math.log(3.0))}


def _lm(problem: _Problem, params: dict[str, AxisParams], names: list[str],
        mask: np.ndarray, start: dict[str, AxisParams], *, iterations: int = 8,
        frozen: dict[str, set[str]] | None = None
        ) -> tuple[dict[str, AxisParams], dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Levenberg-Marquardt on the coordinates ``names`` of both axes at once (but those
    ``frozen[axis]`` holds for that axis); returns the parameters, each axis' Jacobian
    (residuals × coordinates) at the solution and its residual vector."""
    coords = [c for c in _COORDS if c[0] in names]
    frozen = frozen or {}
    active = {a: np.array([c[0] not in frozen.get(a, ()) for c in coords]) for a in AXES}
    lam = {a: 1e-2 for a in AXES}
    res = problem.residuals(params, mask)
    sse = {a: float(res[a] @ res[a]) for a in AXES}
    jac: dict[str, np.ndarray] = {}
    for _ in range(iterations):
        jac = {a: np.empty((len(res[a]), len(coords))) for a in AXES}
        for i, (name, kind, h) in enumerate(coords):
            trial, steps = {}, {}
            for a in AXES:
                x = _get(params[a], start[a], name, kind)
                steps[a] = h if x + h <= _BOUNDS[name][1] else -h
                trial[a] = _set(params[a], start[a], name, kind, x + steps[a])
            r2 = problem.residuals(trial, mask)
            for a in AXES:
                jac[a][:, i] = (r2[a] - res[a]) / steps[a]
        proposal = {}
        for a in AXES:
            j, r = jac[a], res[a]
            jtj = j.T @ j
            g = j.T @ r
            damp = lam[a] * np.diag(np.diag(jtj) + 1e-12)
            on = active[a]
            delta = np.zeros(len(coords))
            try:
                delta[on] = -np.linalg.solve((jtj + damp)[np.ix_(on, on)], g[on])
            except np.linalg.LinAlgError:
                pass
            p = params[a]
            for i, (name, kind, _h) in enumerate(coords):
                lo, hi = _BOUNDS[name]
                x = min(max(_get(p, start[a], name, kind) + delta[i], lo), hi)
                p = _set(p, start[a], name, kind, x)
            proposal[a] = p
        trial_res = problem.residuals(proposal, mask)
        improved = False
        for a in AXES:
            new = float(trial_res[a] @ trial_res[a])
            if new < sse[a]:
                if (sse[a] - new) > 1e-4 * sse[a]:
                    improved = True
                params = {**params, a: proposal[a]}
                res = {**res, a: trial_res[a]}
                sse[a] = new
                lam[a] = max(lam[a] / 4.0, 1e-6)
            else:
                lam[a] = min(lam[a] * 8.0, 1e6)
                improved = improved or lam[a] < 1e6
        if not improved:
            break
    return params, jac, res


def _intervals(jac: np.ndarray, res: np.ndarray, channels: int = 2) -> np.ndarray:
    """95 % half-intervals of the coordinates from the Gauss-Newton covariance, widened by
    the residuals' integrated autocorrelation time: the replay's floor is smooth in time,
    not white, so n samples carry far fewer than n independent errors."""
    n, p = jac.shape
    s2 = float(res @ res) / max(n - p, 1)
    inflation = 1.0
    for part in np.split(res, channels):   # position, then tacho: one series each
        x = part - part.mean()
        var = float(x @ x)
        if var <= 0.0 or len(x) < 4:
            continue
        tau = 1.0
        for lag in range(1, len(x) // 4):
            rho = float(x[:-lag] @ x[lag:]) / var
            if rho <= 0.05:
                break
            tau += 2.0 * rho
        inflation = max(inflation, tau)
    cov = s2 * inflation * np.linalg.pinv(jac.T @ jac)
    diag = np.diag(cov)
    return 1.96 * np.sqrt(np.where(diag > 0, diag, np.inf))


def _regress_gains(problem: _Problem, base: MachineConfig
                   ) -> tuple[dict[str, dict[str, float]], dict[str, dict[str, float]]]:
    """Stage 1: tacho gain, DAC gain error and offset per axis from the steady parts of the
    speed steps. Returns (values, 95 % half-intervals)."""
    log, period = problem.log, problem.base.controller.period
    pieces = log.data["piece"].astype(int)
    values, halfs = {}, {}
    for k, a in enumerate(AXES):
        r = base.axes[a].transmission.ratio
        rows = []
        for i, piece in enumerate(log.plan):
            if piece.experiment != "steps" or piece.value == 0.0:
                continue
            idx = np.flatnonzero(pieces == i)
            if len(idx) < 8:
                continue
            tail = idx[len(idx) // 2:]
            dt = (len(tail) - 1) * period
            omega = (problem.pos[tail[-1], k] - problem.pos[tail[0], k]) / dt / r
            u = log.data["dac_x" if k == 0 else "dac_y"][tail].mean()
            tacho = problem.tacho[tail, k].mean()
            rows.append((u, omega, tacho))
        if len(rows) < 3:
            raise FitError(f"axis {a}: the steps experiment has too few steady parts")
        u, omega, tacho = (np.array(c) for c in zip(*rows, strict=True))
        a_fit, c_fit = np.polyfit(u, omega, 1)
        k_c = float(tacho @ omega / (omega @ omega))
        gain_error = a_fit * k_c - 1.0
        offset = c_fit * k_c
        # intervals: regression residuals
        res_w = omega - (a_fit * u + c_fit)
        s_w = math.sqrt(float(res_w @ res_w) / max(len(u) - 2, 1))
        s_a = s_w / math.sqrt(float(((u - u.mean()) ** 2).sum()))
        res_t = tacho - k_c * omega
        s_k = math.sqrt(float(res_t @ res_t) / max(len(u) - 1, 1) / float(omega @ omega))
        values[a] = {"tacho_gain": k_c, "gain_error": float(gain_error),
                     "offset": float(offset)}
        halfs[a] = {"tacho_gain": 1.96 * s_k,
                    "gain_error": 1.96 * (s_a * k_c + abs(a_fit) * s_k),
                    "offset": 1.96 * s_w / math.sqrt(len(u)) * k_c}
    return values, halfs


def _coast_regression(problem: _Problem, params: dict[str, AxisParams]
                      ) -> dict[str, tuple[float, float]]:
    """Stage 2: friction over inertia from the coast-downs, by linear regression.

    With the drive disabled the rotor obeys J·dω/dt = −(T_c·sign ω + B·ω) once the
    armature current has died out; the encoder's speed and acceleration (Savitzky-Golay
    derivatives over 0.1 s) regressed on [sign ω, ω], away from the start of the coast and
    from the Stribeck region near rest, give T_c/J and B/J. Returns, per axis, the Coulomb
    and viscous multipliers of BASE's friction for the current inertia (NaN where the
    coasts do not show enough motion)."""
    log, base = problem.log, problem.base
    period = base.controller.period
    pieces = log.data["piece"].astype(int)
    window = max(5, 2 * round(0.05 / period) + 1)
    moved = moving_masses(base)
    out = {}
    for k, a in enumerate(AXES):
        ax = base.axes[a]
        m, r = ax.mechanics, ax.transmission.ratio
        rows, rhs = [], []
        for i, piece in enumerate(log.plan):
            if piece.experiment != "coast" or piece.kind != "coast":
                continue
            idx = np.flatnonzero(pieces == i)
            if len(idx) < 3 * window:
                continue
            angle = problem.pos[idx, k] / r
            w = savgol_filter(angle, window, 2, deriv=1, delta=period)
            dw = savgol_filter(angle, window, 2, deriv=2, delta=period)
            w0 = abs(w[window])
            keep = np.zeros(len(idx), dtype=bool)
            keep[window:-window // 2] = True
            keep &= np.abs(w) > max(0.1 * w0, 3.0 * m.stribeck_velocity / r)
            rows += list(zip(np.sign(w[keep]), w[keep], strict=True))
            rhs += list(-dw[keep])
        if len(rows) < 10:
            out[a] = (math.nan, math.nan)
            continue
        theta, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
        j = params[a].inertia + moved[a] * r * r
        coulomb = theta[0] * j / (m.rotor_coulomb + r * m.slide_coulomb) \
            if m.rotor_coulomb + r * m.slide_coulomb > 0 else math.nan
        viscous = theta[1] * j / (m.rotor_viscous + r * r * m.slide_viscous) \
            if m.rotor_viscous + r * r * m.slide_viscous > 0 else math.nan
        out[a] = (float(coulomb), float(viscous))
    return out


def _limit_inertia(problem: _Problem, params: dict[str, AxisParams]) -> dict[str, float]:
    """Stage 2b: the rotor inertia from the current-limited reversals of the steps, given
    the friction over inertia (``_coast_regression``): in the middle of a reversal the
    drive holds its current limit I_m, so J·dω/dt = ∓k·I_m − T_c·sign ω − B·ω; the tacho's
    slope there, less the friction's share, is k·I_m/J (k and I_m are BASE's). NaN where
    no reversal reaches the limit."""
    log, base = problem.log, problem.base
    period = base.controller.period
    pieces = log.data["piece"].astype(int)
    out = {}
    for k, a in enumerate(AXES):
        ax = base.axes[a]
        m, r = ax.mechanics, ax.transmission.ratio
        p = params[a]
        j_total = p.inertia + moving_masses(base)[a] * r * r
        theta_c = p.coulomb * (m.rotor_coulomb + r * m.slide_coulomb) / j_total
        theta_v = p.viscous * (m.rotor_viscous + r * r * m.slide_viscous) / j_total
        torque = ax.motor.emf_constant * ax.motor.current_limit
        estimates = []
        previous = None
        for i, piece in enumerate(log.plan):
            if piece.experiment != "steps" or piece.kind != "speed":
                previous = None
                continue
            if previous is not None and previous.value * piece.value < 0.0 \
                    and abs(piece.value) >= 0.5 * max(abs(q.value) for q in log.plan
                                                      if q.experiment == "steps"):
                idx = np.flatnonzero(pieces == i)[:round(0.2 / period)]
                w = problem.tacho[idx, k] / p.tacho_gain
                s = math.copysign(1.0, piece.value)
                slope = s * np.diff(w) / period          # the steepest: at the limit
                top = np.argsort(slope)[-3:]
                if len(top) == 3:
                    mid = 0.5 * (w[top] + w[top + 1])
                    friction = float(np.mean(theta_c * np.sign(mid) + theta_v * mid))
                    accel = float(np.mean(slope[top])) + s * friction  # k·I_m/J
                    if accel > 0.0:
                        estimates.append(torque / accel)
            previous = piece
        out[a] = float(np.median(estimates)) - moving_masses(base)[a] * r * r \
            if estimates else math.nan
    return out


def _scan_phase(problem: _Problem, params: dict[str, AxisParams], steps: int = 24) -> None:
    """Stage 0: the mains phase that best replays the first second of the steps: a scan of
    one pulse period, then a golden-section search around the best point of the grid."""
    base = problem.base
    if not any(base.axes[a].converter.kind == "thyristor" for a in AXES):
        return
    p = base.axes["x"].converter.pulse_number
    first = problem.log.experiment_mask("steps")
    first[round(1.2 / base.controller.period):] = False

    def sse(phase: float) -> float:
        problem.mains_phase = phase % (2.0 * math.pi)
        r = problem.residuals(params, first)
        return sum(float(v @ v) for v in r.values())

    step = 2.0 * math.pi / p / steps
    grid = [k * step for k in range(steps)]
    values = [sse(x) for x in grid]
    best = grid[int(np.argmin(values))]
    lo, hi = best - step, best + step
    golden = 0.5 * (math.sqrt(5.0) - 1.0)
    c, d = hi - golden * (hi - lo), lo + golden * (hi - lo)
    fc, fd = sse(c), sse(d)
    for _ in range(6):
        if fc < fd:
            hi, d, fd = d, c, fc
            c = hi - golden * (hi - lo)
            fc = sse(c)
        else:
            lo, c, fc = c, d, fd
            d = lo + golden * (hi - lo)
            fd = sse(d)
    candidates = [(min(values), best), (fc, c), (fd, d)]
    problem.mains_phase = min(candidates)[1] % (2.0 * math.pi)


def _lost_motion(problem: _Problem, params: dict[str, AxisParams]
                 ) -> dict[str, tuple[float, float]]:
    """Stage 4: the lost motion from the home switch's edges (value, 95 % half-interval),
    per axis; NaN where the crossings do not show both edges both ways."""
    log, base = problem.log, problem.base
    period = base.controller.period
    pieces = log.data["piece"].astype(int)
    up = np.array([p.experiment == "crossings" and p.kind == "ramp" and p.value > 0
                   for p in log.plan])[pieces]
    down = np.array([p.experiment == "crossings" and p.kind == "ramp" and p.value < 0
                     for p in log.plan])[pieces]
    speed = max((abs(p.value) for p in log.plan if p.experiment == "crossings"),
                default=0.0)
    out = {}
    for k, a in enumerate(AXES):
        home = log.data[f"home_{a}"]
        pos = problem.pos[:, k]

        def edges(mask: np.ndarray, home: np.ndarray = home, pos: np.ndarray = pos
                  ) -> tuple[float, float]:
            idx = np.flatnonzero(mask)
            if len(idx) < 2:
                return math.nan, math.nan
            h = home[idx]
            change = np.flatnonzero(np.diff(h) != 0)
            rise = [i for i in change if h[i + 1] > h[i]]
            fall = [i for i in change if h[i + 1] < h[i]]
            if not rise or not fall:
                return math.nan, math.nan
            mid = 0.5 * (pos[idx[:-1]] + pos[idx[1:]])  # between the two samples
            return float(mid[rise[0]]), float(mid[fall[0]])

        up_close, up_open = edges(up)          # table at home − w/2, then home + w/2
        down_close, down_open = edges(down)    # table at home + w/2, then home − w/2
        seen = 0.5 * ((up_open - down_close) + (up_close - down_open))
        ax = base.axes[a]
        m, p = ax.mechanics, params[a]
        force = p.coulomb * m.slide_coulomb + p.viscous * m.slide_viscous * speed
        preload = 2.0 * force / ax.transmission.axial_stiffness
        debounce = 2.0 * speed * ax.switches.debounce
        b = seen - preload - debounce
        # each edge is known to within a tick of travel (uniform): four edges averaged
        # in pairs; the preload's share of the rotor/slide split is not known (±50 %)
        half = 1.96 * math.sqrt(speed * period * speed * period / 12.0
                                + (0.5 * preload / 1.96) ** 2)
        out[a] = (max(b, 0.0) if math.isfinite(b) else math.nan, half)
    return out


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
    t0 = time.perf_counter()
    say = progress or (lambda _msg: None)
    log.check(base)
    problem = _Problem(base, log)
    start = base_params(base)
    # 1. gains by regression (they do not depend on the mains phase)
    gains, gain_halfs = _regress_gains(problem, base)
    params = {a: start[a].with_(**gains[a]) for a in AXES}
    say("gains: " + ", ".join(f"{a} K_C {gains[a]['tacho_gain']:.5g}" for a in AXES))
    # 2. friction over inertia from the coast-downs (linear regression), the inertia from
    #    the current-limited reversals with them; then the inertia (friction in proportion)
    #    and the armature resistance from the replayed steps, the phase again once near
    ratios = _coast_regression(problem, params)
    for a in AXES:
        c, v = ratios[a]
        if math.isfinite(c) and c > 0.0 and math.isfinite(v) and v > 0.0:
            params[a] = params[a].with_(coulomb=c, viscous=v)
    inertia = _limit_inertia(problem, params)
    for a in AXES:
        if math.isfinite(inertia[a]) and inertia[a] > 0.0:
            f = inertia[a] / params[a].inertia
            p = params[a]
            params[a] = p.with_(inertia=p.inertia * f, coulomb=p.coulomb * f,
                                viscous=p.viscous * f)
    _scan_phase(problem, params)
    steps = log.experiment_mask("steps")
    params, _, _ = _lm(problem, params, ["scale", "resistance"], steps, start, iterations=8)
    _scan_phase(problem, params)
    say("inertia: " + ", ".join(f"{a} {params[a].inertia:.4g} kg·m²" for a in AXES))
    # 3. friction: the coast-downs (friction alone), then with the speed loop's data
    coast = log.experiment_mask("coast")
    params, _, _ = _lm(problem, params, ["coulomb", "viscous", "breakaway"], coast, start,
                       iterations=5)
    # 4. lost motion from the home switch
    lost = _lost_motion(problem, params)
    for a in AXES:
        if math.isfinite(lost[a][0]):
            params[a] = params[a].with_(backlash=lost[a][0])
    say("lost motion: " + ", ".join(f"{a} {1e6 * params[a].backlash:.1f} µm" for a in AXES))
    # 5. everything the replay carries, together
    fit_mask = log.experiment_mask(FIT_EXPERIMENTS)
    names = ["inertia", "coulomb", "viscous", "breakaway", "resistance", "inductance"]
    params, jac, res = _lm(problem, params, names, fit_mask, start, iterations=3)
    coords = [c for c in _COORDS if c[0] in names]
    # a parameter whose interval is too wide is not pinned down: BASE's value is kept and
    # the others are fitted again around it
    halfs = {a: _intervals(jac[a], res[a]) for a in AXES}
    loose = {a: {c[0] for c, h in zip(coords, halfs[a], strict=True)
                 if not h <= TOLERANCE[c[0]]} for a in AXES}
    fitted = dict(params)
    if any(loose.values()):
        params = {a: params[a].with_(**{n: getattr(start[a], n) for n in loose[a]})
                  for a in AXES}
        params, jac, res = _lm(problem, params, names, fit_mask, start, iterations=3,
                               frozen=loose)
        for a in AXES:
            on = np.array([c[0] not in loose[a] for c in coords])
            halfs[a][on] = _intervals(jac[a][:, on], res[a])
    estimates: dict[str, dict[str, Estimate]] = {}
    final = {}
    for a in AXES:
        half = halfs[a]
        est: dict[str, Estimate] = {}
        p = params[a]
        for name in ("tacho_gain", "gain_error", "offset"):
            v, h = getattr(p, name), gain_halfs[a][name]
            est[name] = Estimate(v, v - h, v + h, True, _SOURCE[name])
        for i, (name, kind, _h) in enumerate(coords):
            ok = name not in loose[a]
            at = p if ok else fitted[a]   # a loose one's interval is about its fitted value
            x = _get(at, start[a], name, kind)
            span = half[i] if math.isfinite(half[i]) else 1e9
            lo = _set(at, start[a], name, kind, max(x - span, _BOUNDS[name][0]))
            hi = _set(at, start[a], name, kind, min(x + span, _BOUNDS[name][1]))
            est[name] = Estimate(getattr(p, name), getattr(lo, name), getattr(hi, name), ok,
                                 _SOURCE[name])
        b, h = lost[a]
        ok = math.isfinite(b) and h <= TOLERANCE["backlash"]
        if not ok:
            p = p.with_(backlash=start[a].backlash)
        est["backlash"] = Estimate(p.backlash, max(b - h, 0.0) if ok else math.nan,
                                   b + h if ok else math.nan, ok, _SOURCE["backlash"])
        estimates[a] = est
        final[a] = p
    if not all(math.isfinite(v) for p in final.values() for v in p.to_dict().values()):
        raise FitError("the fit ran away: a parameter is not finite")
    calibrated = candidate(base, final)
    # fit quality: the fit experiments' residual, and the held-out prediction
    held = log.experiment_mask(HELD_OUT)
    pos, tacho = problem.simulate(final, int(np.flatnonzero(held)[-1]) + 1)
    n = len(pos)
    residual, nrmse = {}, {}
    fm, hm = fit_mask[:n], held[:n]
    for k, a in enumerate(AXES):
        residual[a] = {
            "position_um": float(np.sqrt(np.mean((pos[fm, k] - problem.pos[:n][fm, k]) ** 2))
                                 * 1e6),
            "tacho_v": float(np.sqrt(np.mean((tacho[fm, k] - problem.tacho[:n][fm, k]) ** 2)))}
        nrmse[a] = {"position": _nrmse(pos[hm, k], problem.pos[:n][hm, k]),
                    "tacho": _nrmse(tacho[hm, k], problem.tacho[:n][hm, k])}
    worst = max(max(v.values()) for v in nrmse.values())
    if not math.isfinite(worst) or worst > 0.25:
        raise FitError(f"the fit did not converge: the held-out experiment is predicted "
                       f"with a normalised RMS error of {100 * worst:.1f} %")
    say(f"held out: NRMSE {100 * worst:.2f} %")
    curves = {"t": log.data["t"][:n], "pos_meas": problem.pos[:n], "pos_fit": pos,
              "tacho_meas": problem.tacho[:n], "tacho_fit": tacho}
    result = Identification(final, estimates, calibrated, nrmse, residual, problem.replays,
                            time.perf_counter() - t0, curves)
    result.mains_phase = problem.mains_phase
    return result


def _nrmse(pred: np.ndarray, meas: np.ndarray) -> float:
    """RMS(pred − meas) over the measurement's range (1)."""
    span = float(np.ptp(meas))
    if span == 0.0:
        return math.inf
    return float(np.sqrt(np.mean((pred - meas) ** 2))) / span
