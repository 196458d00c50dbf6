"""Estimates read directly off the measured signals, without replaying the twin: the
gains (regression on the steady speed steps), friction over inertia (regression on the
coast-downs), a first inertia (the current-limited reversals) and the lost motion (the home
switch's edges). They start, and for the gains and the lost motion end, the fit.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import savgol_filter

from twin.config import AXES, MachineConfig
from twin.errors import FitError
from twin.identify.replay import AxisParams, Problem, axis_figures

__all__ = ["coast_regression", "limit_inertia", "lost_motion", "regress_gains"]


def _carriage_inertia(base: MachineConfig) -> dict[str, float]:
    """The moving mass reflected to each motor, m·r² (kg·m²): the fitted rotor inertia
    plus this is what the motor accelerates."""
    moved = base.moving_masses()
    return {a: moved[a] * base.axes[a].transmission.ratio * base.axes[a].transmission.ratio
            for a in AXES}


def regress_gains(problem: Problem, base: MachineConfig
                   ) -> tuple[dict[str, dict[str, float]], dict[str, dict[str, float]]]:
    """Stage 1: tacho gain, DAC gain error and offset per axis from the steady parts of the
    speed steps. Returns (values, 95 % half-intervals)."""
    log, period = problem.log, problem.base.controller.period
    pieces = log.data["piece"].astype(int)
    values, halfs = {}, {}
    for k, a in problem.excited:
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
            tacho = problem.tacho[tail, k]
            rows.append((u, omega, tacho.mean(), tacho.std()))
        if len(rows) < 3:
            raise FitError(f"axis {a}: the steps experiment has too few steady parts")
        u, omega, tacho, spread = (np.array(c) for c in zip(*rows, strict=True))
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
        # the tacho is read once a period, in step with the converter's pulses (200 Hz
        # against 300 Hz): the ripple left after its filter need not average out of a
        # steady part's mean, which may then be off by up to the spread of its samples
        # (seen: 0.05-0.07 % of K_C at amplitude 0.3, beyond the residuals' interval)
        bias = float(np.abs(omega) @ spread / float(omega @ omega))
        values[a] = {"tacho_gain": k_c, "gain_error": float(gain_error),
                     "offset": float(offset)}
        halfs[a] = {"tacho_gain": 1.96 * s_k + bias,
                    "gain_error": 1.96 * (s_a * k_c + abs(a_fit) * s_k) + abs(a_fit) * bias,
                    "offset": 1.96 * s_w / math.sqrt(len(u)) * k_c + abs(c_fit) * bias}
    return values, halfs


def coast_regression(problem: Problem, params: dict[str, AxisParams]
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
    carriage, at_motor = _carriage_inertia(base), axis_figures(base)
    out = {}
    for k, a in problem.excited:
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
        j = params[a].inertia + carriage[a]
        c0, v0 = at_motor[a]["coulomb_at_motor"], at_motor[a]["viscous_at_motor"]
        out[a] = (float(theta[0] * j / c0) if c0 > 0 else math.nan,
                  float(theta[1] * j / v0) if v0 > 0 else math.nan)
    return out


def limit_inertia(problem: Problem, params: dict[str, AxisParams]) -> dict[str, float]:
    """Stage 2b: the rotor inertia from the current-limited reversals of the steps, given
    the friction over inertia (``coast_regression``): in the middle of a reversal the
    drive holds its current limit I_m, so J·dω/dt = ∓k·I_m − T_c·sign ω − B·ω; the tacho's
    slope there, less the friction's share, is k·I_m/J (k and I_m are BASE's). NaN where
    no reversal reaches the limit."""
    log, base = problem.log, problem.base
    period = base.controller.period
    pieces = log.data["piece"].astype(int)
    carriage, at_motor = _carriage_inertia(base), axis_figures(base)
    large = 0.5 * max((abs(q.value) for q in log.plan if q.experiment == "steps"),
                      default=0.0)
    out = {}
    for k, a in problem.excited:
        ax = base.axes[a]
        p = params[a]
        j_total = p.inertia + carriage[a]
        theta_c = p.coulomb * at_motor[a]["coulomb_at_motor"] / j_total
        theta_v = p.viscous * at_motor[a]["viscous_at_motor"] / j_total
        torque = ax.motor.emf_constant * ax.motor.current_limit
        estimates = []
        previous = None
        for i, piece in enumerate(log.plan):
            if piece.experiment != "steps" or piece.kind != "speed":
                previous = None
                continue
            if previous is not None and previous.value * piece.value < 0.0 \
                    and abs(piece.value) >= large:
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
        out[a] = float(np.median(estimates)) - carriage[a] if estimates else math.nan
    return out


def lost_motion(problem: Problem, params: dict[str, AxisParams],
                friction_known: dict[str, bool] | None = None
                ) -> dict[str, tuple[float, float]]:
    """Stage 4: the lost motion from the home switch's edges (value, 95 % half-interval),
    per axis; NaN where the crossings do not show both edges both ways. Where
    ``friction_known[axis]`` is False (the fit could not pin the friction down) the
    friction's preload is uncertain as a whole, not only its rotor/slide split."""
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
    for k, a in problem.excited:
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
        share = 0.5 if (friction_known or {}).get(a, True) else 1.0
        half = 1.96 * math.sqrt(speed * period * speed * period / 12.0
                                + (share * preload / 1.96) ** 2)
        out[a] = (max(b, 0.0) if math.isfinite(b) else math.nan, half)
    return out
