"""The MuJoCo model of the cross table, parameterised by a machine file.

``twin/models/xy_table.xml`` holds the structure (bodies, joints, screw tendons, solver);
:func:`build_spec` applies a machine's numbers to it with ``mujoco.MjSpec`` so that one XML
serves every machine, and :func:`load_model` compiles it. :func:`axis_mechanics` is the
analytic two-mass model of one axis (stiffness chain, damping, elastic modes): the numbers
that ``models/README.md`` tabulates, that the spec receives, and that the tests compare the
simulated modes against.

Typical use::

    model = load_model("tomsk_xy")                   # compiled mujoco.MjModel
    modes = axis_mechanics(load_machine("tomsk_xy"), "y")
    modes.locked_rotor_frequency                     # rad/s

Export a machine for the MuJoCo viewer: ``python -m twin.plant tomsk_xy -o tomsk.xml``.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, replace
from pathlib import Path

import mujoco
import numpy as np
import scipy.linalg

from twin.config import AXES, MachineConfig, load_machine
from twin.errors import ConfigError

__all__ = [
    "MODELS_DIR",
    "MODEL_XML",
    "SCENE_XML",
    "AxisMechanics",
    "axis_mechanics",
    "build_spec",
    "chain_parameters",
    "load_model",
    "mode_periods",
    "passive_parameters",
    "resolve_machine",
]

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"
MODEL_XML = MODELS_DIR / "xy_table.xml"
SCENE_XML = MODELS_DIR / "scene.xml"

@dataclass(frozen=True)
class AxisMechanics:
    """Analytic lumped model of one axis, with the nut at one position.

    The chain, every coordinate referred to the table (m)::

        rotor M = J/r² ── gear spring k_g ── screw m_s = J_s/r_s² ── axial spring k ── table m

    Without a screw body (``screw_inertia = 0``) the gear spring is rigid and the chain is
    the two-mass model rotor ── k ── table, k being the whole chain's compliance. The
    springs' damping is proportional to their stiffness, c = β·k (β = ``damping_per_
    stiffness``), chosen so that the first locked-rotor mode at the reference nut position
    (where the file quotes the screw's stiffness) has the file's damping ratio ζ; every
    mode then has ζ_i = β·ω_i/2.

    Attributes
    ----------
    ratio : float
        Transmission r: table travel per rotor angle (m/rad).
    moving_mass : float
        Mass the slide moves, m (kg): its carriage and every carriage riding on it.
    rotor_inertia : float
        Rotor (and gear) inertia at the motor shaft, J (kg·m²).
    stiffness : float
        The axial spring, k (N/m, at the table): screw shaft, nut and thrust bearing in
        series at this nut position; the whole chain without a screw body.
    damping_ratio : float
        ζ of the first locked-rotor mode at the reference nut position, from the machine
        file (1).
    damping : float
        Damping of the axial spring, c = β·k (N·s/m).
    screw_ratio : float
        r_s: table travel per screw angle, lead/2π (m/rad); 0 without a screw body.
    screw_inertia : float
        The screw shaft's own inertia J_s (kg·m²); 0 without a screw body.
    gear_stiffness : float
        The gear spring between rotor and screw, k_g (N/m, at the table); ``inf`` without
        a screw body.
    gear_damping : float
        Its damping c_g = β·k_g (N·s/m); 0 without a screw body.
    position : float
        Table position these numbers hold at (m); ``nan`` where nothing varies with it.
    """

    ratio: float
    moving_mass: float
    rotor_inertia: float
    stiffness: float
    damping_ratio: float
    damping: float
    screw_ratio: float = 0.0
    screw_inertia: float = 0.0
    gear_stiffness: float = math.inf
    gear_damping: float = 0.0
    position: float = math.nan

    @property
    def has_screw(self) -> bool:
        """The screw is a body of its own (the three-mass chain)."""
        return self.screw_inertia > 0.0

    @property
    def reflected_mass(self) -> float:
        """Rotor inertia seen at the table, M = J/r² (kg)."""
        return self.rotor_inertia / self.ratio**2

    @property
    def screw_mass(self) -> float:
        """Screw inertia seen at the table, m_s = J_s/r_s² (kg); 0 without a screw body."""
        return self.screw_inertia / self.screw_ratio**2 if self.has_screw else 0.0

    @property
    def series_stiffness(self) -> float:
        """The whole chain's static stiffness, 1/(1/k_g + 1/k) (N/m)."""
        return 1.0 / (1.0 / self.gear_stiffness + 1.0 / self.stiffness)

    @property
    def damping_per_stiffness(self) -> float:
        """β = c/k (s): each spring's damping over its stiffness."""
        return self.damping / self.stiffness

    @property
    def locked_rotor_frequency(self) -> float:
        """First mode with the rotor held still (rad/s): √(k/m) for two masses, else the
        lowest of :meth:`frequencies` ``("locked")``.

        The mode a position loop sees when the speed loop holds the motor; the machine
        files state their first elastic mode (frequency and ζ) in this sense.
        """
        if not self.has_screw:
            return math.sqrt(self.stiffness / self.moving_mass)
        return float(self.frequencies("locked")[0])

    @property
    def free_rotor_frequency(self) -> float:
        """First elastic mode with a free rotor (rad/s): √(k·(1/m + 1/M)) for two masses,
        else the lowest of :meth:`frequencies` ``("free")``.

        The mode of the bare mechanics (no speed loop): what a rotor torque step excites.
        """
        if not self.has_screw:
            return math.sqrt(self.stiffness * (1.0 / self.moving_mass
                                               + 1.0 / self.reflected_mass))
        return float(self.frequencies("free")[0])

    @property
    def free_rotor_damping_ratio(self) -> float:
        """Damping ratio of the free-rotor mode, ζ_F = β·ω_F/2 (1); two masses at the
        reference position: ζ·√(1 + m/M)."""
        return 0.5 * self.damping_per_stiffness * self.free_rotor_frequency

    @property
    def mass_ratio(self) -> float:
        """m/M: how far the free-rotor mode lies above the locked-rotor one (1)."""
        return self.moving_mass / self.reflected_mass

    def matrices(self, rotor: str = "free") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mass, stiffness and damping matrices (kg, N/m, N·s/m) of the chain, coordinates
        referred to the table: (rotor, screw, table) — the screw only with a screw body,
        the rotor only when ``rotor`` is ``"free"`` (``"locked"``: held still)."""
        if rotor not in ("free", "locked"):
            raise ValueError(f"rotor must be 'free' or 'locked', got {rotor!r}")
        masses = [self.reflected_mass, self.moving_mass]
        springs = [(self.stiffness, self.damping)]
        if self.has_screw:
            masses.insert(1, self.screw_mass)
            springs.insert(0, (self.gear_stiffness, self.gear_damping))
        n = len(masses)
        stiffness, damping = np.zeros((n, n)), np.zeros((n, n))
        for i, (k, c) in enumerate(springs):  # spring i joins body i and body i + 1
            for matrix, value in ((stiffness, k), (damping, c)):
                matrix[i:i + 2, i:i + 2] += value * np.array([[1.0, -1.0], [-1.0, 1.0]])
        keep = slice(0 if rotor == "free" else 1, n)
        return np.diag(masses)[keep, keep], stiffness[keep, keep], damping[keep, keep]

    def frequencies(self, rotor: str = "free") -> np.ndarray:
        """Undamped elastic modes (rad/s, ascending): the generalized eigenproblem
        K·v = ω²·M·v of :meth:`matrices` (``scipy.linalg.eig``), the free rotor's rigid-body
        mode left out."""
        mass, stiffness, _ = self.matrices(rotor)
        eigenvalues = np.sort(scipy.linalg.eig(stiffness, mass, right=False).real)
        if rotor == "free":
            eigenvalues = eigenvalues[1:]
        return np.sqrt(eigenvalues)

    def poles(self, rotor: str = "free") -> np.ndarray:
        """The damped chain's poles s (1/s), the oscillating ones with Im s > 0, ascending
        in |s|: the generalized eigenproblem of M·ẍ + C·ẋ + K·x = 0 in state space (the
        free rotor's rigid-body pole s = 0 left out)."""
        mass, stiffness, damping = self.matrices(rotor)
        n = len(mass)
        eye, zero = np.eye(n), np.zeros((n, n))
        a = np.block([[zero, eye], [-stiffness, -damping]])
        b = np.block([[eye, zero], [zero, mass]])
        s = scipy.linalg.eig(a, b, right=False)
        s = s[(s.imag > 0.0) & (np.abs(s) > 1e-6 * np.abs(s).max())]  # 0 is ~1e-8 of it
        return s[np.argsort(np.abs(s))]


def axis_mechanics(cfg: MachineConfig, axis: str, position: float | None = None
                   ) -> AxisMechanics:
    """The analytic mechanics of ``axis`` ("x" or "y") of machine ``cfg`` with the table at
    ``position`` (m; default: where the screw is weakest, the stiffness the file quotes).

    Raises
    ------
    ConfigError
        If ``axis`` is not one of the machine's axes, or ``position`` lies outside its
        travel.
    """
    if axis not in AXES:
        raise ConfigError("axis", f"must be one of {AXES}, got {axis!r}")
    ax = cfg.axes[axis]
    tr, travel = ax.transmission, ax.mechanics.travel
    if position is not None and not travel[0] <= position <= travel[1]:
        raise ConfigError("position", f"must lie within the travel of axis {axis} "
                          f"[{travel[0]:g}, {travel[1]:g}] m, got {position!r}")
    k_gear, k = tr.spring_stiffness(position, travel)
    m, zeta = cfg.moving_masses()[axis], tr.damping_ratio
    base = AxisMechanics(ratio=tr.ratio, moving_mass=m,
                         rotor_inertia=ax.mechanics.rotor_inertia, stiffness=k,
                         damping_ratio=zeta, damping=0.0, screw_ratio=tr.screw_ratio
                         if tr.screw_diameter > 0.0 else 0.0,
                         screw_inertia=tr.screw_inertia, gear_stiffness=k_gear,
                         position=math.nan if position is None else float(position))
    if not base.has_screw and (position is None or tr.nut_start <= 0.0):
        return replace(base, damping=2.0 * zeta * math.sqrt(k * m))  # c = 2ζ√(k·m)
    reference = axis_mechanics(cfg, axis) if position is not None else base
    beta = 2.0 * zeta / reference.locked_rotor_frequency
    return replace(base, damping=beta * k,
                   gear_damping=beta * k_gear if base.has_screw else 0.0)


def mode_periods(cfg: MachineConfig) -> tuple[float, float]:
    """Period of the first (locked-rotor) elastic mode of x and y (s) where the screw is
    weakest (the lowest over the travel), the x axis carrying the y carriage."""
    return tuple(2.0 * math.pi / axis_mechanics(cfg, a).locked_rotor_frequency
                 for a in AXES)  # type: ignore[return-value]


def resolve_machine(machine: str | Path | MachineConfig) -> MachineConfig:
    """A machine given by preset name, TOML path or an already validated config."""
    if isinstance(machine, MachineConfig):
        return machine
    return load_machine(machine)


def build_spec(machine: str | Path | MachineConfig, *, scene: bool = False,
               timestep: float | None = None) -> mujoco.MjSpec:
    """The model spec with the machine's parameters applied (not yet compiled).

    Parameters
    ----------
    machine : str, Path or MachineConfig
        Preset name, TOML path or config.
    scene : bool
        Load ``scene.xml`` (floor, light, cameras) instead of the bare model.
    timestep : float, optional
        Physics timestep (s); default ``simulation.timestep`` of the machine.

    Raises
    ------
    ConfigError
        If a parameter does not fit the model (switches outside the travel, bad timestep).
    """
    cfg = resolve_machine(machine)
    dt = cfg.simulation.timestep if timestep is None else timestep
    if not (isinstance(dt, float | int) and math.isfinite(dt) and dt > 0):
        raise ConfigError("simulation.timestep", f"must be a number > 0 (s), got {dt!r}")
    spec = mujoco.MjSpec.from_file(str(SCENE_XML if scene else MODEL_XML))
    spec.option.timestep = float(dt)
    # the springs are rebuilt (MjSpec cannot edit a tendon's wrap coefficients), screws
    # first, so the tendon ids stay x_screw, y_screw (then x_gear, y_gear) for every machine
    for name in ("screw", "gear"):
        for axis in AXES:
            spec.delete(spec.tendon(f"{axis}_{name}"))
    home = {}
    for axis in AXES:
        _apply_axis(spec, cfg, axis)
        tr = cfg.axes[axis].transmission
        x_home = cfg.axes[axis].switches.home
        home[axis] = x_home
        home[f"{axis}_rotor"] = x_home / tr.ratio  # springs relaxed: r·θ − x = 0
        home[f"{axis}_shaft"] = x_home / tr.screw_ratio if tr.screw_diameter > 0.0 else 0.0
    for axis in AXES:
        if cfg.axes[axis].transmission.screw_diameter > 0.0:
            _add_gear(spec, cfg, axis)
    spec.key("home").qpos = [home[j.name] for j in spec.joints]
    return spec


def load_model(machine: str | Path | MachineConfig, *, scene: bool = False,
               timestep: float | None = None) -> mujoco.MjModel:
    """Compile the model of ``machine`` (see :func:`build_spec` for the arguments)."""
    return build_spec(machine, scene=scene, timestep=timestep).compile()


def _apply_axis(spec: mujoco.MjSpec, cfg: MachineConfig, axis: str) -> None:
    """Write one axis' masses, inertias, friction, travel and axial spring into the spec
    (deleting the screw body of a two-mass machine)."""
    ax = cfg.axes[axis]
    mech, tr = ax.mechanics, ax.transmission
    # the model as loaded: the springs at the home position (the plant rewrites a varying
    # axial spring before every physics step)
    chain = axis_mechanics(cfg, axis, ax.switches.home)

    spec.geom(f"{axis}_table").mass = mech.carriage_mass
    slide = spec.joint(axis)
    slide.range = list(mech.travel)
    slide.damping = [mech.slide_viscous, 0.0, 0.0]
    # dof friction holds the break-away force; the plant gives the excess over Coulomb back
    # while the axis slides (Stribeck, twin.plant.loop.passive_forces)
    slide.frictionloss = mech.breakaway("slide")

    spec.body(f"{axis}_motor").inertia = [mech.rotor_inertia] * 3
    rotor = spec.joint(f"{axis}_rotor")
    rotor.damping = [mech.rotor_viscous, 0.0, 0.0]
    rotor.frictionloss = mech.breakaway("rotor")

    if chain.has_screw:
        spec.body(f"{axis}_shaft").inertia = [chain.screw_inertia] * 3
        spec.geom(f"{axis}_shaft").size = [0.5 * tr.screw_diameter, 0.5 * tr.screw_length, 0]
        driver, coef = f"{axis}_shaft", chain.screw_ratio
    else:
        spec.delete(spec.body(f"{axis}_shaft"))
        driver, coef = f"{axis}_rotor", chain.ratio
    screw = spec.add_tendon(name=f"{axis}_screw", default=spec.find_default("screw"))
    screw.wrap_joint(driver, coef)
    screw.wrap_joint(axis, -1.0)
    screw.stiffness = [chain.stiffness, 0.0, 0.0]
    # Lost motion: a dead band of the spring (no force while the gap is open). MuJoCo's
    # tendon damper would still act inside the gap, so with lost motion the plant applies
    # the damping itself, only while the gap is closed (passive_parameters).
    half = 0.5 * tr.backlash
    screw.damping = [chain.damping if half == 0.0 else 0.0, 0.0, 0.0]
    screw.springlength = [-half, half]


def _add_gear(spec: mujoco.MjSpec, cfg: MachineConfig, axis: str) -> None:
    """The gear spring of a three-mass axis: r·θ_rotor − r_s·θ_shaft (m, at the table)."""
    chain = axis_mechanics(cfg, axis, cfg.axes[axis].switches.home)
    gear = spec.add_tendon(name=f"{axis}_gear", default=spec.find_default("gear"))
    gear.wrap_joint(f"{axis}_rotor", chain.ratio)
    gear.wrap_joint(f"{axis}_shaft", -chain.screw_ratio)
    gear.stiffness = [chain.gear_stiffness, 0.0, 0.0]
    gear.damping = [chain.gear_damping, 0.0, 0.0]
    gear.springlength = [0.0, 0.0]


def passive_parameters(machine: str | Path | MachineConfig) -> np.ndarray:
    """Per-axis parameters of the forces the plant applies itself before every physics step
    (``twin.plant.loop.passive_forces``), shape (2, ``plant_loop.NPASSIVE``): the Stribeck
    excess of slide and rotor friction over Coulomb with its speed, and the screw damping
    with half the lost motion. All zero for a machine without break-away friction or lost
    motion (then MuJoCo does everything and nothing is applied). With lost motion the
    damping is the axial spring's, as at the home position (a varying spring's is written
    before every step: :func:`screw_parameters`); the lost motion lies between the
    screw's driver (rotor, or screw body) and the table."""
    cfg = resolve_machine(machine)
    out = np.zeros((len(AXES), 7))
    for k, axis in enumerate(AXES):
        ax = cfg.axes[axis]
        mech = ax.mechanics
        chain = axis_mechanics(cfg, axis, ax.switches.home)
        r = chain.screw_ratio if chain.has_screw else chain.ratio
        out[k, 0] = mech.breakaway("slide") - mech.slide_coulomb
        out[k, 1] = mech.stribeck_velocity
        out[k, 2] = mech.breakaway("rotor") - mech.rotor_coulomb
        out[k, 3] = mech.stribeck_velocity / ax.transmission.ratio
        if ax.transmission.backlash > 0.0:
            out[k, 4] = 0.5 * ax.transmission.backlash
            out[k, 5] = chain.damping
        out[k, 6] = r
    if not (out[:, 0].any() or out[:, 2].any() or out[:, 4].any()):
        out[:] = 0.0
    return out


def chain_parameters(machine: str | Path | MachineConfig, model: mujoco.MjModel
                     ) -> np.ndarray:
    """Per-axis parameters of the transmission chain the plant needs before every physics
    step (``twin.plant.loop.chain_springs`` and ``passive_forces``), shape (2,
    ``plant_loop.NCHAIN``), for the compiled ``model`` of ``machine``: how the axial spring
    varies with the nut position (all zero where it does not), and the screw body's
    addresses (−1 without one). Column 0 is zero on both axes when nothing varies."""
    cfg = resolve_machine(machine)
    out = np.zeros((len(AXES), 14))
    for k, axis in enumerate(AXES):
        ax = cfg.axes[axis]
        tr, travel = ax.transmission, ax.mechanics.travel
        out[k, 8] = model.tendon(f"{axis}_screw").id
        out[k, 12:14] = -1.0
        if tr.screw_diameter > 0.0:
            shaft = model.joint(f"{axis}_shaft")
            out[k, 12:14] = shaft.qposadr[0], shaft.dofadr[0]
        if tr.nut_start <= 0.0:
            continue
        a_ref = tr.nut_distance(tr.reference_position(travel), travel)
        rest = 0.0  # the axial spring's other components
        for name, k_part in tr.stiffness.items():
            if name != "screw" and not (tr.screw_diameter > 0.0 and name in tr.TORSIONAL):
                rest += 1.0 / k_part
        sign = 1.0 if tr.drive_end == "min" else -1.0
        chain = axis_mechanics(cfg, axis, ax.switches.home)
        out[k, 0] = 1.0
        out[k, 1] = tr.nut_distance(0.0, travel)  # a = a₀ + s·x
        out[k, 2] = sign
        out[k, 3] = 1.0 if tr.screw_support == "fixed-fixed" else 0.0
        out[k, 4] = tr.screw_length
        out[k, 5] = tr.stiffness["screw"] * tr.screw_shape(a_ref)
        out[k, 6] = rest
        out[k, 7] = chain.damping_per_stiffness
        out[k, 9] = 1.0 if tr.backlash > 0.0 else 0.0
        out[k, 10:12] = travel
    return out


def main(argv: list[str] | None = None) -> None:
    """Write the compiled-parameter MJCF of a machine, e.g. for the MuJoCo viewer."""
    parser = argparse.ArgumentParser(prog="python -m twin.plant", description=main.__doc__)
    parser.add_argument("machine", help="preset name or TOML path")
    parser.add_argument("-o", "--output", type=Path, required=True, help="MJCF file to write")
    parser.add_argument("--scene", action="store_true", help="include floor, light, cameras")
    args = parser.parse_args(argv)
    spec = build_spec(args.machine, scene=args.scene)
    spec.compile()
    args.output.write_text(spec.to_xml(), encoding="utf-8")
