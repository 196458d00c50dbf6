"""``--set key=value``: override any regulator, DCU, limit or machine parameter of a run.

A key is a dotted path of the machine configuration (``axes.x.mechanics.carriage_mass``,
``axes.*.transmission.damping_ratio`` for both axes) or one of the short names below.
Values are TOML literals (``2.5e3``, ``true``, ``"cosine"``) or numbers with a unit
(``900mm/min``, ``5um``, ``2 V/mm``: converted to the field's SI unit,
``twin.config.quantities``); anything else is a string. A field shown in another unit than
its SI one (a feed in mm/min, a tolerance in µm, the period in ms) takes no bare number here:
``max_velocity=900`` is refused, naming the unit to give. ``--set-file FILE.toml`` gives the
same overrides as TOML tables (what ``twin tune`` writes), values with units as strings
(``max_velocity = "900 mm/min"``) and bare numbers in SI; ``--set`` values win over the
file's.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from twin.config import read_toml
from twin.config.quantities import display_unit, example, is_bare_number
from twin.config.schema import field_meta
from twin.errors import ConfigError
from twin.nesting import MAX_DEPTH, toml_too_deep

__all__ = ["SET_HELP", "SHORT_KEYS", "key_units", "parse_sets", "resolve_key",
           "set_file_overrides"]

SHORT_KEYS = {
    **{k: f"controller.regulator.{k}" for k in
       ("kp", "ki", "kd", "ff1", "ff2", "ff3", "dcu_order", "following_error_limit")},
    **{k: f"controller.limits.{k}" for k in ("max_velocity", "max_acceleration", "max_jerk")},
    **{k: f"controller.{k}" for k in
       ("period", "rapid_velocity", "contour_tolerance", "profile", "planner", "lookahead")},
    "timestep": "simulation.timestep",
    "drive_substeps": "simulation.drive_substeps",
}
"""Short names accepted by ``--set`` and the dotted path each stands for."""

_ROOTS = ("axes", "controller", "simulation", "hil", "accelerometer")


def resolve_key(key: str) -> str:
    """The dotted config path of ``key`` (a short name or a dotted path).

    Raises
    ------
    ConfigError
        Naming the valid short names and roots when ``key`` is neither.
    """
    key = key.strip()
    if key in SHORT_KEYS:
        return SHORT_KEYS[key]
    if "." in key and key.split(".", 1)[0] in _ROOTS:
        return key
    raise ConfigError(key, "unknown --set key; valid: " + ", ".join(sorted(SHORT_KEYS))
                      + ", or a dotted path under " + ", ".join(_ROOTS)
                      + " (e.g. axes.x.mechanics.carriage_mass)")


def _value(text: str, key: str) -> Any:
    source = f"v = {text}"
    if toml_too_deep(source) is not None:   # tomllib would recurse into it
        raise ConfigError(key, f"the value nests deeper than {MAX_DEPTH} levels of arrays "
                          "and tables")
    try:
        return tomllib.loads(source)["v"]
    except tomllib.TOMLDecodeError:
        return text


def _bare(value: Any) -> bool:
    if isinstance(value, list):
        return any(_bare(v) for v in value)
    return is_bare_number(value)


def _checked(key: str, path: str, value: Any) -> Any:
    """``value`` for ``path``, refused when it is a bare number for a field shown in
    another unit than its SI one (the unit must be given)."""
    meta = field_meta(path)
    shown = display_unit(meta)
    if shown is not None and _bare(value):
        raise ConfigError(key, f"give a unit: {key}={example(meta['unit'], shown)} (this "
                          f"field is shown in {shown}; a bare {value!r} would be read in "
                          f"{meta['unit']})")
    return value


def parse_sets(items: Iterable[str]) -> dict[str, Any]:
    """``["kp=2000", "max_velocity=900mm/min"]`` → ``{dotted path: value}``; a value with a
    unit stays text until the machine's fields convert it (``MachineConfig.with_overrides``)
    to SI."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(item, "--set needs key=value")
        path = resolve_key(key)
        out[path] = _checked(key.strip(), path, _value(text.strip(), key.strip()))
    return out


def key_units() -> dict[str, str]:
    """Each short ``--set`` key and the unit it takes (``mm/min, with the unit`` for one
    shown in another unit than SI)."""
    out = {}
    for key, path in SHORT_KEYS.items():
        meta = field_meta(path)
        unit = str(meta.get("unit", "")) or "-"
        shown = display_unit(meta)
        out[key] = f"{shown}, with the unit" if shown else unit
    return out


SET_HELP = ("key=value, repeatable: any regulator, DCU, limit or machine parameter by its "
            "dotted path (axes.x.mechanics.carriage_mass=95) or short key; a value may carry "
            "a unit (900mm/min, 5um, 2 V/mm). Short keys and units: "
            + ", ".join(f"{k} ({u})" for k, u in key_units().items()) + ".")
"""The ``--set`` option's help: every short key with the unit it takes."""


def set_file_overrides(path: str | Path) -> dict[str, Any]:
    """The dotted overrides of a machine-override TOML file.

    Tables are flattened to dotted keys (``[controller.regulator] kp = 1`` →
    ``{"controller.regulator.kp": 1}``); arrays stay values. The result goes through
    ``MachineConfig.with_overrides`` like ``--set`` values.

    Raises
    ------
    ConfigError
        Missing file or invalid TOML (naming the file).
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError("set_file", f"no such file: {path}")
    doc = read_toml(p)
    out: dict[str, Any] = {}

    def walk(node: dict[str, Any], prefix: str) -> None:
        for key, value in node.items():
            if isinstance(value, dict) and not key == "stiffness":
                walk(value, f"{prefix}{key}.")
            else:
                out[f"{prefix}{key}"] = value

    walk(doc, "")
    return out
