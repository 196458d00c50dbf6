"""Machine parameter sets: TOML files validated into frozen dataclasses.

A machine file has ``[machine]``, ``[axis_defaults.*]`` (applied to both axes), ``[axes.x.*]``
and ``[axes.y.*]`` (per-axis overrides, deep-merged over the defaults), ``[controller.*]`` and
``[simulation]``. Every value is SI unless its name carries a unit suffix (``_rpm``). Every
error names the dotted field: ``axes.x.mechanics.carriage_mass: must be > 0, got -1``.

Typical use::

    cfg = load_machine("tomsk_xy")             # a preset in twin/machines/
    cfg = load_machine("my_machine.toml")      # or a path
    cfg = cfg.with_overrides({"controller.regulator.kp": 2000.0})
"""

from twin.config.loader import (
    MACHINES_DIR,
    available_machines,
    diff_machines,
    flatten,
    from_dict,
    load_machine,
    machine_from_toml_dict,
    machine_identity,
    read_toml,
)
from twin.config.schema import (
    AXES,
    AccelerometerConfig,
    AxisConfig,
    ControllerSettings,
    ConverterConfig,
    DacConfig,
    DeadlineConfig,
    EncoderConfig,
    LimitsConfig,
    MachineConfig,
    MechanicsConfig,
    MotorConfig,
    RegulatorsConfig,
    RegulatorSettings,
    SimulationConfig,
    SpeedLoopConfig,
    SwitchConfig,
    TachoConfig,
    TimingConfig,
    TransmissionConfig,
    field_unit,
    moving_masses,
)

__all__ = [
    "AXES",
    "MACHINES_DIR",
    "AccelerometerConfig",
    "AxisConfig",
    "ControllerSettings",
    "ConverterConfig",
    "DacConfig",
    "DeadlineConfig",
    "EncoderConfig",
    "LimitsConfig",
    "MachineConfig",
    "MechanicsConfig",
    "MotorConfig",
    "RegulatorSettings",
    "RegulatorsConfig",
    "SimulationConfig",
    "SpeedLoopConfig",
    "SwitchConfig",
    "TachoConfig",
    "TimingConfig",
    "TransmissionConfig",
    "available_machines",
    "diff_machines",
    "field_unit",
    "flatten",
    "from_dict",
    "load_machine",
    "machine_from_toml_dict",
    "machine_identity",
    "moving_masses",
    "read_toml",
]
