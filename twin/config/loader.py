"""Loading machine files: TOML → validated ``MachineConfig``, and dotted overrides.

A machine file has ``[machine]``, ``[axis_defaults.*]`` (applied to both axes), ``[axes.x.*]``
and ``[axes.y.*]`` (per-axis overrides, deep-merged over the defaults), ``[controller.*]`` and
``[simulation]``.
"""

from __future__ import annotations

import copy
import hashlib
import json
import tomllib
from pathlib import Path
from typing import Any

from twin.config.build import deep_merge, from_dict, to_raw
from twin.config.schema import AXES, MachineConfig, machine_from_raw
from twin.errors import ConfigError, byte_place
from twin.nesting import MAX_DEPTH, toml_too_deep

__all__ = ["MACHINES_DIR", "available_machines", "diff_machines", "flatten", "from_dict",
           "load_machine", "machine_from_toml_dict", "machine_identity", "read_toml",
           "toml_document"]

MACHINES_DIR = Path(__file__).resolve().parent.parent / "machines"


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
    return toml_document(text, where, f"{p}: " if field else "")


def toml_document(text: str, where: str, prefix: str = "") -> dict[str, Any]:
    """``tomllib.loads(text)``, refused (``ConfigError`` naming ``where``, the line and the
    table and key) when invalid or nested deeper than ``MAX_DEPTH`` levels: checked before
    it is parsed, as ``tomllib`` and the walks over what it returns recurse."""
    deep = toml_too_deep(text)
    if deep is None:
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(where, f"{prefix}invalid TOML: {exc}") from None
        except RecursionError:      # cannot happen below MAX_DEPTH; never a traceback
            pass
    place = "" if deep is None else f"line {deep.line}, {deep.key}: "
    raise ConfigError(where, f"{prefix}{place}nested deeper than {MAX_DEPTH} levels (tables, "
                      "arrays and dotted keys together; a machine file nests 4)")


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
        "axes": {ax: deep_merge(defaults, axes_over.get(ax, {})) for ax in AXES},
        **doc,
    }
    return machine_from_raw(raw, source)


def flatten(cfg: MachineConfig) -> dict[str, Any]:
    """Every leaf of a machine as ``{dotted path: value}`` (tuples as lists), in field order."""
    out: dict[str, Any] = {}

    def walk(node: Any, prefix: str) -> None:
        if isinstance(node, dict) and node:
            for k, v in node.items():
                walk(v, f"{prefix}.{k}" if prefix else str(k))
        else:
            out[prefix] = node

    walk(to_raw(cfg), "")
    return out


def machine_identity(cfg: MachineConfig) -> dict[str, Any]:
    """Name, file and hashes of a machine, for a run record: ``file_sha256`` of the TOML file
    it was loaded from (None for a config built in memory), ``config_sha256`` of the
    effective configuration (overrides included; canonical JSON)."""
    path = Path(cfg.source) if cfg.source and not cfg.source.startswith("<") else None
    file_hash = (hashlib.sha256(path.read_bytes()).hexdigest()
                 if path is not None and path.is_file() else None)
    canonical = json.dumps(to_raw(cfg), sort_keys=True, separators=(",", ":"),
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
