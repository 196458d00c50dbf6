"""Loading machine files: TOML → validated ``MachineConfig``, and dotted overrides.

A machine file has ``[machine]``, ``[axis_defaults.*]`` (applied to both axes), ``[axes.x.*]``
and ``[axes.y.*]`` (per-axis overrides, deep-merged over the defaults), ``[controller.*]`` and
``[simulation]``.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json
import math
import re
import tomllib
import types
import typing
from pathlib import Path
from typing import Any

from twin.config.quantities import is_bare_number, to_si
from twin.config.schema import AXES, MachineConfig, field_meta
from twin.errors import ConfigError, byte_place

__all__ = ["MACHINES_DIR", "available_machines", "diff_machines", "flatten", "from_dict",
           "load_machine", "machine_from_toml_dict", "machine_identity", "read_toml"]

MACHINES_DIR = Path(__file__).resolve().parent.parent / "machines"


def _to_raw(obj: Any) -> Any:
    if dataclasses.is_dataclass(obj):
        return {f.name: _to_raw(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if f.name != "source"}
    if isinstance(obj, dict):
        return {k: _to_raw(v) for k, v in obj.items()}
    if isinstance(obj, tuple):
        return list(obj)
    return obj


def _set_path(raw: dict[str, Any], parts: list[str], value: Any, key: str) -> None:
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


def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict) and k != "stiffness":
            out[k] = _deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _coerce(tp: Any, value: Any, path: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        errors = []
        for arg in args:  # the first member the value fits
            try:
                return _coerce(arg, value, path)
            except ConfigError as exc:
                errors.append(exc.message)
        raise ConfigError(path, " or ".join(dict.fromkeys(errors)))
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(path, f"must be a table, got {type(value).__name__}")
        return from_dict(tp, value, path)
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(path, f"must be a table, got {type(value).__name__}")
        _, vt = typing.get_args(tp)
        return {k: _coerce(vt, v, f"{path}.{k}") for k, v in value.items()}
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ConfigError(path, f"must be an array, got {value!r}")
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:  # tuple[X, ...]
            return tuple(_coerce(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(path, f"must have {len(args)} items, got {len(value)}")
        pairs = enumerate(zip(args, value, strict=True))
        return tuple(_coerce(a, v, f"{path}[{i}]") for i, (a, v) in pairs)
    if tp is float:
        if isinstance(value, str) and not is_bare_number(value):   # "900 mm/min", "5 µm"
            unit = str(field_meta(re.sub(r"\[\d+\]", "", path)).get("unit", ""))
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


def from_dict(cls: type, data: dict[str, Any], path: str = "") -> Any:
    """Build dataclass ``cls`` from a plain dict, naming the dotted field on any error."""
    hints = typing.get_type_hints(cls)
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
            kwargs[f.name] = _coerce(hints[f.name], data[f.name], fpath)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(fpath, "missing")
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        if exc.field.startswith(prefix) and prefix:
            raise
        raise ConfigError(f"{prefix}{exc.field}", exc.message) from None


def _build(raw: dict[str, Any], source: str) -> MachineConfig:
    cfg = from_dict(MachineConfig, raw)
    return dataclasses.replace(cfg, source=source)


def available_machines() -> list[str]:
    """Names of the presets shipped in ``twin/machines``."""
    return sorted(p.stem for p in MACHINES_DIR.glob("*.toml"))


def load_machine(name_or_path: str | Path) -> MachineConfig:
    """Load and validate a machine by preset name or TOML path.

    Raises
    ------
    ConfigError
        If the file is missing, not valid TOML, or a field is missing or out of range.
    """
    p = Path(name_or_path)
    if not p.suffix and not p.exists():
        p = MACHINES_DIR / f"{name_or_path}.toml"
    if not p.is_file():
        raise ConfigError("machine", f"no machine file {str(name_or_path)!r}; presets: "
                          f"{', '.join(available_machines())}")
    return machine_from_toml_dict(read_toml(p), source=str(p))


def read_toml(path: str | Path, field: str | None = None) -> dict[str, Any]:
    """Parse a TOML file (machine, register map, set-file, best.toml).

    Raises
    ------
    ConfigError
        Naming ``field`` (default: the file) for bytes that are not UTF-8 (with the byte
        offset, line and column of the first) and for invalid TOML; TOML is UTF-8 by
        definition, so nothing is guessed.
    """
    p = Path(path)
    where = field or str(p)
    data = p.read_bytes()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line, column = byte_place(data, exc.start)
        raise ConfigError(where, f"{p}: not UTF-8 text: byte {exc.start} (line {line}, "
                          f"column {column}) is 0x{data[exc.start]:02x}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(where, f"{p}: invalid TOML: {exc}" if field else
                          f"invalid TOML: {exc}") from None


_MACHINE_KEYS = ("description", "name")
"""The keys of a machine file's ``[machine]`` table."""


def machine_from_toml_dict(doc: dict[str, Any], *, source: str = "<dict>") -> MachineConfig:
    """Validate a parsed machine document (``[machine]``, ``[axis_defaults]``, ``[axes]``...)."""
    doc = copy.deepcopy(doc)
    head = doc.pop("machine", None)
    if not isinstance(head, dict) or "name" not in head:
        raise ConfigError("machine.name", "missing")
    for key in head:
        if key not in _MACHINE_KEYS:
            raise ConfigError(f"machine.{key}", "unknown key; valid: "
                              f"{', '.join(_MACHINE_KEYS)}")
    defaults = doc.pop("axis_defaults", {})
    axes_over = doc.pop("axes", {})
    if not isinstance(axes_over, dict):
        raise ConfigError("axes", "must be a table")
    for ax in axes_over:
        if ax not in AXES:
            raise ConfigError(f"axes.{ax}", f"unknown axis; valid: {', '.join(AXES)}")
    raw: dict[str, Any] = {
        "name": head["name"],
        "description": head.get("description", ""),
        "axes": {ax: _deep_merge(defaults, axes_over.get(ax, {})) for ax in AXES},
        **doc,
    }
    return _build(raw, source)


def flatten(cfg: MachineConfig) -> dict[str, Any]:
    """Every leaf of a machine as ``{dotted path: value}`` (tuples as lists), in field order."""
    out: dict[str, Any] = {}

    def walk(node: Any, prefix: str) -> None:
        if isinstance(node, dict) and node:
            for k, v in node.items():
                walk(v, f"{prefix}.{k}" if prefix else str(k))
        else:
            out[prefix] = node

    walk(_to_raw(cfg), "")
    return out


def machine_identity(cfg: MachineConfig) -> dict[str, Any]:
    """Name, file and hashes of a machine, for a run record: ``file_sha256`` of the TOML file
    it was loaded from (None for a config built in memory), ``config_sha256`` of the
    effective configuration (overrides included; canonical JSON)."""
    path = Path(cfg.source) if cfg.source and not cfg.source.startswith("<") else None
    file_hash = (hashlib.sha256(path.read_bytes()).hexdigest()
                 if path is not None and path.is_file() else None)
    canonical = json.dumps(_to_raw(cfg), sort_keys=True, separators=(",", ":"),
                           default=str).encode()
    return {"name": cfg.name, "file": str(path) if path else None, "file_sha256": file_hash,
            "config_sha256": hashlib.sha256(canonical).hexdigest()}


def diff_machines(a: MachineConfig, b: MachineConfig) -> list[tuple[str, Any, Any]]:
    """Where two machines differ: ``(dotted path, value in a, value in b)`` for every leaf
    that differs or exists in one only (None for the missing side), in field order."""
    fa, fb = flatten(a), flatten(b)
    keys = list(fa) + [k for k in fb if k not in fa]
    return [(k, fa.get(k), fb.get(k)) for k in keys
            if k not in ("name", "description") and fa.get(k) != fb.get(k)]
