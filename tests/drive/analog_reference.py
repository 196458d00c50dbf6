"""A self-contained reference for the analog drive (``regulators.implementation =
"analog"``): its continuous PI regulators, the shunt's RC filter, the firing unit that reads
the control voltage at each firing, the 6-pulse bridge and a rigid rotor (or one held at a
constant speed), integrated by ``scipy.integrate.solve_ivp`` (DOP853) with event functions.
It shares no code with ``twin.drive``: every instant is found here.

The cascade, forward bridge only (the cases keep the current reference positive)::

    T1·U_f' = U_ref − U_f                    T_f·U_t' = K_C·ω − U_t
    i* = K_pω·(U_f − U_t) + S_ω               S_ω' = (K_pω/T_iω)·(U_f − U_t)
    T_fi·i_f' = j − i_f                      S_i' = (K_pi/T_ii)·(i* − i_f)   (bridge on)
    U_c = (k/K_C)·U_t + K_pi·(i* − i_f) + S_i
    L·j' = Û·(1 + δ)·cos(ω_m·(t − J·T_p) − π/6) − k·ω − U_v − R·j   (j > 0, pair J)
    J_r·ω' = k·j − τ_load − B·ω

The firing unit. The regulators' sample for natural commutation point J is at
J·T_p + α_{J−1}/ω_m (α_{−1} = 90°, the first sample at t = 0). There the logic switching unit
releases the bridge once i* exceeds its threshold (S_i starts from 0 then, the EMF
compensation carrying the balance), U_c is read, α_J = arccos(U_c/U_d0) within
[α_min, α_max] (U_d0 from the rated mains) and pair J is fired at
max(sample, J·T_p + α_J/ω_m), its gate pulse on until the next firing. A firing commutates a
flowing current at once; a gated pair starts where it is forward biased; the current stops
at zero.

The cases stay inside the regulators' limits (no current limit, no voltage end stop, no
reversal: the kernel would release the reverse bridge for i* < −I_th); :func:`simulate`
reports whether they did.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["Cascade", "simulate"]

_TOL = dict(method="DOP853", rtol=1e-10, atol=1e-12, dense_output=True)


@dataclass(frozen=True)
class Cascade:
    """Constants of the drive (SI)."""

    r: float            # armature circuit resistance (Ω)
    l: float            # armature circuit inductance (H)
    u_ll: float         # rated line-to-line rms voltage (V)
    k: float            # EMF constant (V·s/rad)
    k_c: float          # tacho gain (V·s/rad)
    t_f: float          # tacho filter (s)
    t1: float           # reference filter (s)
    kp_w: float         # speed PI gain (A/V)
    ti_w: float         # speed PI integral time (s)
    kp_i: float         # current PI gain (V/A)
    ti_i: float         # current PI integral time (s)
    t_fi: float         # shunt filter (s)
    i_th: float         # current reference that releases the bridge (A)
    i_lim: float        # current limit (A)
    alpha_min: float    # (rad)
    alpha_max: float    # (rad)
    inertia: float      # rotor inertia (kg·m²); math.inf: the rotor is held at its speed
    load: float = 0.0   # load torque (N·m)
    viscous: float = 0.0  # (N·m·s/rad)
    drop: float = 0.0   # constant drop while current flows: brushes + thresholds (V)
    deviation: float = 0.0  # of the mains from its rating (1)
    mains: float = 50.0  # Hz

    @property
    def w(self) -> float:
        return 2.0 * math.pi * self.mains

    @property
    def t_p(self) -> float:
        return 1.0 / (6.0 * self.mains)

    @property
    def u_d0(self) -> float:
        return 3.0 / math.pi * math.sqrt(2.0) * self.u_ll

    def u(self, pair: int, t: float) -> float:
        """The voltage pair ``pair`` applies (V)."""
        u_hat = math.sqrt(2.0) * self.u_ll * (1.0 + self.deviation)
        return u_hat * math.cos(self.w * (t - pair * self.t_p) - math.pi / 6.0)


# state: j, ω, U_f, U_t, S_ω, i_f, S_i
J_, W_, UF, UT, SW, IF, SI = range(7)


def _rhs(c: Cascade, u_ref: float, pair: int, conducting: bool, released: bool):
    def f(t, y):
        e = y[UF] - y[UT]
        i_ref = c.kp_w * e + y[SW]
        dj = ((c.u(pair, t) - c.k * y[W_] - c.drop - c.r * y[J_]) / c.l
              if conducting else 0.0)
        dw = ((c.k * y[J_] - c.load - c.viscous * y[W_]) / c.inertia
              if math.isfinite(c.inertia) else 0.0)
        return [dj, dw, (u_ref - y[UF]) / c.t1, (c.k_c * y[W_] - y[UT]) / c.t_f,
                c.kp_w / c.ti_w * e, (y[J_] - y[IF]) / c.t_fi,
                c.kp_i / c.ti_i * (i_ref - y[IF]) if released else 0.0]
    return f


def simulate(c: Cascade, reference: Callable[[float], float], breaks: list[float],
             omega0: float, t_end: float, times: np.ndarray) -> dict[str, np.ndarray]:
    """The drive from rest (regulators, filters and current at zero; the rotor at
    ``omega0``), the speed reference ``reference(t)`` (V) constant between ``breaks``.

    Returns the current j, the speed ω and the current reference i* at ``times``, the
    firing log (time, pair, angle) and ``inside``: whether the run stayed inside the
    regulators' limits (at every sample −I_th < i* < I_lim, 0 < i* once the bridge is
    released, the control voltage within the end stops).
    """
    y = np.zeros(7)
    y[W_] = omega0
    t = 0.0
    j_nat, alpha_last = 0, 0.5 * math.pi
    t_sample, t_fire, fire_pair = 0.0, math.inf, -1
    pair, released, conducting, inside = -1, False, False, True
    quiet = 0.0                              # no start before this instant
    firings: list[tuple[float, int, float]] = []
    pieces = []
    lo, hi = c.u_d0 * math.cos(c.alpha_max), c.u_d0 * math.cos(c.alpha_min)
    while t < t_end:
        if t_fire <= t:                      # fire: the gate pulses move to the pair
            pair, t_fire = fire_pair, math.inf
            firings.append((t, pair, alpha_last))
            continue
        if t_sample <= t:                    # the regulators' sample J
            i_ref = c.kp_w * (y[UF] - y[UT]) + y[SW]
            inside &= -c.i_th < i_ref < c.i_lim
            if not released and i_ref > c.i_th:
                released, y[SI] = True, 0.0
            if released:
                u_c = c.k / c.k_c * y[UT] + c.kp_i * (i_ref - y[IF]) + y[SI]
                inside &= lo < u_c < hi and i_ref > 0.0
                alpha_last = min(max(math.acos(min(max(u_c / c.u_d0, -1.0), 1.0)),
                                     c.alpha_min), c.alpha_max)
                t_fire = max(t, j_nat * c.t_p + alpha_last / c.w)
                fire_pair = j_nat
            j_nat += 1
            t_sample = j_nat * c.t_p + alpha_last / c.w
            continue
        t_next = min(t_sample, t_fire, t_end, *(b for b in breaks if b > t))
        if not conducting and pair >= 0 and t >= quiet and \
                c.u(pair, t) - c.k * y[W_] - c.drop > 0.0:
            conducting = True                # the gated pair is forward biased
        if conducting and y[J_] <= 0.0 and t >= quiet:
            quiet = t + 1e-9                 # a start: let the current rise, then watch it
        events = []
        if t < quiet:                        # no events
            t_next = min(t_next, quiet)
        elif conducting:
            def gone(s, v):
                return v[J_]
            gone.terminal, gone.direction = True, -1
            events.append(gone)
        elif pair >= 0:
            def start(s, v, pair=pair):
                return c.u(pair, s) - c.k * v[W_] - c.drop
            start.terminal, start.direction = True, 1
            events.append(start)
        sol = solve_ivp(_rhs(c, reference(t), pair, conducting, released), (t, t_next), y,
                        events=events, **_TOL)
        pieces.append((t, sol.t[-1], sol.sol, released))
        y = sol.y[:, -1].copy()
        t = float(sol.t[-1])
        if sol.status == 1:                  # an event ended the piece
            if conducting:
                y[J_], conducting = 0.0, False
            else:
                conducting = True
        elif conducting and y[J_] <= 0.0:    # a start that did not rise
            y[J_], conducting = 0.0, False
    out = {name: np.zeros(len(times)) for name in ("current", "omega", "current_reference")}
    for t0, t1, dense, _ in pieces:
        inside_piece = (times > t0) & (times <= t1)
        if inside_piece.any():
            v = dense(times[inside_piece])
            out["current"][inside_piece] = v[J_]
            out["omega"][inside_piece] = v[W_]
            out["current_reference"][inside_piece] = c.kp_w * (v[UF] - v[UT]) + v[SW]
    out["firings"] = np.array(firings)
    out["inside"] = np.array(inside)
    return out
