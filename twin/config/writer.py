"""A machine configuration back to a machine file: ``machine_to_toml``.

The file is complete (every field, both axes written out, no ``axis_defaults``) so that it
reads back to the same configuration (``tests/test_config.py``), and it carries an optional
header of comment lines: what ``twin identify`` writes about where each value came from.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from typing import Any

from twin.config.schema import AXES, MachineConfig

__all__ = ["machine_to_toml"]


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"a machine file holds finite numbers only, got {v}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, tuple | list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _table(name: str, obj: Any, out: list[str]) -> None:
    """Write dataclass ``obj`` as ``[name]`` and its nested dataclasses as sub-tables."""
    scalars, nested = [], []
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if f.name == "source" or v is None:
            continue
        (nested if dataclasses.is_dataclass(v) else scalars).append((f.name, v))
    if scalars:
        out.append(f"\n[{name}]")
        out.extend(f"{k} = {_value(v)}" for k, v in scalars)
    for k, v in nested:
        _table(f"{name}.{k}", v, out)


def machine_to_toml(cfg: MachineConfig, *, header: Sequence[str] = ()) -> str:
    """The text of a machine file that loads to ``cfg``.

    Parameters
    ----------
    cfg : MachineConfig
    header : sequence of str
        Comment lines put at the top (without the ``#``).
    """
    out = [f"# {line}".rstrip() for line in header]
    out.append("\n[machine]")
    out.append(f"name = {_value(cfg.name)}")
    out.append(f"description = {_value(cfg.description)}")
    for a in AXES:
        for f in dataclasses.fields(cfg.axes[a]):
            _table(f"axes.{a}.{f.name}", getattr(cfg.axes[a], f.name), out)
    _table("controller", cfg.controller, out)
    _table("simulation", cfg.simulation, out)
    _table("hil", cfg.hil, out)
    _table("accelerometer", cfg.accelerometer, out)
    return "\n".join(out).lstrip("\n") + "\n"
