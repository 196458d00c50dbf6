"""Values with units at the edges: ``900mm/min``, ``5 µm``, ``12ms``, ``2 V/mm``.

Inside xy-twin every number is SI. Where a person types a value (``--set``, an override or
machine TOML file such as ``best.toml``) it may carry a unit; pint converts it once to the
field's SI unit (the schema's ``unit``), and a unit of the wrong dimension is refused naming
the field and the unit it takes.

Some fields are shown in a unit other than SI (feeds in mm/min, small lengths in µm, the
period in ms: :func:`display_unit`). A bare number typed for one of them at the command line
is ambiguous (900 meant as mm/min would be 900 m/s) and is refused, naming the unit to give.
Files keep bare numbers in SI, as the machine files always have.
"""

from __future__ import annotations

import functools
import math
import re
from typing import Any

from twin.errors import ConfigError

__all__ = ["display_unit", "example", "is_bare_number", "to_si"]

_TO_PINT = (("·", "*"), ("²", "**2"), ("³", "**3"), ("Ω", "ohm"), ("µ", "u"), ("μ", "u"))
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
_NUMBER_START = re.compile(r"^[+-]?((\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|inf|nan)")
_QUANTITY = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+|inf|nan)([eE][+-]?\d+)?\s*"
                       r"[A-Za-zµμΩ°][A-Za-z0-9µμΩ°·*/^()²³ .-]*$")
"""A number then a unit (letters, products, quotients, powers): nothing else is given to
pint, whose parser evaluates expressions."""

DISPLAY_BY_UNIT = {"m/s": "mm/min", "m": "mm"}
"""The display unit of a field by its SI unit, unless the field names its own
(``display`` in its metadata)."""


@functools.cache
def _registry():
    import pint

    return pint.UnitRegistry()


def _pint_text(text: str) -> str:
    for a, b in _TO_PINT:
        text = text.replace(a, b)
    return text


def is_bare_number(value: Any) -> bool:
    """A number without a unit (a TOML number, or text that is only a number)."""
    if isinstance(value, bool):
        return False
    if isinstance(value, int | float):
        return True
    return isinstance(value, str) and bool(_NUMBER.match(value.strip()))


def display_unit(meta: dict[str, Any]) -> str | None:
    """The unit a field is shown in when it is not its SI unit (``mm/min`` for a feed,
    ``µm`` for a tolerance, ``ms`` for the period), from the field's metadata; None when
    the field is shown in SI or has no unit."""
    if not meta.get("unit"):
        return None
    if meta.get("display"):
        return str(meta["display"])
    return DISPLAY_BY_UNIT.get(str(meta.get("unit", "")))


def example(unit: str, display: str | None) -> str:
    """An example of a value with a unit for the messages (``900mm/min``)."""
    return {"mm/min": "900mm/min", "µm": "5um", "mm": "12.5mm", "ms": "5ms",
            "mm/s": "2mm/s"}.get(display or "", f"1 {unit}")


def to_si(text: str, unit: str, field: str) -> float:
    """``text`` (a number with a unit, or a bare number: already SI) in the SI ``unit`` of
    ``field``.

    Raises
    ------
    ConfigError
        Naming ``field``: text that is not a quantity, a unit of another dimension, a
        non-finite value.
    """
    import pint

    ureg = _registry()
    target = "dimensionless" if unit in ("", "1") else _pint_text(unit)
    bad = ConfigError(field, f"{text!r} is not a number with a unit (e.g. "
                      f"{example(unit, None)})")
    if _NUMBER.match(text.strip()):
        return float(text)          # no unit: the field's own (SI)
    if len(text) > 64 or not _QUANTITY.match(text.strip()):
        raise bad                   # pint parses expressions; a value is a number and a unit
    number = _NUMBER_START.match(text.strip())
    magnitude, unit_text = float(number.group(0)), text.strip()[number.end():].strip()
    try:
        factor = ureg.Quantity(1.0, _pint_text(unit_text)).to(target).magnitude
    except pint.DimensionalityError:
        raise ConfigError(field, f"{text!r} is not in {unit}: give a value in {unit} or a "
                          "unit of the same kind") from None
    except Exception:       # whatever pint's parser makes of it (TokenError, ...)
        raise bad from None
    # the factor of a unit is a decimal constant (1e-6, 0.0254/60): pint's products of
    # prefixes leave an ulp on it (µm → m is 1.0000000000000002e-06); none where it is 1
    factor = float(f"{float(factor):.15g}")
    value = magnitude if factor == 1.0 else float(f"{magnitude * factor:.15g}")
    if not math.isfinite(value):
        raise ConfigError(field, f"must be finite, got {text!r}")
    return value

