"""The plant's inner loop compiled: drive kernel ⇄ MuJoCo's C ``mj_step``, in one call.

Between two controller periods the plant alternates, every drive interval, between the drive
kernel (``twin.drive.kernel.drive_step``, numba) and ``drive_substeps`` physics steps. In
Python each alternation costs about a microsecond and a half of call overhead — as much as
the whole drive model. Here the alternation runs inside one numba function that calls
``mj_step`` of the MuJoCo shared library, on the very ``mjModel``/``mjData`` the Python
bindings own (their addresses), so the state is the same memory and the result is
bit-identical to the Python loop (``tests/plant/test_fast_paths.py``). The library's
``mj_step`` is found with ctypes and registered with LLVM under a symbol of its own
(``MJ_STEP_SYMBOL``); the loop calls it by that name, so numba can cache the compiled loop
like every other kernel (a function pointer baked into the code could not be cached: every
process would compile the loop again, about a second).

Forces MuJoCo's passive elements cannot give are applied before every physics step
(:func:`passive_forces`, shared with the Python loop): the Stribeck part of break-away
friction, and the damping of a screw with lost motion, which acts only while the dead band
is closed. Before them, the stiffness and damping of an axial spring that varies with the
nut position are written into the model's tendon arrays (:func:`chain_springs`).

If the shared library cannot be found, or the bindings do not expose the structs' addresses
(``_address``, present in MuJoCo 3 and 4), ``available()`` is False and the plant keeps its
Python loop.
"""

from __future__ import annotations

import ctypes
import glob
import math
import os

import llvmlite.binding as llvm
import mujoco
import numba
import numpy as np
from numba import types

from twin.drive.kernel import drive_step
from twin.drive.layout import S_ADC, S_CONDUCT, S_FAULT, S_I, S_VOUT

__all__ = ["NCHAIN", "NPASSIVE", "NREADOUT", "TICK_CHECK", "TICK_DONE", "TICK_ENABLE",
           "TICK_ERROR", "addresses", "apply_forces", "available",
           "chain_springs", "passive_forces", "quantise", "readout", "record_interval",
           "step_intervals", "ticks"]

NREADOUT = 8
"""The drive state a period's readers need, per axis pair: tacho as the ADC reads it (V),
the fault flag, the armature current (A), the interval's mean converter voltage (V)."""

NPASSIVE = 7
"""Columns of the per-axis passive-force parameters: slide break-away excess F_s − F_c (N),
slide Stribeck speed (m/s), rotor excess (N·m), rotor Stribeck speed (rad/s), half the lost
motion (m), screw damping (N·s/m), the axial spring's ratio (m/rad: r of the rotor, or r_s
of a screw body)."""

NCHAIN = 14
"""Columns of the per-axis chain parameters (``model.chain_parameters``): the axial spring
varies with the nut (1/0), a₀ (m) and s (±1) of the nut distance a = a₀ + s·x, fixed-fixed
(1/0), screw length L (m), E·A (N), the spring's other compliance (m/N), β (s), the axial
tendon's id, lost motion (1/0), the travel (min, max) (m), the screw body's qpos and dof
address (−1: none)."""


TICK_DONE, TICK_ENABLE, TICK_ERROR, TICK_CHECK = range(4)
"""Why :func:`ticks` returned: all ticks run; the drive enable changes at the tick; the
kernel or the DAC refused the tick; the tick needs ``Plant.step``'s checks."""

MJ_STEP_SYMBOL = "xy_twin_mj_step"
"""The name the compiled loop calls MuJoCo's ``mj_step`` by (registered with LLVM)."""


def _load_mj_step():
    if not (hasattr(mujoco.MjModel, "_address") and hasattr(mujoco.MjData, "_address")):
        return None  # bindings that do not expose the struct addresses: keep the Python loop
    base = os.path.dirname(mujoco.__file__)
    names = ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll")
    paths = sorted(p for n in names for p in glob.glob(os.path.join(base, n)))
    if not paths:
        return None
    try:
        fn = ctypes.CDLL(paths[0]).mj_step
    except (OSError, AttributeError):
        return None
    llvm.add_symbol(MJ_STEP_SYMBOL, ctypes.cast(fn, ctypes.c_void_p).value)
    # Pointers travel as 64-bit integers: identical in the x86-64 and AArch64 C ABIs.
    return types.ExternalFunction(MJ_STEP_SYMBOL, types.void(types.uint64, types.uint64))


_MJ_STEP = _load_mj_step()


def available() -> bool:
    """True if the compiled loop can run (MuJoCo's shared library was found)."""
    return _MJ_STEP is not None


@numba.njit(cache=True)
def quantise(dac_in, dac, u):
    """The plant's DAC output stage: each axis' request (V) rounded to its code, clipped to
    the code range, then the stage's own gain error and offset (``dac`` rows: LSB (V),
    lowest and highest code, gain, offset (V)); written into ``u``. Returns a bit mask of
    the clipped axes, or −1 − axis for a request that is not finite (nothing written)."""
    for k in range(u.shape[0]):
        if not math.isfinite(dac_in[k]):
            return -1 - k
    clipped = 0
    for k in range(u.shape[0]):
        lsb, lowest, highest = dac[k, 0], dac[k, 1], dac[k, 2]
        code = math.floor(dac_in[k] / lsb + 0.5)
        if not lowest <= code <= highest:
            clipped |= 1 << k
            code = min(max(code, lowest), highest)
        u[k] = code * lsb * dac[k, 3] + dac[k, 4]
    return clipped


@numba.njit(cache=True)
def readout(state, out):
    """Fill ``out`` (``NREADOUT``) from the drive state: ADC tacho, fault, current and mean
    converter voltage of x and y."""
    for k in range(2):
        out[k] = state[k, S_ADC]
        out[2 + k] = state[k, S_FAULT]
        out[4 + k] = state[k, S_I]
        out[6 + k] = state[k, S_VOUT]


@numba.njit(cache=True)
def apply_forces(passive, has_passive, chain, has_chain, sub_torque, s, rotor_frc, slide_frc,
                 table_pos, table_vel, rotor_pos, rotor_vel, qpos, qvel, qfrc, ten_stiffness,
                 ten_damping):
    """Prepare physics step ``s`` of the interval: the axial springs that vary with the
    nut position when the machine has any (:func:`chain_springs`), the drive's torque over
    that step (``sub_torque[:, s]``) on the rotors, plus the passive forces MuJoCo cannot
    give when the machine has any (:func:`passive_forces`)."""
    if has_chain:
        chain_springs(chain, table_pos, ten_stiffness, ten_damping, passive)
    if has_passive:
        passive_forces(passive, chain, sub_torque[:, s], rotor_frc, slide_frc, table_pos,
                       table_vel, rotor_pos, rotor_vel, qpos, qvel, qfrc)
    else:
        for k in range(rotor_frc.shape[0]):
            rotor_frc[k] = sub_torque[k, s]


@numba.njit(cache=True)
def chain_springs(chain, table_pos, ten_stiffness, ten_damping, passive):
    """Write each varying axial spring's stiffness and damping for the nut's position now.

    Per axis (a row of ``chain``, ``NCHAIN`` columns, ``model.chain_parameters``) the nut
    is at a = a₀ + s·x from the drive-end bearing (x clamped to the travel: the end stops
    give way by micrometres); the screw's compliance is g(a)/(E·A), g = a (fixed-free) or
    a·(L − a)/L (fixed-fixed), in series with the spring's other components; the damping is
    β times the stiffness: into the tendon, or into ``passive`` when lost motion makes the
    plant apply it (:func:`passive_forces`).
    """
    for k in range(chain.shape[0]):
        p = chain[k]
        if p[0] == 0.0:
            continue
        x = min(max(table_pos[k], p[10]), p[11])
        a = p[1] + p[2] * x
        g = a * (p[4] - a) / p[4] if p[3] != 0.0 else a
        stiffness = 1.0 / (g / p[5] + p[6])
        t = int(p[8])
        ten_stiffness[t] = stiffness
        if p[9] != 0.0:
            passive[k, 5] = p[7] * stiffness
        else:
            ten_damping[t] = p[7] * stiffness


@numba.njit(cache=True)
def passive_forces(passive, chain, drive_torque, rotor_frc, slide_frc, table_pos, table_vel,
                   rotor_pos, rotor_vel, qpos, qvel, qfrc):
    """Write the applied forces of one physics step: the drive torque plus the extra passive
    forces on the rotors, the extra passive forces on the slides (and screw bodies).

    Break-away friction: MuJoCo's dof friction holds the break-away value F_s (it is what a
    standing axis must overcome); the excess F_s − F_c is given back while sliding,
    f = sign(v)·(F_s − F_c)·(1 − exp(−(v/v_s)²)), so the kinetic friction is the Stribeck
    curve F_c + (F_s − F_c)·exp(−(v/v_s)²). Lost motion: the axial (screw) tendon's spring
    has a dead band of width b; its damping c is applied here, only outside the dead band,
    between the table and the spring's driver: the rotor, or the screw body whose qpos and
    dof addresses are ``chain[k, 12:14]`` (−1: none) in ``qpos``, ``qvel``, ``qfrc``.
    """
    for k in range(rotor_frc.shape[0]):
        p = passive[k]
        f_rotor = 0.0
        f_slide = 0.0
        if p[0] > 0.0:
            v = table_vel[k]
            f_slide += math.copysign(p[0] * -math.expm1(-(v / p[1]) ** 2), v)
        if p[2] > 0.0:
            w = rotor_vel[k]
            f_rotor += math.copysign(p[2] * -math.expm1(-(w / p[3]) ** 2), w)
        if p[4] > 0.0:
            r = p[6]
            shaft = int(chain[k, 12])
            if shaft >= 0:
                dof = int(chain[k, 13])
                f_shaft = 0.0
                length = r * qpos[shaft] - table_pos[k]
                if abs(length) > p[4]:
                    f_t = -p[5] * (r * qvel[dof] - table_vel[k])  # the tendon's damper
                    f_shaft = r * f_t
                    f_slide -= f_t
                qfrc[dof] = f_shaft
            else:
                length = r * rotor_pos[k] - table_pos[k]
                if abs(length) > p[4]:
                    f_t = -p[5] * (r * rotor_vel[k] - table_vel[k])  # the tendon's damper
                    f_rotor += r * f_t
                    f_slide -= f_t
        rotor_frc[k] = drive_torque[k] + f_rotor
        slide_frc[k] = f_slide


@numba.njit(cache=True)
def record_interval(i, t, state, table_pos, qpos, spring_adr, spring_ratio, samples, extent,
                    ring, ring_n):
    """Row i of the drive-rate samples (``plant_records.FINE_FIELDS``, at plant time t),
    also written to row ``ring_n + i`` (modulo its length) of the ring buffer ``ring``, and
    the running extent of the table position (x lo, x hi, y lo, y hi; NaN if a sample was
    NaN). The screw deflection is the axial spring's, ``spring_ratio[k]·qpos[spring_adr[k]]
    − x``: its driver (the rotor, or the screw body) at ``spring_adr``."""
    r = (ring_n + i) % ring.shape[0]
    samples[i, 10] = t
    ring[r, 10] = t
    for k in range(2):
        x = table_pos[k]
        samples[i, k] = x
        samples[i, 2 + k] = state[k, S_I]
        samples[i, 4 + k] = state[k, S_VOUT]
        samples[i, 6 + k] = state[k, S_CONDUCT]
        samples[i, 8 + k] = spring_ratio[k] * qpos[spring_adr[k]] - x
        for c in range(k, 10, 2):
            ring[r, c] = samples[i, c]
        if i == 0:
            extent[2 * k] = extent[2 * k + 1] = x
        else:
            if x < extent[2 * k] or x != x:
                extent[2 * k] = x
            if x > extent[2 * k + 1] or x != x:
                extent[2 * k + 1] = x


if _MJ_STEP is not None:
    _c_mj_step = _MJ_STEP

    @numba.njit(cache=True)
    def _intervals(m_addr, d_addr, n, substeps, params, state, tables, dac_in, dac, u, noise,
                   log, n0, dt, enabled, passive, has_passive, chain, has_chain, torque,
                   sub_torque, scratch, rotor_frc, slide_frc, table_pos, table_vel, rotor_pos,
                   rotor_vel, qpos, qvel, qfrc, ten_stiffness, ten_damping, spring_adr,
                   spring_ratio, samples, steps, extent, ring, ring_n, out):
        clipped = quantise(dac_in, dac, u)
        if clipped < 0:
            return 0, 0, clipped
        for i in range(n):
            noise_i = noise[i] if noise.shape[0] > 1 else noise[0]
            status = drive_step(params, state, tables, u, rotor_vel, rotor_pos, noise_i, log,
                                n0 + i, dt, enabled, torque, sub_torque, scratch)
            if status != 0:
                readout(state, out)
                return i, status, clipped
            for s in range(substeps):
                apply_forces(passive, has_passive, chain, has_chain, sub_torque, s,
                             rotor_frc, slide_frc, table_pos, table_vel, rotor_pos, rotor_vel,
                             qpos, qvel, qfrc, ten_stiffness, ten_damping)
                _c_mj_step(m_addr, d_addr)
                if steps.shape[0] > 0:
                    j = i * substeps + s
                    steps[j, 0] = table_vel[0]
                    steps[j, 1] = table_vel[1]
            record_interval(i, (n0 + i + 1) * dt, state, table_pos, qpos, spring_adr,
                            spring_ratio, samples, extent, ring, ring_n)
        readout(state, out)
        return n, 0, clipped


    @numba.njit(cache=True)
    def _ticks(first, intervals, dac_in, enable, enabled, cpr, offset, mask, free, warnings,
               warnings_seen, clock, timestep, counts, tacho, m_addr, d_addr, substeps,
               params, state, tables, dac, u, noise, log, n0, dt, passive, has_passive,
               chain, has_chain, torque, sub_torque, scratch, rotor_frc, slide_frc,
               table_pos, table_vel, rotor_pos, rotor_vel, qpos, qvel, qfrc, ten_stiffness,
               ten_damping, spring_adr, spring_ratio, samples, steps, extent, ring, ring_n,
               out):
        done = 0
        for k in range(first, intervals.shape[0]):
            clock[0] = clock[1]
            for a in range(2):   # Plant.read_into without noise
                counts[k, a] = (math.floor(rotor_pos[a] * cpr[a]) + offset[a]) & mask[a]
                tacho[k, a] = out[a]
            if enable[k] != enabled:
                return k, done, TICK_ENABLE, 0, 0
            n, status, clip = _intervals(
                m_addr, d_addr, intervals[k], substeps, params, state, tables, dac_in[k], dac,
                u, noise, log, n0 + done, dt, enabled, passive, has_passive, chain,
                has_chain, torque, sub_torque, scratch, rotor_frc, slide_frc, table_pos,
                table_vel, rotor_pos, rotor_vel, qpos, qvel, qfrc, ten_stiffness,
                ten_damping, spring_adr, spring_ratio, samples, steps, extent, ring,
                ring_n + done, out)
            done += n
            for _ in range(n * substeps):   # MuJoCo's own sum: time += timestep per step
                clock[1] += timestep
            if status != 0 or clip < 0:
                return k, done, TICK_ERROR, status, clip
            check = False
            for a in range(2):
                check |= not (free[a, 0] < extent[2 * a] and extent[2 * a + 1] < free[a, 1])
            for w in range(warnings.shape[0]):
                check |= warnings[w] != warnings_seen[w]
            if check:
                return k, done, TICK_CHECK, 0, clip
        return intervals.shape[0], done, TICK_DONE, 0, 0


def ticks(first: int, intervals: np.ndarray, dac_in: np.ndarray, enable: np.ndarray,
          enabled: bool, cpr: np.ndarray, offset: np.ndarray, mask: np.ndarray,
          free: np.ndarray, warnings: np.ndarray, warnings_seen: np.ndarray,
          clock: np.ndarray, timestep: float, counts: np.ndarray, tacho: np.ndarray,
          *loop: object) -> tuple[int, int, int, int, int]:
    """Ticks ``first``… of an open-loop run, each as ``Plant.read_into`` then
    ``Plant.step``: the sensors sampled (without noise) into ``counts[k]`` (the counters,
    ``floor(θ·cpr) + offset`` masked to their width) and ``tacho[k]`` (V), then
    ``intervals[k]`` drive intervals of :func:`step_intervals` under ``dac_in[k]`` (``loop``
    is that function's arguments after ``dac_in``, with ``n0`` and ``ring_n`` those of tick
    ``first``).

    It stops, for the caller to finish in Python, before a tick whose ``enable[k]`` differs
    from ``enabled`` (``TICK_ENABLE``, the tick read but not stepped), at a tick the kernel
    refused (``TICK_ERROR``, as :func:`step_intervals` returns it) and after a tick that
    ``Plant.step``'s checks must see (``TICK_CHECK``): a table sample outside the axis'
    ``free`` row (the open interval where no switch can change, ``AxisMonitor.free``; NaN
    is outside) or a MuJoCo warning counter that moved from ``warnings_seen``.
    ``clock[0]`` is then the plant time at the start of that tick, ``clock[1]`` now, summed
    step by step as MuJoCo sums it (``clock[1]`` is the time at ``first`` on entry).

    Returns (tick, intervals done, reason, kernel status, DAC clip mask).
    """
    return _ticks(first, intervals, dac_in, enable, enabled, cpr, offset, mask, free,
                  warnings, warnings_seen, clock, timestep, counts, tacho, *loop)


def addresses(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[int, int]:
    """The C addresses of the bindings' ``mjModel`` and ``mjData`` (fixed for their life):
    what :func:`step_intervals` takes."""
    return model._address, data._address


def step_intervals(m_addr: int, d_addr: int, n: int, substeps: int, params: np.ndarray,
                   state: np.ndarray, tables: np.ndarray, dac_in: np.ndarray,
                   dac: np.ndarray, u: np.ndarray, noise: np.ndarray,
                   log: np.ndarray, n0: int, dt: float, enabled: bool, passive: np.ndarray,
                   has_passive: bool, chain: np.ndarray, has_chain: bool,
                   torque: np.ndarray, sub_torque: np.ndarray,
                   scratch: np.ndarray, rotor_frc: np.ndarray, slide_frc: np.ndarray,
                   table_pos: np.ndarray, table_vel: np.ndarray, rotor_pos: np.ndarray,
                   rotor_vel: np.ndarray, qpos: np.ndarray, qvel: np.ndarray,
                   qfrc: np.ndarray, ten_stiffness: np.ndarray, ten_damping: np.ndarray,
                   spring_adr: np.ndarray, spring_ratio: np.ndarray, samples: np.ndarray,
                   steps: np.ndarray, extent: np.ndarray,
                   ring: np.ndarray, ring_n: int, out: np.ndarray) -> tuple[int, int, int]:
    """Quantise the DAC requests ``dac_in`` into ``u`` (:func:`quantise`), then run ``n``
    drive intervals: drive kernel, then ``substeps`` × (applied forces,
    ``mj_step``), and the drive-rate samples into ``samples[i]`` (and row ``ring_n + i`` of
    the ring buffer ``ring``) after each, and, when ``steps`` has rows (n·substeps, 2), the
    table velocities after every physics step (m/s, for the accelerometer); ``extent`` (4,)
    receives the lowest and highest
    table position of each axis.

    ``m_addr``, ``d_addr`` are :func:`addresses`; the ``*_frc``, ``*_pos`` and ``*_vel``
    arrays are views of the data, ``qpos``, ``qvel``, ``qfrc`` (applied) the whole of them,
    ``ten_stiffness``, ``ten_damping`` the model's tendon arrays (:func:`chain_springs`
    writes them when ``has_chain``); ``spring_adr``, ``spring_ratio`` locate each axial
    spring's driver for the samples (:func:`record_interval`). ``noise`` is (n, axes, m)
    standard normal samples (or one (1, axes, m) block reused). ``torque`` (axes,) and
    ``sub_torque`` (axes, substeps) are the drive's outputs (interval and per-physics-step
    averages), ``scratch`` its work space; ``out`` receives the :func:`readout`. Returns
    (intervals done, kernel status, DAC clip mask): a non-zero status stops before the
    interval it refers to, with nothing of it applied; a negative clip mask (−1 − axis: a
    request not finite) stops before anything.
    """
    return _intervals(m_addr, d_addr, n, substeps, params, state, tables, dac_in, dac, u,
                      noise, log, n0, dt, enabled, passive, has_passive, chain, has_chain,
                      torque, sub_torque, scratch, rotor_frc, slide_frc, table_pos, table_vel,
                      rotor_pos, rotor_vel, qpos, qvel, qfrc, ten_stiffness, ten_damping,
                      spring_adr, spring_ratio, samples, steps, extent, ring, ring_n, out)
