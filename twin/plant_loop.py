"""The plant's inner loop compiled: drive kernel ⇄ MuJoCo's C ``mj_step``, in one call.

Between two controller periods the plant alternates, every drive interval, between the drive
kernel (``twin.drive.kernel.drive_step``, numba) and ``drive_substeps`` physics steps. In
Python each alternation costs about a microsecond and a half of call overhead — as much as
the whole drive model. Here the alternation runs inside one numba function that calls
``mj_step`` of the MuJoCo shared library through ctypes, on the very ``mjModel``/``mjData``
the Python bindings own (their addresses), so the state is the same memory and the result is
bit-identical to the Python loop (``tests/plant/test_fast_paths.py``).

If the shared library cannot be found, or the bindings do not expose the structs' addresses
(``_address``, present in MuJoCo 3 and 4), ``available()`` is False and the plant keeps its
Python loop.
"""

from __future__ import annotations

import ctypes
import glob
import os

import mujoco
import numba
import numpy as np

from twin.drive.kernel import drive_step

__all__ = ["addresses", "available", "step_intervals"]


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
    # Pointers travel as 64-bit integers: identical in the x86-64 and AArch64 C ABIs.
    fn.argtypes = [ctypes.c_uint64, ctypes.c_uint64]
    fn.restype = None
    return fn


_MJ_STEP = _load_mj_step()


def available() -> bool:
    """True if the compiled loop can run (MuJoCo's shared library was found)."""
    return _MJ_STEP is not None


if _MJ_STEP is not None:
    _c_mj_step = _MJ_STEP

    @numba.njit
    def _intervals(m_addr, d_addr, n, substeps, params, state, u, omega, noise, n0, dt,
                   enabled, torque, table, samples, extent):
        for i in range(n):
            status = drive_step(params, state, u, omega, noise, n0 + i, dt, enabled, torque)
            if status != 0:
                return i, status
            for _ in range(substeps):
                _c_mj_step(m_addr, d_addr)
            for k in range(2):
                x = table[k]
                samples[i, k] = x
                if i == 0:
                    extent[2 * k] = extent[2 * k + 1] = x
                else:  # a NaN sample makes both ends NaN, and they stay NaN
                    if x < extent[2 * k] or x != x:
                        extent[2 * k] = x
                    if x > extent[2 * k + 1] or x != x:
                        extent[2 * k + 1] = x
        return n, 0


def addresses(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[int, int]:
    """The C addresses of the bindings' ``mjModel`` and ``mjData`` (fixed for their life):
    what :func:`step_intervals` takes."""
    return model._address, data._address


def step_intervals(m_addr: int, d_addr: int, n: int, substeps: int,
                   params: np.ndarray, state: np.ndarray, u: np.ndarray, omega: np.ndarray,
                   noise: np.ndarray, n0: int, dt: float, enabled: bool, torque: np.ndarray,
                   table: np.ndarray, samples: np.ndarray, extent: np.ndarray
                   ) -> tuple[int, int]:
    """Run ``n`` drive intervals: drive kernel, then ``substeps`` × ``mj_step``, and the
    table position into ``samples[i]`` after each; ``extent`` (4,) receives the lowest and
    highest sample of each axis (x lo, x hi, y lo, y hi; NaN if a sample was NaN).

    ``m_addr``, ``d_addr`` are :func:`addresses`; ``omega``, ``torque`` and ``table`` are views
    of the data (rotor speeds, rotor applied forces, table positions). Returns (intervals
    done, kernel status): a non-zero status stops before the interval it refers to, with
    nothing of it applied.
    """
    return _intervals(m_addr, d_addr, n, substeps, params, state, u, omega, noise, n0, dt,
                      enabled, torque, table, samples, extent)
