"""Plain dicts ⇄ the config dataclasses, generic over the dataclass: ``from_dict`` builds
one (coercing TOML values to the field types, units in strings to SI, naming the dotted
field on any error), ``to_raw`` gives its plain dict back, ``set_path`` sets a dotted key in
such a dict. The machine's schema and the loader both use it, so neither imports the other
for it (``MachineConfig.with_overrides`` is a round trip through here).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import re
import types
import typing
from collections.abc import Callable
from typing import Any

from twin.config.quantities import is_bare_number, to_si
from twin.errors import ConfigError

__all__ = ["UnitOf", "deep_merge", "from_dict", "set_path", "to_raw"]

UnitOf = Callable[[str], str]
"""The SI unit of the field at a dotted path (``""``: none)."""


def to_raw(obj: Any) -> Any:
    """The plain dict (lists for tuples) of a config dataclass, without its ``source``."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_raw(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if f.name != "source"}
    if isinstance(obj, dict):
        return {k: to_raw(v) for k, v in obj.items()}
    if isinstance(obj, tuple):
        return list(obj)
    return obj


def set_path(raw: dict[str, Any], parts: list[str], value: Any, key: str) -> None:
    """Set ``raw[parts[0]][parts[1]]… = value``; an unknown key is a ``ConfigError`` naming
    ``key`` and the keys valid at that level (a stiffness table takes new components)."""
    node: Any = raw
    for i, p in enumerate(parts[:-1]):
        if not isinstance(node, dict) or p not in node:
            valid = sorted(node) if isinstance(node, dict) else []
            raise ConfigError(key, f"unknown key {'.'.join(parts[: i + 1])!r}; "
                              f"valid here: {', '.join(valid)}")
        node = node[p]
    leaf = parts[-1]
    if not isinstance(node, dict) or (leaf not in node and not _open_dict(parts)):
        valid = sorted(node) if isinstance(node, dict) else []
        raise ConfigError(key, f"unknown key {key!r}; valid here: {', '.join(valid)}")
    node[leaf] = value


def _open_dict(parts: list[str]) -> bool:
    return len(parts) >= 2 and parts[-2] == "stiffness"


def deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``over`` merged into a copy of ``base``, table by table (a stiffness table is
    replaced whole: its components are one series)."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict) and k != "stiffness":
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _coerce(tp: Any, value: Any, path: str, unit_of: UnitOf | None) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        errors = []
        for arg in args:  # the first member the value fits
            try:
                return _coerce(arg, value, path, unit_of)
            except ConfigError as exc:
                errors.append(exc.message)
        raise ConfigError(path, " or ".join(dict.fromkeys(errors)))
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(path, f"must be a table, got {type(value).__name__}")
        return from_dict(tp, value, path, unit_of)
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(path, f"must be a table, got {type(value).__name__}")
        _, vt = typing.get_args(tp)
        return {k: _coerce(vt, v, f"{path}.{k}", unit_of) for k, v in value.items()}
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(path, f"must be an array, got {value!r}")
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:  # tuple[X, ...]
            return tuple(_coerce(args[0], v, f"{path}[{i}]", unit_of) for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(path, f"must have {len(args)} items, got {len(value)}")
        pairs = enumerate(zip(args, value, strict=True))
        return tuple(_coerce(a, v, f"{path}[{i}]", unit_of) for i, (a, v) in pairs)
    if tp is float:
        if isinstance(value, str) and not is_bare_number(value):   # "900 mm/min", "5 µm"
            unit = unit_of(re.sub(r"\[\d+\]", "", path)) if unit_of is not None else ""
            value = to_si(value, unit, path)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(path, f"must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ConfigError(path, f"must be finite, got {value}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(path, f"must be an integer, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(path, f"must be a string, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(path, f"must be true or false, got {value!r}")
        return value
    return value


@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints`` of a config dataclass, evaluated once per class (a
    machine file builds about a hundred of them; the hints never change). Read only."""
    return typing.get_type_hints(cls)


def from_dict(cls: type, data: dict[str, Any], path: str = "",
              unit_of: UnitOf | None = None) -> Any:
    """Build dataclass ``cls`` from a plain dict, naming the dotted field on any error.

    A float field given as a string with a unit (``"900 mm/min"``) is converted to the
    unit ``unit_of(dotted path)`` names (SI); without ``unit_of`` such a string is refused
    as not a number."""
    hints = _type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    prefix = f"{path}." if path else ""
    for key in data:
        if key not in names:
            raise ConfigError(f"{prefix}{key}", f"unknown key; valid: {', '.join(sorted(names))}")
    kwargs = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        fpath = f"{prefix}{f.name}"
        if f.name in data:
            kwargs[f.name] = _coerce(hints[f.name], data[f.name], fpath, unit_of)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(fpath, "missing")
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        if exc.field.startswith(prefix) and prefix:
            raise
        raise ConfigError(f"{prefix}{exc.field}", exc.message) from None
