"""A second, self-contained reference for the pulse-level converter with its low-current
physics: the 6-pulse bridge (or the 3-pulse midpoint circuit) fired at a fixed angle into an
armature with a constant EMF, integrated by ``scipy.integrate.solve_ivp`` (DOP853) with
event functions. It computes its own firing instants from the angle (nothing is replayed
from the kernel) and shares no code with ``twin.drive``.

Circuit, in the converter's conducting sense, while pair J conducts alone::

    (L + L_s + n·L_c)·dj/dt = u_J(t) − E − U_b − n_d·V_T0 − (R + n_d·r_T)·j

u_J(t) = Û·(1 + δ)·cos(ω·(t − J·T_p) − π/p) (δ the mains' deviation), n_d thyristors in
series (2 bridge, 1 midpoint), n line inductances (the same). During a commutation from
pair J−1 to J through L_c the commutating group's two branches share j; from the branch
equations u − L_c·di/dt − V_T0 − r_T·i = v (the same node voltage v for both):

    (L + L_s + (n − ½)·L_c)·dj/dt = (u_out + u_in)/2 − E − U_b − n_d·V_T0
                                     − (R + (n_d − ½)·r_T)·j
    L_c·d(i_in − i_out)/dt = u_in − u_out − r_T·(i_in − i_out)

and the overlap ends where i_in reaches j.

Thyristors. The firing unit gates pair J at t_J = J·T_p + α/ω for ``gate`` seconds (0: until
the next firing). A gated pair starts conducting where its driving voltage
u_J − E − U_b − n_d·V_T0 turns positive. While its gate current flows a thyristor conducts
down to zero current; once the gate pulse has ended it stays on only if its current reached
the latching current I_L during the pulse (else the current is cut at the pulse's end),
and it turns off where its current falls to the holding current I_H. A firing while current
flows commutates it to the new pair.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

__all__ = ["Bridge", "simulate"]

_TOL = dict(method="DOP853", rtol=1e-11, atol=1e-13, dense_output=True)


@dataclass(frozen=True)
class Bridge:
    """Constants of the circuit (SI)."""

    r: float                # armature resistance (Ω)
    l: float                # armature inductance (H)
    u_ll: float             # rated line-to-line rms voltage (V)
    pulses: int = 6         # 6: bridge, 3: midpoint circuit
    mains: float = 50.0     # Hz
    deviation: float = 0.0  # of the mains voltage from its rating (1)
    l_s: float = 0.0        # smoothing reactor (H)
    l_c: float = 0.0        # line inductance per phase (H)
    brush: float = 0.0      # brush drop (V)
    v_t0: float = 0.0       # thyristor threshold (V)
    r_t: float = 0.0        # thyristor slope resistance (Ω)
    i_l: float = 0.0        # latching current (A)
    i_h: float = 0.0        # holding current (A)
    gate: float = 0.0       # gate pulse width (s), 0: until the next firing

    @property
    def w(self) -> float:
        return 2.0 * math.pi * self.mains

    @property
    def t_p(self) -> float:
        return 1.0 / (self.pulses * self.mains)

    @property
    def n(self) -> int:
        return 2 if self.pulses == 6 else 1

    @property
    def u_hat(self) -> float:
        u = math.sqrt(2.0) * self.u_ll * (1.0 + self.deviation)
        return u if self.pulses == 6 else u / math.sqrt(3.0)

    def u(self, pair: int, t: float) -> float:
        return self.u_hat * math.cos(self.w * (t - pair * self.t_p) - math.pi / self.pulses)

    @property
    def drop(self) -> float:
        return self.brush + self.n * self.v_t0


def simulate(c: Bridge, alpha: float, emf: float, t_end: float,
             times: np.ndarray) -> tuple[np.ndarray, float]:
    """Current (A) at ``times`` and ∫i dt over [0, t_end] for firing angle ``alpha`` (rad)
    against the constant EMF ``emf`` (V)."""
    fire = [k * c.t_p + alpha / c.w for k in range(int(t_end / c.t_p) + 2)]
    fire = [t for t in fire if t < t_end]
    ends = [t + c.gate for t in fire] if c.gate > 0.0 else []
    marks = sorted({0.0, t_end, *fire, *(t for t in ends if t < t_end)})
    pieces = []          # (t0, t1, dense solution of j)
    j, pair, latched, overlap, i_in = 0.0, -1, False, False, 0.0
    l_one, l_ovl = c.l + c.l_s + c.n * c.l_c, c.l + c.l_s + (c.n - 0.5) * c.l_c
    r_one, r_ovl = c.r + c.n * c.r_t, c.r + (c.n - 0.5) * c.r_t
    for ta, tb in pairwise(marks):
        if ta in fire:                          # a firing: gate pulses move to the pair
            new = fire.index(ta)
            if j > 0.0 and c.l_c > 0.0:
                overlap, i_in = True, 0.0
            latched = j > 0.0 and j >= c.i_l
            pair = new
        if pair < 0:
            continue
        gate_on = ta < (fire[pair] + c.gate if c.gate > 0.0 else math.inf)
        if c.gate > 0.0 and ta == fire[pair] + c.gate and j > 0.0 and not latched \
                and c.i_l > 0.0:
            j, overlap = 0.0, False             # not latched: cut at the pulse's end
        t = ta
        while t < tb - 1e-15:
            if j <= 0.0:
                if not gate_on:
                    break
                def g(s, pair=pair):
                    return c.u(pair, s) - emf - c.drop
                grid = np.linspace(t, tb, 300)
                vals = np.array([g(s) for s in grid])
                if vals[0] > 0.0:
                    t_on = t
                else:
                    up = np.flatnonzero((vals[:-1] <= 0.0) & (vals[1:] > 0.0))
                    if not up.size:
                        break
                    t_on = brentq(g, grid[up[0]], grid[up[0] + 1], xtol=1e-15)
                t, j, latched, overlap = t_on, 0.0, False, False
            off = 0.0 if gate_on else c.i_h
            if not gate_on and j <= off:        # below the holding current, ungated: off
                j, overlap = 0.0, False
                break
            if gate_on and j >= c.i_l:
                latched = True
            if overlap:
                def rhs(s, y, pair=pair):
                    uo, ui = c.u(pair - 1, s), c.u(pair, s)
                    dj = (0.5 * (uo + ui) - emf - c.drop - r_ovl * y[0]) / l_ovl
                    return [dj, 0.5 * (dj + (ui - uo - c.r_t * (2.0 * y[1] - y[0])) / c.l_c)]

                def done(s, y):
                    return y[1] - y[0]
                done.terminal, done.direction = True, 1
                events = [done]
                y0 = [j, i_in]
            else:
                def rhs(s, y, pair=pair):
                    return [(c.u(pair, s) - emf - c.drop - r_one * y[0]) / l_one]
                events = []
                y0 = [j]

            def rise(s, y):
                return y[0] - c.i_l
            rise.terminal, rise.direction = False, 1
            events.append(rise)

            def gone(s, y, off=off):
                return y[0] - off
            gone.terminal, gone.direction = True, -1
            events.append(gone)
            sol = solve_ivp(rhs, (t, tb), y0, events=events, **_TOL)
            pieces.append((t, sol.t[-1], sol.sol))
            if gate_on and sol.t_events[-2].size:
                latched = True                  # reached I_L while gated
            t = sol.t[-1]
            if sol.t_events[-1].size:           # extinction (at zero or the holding current)
                j, overlap = 0.0, False
                continue
            j = float(sol.y[0, -1])
            if overlap:
                i_in = float(sol.y[1, -1])
                if sol.t_events[0].size:
                    overlap = False
    out = np.zeros(len(times))
    total = 0.0
    for t0, t1, sol in pieces:
        inside = (times > t0) & (times <= t1)
        if inside.any():
            out[inside] = sol(times[inside])[0]
        if t1 > t0:
            s = np.linspace(t0, t1, 401)
            total += float(np.trapezoid(sol(s)[0], s))
    return out, total
