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
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from twin.config import AXES, MachineConfig, load_machine
from twin.errors import ConfigError

__all__ = [
    "MODELS_DIR",
    "MODEL_XML",
    "SCENE_XML",
    "AxisMechanics",
    "axis_mechanics",
    "build_spec",
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
    """Analytic two-mass model of one axis: rotor (reflected) — screw spring — table.

    The screw is one spring of stiffness ``k`` and damping ``c`` between the table (mass
    ``m``) and the rotor, whose inertia ``J`` appears at the table as ``M = J/r²``.

    Attributes
    ----------
    ratio : float
        Transmission r: table travel per rotor angle (m/rad).
    moving_mass : float
        Mass the slide moves, m (kg): its carriage and every carriage riding on it.
    rotor_inertia : float
        Rotor (and gear) inertia at the motor shaft, J (kg·m²).
    stiffness : float
        Series stiffness of the transmission chain, k (N/m, at the table).
    damping_ratio : float
        Damping ratio ζ of the locked-rotor mode, from the machine file (1).
    """

    ratio: float
    moving_mass: float
    rotor_inertia: float
    stiffness: float
    damping_ratio: float

    @property
    def reflected_mass(self) -> float:
        """Rotor inertia seen at the table, M = J/r² (kg)."""
        return self.rotor_inertia / self.ratio**2

    @property
    def damping(self) -> float:
        """Screw damping c = 2·ζ·√(k·m) that gives the locked-rotor mode ratio ζ (N·s/m)."""
        return 2.0 * self.damping_ratio * math.sqrt(self.stiffness * self.moving_mass)

    @property
    def locked_rotor_frequency(self) -> float:
        """Table on the screw with the rotor held still, ω_L = √(k/m) (rad/s).

        The mode a position loop sees when the speed loop holds the motor; the machine
        files state their first elastic mode (frequency and ζ) in this sense.
        """
        return math.sqrt(self.stiffness / self.moving_mass)

    @property
    def free_rotor_frequency(self) -> float:
        """Two-mass mode with a free rotor, ω_F = √(k·(1/m + 1/M)) (rad/s).

        The mode of the bare mechanics (no speed loop): what a rotor torque step excites.
        """
        return math.sqrt(self.stiffness * (1.0 / self.moving_mass + 1.0 / self.reflected_mass))

    @property
    def free_rotor_damping_ratio(self) -> float:
        """Damping ratio of the free-rotor mode, ζ_F = ζ·√(1 + m/M) (1)."""
        return self.damping_ratio * math.sqrt(1.0 + self.moving_mass / self.reflected_mass)

    @property
    def mass_ratio(self) -> float:
        """m/M: how far the free-rotor mode lies above the locked-rotor one (1)."""
        return self.moving_mass / self.reflected_mass


def axis_mechanics(cfg: MachineConfig, axis: str) -> AxisMechanics:
    """The analytic mechanics of ``axis`` ("x" or "y") of machine ``cfg``.

    Raises
    ------
    ConfigError
        If ``axis`` is not one of the machine's axes.
    """
    if axis not in AXES:
        raise ConfigError("axis", f"must be one of {AXES}, got {axis!r}")
    ax = cfg.axes[axis]
    return AxisMechanics(
        ratio=ax.transmission.ratio,
        moving_mass=cfg.moving_masses()[axis],
        rotor_inertia=ax.mechanics.rotor_inertia,
        stiffness=ax.transmission.axial_stiffness,
        damping_ratio=ax.transmission.damping_ratio,
    )


def mode_periods(cfg: MachineConfig) -> tuple[float, float]:
    """Period of the first (locked-rotor) elastic mode of x and y (s): ``2π/√(k/m)``, the
    x axis carrying the y carriage."""
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
    home = {}
    for axis in AXES:
        _apply_axis(spec, cfg, axis)
        r = cfg.axes[axis].transmission.ratio
        x_home = cfg.axes[axis].switches.home
        home[axis] = x_home
        home[f"{axis}_rotor"] = x_home / r  # screw relaxed: r·θ − x = 0
    spec.key("home").qpos = [home[j.name] for j in spec.joints]
    return spec


def load_model(machine: str | Path | MachineConfig, *, scene: bool = False,
               timestep: float | None = None) -> mujoco.MjModel:
    """Compile the model of ``machine`` (see :func:`build_spec` for the arguments)."""
    return build_spec(machine, scene=scene, timestep=timestep).compile()


def _apply_axis(spec: mujoco.MjSpec, cfg: MachineConfig, axis: str) -> None:
    """Write one axis' masses, inertia, friction, travel and screw into the spec."""
    ax = cfg.axes[axis]
    mech = ax.mechanics
    two_mass = axis_mechanics(cfg, axis)

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

    # MjSpec exposes no way to edit an existing tendon's wrap coefficients: rebuild the
    # tendon under the same name and default class with length r·θ − x.
    old = spec.tendon(f"{axis}_screw")
    default = old.default()
    spec.delete(old)
    screw = spec.add_tendon(name=f"{axis}_screw", default=default)
    screw.wrap_joint(f"{axis}_rotor", two_mass.ratio)
    screw.wrap_joint(axis, -1.0)
    screw.stiffness = [two_mass.stiffness, 0.0, 0.0]
    # Lost motion: a dead band of the spring (no force while the gap is open). MuJoCo's
    # tendon damper would still act inside the gap, so with lost motion the plant applies
    # the damping itself, only while the gap is closed (passive_parameters).
    half = 0.5 * ax.transmission.backlash
    screw.damping = [two_mass.damping if half == 0.0 else 0.0, 0.0, 0.0]
    screw.springlength = [-half, half]


def passive_parameters(machine: str | Path | MachineConfig) -> np.ndarray:
    """Per-axis parameters of the forces the plant applies itself before every physics step
    (``twin.plant.loop.passive_forces``), shape (2, ``plant_loop.NPASSIVE``): the Stribeck
    excess of slide and rotor friction over Coulomb with its speed, and the screw damping
    with half the lost motion. All zero for a machine without break-away friction or lost
    motion (then MuJoCo does everything and nothing is applied)."""
    cfg = resolve_machine(machine)
    out = np.zeros((len(AXES), 7))
    for k, axis in enumerate(AXES):
        ax = cfg.axes[axis]
        mech, r = ax.mechanics, ax.transmission.ratio
        out[k, 0] = mech.breakaway("slide") - mech.slide_coulomb
        out[k, 1] = mech.stribeck_velocity
        out[k, 2] = mech.breakaway("rotor") - mech.rotor_coulomb
        out[k, 3] = mech.stribeck_velocity / r
        if ax.transmission.backlash > 0.0:
            out[k, 4] = 0.5 * ax.transmission.backlash
            out[k, 5] = axis_mechanics(cfg, axis).damping
        out[k, 6] = r
    if not (out[:, 0].any() or out[:, 2].any() or out[:, 4].any()):
        out[:] = 0.0
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
