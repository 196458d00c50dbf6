"""Seed 000, Table 2: the digital correcting device (DCU) of orders 0-3 on a straight X move.

The rig moved its X axis along a straight line described by a spline, with the parabolic
acceleration law, and measured the largest velocity error while accelerating and while
decelerating and the largest coordinate error, for DCU orders 0 (none) to 3.

Choice of the move. The table gives 30 µm of coordinate error and 42 µm/s of velocity
error without DCU. A P position loop (type 1, velocity gain K_v) lags a cruise at speed V by
``V/K_v`` and, while the reference accelerates at A, its speed lags by ``A/K_v``. So the
seed's move had ``V/A = 30/42 s`` whatever its K_v, and the twin reproduces the *size* of the
errors with ``V = 30 µm · K_v`` (K_v of the twin's own loop: ``kp·K_H``) and
``A = V · 42/30 s⁻¹``: a slow move (0.44 mm/s on tomsk_xy), as on the rig. The jerk limit is
set high so that the peak acceleration of the parabolic law is A.

Measured like the rig: the coordinate error from the position the controller measures (the
motor-shaft encoder), the velocity error from the table speed; "acceleration" is the first
half of the move up to the middle of the cruise, "deceleration" the rest.

A second table repeats orders 1-3 with the controller's model nominal (``controller_model =
tomsk_xy``) and the plant's drive gain K_H off by 0, 10, 20 and 30 % (the plant's tacho gain
scaled): the DCU coefficients are derived from K_H, and a rig's K_H is known only to the
tolerance of its drive settings. The plant is the pulse-level thyristor drive throughout.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from twin.analysis.studies.common import percent, run_items
from twin.controller.library import spline_line
from twin.session.run import RunSpec, prepare

__all__ = ["SEED_TABLE", "measure", "move_for", "run_study", "spec_for"]

SEED_TABLE = {
    0: {"velocity_error_accel_um_s": 42.0, "velocity_error_decel_um_s": -41.0,
        "coordinate_error_um": 30.0, "pct_accel": 100.0, "pct_decel": 100.0,
        "pct_coordinate": 100.0},
    1: {"velocity_error_accel_um_s": 19.0, "velocity_error_decel_um_s": -21.0,
        "coordinate_error_um": 9.8, "pct_accel": 45.2, "pct_decel": 51.2,
        "pct_coordinate": 32.6},
    2: {"velocity_error_accel_um_s": 16.0, "velocity_error_decel_um_s": -19.0,
        "coordinate_error_um": 9.5, "pct_accel": 38.0, "pct_decel": 46.3,
        "pct_coordinate": 31.6},
    3: {"velocity_error_accel_um_s": 15.0, "velocity_error_decel_um_s": -16.0,
        "coordinate_error_um": 9.3, "pct_accel": 35.7, "pct_decel": 39.0,
        "pct_coordinate": 31.0},
}
"""Seed 000, Table 2 as printed (X axis; µm/s, µm, % of order 0)."""

MACHINE = "tomsk_xy"
_SEED_COORD, _SEED_VEL = 30e-6, 42e-6     # order 0 figures of the rig (m, m/s)
_CRUISE = 1.5                              # cruise time (s): 20 lag time constants


def move_for(machine: str = MACHINE) -> dict[str, float]:
    """The seed-sized move on ``machine``: speed, acceleration, jerk limit, length (SI)."""
    p = prepare(RunSpec(machine=machine, builtin="none", dcu_order=0))
    kp = p.controller.gains.kp
    kv = (kp[0] if isinstance(kp, tuple) else kp) / p.cfg.axes["x"].volts_per_speed
    speed = _SEED_COORD * kv
    accel = speed * _SEED_VEL / _SEED_COORD
    change = 1.5 * speed / accel             # parabolic speed change at peak acceleration A
    return {"velocity_gain": kv, "speed": speed, "acceleration": accel,
            "jerk": 100.0 * accel, "length": speed * (change + _CRUISE)}


MISMATCH = (0.0, 0.1, 0.2, 0.3)
"""Errors of the plant's drive gain K_H against the controller's nominal model (1)."""


def spec_for(move: dict[str, float], order: int, overrides: dict[str, Any] | None = None,
             controller_model: str | None = None, machine: str = MACHINE) -> RunSpec:
    """The run of the seed-sized ``move`` with DCU ``order`` on ``machine`` (the plant)."""
    sets = {"controller.limits.max_velocity": move["speed"],
            "controller.limits.max_acceleration": move["acceleration"],
            "controller.limits.max_jerk": move["jerk"], **(overrides or {})}
    return RunSpec(machine=machine, controller_model=controller_model, profile="parabolic",
                   planner="lookahead", dcu_order=order, overrides=sets)


def measure(rec: dict[str, np.ndarray], speed: float) -> dict[str, float]:
    """Table 2's figures of one X move (µm/s, µm).

    Parameters
    ----------
    rec : dict of ndarray
        The run record (``RunResult.record``).
    speed : float
        Cruise speed of the move (m/s): the split between acceleration and deceleration is
        the middle of the cruise.
    """
    v_ref = rec["ref_velocity"][:, 0]
    verr = v_ref - rec["table_velocity"][:, 0]
    cruise = np.flatnonzero(np.abs(v_ref - speed) <= 1e-9 * speed)
    split = (int(cruise[0]) + int(cruise[-1])) // 2 if cruise.size else len(v_ref) // 2
    coord = rec["ref_position"][:, 0] - rec["position"][:, 0]
    i = int(np.argmax(verr[:split]))
    return {"velocity_error_accel_um_s": float(verr[:split].max()) * 1e6,
            "velocity_error_decel_um_s": float(verr[split:].min()) * 1e6,
            "coordinate_error_um": float(np.abs(coord).max()) * 1e6,
            "accel_peak_time_s": float(rec["t"][i]),
            "accel_peak_ref_speed_um_s": float(v_ref[i]) * 1e6}


def _with_percentages(rows: dict[int, dict[str, float]]) -> None:
    base = rows[0]
    for row in rows.values():
        row["pct_accel"] = percent(row["velocity_error_accel_um_s"],
                                   base["velocity_error_accel_um_s"])
        row["pct_decel"] = percent(row["velocity_error_decel_um_s"],
                                   base["velocity_error_decel_um_s"])
        row["pct_coordinate"] = percent(row["coordinate_error_um"], base["coordinate_error_um"])


def run_study(*, quick: bool = False, errors: tuple[float, ...] | None = None
              ) -> dict[str, Any]:
    """Orders 0-3 on the seed-sized move, and the K_H mismatch table for ``errors`` (default
    ``MISMATCH``; none when ``quick``).

    Returns
    -------
    dict
        JSON-ready: the move, ``rows`` {order: twin figures and %}, ``seed`` (Table 2),
        ``mismatch`` (drive gain error → orders 1 and 3, % of the matched order 0).
    """
    t0 = time.perf_counter()
    move = move_for()

    def build(cfg, start):
        return spline_line(cfg, start, length=move["length"], feed=move["speed"])

    rows = {}
    for order in range(4):
        result = run_items(spec_for(move, order), build)
        rows[order] = measure(result.record, move["speed"])
    _with_percentages(rows)
    mismatch = []
    errors = (() if quick else MISMATCH) if errors is None else errors
    if errors:
        cfg = spec_for(move, 0).machine_config()
        for error in errors:
            gain = {"axes.*.tacho.gain": cfg.axes["x"].tacho.gain / (1.0 + error)}
            for order in (1, 2, 3):
                result = run_items(spec_for(move, order, gain, controller_model=MACHINE), build)
                row = measure(result.record, move["speed"])
                mismatch.append({"drive_gain_error": error, "order": order, **row,
                                 "pct_coordinate": percent(row["coordinate_error_um"],
                                                           rows[0]["coordinate_error_um"])})
    return {
        "study": "seed000_dcu",
        "title": "Seed 000 Table 2: DCU orders 0-3 on a straight X spline move",
        "machine": MACHINE,
        "move": {"length_mm": move["length"] * 1e3, "feed_mm_per_s": move["speed"] * 1e3,
                 "feed_mm_per_min": move["speed"] * 6e4,
                 "acceleration_mm_per_s2": move["acceleration"] * 1e3,
                 "velocity_gain_per_s": move["velocity_gain"], "law": "parabolic"},
        "rows": {str(k): v for k, v in rows.items()},
        "seed": {str(k): v for k, v in SEED_TABLE.items()},
        "mismatch": mismatch,
        "quick": quick,
        "wall_time_s": time.perf_counter() - t0,
    }
