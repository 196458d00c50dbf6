"""The twin with candidate parameters, replaying a log: what the fit compares with the
measurements.

``candidate`` turns one ``AxisParams`` per axis into a machine configuration (BASE with the
identified fields replaced); ``replay`` runs that machine's plant — the same drive kernel and
MuJoCo mechanics as every run — under the DAC volts the log recorded, tick by tick, and
returns what its encoders and tachos would have read. Positions are taken relative to the
first tick (a real machine's counters have an arbitrary origin), and the replay starts at
rest in the middle of the travel (the switches play no part in the experiments).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from twin.config import AXES, MachineConfig
from twin.controller.encoder import EncoderUnwrapper
from twin.drive.design import design
from twin.identify.log import IdentLog
from twin.plant import Plant

__all__ = ["NAMES", "SIGMA_POSITION", "SIGMA_TACHO", "AxisParams", "Problem", "axis_figures",
           "base_params", "candidate", "measured", "replay"]


@dataclass(frozen=True)
class AxisParams:
    """The physical parameters ``twin identify`` fits, of one axis (SI).

    Attributes
    ----------
    tacho_gain : float
        K_C (V·s/rad): the tacho's volts per rad/s, and the drive's speed scaling.
    gain_error, offset : float
        The DAC output stage (1, V): the drive gets (1 + gain_error)·U + offset; with
        K_C they make K_H = r·(1 + gain_error)/K_C (table speed per volt).
    inertia : float
        Rotor (and gear) inertia at the motor shaft (kg·m²).
    coulomb, viscous : float
        Multipliers of BASE's Coulomb and viscous friction, rotor and slide together
        (motor signals see only their sum at the motor: BASE's split is kept).
    breakaway : float
        Break-away over Coulomb friction (≥ 1; 1: none).
    backlash : float
        Lost motion of gear and nut (m).
    resistance, inductance : float
        Armature R (Ω) and L (H).
    speed_kp, speed_ti : float
        The drive's speed regulator: gain (A/V) and integral time (s).
    reference_filter : float
        The drive's speed-reference filter T1 (s).
    current_kp, current_ti : float
        The drive's current regulator: gain (V/A) and integral time (s).
    dcm_compensation : float
        1: the current regulator adapts to discontinuous conduction; 0: it does not (a
        model choice the fit makes by comparing both, never a fitted coordinate).
    analog : float
        1: analog regulators; 0: digital (a model choice as well).
    brush_drop : float
        The brushes' contact drop (V): at feed speeds, in discontinuous conduction, it is
        of the order of the whole driving margin.
    current_designed : float
        1: the current regulator is the modulus optimum for the candidate's own R and L
        (as a drive's current loop is set for its motor at commissioning), while the fit
        does not fit it (a drive with the adaptation, whose current loop does not show);
        0: ``current_kp`` and ``current_ti`` are written as they are.
    """

    tacho_gain: float
    gain_error: float
    offset: float
    inertia: float
    coulomb: float
    viscous: float
    breakaway: float
    backlash: float
    resistance: float
    inductance: float
    speed_kp: float
    speed_ti: float
    reference_filter: float
    current_kp: float
    current_ti: float
    dcm_compensation: float
    analog: float
    brush_drop: float
    current_designed: float

    def to_dict(self) -> dict[str, float]:
        """Plain dict."""
        return asdict(self)

    def with_(self, **changes: float) -> AxisParams:
        """A copy with some values changed."""
        return replace(self, **changes)


NAMES = tuple(f.name for f in fields(AxisParams))
"""The fitted parameters' names, in ``AxisParams`` order."""


def base_params(base: MachineConfig) -> dict[str, AxisParams]:
    """The parameters BASE has (the fit's starting point); its drive's settings are what
    ``design`` gives for it (the file's, or the derived ones where the file has none)."""
    out = {}
    moved = base.moving_masses()
    for a in AXES:
        ax = base.axes[a]
        m = ax.mechanics
        d = design(ax, moving_mass=moved[a])
        ratio = m.breakaway("rotor") / m.rotor_coulomb if m.rotor_coulomb > 0 else 1.0
        out[a] = AxisParams(tacho_gain=ax.tacho.gain, gain_error=ax.dac.gain_error,
                            offset=ax.dac.offset, inertia=m.rotor_inertia, coulomb=1.0,
                            viscous=1.0, breakaway=max(ratio, 1.0),
                            backlash=ax.transmission.backlash,
                            resistance=ax.motor.armature_resistance,
                            inductance=ax.motor.armature_inductance,
                            speed_kp=d.speed_kp, speed_ti=d.speed_ti,
                            reference_filter=d.reference_filter, current_kp=d.current_kp,
                            current_ti=d.current_ti,
                            dcm_compensation=1.0 if ax.converter.dcm_compensation else 0.0,
                            analog=1.0 if ax.regulators.implementation == "analog" else 0.0,
                            brush_drop=ax.motor.brush_drop,
                            current_designed=1.0 if d.current_regulator_designed else 0.0)
    return out


def candidate(base: MachineConfig, params: dict[str, AxisParams], *,
              mains_phase: float | None = None) -> MachineConfig:
    """BASE with every field ``params`` sets replaced (validated as any machine file), and
    the thyristor drives' ``mains_phase`` (rad) when given (as :func:`replay` sets it).

    The drive's speed regulator and reference filter are written out, never derived again
    from the candidate's inertia: the drive on a machine is set once, at commissioning, and
    does not retune itself to a different motor (a mistuned drive is then one the fit can
    represent, and the inertia shows in the speed loop's response). The current regulator
    is written out too, unless ``current_designed``: then it is the modulus optimum for the
    candidate's R and L, as BASE's is for its own."""
    sets: dict[str, float | bool] = {}
    own = base_params(base)
    for a in AXES:
        p, m = params[a], base.axes[a].mechanics
        if p == own[a]:   # BASE's own values (an axis not excited): BASE's axis as it is
            continue
        pre = f"axes.{a}"
        rotor_c, slide_c = p.coulomb * m.rotor_coulomb, p.coulomb * m.slide_coulomb
        sets.update({
            f"{pre}.tacho.gain": p.tacho_gain,
            f"{pre}.dac.gain_error": p.gain_error,
            f"{pre}.dac.offset": p.offset,
            f"{pre}.mechanics.rotor_inertia": p.inertia,
            f"{pre}.mechanics.rotor_coulomb": rotor_c,
            f"{pre}.mechanics.slide_coulomb": slide_c,
            f"{pre}.mechanics.rotor_viscous": p.viscous * m.rotor_viscous,
            f"{pre}.mechanics.slide_viscous": p.viscous * m.slide_viscous,
            f"{pre}.mechanics.rotor_breakaway": p.breakaway * rotor_c
            if p.breakaway > 1.0 else 0.0,
            f"{pre}.mechanics.slide_breakaway": p.breakaway * slide_c
            if p.breakaway > 1.0 else 0.0,
            f"{pre}.transmission.backlash": p.backlash,
            f"{pre}.motor.armature_resistance": p.resistance,
            f"{pre}.motor.armature_inductance": p.inductance,
            f"{pre}.regulators.speed_kp": p.speed_kp,
            f"{pre}.regulators.speed_ti": p.speed_ti,
            f"{pre}.speed_loop.reference_filter": p.reference_filter,
        })
        if not p.current_designed:
            sets[f"{pre}.regulators.current_kp"] = p.current_kp
            sets[f"{pre}.regulators.current_ti"] = p.current_ti
        if base.axes[a].converter.kind == "thyristor":
            sets[f"{pre}.converter.dcm_compensation"] = bool(p.dcm_compensation)
            sets[f"{pre}.regulators.implementation"] = "analog" if p.analog > 0.5 \
                else "digital"
            sets[f"{pre}.motor.brush_drop"] = p.brush_drop
    if mains_phase is not None and _thyristor(base):
        sets.update({f"axes.{a}.converter.mains_phase": float(mains_phase) for a in AXES})
    return base.with_overrides(sets)


def _thyristor(cfg: MachineConfig) -> bool:
    """A thyristor drive on some axis: the mains phase matters."""
    return any(cfg.axes[a].converter.kind == "thyristor" for a in AXES)


def measured(log: IdentLog, base: MachineConfig) -> tuple[np.ndarray, np.ndarray]:
    """The log's positions (relative to its first tick, m) and tacho volts, (ticks, 2)."""
    counts = np.column_stack([log.data["counts_x"], log.data["counts_y"]]).astype(np.int64)
    pos = _positions(base, counts)
    tacho = np.column_stack([log.data["tacho_x"], log.data["tacho_y"]])
    return pos, tacho


def replay(cfg: MachineConfig, log: IdentLog, *, until: int | None = None,
           mains_phase: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The plant of ``cfg`` under the log's DAC volts: positions relative to the first tick
    (m) and tacho volts, shape (ticks, 2), for the first ``until`` ticks (default all).

    Each tick reads the sensors, then applies the tick's DAC volts and enable until the next
    tick's time (a paced run may have skipped a slot); the drives start from rest, as the
    experiments start from a disabled drive. ``mains_phase`` (rad) places the
    mains of a thyristor drive relative to the log's first tick: a real machine's is
    unknown, and the fit estimates it (``fit.mains_phase``).
    """
    n = log.ticks if until is None else min(until, log.ticks)
    if mains_phase is not None and _thyristor(cfg):
        cfg = cfg.with_overrides({"axes.*.converter.mains_phase": float(mains_phase)})
    plant = Plant(cfg, noise=False)  # the measurement has the noise; the replay is its mean
    mid = np.array([0.5 * sum(cfg.axes[a].mechanics.travel) for a in AXES])
    plant.reset(positions=mid)
    t = log.data["t"]
    steps = np.diff(t, append=t[-1] + cfg.controller.period)
    intervals = np.maximum(np.round(steps / plant.drive_dt), 1).astype(np.int64)
    dac = np.column_stack([log.data["dac_x"], log.data["dac_y"]])
    counts, tacho = plant.run_open_loop(dac[:n], log.data["enable"][:n] != 0.0,
                                        intervals[:n])
    return _positions(cfg, counts), tacho


def _positions(cfg: MachineConfig, counts: np.ndarray) -> np.ndarray:
    """Encoder counter samples (ticks, 2) unwrapped to positions relative to the first
    (m), as the controller's ``EncoderUnwrapper`` reads them."""
    enc = EncoderUnwrapper([cfg.axes[a].counts_per_metre for a in AXES],
                           bits=[cfg.axes[a].encoder.bits for a in AXES])
    pos = np.empty((len(counts), 2))
    if len(counts):
        enc.reset(counts[0])
    for k, c in enumerate(counts.tolist()):
        pos[k] = enc.update(c)
    return pos


def finite_params(params: dict[str, AxisParams]) -> bool:
    """Every value finite (a fit that ran away is caught before it reaches a machine)."""
    return all(math.isfinite(v) for p in params.values() for v in asdict(p).values())


SIGMA_POSITION = 5e-6
"""Position residual scale (m): the replay's own floor (unknown mains phase)."""
SIGMA_TACHO = 0.02
"""Tacho residual scale (V)."""


class Problem:
    """A log and BASE: the measured positions and tacho volts, and the residuals of replays
    of candidate parameters against them (counting the replays; ``mains_phase`` is the
    thyristor mains phase the replays use, once the fit has estimated it). ``axes`` are the
    axes the log excited: the only ones with residuals, and the only ones fitted."""

    def __init__(self, base: MachineConfig, log: IdentLog):
        self.base, self.log = base, log
        self.axes = tuple(a for a in AXES if a in log.axes)
        self.excited = [(k, a) for k, a in enumerate(AXES) if a in self.axes]
        """(column, axis) of each excited axis, in the machine's axis order."""
        self.pos, self.tacho = measured(log, base)
        pieces = log.data["piece"].astype(int)
        starts = np.flatnonzero(np.diff(pieces, prepend=pieces[0] - 1))
        self.piece_start = starts[np.searchsorted(starts, np.arange(len(pieces)),
                                                  side="right") - 1]
        """Per tick: the first tick of its piece of the plan."""
        self.replays = 0
        self.mains_phase: float | None = None
        self._recent: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    RECENT = 48
    """Replays kept (the latest): the same parameters at the same mains phase again (the
    models' coarse phase screen, 3 × 12 replays of the steps, in a kept model's full scan;
    a fit's own start) are not replayed. At most 48 × 120 kB on tomsk_xy."""

    def simulate(self, params: dict[str, AxisParams], until: int
                 ) -> tuple[np.ndarray, np.ndarray]:
        """The replay of ``params`` (positions, tacho volts) over the first ``until``
        ticks; one of the same parameters and mains phase over as many ticks or more is
        reused (a replay's first ticks do not depend on its later ones)."""
        key = (self.mains_phase, tuple(tuple(asdict(params[a]).values())
                                       for a in AXES if a in params))
        kept = self._recent.get(key)
        if kept is not None and len(kept[0]) >= until:
            return kept[0][:until], kept[1][:until]
        self.replays += 1
        pos, tacho = replay(candidate(self.base, params, mains_phase=self.mains_phase),
                            self.log, until=until)
        pos.flags.writeable = tacho.flags.writeable = False
        self._recent.pop(key, None)
        self._recent[key] = (pos, tacho)
        while len(self._recent) > self.RECENT:
            self._recent.pop(next(iter(self._recent)))
        return pos, tacho

    def residuals(self, params: dict[str, AxisParams], mask: np.ndarray
                  ) -> dict[str, np.ndarray]:
        """Per excited axis: scaled position and tacho residuals over the ticks of
        ``mask``. Positions are compared as the travel since the start of each piece of
        the plan: a replay that parts from the machine in one piece (a drive that
        limit-cycles at feed speed does so wherever its current pulses fall) is not charged
        for it again in every later one."""
        until = int(np.flatnonzero(mask)[-1]) + 1
        pos, tacho = self.simulate(params, until)
        m = mask[:until]
        first = self.piece_start[:until]
        out = {}
        for k, a in self.excited:
            travel = pos[:, k] - pos[first, k]
            seen = self.pos[:until, k] - self.pos[first, k]
            dp = (travel[m] - seen[m]) / SIGMA_POSITION
            dt = (tacho[m, k] - self.tacho[:until][m, k]) / SIGMA_TACHO
            out[a] = np.concatenate([dp, dt])
        return out


def axis_figures(cfg: MachineConfig) -> dict[str, dict[str, float]]:
    """What identification results are quoted in, per axis (SI): K_H = r·(1 + g)/K_C,
    the tacho gain, the rotor inertia, the Coulomb and viscous friction at the motor (rotor
    plus slide) and the lost motion."""
    out = {}
    for a in AXES:
        ax = cfg.axes[a]
        m, r = ax.mechanics, ax.transmission.ratio
        out[a] = {"K_H": r * (1.0 + ax.dac.gain_error) / ax.tacho.gain,
                  "tacho_gain": ax.tacho.gain, "inertia": m.rotor_inertia,
                  "coulomb_at_motor": m.rotor_coulomb + r * m.slide_coulomb,
                  "viscous_at_motor": m.rotor_viscous + r * r * m.slide_viscous,
                  "backlash": ax.transmission.backlash}
    return out
