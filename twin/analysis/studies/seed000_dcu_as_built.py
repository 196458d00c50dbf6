"""Seed 000, Table 2 on drives as they may be built: mistuned analog regulators without
adaptation to discontinuous conduction, brush and thyristor drops
(``docs/examples/tomsk_xy_as_built.toml``), against the ideal drive of tomsk_xy.

The same seed-sized X move as :mod:`twin.analysis.studies.seed000_dcu` (the controller's own
K_v), the same measurements; the controller's model is the nominal tomsk_xy in both columns
(its gains and DCU come from the designed drive, as the rig's came from nominal data), the
plant is tomsk_xy or its as-built variant.

Two figures of the drive itself explain the difference:

- the current loop's gain at the feed: the slope of the mean armature current against the
  control voltage U_c = U_d0·cos α (what the current regulator commands), at the firing
  angle where the mean current carries the friction load, against the EMF of the feed;
  1/R_eff in continuous conduction, where the designs assume it;
- the table's speed ripple during the cruise: (max − min) of the table speed over the middle
  half of the cruise, per cent of the feed (the controller's period samples it).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from twin.analysis.studies.common import percent, run_items
from twin.analysis.studies.seed000_dcu import MACHINE, measure, move_for, spec_for
from twin.config import load_machine
from twin.controller.library import spline_line
from twin.drive import Drives

__all__ = ["AS_BUILT", "current_loop_gain", "run_study"]

AS_BUILT = str(Path(__file__).resolve().parents[3] / "docs" / "examples"
               / "tomsk_xy_as_built.toml")
"""The as-built machine file (a documentation example, not a preset)."""


def _mean_current(ax, alpha: float, emf: float) -> float:
    """Steady mean armature current (A) of the forward converter fired at ``alpha`` (rad)
    against ``emf`` (V): the last of 12 mains periods, open loop."""
    t_p = ax.converter.firing_period
    drives = Drives([ax], dt=t_p / 4)
    drives.set_firing_angle([alpha])
    omega = np.array([emf / ax.motor.emf_constant])
    periods = round(12 / ax.converter.mains_frequency / drives.dt)
    last = round(1 / ax.converter.mains_frequency / drives.dt)
    q = 0.0
    for n in range(periods):
        tau = float(drives.step(np.zeros(1), omega)[0])
        if n >= periods - last:
            q += tau * drives.dt / ax.motor.emf_constant
    return q / (last * drives.dt)


def current_loop_gain(machine: str, axis: str, speed: float) -> dict[str, float]:
    """The converter's gain from the control voltage U_d0·cos α to the mean current at the
    operating point of a table moving at ``speed`` (m/s) against its friction.

    Returns
    -------
    dict
        ``load_current`` (A), ``alpha_deg`` (°), ``gain_a_per_v`` (A/V, the slope by
        central differences of ±0.25°), ``continuous_gain_a_per_v`` (1/R_eff) and
        ``drop`` (continuous over this gain).
    """
    cfg = load_machine(machine)
    ax = cfg.axes[axis]
    mech, r, k = ax.mechanics, ax.transmission.ratio, ax.motor.emf_constant
    omega = speed / r
    load = (mech.rotor_coulomb + mech.rotor_viscous * omega
            + (mech.slide_coulomb + mech.slide_viscous * speed) * r) / k
    emf = k * omega
    lo, hi = math.radians(30.0), math.radians(150.0)   # current falls with α
    for _ in range(20):
        mid = 0.5 * (lo + hi)
        if _mean_current(ax, mid, emf) > load:
            lo = mid
        else:
            hi = mid
    alpha = 0.5 * (lo + hi)
    step = math.radians(0.25)
    u_d0 = ax.converter.max_voltage
    di = _mean_current(ax, alpha - step, emf) - _mean_current(ax, alpha + step, emf)
    dv = u_d0 * (math.cos(alpha - step) - math.cos(alpha + step))
    continuous = 1.0 / (ax.motor.armature_resistance
                        + ax.converter.series_devices * ax.converter.thyristor_resistance)
    gain = di / dv
    return {"load_current": load, "alpha_deg": math.degrees(alpha), "gain_a_per_v": gain,
            "continuous_gain_a_per_v": continuous, "drop": continuous / gain}


def _ripple(rec: dict[str, np.ndarray], speed: float) -> float:
    """(max − min) of the table speed over the middle half of the cruise (% of the feed)."""
    v_ref = rec["ref_velocity"][:, 0]
    cruise = np.flatnonzero(np.abs(v_ref - speed) <= 1e-9 * speed)
    n = cruise.size
    mid = cruise[n // 4: n - n // 4] if n >= 4 else cruise
    v = rec["table_velocity"][mid, 0]
    return float(100.0 * (v.max() - v.min()) / speed)


def run_study(*, quick: bool = False) -> dict[str, Any]:
    """DCU orders 0-3 on the ideal and the as-built drive (``quick``: orders 0 and 3).

    Returns
    -------
    dict
        JSON-ready: the move, ``rows`` {drive: {order: Table 2's figures, % of that drive's
        order 0, speed ripple}}, ``gain`` {drive: :func:`current_loop_gain` of the X axis}.
    """
    t0 = time.perf_counter()
    move = move_for()

    def build(cfg, start):
        return spline_line(cfg, start, length=move["length"], feed=move["speed"])

    drives = {"ideal": MACHINE, "as_built": AS_BUILT}
    orders = (0, 3) if quick else (0, 1, 2, 3)
    rows: dict[str, dict[str, Any]] = {}
    for name, machine in drives.items():
        rows[name] = {}
        for order in orders:
            result = run_items(spec_for(move, order, controller_model=MACHINE,
                                        machine=machine), build)
            row = measure(result.record, move["speed"])
            row["speed_ripple_pct"] = _ripple(result.record, move["speed"])
            rows[name][str(order)] = row
        base = rows[name]["0"]
        for row in rows[name].values():
            row["pct_coordinate"] = percent(row["coordinate_error_um"],
                                            base["coordinate_error_um"])
    return {
        "study": "seed000_dcu_as_built",
        "title": "Seed 000 Table 2 on mistuned analog drives without DCM adaptation",
        "machine": MACHINE,
        "as_built": "docs/examples/tomsk_xy_as_built.toml",
        "move": {"length_mm": move["length"] * 1e3, "feed_mm_per_s": move["speed"] * 1e3,
                 "feed_mm_per_min": move["speed"] * 6e4,
                 "acceleration_mm_per_s2": move["acceleration"] * 1e3},
        "rows": rows,
        "gain": {name: current_loop_gain(machine, "x", move["speed"])
                 for name, machine in drives.items()},
        "quick": quick,
        "wall_time_s": time.perf_counter() - t0,
    }
