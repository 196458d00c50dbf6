"""``--set key=value``: override any regulator, DCU, limit or machine parameter of a run.

A key is a dotted path of the machine configuration (``axes.x.mechanics.carriage_mass``,
``axes.*.transmission.damping_ratio`` for both axes) or one of the short names below.
Values are TOML literals (``2.5e3``, ``true``, ``"cosine"``); anything else is a string.
``--set-file FILE.toml`` gives the same overrides as TOML tables (what ``twin tune`` writes);
``--set`` values win over the file's.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from twin.config import read_toml
from twin.errors import ConfigError

__all__ = ["SHORT_KEYS", "parse_sets", "resolve_key", "set_file_overrides"]

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

_ROOTS = ("axes", "controller", "simulation")


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


def _value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_sets(items: Iterable[str]) -> dict[str, Any]:
    """``["kp=2000", "axes.x.mechanics.carriage_mass=90"]`` → ``{dotted path: value}``."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(item, "--set needs key=value")
        out[resolve_key(key)] = _value(text.strip())
    return out


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
