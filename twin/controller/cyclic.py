"""The compiled cyclic path: one steady controller tick in one numba kernel.

A tick of ``Controller.tick`` in plain Python costs about 15 µs: encoder unwrap, safety,
the interpolator's profile and geometry, the regulator, the held outputs and the record row
are each a few attribute look-ups and float operations apart. ``steady_tick`` does all of it
in one compiled call for the ticks that make up almost every period of a run: moving along
(or dwelling inside) one block, no switch closed, drives ready, no homing. Every other tick
— a block change, a limit switch, the end of the program, settling, homing, the
traditional interface — takes the Python path, which stays the reference: the kernel is a
transcription of it, operation for operation and in the same order, so both give the same
bits (``tests/controller/test_cyclic.py`` runs programs of every law and geometry both ways
and compares every record column exactly).

Things the transcription has to respect to stay bit-identical: Python's ``min``/``max``
keep the first argument on ties (``_pmin``/``_pmax``), ``x ** 3`` is written out as
products (numba and CPython compute integer powers differently), and the spline's norm is
``sqrt(x·x + y·y)`` on both sides (CPython's ``math.hypot`` is not libm's).

The block being run is handed to the kernel as flat arrays, built once per block by
``block_tables``:

* ``geo`` (``G_SIZE``,): geometry kind and constants, the profile's duration, distance and
  end speed;
* ``pieces`` (n, 9): the profile's pieces ``start, duration, s0, v0, kind, p1 … p4`` — kind
  ``PIECE_POLY`` (constant jerk: p1 = a0, p2 = j), one of the shape laws (a whole change,
  ``Blend``: p1 = Δv), or ``PART`` + a shape law (a part of a change the planner spread over
  several blocks, ``BlendPart``: p1 = Δv, p2 = base speed, p3 = span, p4 = offset);
* for a spline, ``SplineCurve.kernel_tables()``: sub-interval starts, the inverse table and
  the coefficient rows.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from twin.controller._spline_curve import _GL_W, _GL_X, _MAX_NEWTON, _NEWTON_DONE
from twin.controller.compensation import NO_COMPENSATION, compensate_reference
from twin.controller.geometry import Arc, Line, arc_point
from twin.controller.profiles.profile import Blend, BlendPart, Polynomial
from twin.controller.regulator import _regulate
from twin.controller.shaping import NO_TAPS, shape_reference

__all__ = ["FALLBACK", "G_SIZE", "P_SIZE", "block_tables", "steady_tick", "warm_up"]

FALLBACK = -1
"""``steady_tick``'s answer when the tick needs the Python path (nothing was changed)."""

# geometry kinds (the interpolator's)
K_LINE, K_ARC, K_CURVE, K_DWELL = 0, 1, 2, 3
# geo columns
(G_KIND, G_S0, G_X0, G_Y0, G_UX, G_UY, G_CX, G_CY, G_R, G_SIGN, G_K, G_TH0, G_ENDX, G_ENDY,
 G_PDUR, G_DIST, G_VEND, G_LEN) = range(18)
G_SIZE = 18
# piece kinds: constant jerk, or the shape of a law's speed change
PIECE_POLY, PIECE_LINEAR, PIECE_PARABOLIC, PIECE_COSINE, PIECE_CUBIC = range(5)
PART = 8
"""Added to a shape's kind: a part of a change (``BlendPart``)."""
P_SIZE = 9
_SHAPE_KIND = {"trapezoid": PIECE_LINEAR, "parabolic": PIECE_PARABOLIC,
               "cosine": PIECE_COSINE, "cubic": PIECE_CUBIC}
# the cosine shape's constants, as the Python path computes them
_PI = math.pi
_TWO_PI = 2.0 * math.pi
_HALF_PI = 0.5 * math.pi
_HALF_PI2 = 0.5 * math.pi**2
# controller status codes (ControllerStatus) the kernel produces
_RUNNING, _DWELLING, _FOLLOWING_ERROR, _INVALID_INPUT = 1, 2, 7, 8
_NO_TABLE = np.zeros((1, 1))
_NO_STARTS = np.zeros(1)


# --------------------------------------------------------------------------- set-up (Python)
def block_tables(act: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                    np.ndarray] | None:
    """The kernel's arrays of an interpolator's active block or dwell (``_Active``):
    (geo, pieces, spline starts, spline table, spline rows), or None if the kernel cannot
    run it (a piece it does not know)."""
    geo = np.zeros(G_SIZE)
    geo[G_KIND] = act.kind
    geo[G_ENDX], geo[G_ENDY] = act.end
    if act.kind == K_DWELL:
        return geo, _NO_TABLE, _NO_STARTS, _NO_TABLE, _NO_TABLE
    prof = act.profile
    geo[G_S0], geo[G_X0], geo[G_Y0] = act.s0, act.x0, act.y0
    geo[G_PDUR], geo[G_DIST], geo[G_VEND] = prof.duration, prof.distance, prof.v_end
    rows = []
    for seg in prof.segments:
        if type(seg) is Polynomial:
            rows.append((seg.start, seg.duration, seg.s0, seg.v0, PIECE_POLY, seg.a0, seg.j,
                         0.0, 0.0))
        elif type(seg) is Blend and seg.shape.name in _SHAPE_KIND:
            rows.append((seg.start, seg.duration, seg.s0, seg.v0, _SHAPE_KIND[seg.shape.name],
                         seg.dv, 0.0, 0.0, 0.0))
        elif type(seg) is BlendPart and seg.shape.name in _SHAPE_KIND:
            rows.append((seg.start, seg.duration, seg.s0, seg.v0,
                         PART + _SHAPE_KIND[seg.shape.name], seg.dv, seg.base, seg.span,
                         seg.offset))
        else:
            return None
    pieces = (np.array(rows, dtype=np.float64).reshape(-1, P_SIZE) if rows
              else np.zeros((1, P_SIZE)))
    segment = act.segment
    if act.kind == K_LINE and type(segment) is Line:
        geo[G_UX], geo[G_UY] = act.ux, act.uy
        return geo, pieces, _NO_STARTS, _NO_TABLE, _NO_TABLE
    if act.kind == K_ARC and type(segment) is Arc:
        geo[G_CX], geo[G_CY], geo[G_R] = act.cx, act.cy, act.r
        geo[G_SIGN], geo[G_K], geo[G_TH0] = act.sign, act.k, act.th0
        return geo, pieces, _NO_STARTS, _NO_TABLE, _NO_TABLE
    tables = getattr(segment, "kernel_tables", None)
    if act.kind != K_CURVE or tables is None:
        return None
    geo[G_LEN] = segment.length
    starts, table, coef = tables()
    return geo, pieces, starts, table, coef


# --------------------------------------------------------------------------- kernels
@numba.njit(cache=True, inline="always")
def _pmax(a, b):
    """Python's ``max(a, b)``: the first argument unless the second is larger."""
    return b if b > a else a


@numba.njit(cache=True, inline="always")
def _pmin(a, b):
    """Python's ``min(a, b)``: the first argument unless the second is smaller."""
    return b if b < a else a


@numba.njit(cache=True)
def profile_at(pieces, duration, distance, v_end, t):
    """``Profile.at``: path state (s, v, a, j) at time ``t`` of the block."""
    if t < 0.0:
        t = 0.0
    if t >= duration:
        return distance, v_end, 0.0, 0.0
    lo, hi = 0, pieces.shape[0]            # bisect_right on the pieces' starts, minus one
    while lo < hi:
        mid = (lo + hi) // 2
        if t < pieces[mid, 0]:
            hi = mid
        else:
            lo = mid + 1
    p = pieces[lo - 1]
    tau = t - p[0]
    s0, v0, kind = p[2], p[3], p[4]
    if kind == PIECE_POLY:                 # Polynomial.at (constant_jerk)
        a0, j = p[5], p[6]
        return (s0 + tau * (v0 + tau * (0.5 * a0 + tau * (j / 6.0))),
                v0 + tau * (a0 + 0.5 * j * tau), a0 + j * tau, j)
    if kind >= PART:                       # BlendPart._eval
        dv, base, T, offset = p[5], p[6], p[7], p[8]
        u0 = offset / T
        u = (tau + offset) / T
        integral0, _, _, _ = _shape(kind - PART, u0)
        integral, vel, acc, jerk = _shape(kind - PART, u)
        return (s0 + T * (base * (u - u0) + dv * (integral - integral0)),
                base + dv * vel, dv / T * acc, dv / (T * T) * jerk)
    T, dv = p[1], p[5]                     # Blend._eval
    u = tau / T
    integral, vel, acc, jerk = _shape(kind, u)
    return (s0 + T * (v0 * u + dv * integral), v0 + dv * vel, dv / T * acc,
            dv / (T * T) * jerk)


@numba.njit(cache=True, inline="always")
def _shape(kind, u):
    """The law's Φ(u), φ(u), φ'(u), φ''(u) (``Shape``'s methods, written alike)."""
    if kind == PIECE_LINEAR:
        return 0.5 * u * u, u, 1.0 + 0.0 * u, 0.0 * u
    if kind == PIECE_PARABOLIC:
        return (u * u * u * (1.0 - 0.5 * u), u * u * (3.0 - 2.0 * u), 6.0 * u * (1.0 - u),
                6.0 - 12.0 * u)
    if kind == PIECE_COSINE:
        return (0.5 * u - math.sin(_PI * u) / _TWO_PI, 0.5 - 0.5 * math.cos(_PI * u),
                _HALF_PI * math.sin(_PI * u), _HALF_PI2 * math.cos(_PI * u))
    w = u * (1.0 - u)
    return (u * u * u * u * (2.5 + u * (u - 3.0)), u * u * u * (10.0 + u * (6.0 * u - 15.0)),
            30.0 * w * w, 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u))


@numba.njit(cache=True, inline="always")
def _derivatives(row, t):
    """``_spline_curve._derivatives_py``."""
    ax, ay, bx, by, cx, cy, dx, dy = row[0], row[1], row[2], row[3], row[4], row[5], \
        row[6], row[7]
    return (ax + t * (bx + t * (cx + t * dx)), ay + t * (by + t * (cy + t * dy)),
            bx + t * (2.0 * cx + 3.0 * t * dx), by + t * (2.0 * cy + 3.0 * t * dy),
            2.0 * cx + 6.0 * t * dx, 2.0 * cy + 6.0 * t * dy)


@numba.njit(cache=True)
def _integral(row, t0, t1):
    """``SplineCurve._integral_py``."""
    bx, by = row[2], row[3]
    cx, cy, dx, dy = 2.0 * row[4], 2.0 * row[5], 3.0 * row[6], 3.0 * row[7]
    acc, dt = 0.0, t1 - t0
    for m in range(_GL_X.size):
        t = t0 + dt * _GL_X[m]
        ex, ey = bx + t * (cx + t * dx), by + t * (cy + t * dy)
        acc += _GL_W[m] * math.sqrt(ex * ex + ey * ey)
    return acc * dt


@numba.njit(cache=True)
def curve_frame(s, starts, table, coef):
    """``SplineCurve.frame_at`` (``_locate`` then the frame) at arc length ``s``."""
    n = starts.size
    lo, hi = 0, n                           # bisect_right(starts, s) − 1, clipped
    while lo < hi:
        mid = (lo + hi) // 2
        if s < starts[mid]:
            hi = mid
        else:
            lo = mid + 1
    j = _pmin(_pmax(lo - 1, 0), n - 1)
    rec = table[j]
    a, b, length = rec[1], rec[2], rec[3]
    row = coef[int(rec[0])]
    sigma = _pmin(_pmax(s - starts[j], 0.0), length)
    x = sigma / length
    tau = 0.0
    for m in range(rec.size - 1, 3, -1):
        tau = tau * x + rec[m]
    t = a + (b - a) * _pmin(_pmax(tau, 0.0), 1.0)
    lo_t, hi_t = a, b
    for _ in range(_MAX_NEWTON):
        f = _integral(row, a, t) - sigma
        if f > 0.0:
            hi_t = t
        else:
            lo_t = t
        _, _, vx, vy, _, _ = _derivatives(row, t)
        v = math.sqrt(vx * vx + vy * vy)
        new = t - f / v if v > 0.0 else 0.5 * (lo_t + hi_t)
        if not lo_t <= new <= hi_t:
            new = 0.5 * (lo_t + hi_t)
        done = abs(new - t) <= _NEWTON_DONE * (b - a)
        t = new
        if done:
            break
    px, py, vx, vy, ax, ay = _derivatives(row, t)
    speed = math.sqrt(vx * vx + vy * vy)
    cross, dot = vx * ay - vy * ax, vx * ax + vy * ay
    cube = speed * speed * speed
    rate = (vx * row[7] - vy * row[6]) * 6.0 / cube - 3.0 * cross * dot / (cube * (speed
                                                                                  * speed))
    return px, py, vx / speed, vy / speed, cross / cube, rate / speed


@numba.njit(cache=True)
def reference_at(geo, pieces, starts, table, coef, tau, ref_p, ref_v, ref_a, ref_j):
    """``Interpolator._evaluate`` (or a dwell's hold) at block time ``tau``, written into
    the reference arrays."""
    kind = geo[G_KIND]
    if kind == K_DWELL:
        ref_p[0], ref_p[1] = geo[G_ENDX], geo[G_ENDY]
        ref_v[0] = ref_v[1] = ref_a[0] = ref_a[1] = ref_j[0] = ref_j[1] = 0.0
        return
    s, v, a, j = profile_at(pieces, geo[G_PDUR], geo[G_DIST], geo[G_VEND], tau)
    s += geo[G_S0]
    if kind == K_LINE:
        ux, uy = geo[G_UX], geo[G_UY]
        ref_p[0], ref_p[1] = geo[G_X0] + s * ux, geo[G_Y0] + s * uy
        ref_v[0], ref_v[1] = v * ux, v * uy
        ref_a[0], ref_a[1] = a * ux, a * uy
        ref_j[0], ref_j[1] = j * ux, j * uy
        return
    if kind == K_ARC:
        k = geo[G_K]
        x, y, tx, ty = arc_point(geo[G_CX], geo[G_CY], geo[G_R], geo[G_TH0], k, geo[G_SIGN],
                                 s)
        dk = 0.0
    else:                                   # SplinePath.frame
        length = geo[G_LEN]
        s = _pmin(_pmax(s, 0.0), length)
        x, y, tx, ty, k, dk = curve_frame(s, starts, table, coef)
        if s == 0.0:
            x, y = geo[G_X0], geo[G_Y0]
        elif s == length:
            x, y = geo[G_ENDX], geo[G_ENDY]
    nx, ny = -ty, tx
    an = v * v * k
    jt = j - v * v * v * k * k
    jn = 3.0 * v * a * k + v * v * v * dk
    ref_p[0], ref_p[1] = x, y
    ref_v[0], ref_v[1] = v * tx, v * ty
    ref_a[0], ref_a[1] = a * tx + an * nx, a * ty + an * ny
    ref_j[0], ref_j[1] = jt * tx + jn * nx, jt * ty + jn * ny


@numba.njit(cache=True)
def steady_tick(counts, tacho, limit_min, limit_max, drive_ready, limits_prev, enc_int,
                enc_float, pos, geo, pieces, starts, table, coef, tau, ticks, period,
                ref_p, ref_v, ref_a, ref_j, cp_par, cp_state, sh_index, sh_weight, sh_history,
                sh_state, par, st, reg_out, reg_err, terms, code_min, code_max, held, dac,
                chunk, row, block, line):
    """One steady tick of ``Controller.tick`` (see the module docstring).

    Returns ``FALLBACK`` (and changes nothing) when a switch is closed or was closed last
    tick or the drives are not ready: the Python path handles those. Otherwise the tick is
    done — encoder, reference, regulator, outputs, the record row ``chunk[row]`` — and the
    answer is ``32·regulator code + controller status``.

    ``enc_int`` (3, n) int64: last raw sample, unwrapped count, counter width; ``enc_float``
    (2, n): origin (m), counts per metre. ``cp_*``: the reference compensations'
    parameters and state (``compensation.compensate_reference``). ``sh_*``: the input
    shapers' taps and history (``shaping.shape_reference``). Both are the one
    implementation the Python tick calls as well; no parameters or taps: nothing.
    """
    if not drive_ready:
        return FALLBACK
    for k in range(2):
        if limit_min[k] or limit_max[k] or limits_prev[2 * k] or limits_prev[2 * k + 1]:
            return FALLBACK
    # 1. encoder (EncoderUnwrapper.update)
    for k in range(2):
        r = np.int64(counts[k])
        half = np.int64(1) << (enc_int[2, k] - 1)
        enc_int[1, k] += ((r - enc_int[0, k] + half) % (half << 1)) - half
        enc_int[0, k] = r
        pos[k] = enc_float[0, k] + enc_int[1, k] / enc_float[1, k]
    # 2. safety passed (checked above); 3. interpolation
    reference_at(geo, pieces, starts, table, coef, tau, ref_p, ref_v, ref_a, ref_j)
    compensate_reference(cp_par, cp_state, period, 0, ref_p, ref_v, ref_a, ref_j)
    shape_reference(sh_index, sh_weight, sh_history, sh_state, ref_p, ref_v, ref_a, ref_j)
    compensate_reference(cp_par, cp_state, period, 1, ref_p, ref_v, ref_a, ref_j)
    # 4. regulation
    rc = _regulate(par, st, ref_p, ref_v, ref_a, ref_j, pos, reg_out, reg_err, terms,
                   code_min, code_max)
    if rc >= 2:                             # tripped: PositionRegulator._trip
        reg_out[:] = 0.0
        terms[:] = 0.0
        status = _FOLLOWING_ERROR if rc == 2 else _INVALID_INPUT
        dac[:] = 0.0
        held[0] = held[1] = 0.0
        enable = 0.0
    else:
        status = _DWELLING if geo[G_KIND] == K_DWELL else _RUNNING
        # 5. outputs: what the previous tick computed (compute ahead)
        dac[0], dac[1] = held[0], held[1]
        held[0], held[1] = reg_out[0], reg_out[1]
        enable = 1.0
    # the record row (Controller._log, RECORD_FIELDS)
    out = chunk[row]
    out[0] = ticks * period
    for k in range(2):
        out[1 + k] = ref_p[k]
        out[3 + k] = ref_v[k]
        out[5 + k] = ref_a[k]
        out[7 + k] = ref_j[k]
        out[9 + k] = pos[k]
        out[11 + k] = reg_err[k]
        out[13 + k] = dac[k]
        out[15 + k] = tacho[k]
        for m in range(5):
            out[17 + 5 * k + m] = terms[k, m]
    out[27] = enable
    out[28] = block
    out[29] = line
    out[30] = status
    return 32 * rc + status


_warm = False


def warm_up() -> None:
    """Load (or compile) ``steady_tick`` for the argument types ``Controller`` passes, once
    per process: a first tick that compiled would stall a paced loop for seconds (the
    deadline policy stops a run after 4 lost periods). Called when a compiled controller is
    built; the call itself returns ``FALLBACK`` at once (drives not ready)."""
    global _warm
    if _warm:
        return
    two, flags = np.zeros(2), np.zeros(2, dtype=bool)
    table = np.zeros((1, 1))
    steady_tick(np.zeros(2, dtype=np.int64), two, flags, flags, False,
                np.zeros(4, dtype=bool), np.zeros((3, 2), dtype=np.int64), np.ones((2, 2)),
                two, np.zeros(G_SIZE), np.zeros((1, P_SIZE)), np.zeros(1), table, table, 0.0, 1,
                1e-3, two, two, two, two, *NO_COMPENSATION, *NO_TAPS, np.zeros((2, 12)),
                np.zeros((2, 5)), two, two, np.zeros((2, 5)), 0, 0, two, two, np.zeros((1, 31)),
                0, 0, 0)
    _warm = True
