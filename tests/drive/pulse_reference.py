"""An independent reference for the pulse-level converter: the bridge-plus-armature circuit
integrated by ``scipy.integrate.solve_ivp`` (DOP853) with zero-crossing events, replaying the
firing events the kernel logged.

Circuit, in the conducting sense j = b·i ≥ 0 of the converter that fired: while pair J
conducts alone, (L + n·L_c)·dj/dt = u_J(t) − b·E(t) − R·j, with u_J(t) = Û·cos(ω·(t − J·T_p)
− π/p). During a commutation from pair J−1 to J the two thyristor branches share the current,
i_out + i_in = j, and the node equations of the bridge give
(L + (n − ½)·L_c)·dj/dt = (u_out + u_in)/2 − b·E − R·j and L_c·d(i_in − i_out)/dt =
u_in − u_out (derived from the three phase inductances, not from the kernel's formulas);
the overlap ends where i_in reaches j. The current stops where j reaches zero (a terminal
event) and restarts where a pair whose gate pulse is on becomes forward biased, found on a
fine grid and refined by ``brentq``. The EMF follows the rotor speed as the kernel
extrapolates it inside each interval.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

__all__ = ["Circuit", "replay"]


@dataclass(frozen=True)
class Circuit:
    """Constants of one axis' converter and armature (SI)."""

    r: float          # Ω
    l: float          # H, armature
    k: float          # V·s/rad
    u_hat: float      # V, peak of a pair's voltage
    pulses: int       # p
    mains: float      # Hz
    l_c: float = 0.0  # H per phase
    series: int = 2   # line inductances in series with a pair

    @property
    def w(self) -> float:
        return 2.0 * math.pi * self.mains

    @property
    def t_p(self) -> float:
        return 1.0 / (self.pulses * self.mains)

    def u(self, pair: float, t: float) -> float:
        return self.u_hat * math.cos(self.w * (t - pair * self.t_p) - math.pi / self.pulses)


def _emf(c: Circuit, omega: np.ndarray, dt: float):
    """E(t): the kernel's linear extrapolation of ω inside each interval (slope 0 at first)."""
    def e(t: float) -> float:
        n = min(int(t / dt), len(omega) - 1)
        slope = 0.0 if n == 0 else (omega[n] - omega[n - 1]) / dt
        return c.k * (omega[n] + slope * (t - n * dt))
    return e


def replay(c: Circuit, log: np.ndarray, omega: np.ndarray, dt: float, t_end: float,
           times: np.ndarray) -> tuple[np.ndarray, float]:
    """The armature current (A, motor sense) at ``times`` and ∫i dt over [0, t_end], for the
    firing events ``log`` (rows: time, pair, bridge, angle; bridge 0 = pulses removed) and
    the rotor speeds ``omega`` given at the starts of the intervals of length ``dt``."""
    emf = _emf(c, omega, dt)
    pieces: list[tuple[float, float, object, float, bool]] = []  # (t0, t1, sol, b, overlap)
    events = [tuple(row[:3]) for row in log] + [(t_end, math.nan, math.nan)]
    j, b, pair, on = 0.0, 0.0, math.nan, False
    tol = dict(method="DOP853", rtol=1e-11, atol=1e-13, dense_output=True)
    for (t0, new_pair, new_b), (t1, _, _) in pairwise(events):
        t1 = min(t1, t_end)
        overlap = False
        if new_b == 0.0:
            on = False
            j = 0.0
        else:
            overlap = j > 0.0 and c.l_c > 0.0 and new_pair == pair + 1 and new_b == b
            old_pair, pair, b, on = pair, new_pair, new_b, True
        t = t0
        i_in = 0.0
        while on and t < t1 - 1e-15:
            if j <= 0.0:  # wait for forward bias of the gated pair
                def g(s, pair=pair, b=b):
                    return c.u(pair, s) - b * emf(s)
                grid = np.linspace(t, t1, 400)
                vals = np.array([g(s) for s in grid])
                if vals[0] > 0.0:
                    t_on = t
                else:
                    up = np.flatnonzero((vals[:-1] <= 0.0) & (vals[1:] > 0.0))
                    if not up.size:
                        break
                    t_on = brentq(g, grid[up[0]], grid[up[0] + 1], xtol=1e-15)
                t, j, overlap = t_on, 0.0, False
            if overlap:
                def rhs(s, y, pair=pair, old=old_pair, b=b):
                    uo, ui = c.u(old, s), c.u(pair, s)
                    dj = (0.5 * (uo + ui) - b * emf(s) - c.r * y[0]) / (
                        c.l + (c.series - 0.5) * c.l_c)
                    return [dj, 0.5 * (dj + (ui - uo) / c.l_c)]

                def done(s, y):
                    return y[1] - y[0]
                done.terminal, done.direction = True, 1

                def gone(s, y):
                    return y[0]
                gone.terminal, gone.direction = True, -1
                sol = solve_ivp(rhs, (t, t1), [j, i_in], events=(done, gone), **tol)
                pieces.append((t, sol.t[-1], sol.sol, b, True))
                j, t = max(sol.y[0, -1], 0.0), sol.t[-1]
                overlap = False
                if sol.t_events[1].size:
                    j = 0.0
                continue

            def rhs(s, y, pair=pair, b=b):
                return [(c.u(pair, s) - b * emf(s) - c.r * y[0]) / (c.l + c.series * c.l_c)]

            def zero(s, y):
                return y[0]
            zero.terminal, zero.direction = True, -1
            sol = solve_ivp(rhs, (t, t1), [j], events=zero, **tol)
            pieces.append((t, sol.t[-1], sol.sol, b, False))
            t = sol.t[-1]
            j = 0.0 if sol.t_events[0].size else max(sol.y[0, -1], 0.0)
            if sol.t_events[0].size and t >= t1 - 1e-15:
                break
    out = np.zeros(len(times))
    for t0, t1, sol, sign, _ in pieces:
        inside = (times > t0) & (times <= t1)
        if inside.any():
            out[inside] = sign * np.maximum(sol(times[inside])[0], 0.0)
    total = 0.0
    for t0, t1, sol, sign, _ in pieces:
        if t1 > t0:
            s = np.linspace(t0, t1, 201)
            total += sign * np.trapezoid(np.maximum(sol(s)[0], 0.0), s)
    return out, total
