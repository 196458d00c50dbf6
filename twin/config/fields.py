"""The field machinery of the machine schema: numeric fields with their unit and physical
range, fields that take one of a set of choices, and the mixin that checks both on
construction (``ConfigError`` naming the field and its range).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import field
from typing import Any

from twin.errors import ConfigError

__all__ = ["Validated", "choice", "flag", "num", "range_text", "spec"]


def spec(unit: str, *, gt: float | None = None, ge: float | None = None,
         le: float | None = None, doc: str = "", display: str | None = None
         ) -> dict[str, Any]:
    """The metadata of a numeric field: unit, bounds (``gt``/``ge`` below, ``le`` above),
    meaning and, for a field shown in another unit than its SI one, that ``display`` unit
    (``twin.config.quantities.display_unit``)."""
    return {"unit": unit, "gt": gt, "ge": ge, "le": le, "doc": doc, "display": display}


def num(default: Any = dataclasses.MISSING, unit: str = "", *, gt: float | None = None,
        ge: float | None = None, le: float | None = None, doc: str = "",
        display: str | None = None) -> Any:
    """A numeric field with its unit and its physically meaningful range (checked on load;
    :func:`range_text` states it); ``display``: the unit it is shown in, when not SI."""
    return field(default=default, metadata=spec(unit, gt=gt, ge=ge, le=le, doc=doc,
                                                display=display))


def choice(default: Any, choices: tuple[Any, ...], doc: str) -> Any:
    """A field that takes one of ``choices`` (checked on load)."""
    return field(default=default, metadata={"choices": choices, "doc": doc})


def flag(default: bool, doc: str) -> Any:
    """A true/false field."""
    return field(default=default, metadata={"choices": (True, False), "doc": doc})


def range_text(meta: Any) -> str:
    """The range of a numeric field as ``[lo, hi] unit`` (``(`` for an open end), the
    choices of a field that takes one of them (``one of a, b``), or ``""`` for a field with
    neither."""
    if not any(meta.get(k) is not None for k in ("gt", "ge", "le", "choices")):
        return ""
    if meta.get("choices"):
        return "one of " + ", ".join(
            str(c).lower() if isinstance(c, bool) else str(c) for c in meta["choices"])
    lo = f"({meta['gt']:g}" if meta.get("gt") is not None else (
        f"[{meta['ge']:g}" if meta.get("ge") is not None else "(-inf")
    hi = f"{meta['le']:g}]" if meta.get("le") is not None else "inf)"
    unit = meta.get("unit", "")
    return f"{lo}, {hi}" + (f" {unit}" if unit and unit != "1" else "")


def _leaves(value: Any) -> list[Any]:
    if isinstance(value, tuple | list):
        return [v for item in value for v in _leaves(item)]
    return [value]


class Validated:
    """Mixin: check every numeric field against its metadata bounds after construction."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            meta = f.metadata
            choices = meta.get("choices")
            flag = choices == (True, False)
            if choices and value is not None and (value not in choices or (
                    flag and not isinstance(value, bool))):
                raise ConfigError(f.name, f"must be {range_text(meta)}, got {value!r}")
            if not meta or value is None or isinstance(value, bool):
                continue
            for v in _leaves(value):
                if not isinstance(v, int | float) or isinstance(v, bool):
                    continue
                inside = (math.isfinite(v)
                          and (meta.get("gt") is None or v > meta["gt"])
                          and (meta.get("ge") is None or v >= meta["ge"])
                          and (meta.get("le") is None or v <= meta["le"]))
                if not inside:
                    raise ConfigError(f.name, f"must lie in {range_text(meta)}, got {v:g}")
        self._check()

    def _check(self) -> None:
        """Cross-field checks; override."""
