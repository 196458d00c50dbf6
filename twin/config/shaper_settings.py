"""The input shaper settings of a machine (``[controller.shaper.x]``, ``[controller.shaper.y]``)
and the one parser of the ``law+shaper`` profile syntax (``trapezoid+mzv``).

A machine file::

    [controller.shaper.x]
    type = "mzv"          # none, zv, mzv, zvd, ei, 2hump-ei, 3hump-ei
    frequency = 16.0      # Hz; unset: the first elastic mode of the controller's model
    damping = 0.1         # 1;  unset: the model's transmission damping ratio

    [controller.shaper]
    curve_share = 0.25    # of the contour tolerance a shaped curve may lose; 0: no cap

``--profile trapezoid+mzv`` (``twin run``, ``twin compare --profiles``, ``RunSpec.profile``)
is the law ``trapezoid`` with the shaper ``mzv`` on both axes, at the frequency and damping
of the machine file (or its model); ``trapezoid+none`` turns shaping off; a bare law keeps
the machine's shaper. The shapers themselves are ``twin.controller.shaping``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from twin.config.fields import Validated, choice, num
from twin.errors import ConfigError

__all__ = ["SHAPER_TYPES", "ShaperAxes", "ShaperSettings", "profile_overrides",
           "shaper_overrides", "split_profile"]

SHAPER_TYPES = ("none", "zv", "mzv", "zvd", "ei", "2hump-ei", "3hump-ei")
""""none" and the shapers of ``twin.controller.shaping.SHAPERS`` (a test keeps them equal)."""

_LAWS = ("trapezoid", "parabolic", "cosine", "cubic", "jerk-limited")
"""The acceleration laws (``schema.PROFILES``, which a test keeps equal to the planner's)."""


@dataclass(frozen=True, kw_only=True)
class ShaperSettings(Validated):
    """The input shaper of one axis (``twin.controller.shaping``)."""

    type: str = choice("none", SHAPER_TYPES, "the shaper of this axis' position reference")
    frequency: float | None = num(None, "Hz", gt=0, le=1e4, doc="the mode it cancels; unset: "
                                  "the first elastic mode of the controller's model (√(k/m) "
                                  "of the transmission and the moving mass)")
    damping: float | None = num(None, "1", ge=0, le=0.95, doc="that mode's damping ratio; "
                                "unset: the model's transmission damping ratio")


def _axis() -> ShaperSettings:
    return ShaperSettings()


@dataclass(frozen=True, kw_only=True)
class ShaperAxes(Validated):
    """The shapers of both axes."""

    x: ShaperSettings = field(default_factory=_axis)
    y: ShaperSettings = field(default_factory=_axis)
    curve_share: float = num(0.25, "1", ge=0.0, le=4.0, doc="share of the contour tolerance "
                             "a curve may lose to the shapers: the planner caps the "
                             "centripetal acceleration at 2·share·tolerance/σ² (σ the "
                             "shaper's impulse spread); 0: no cap (shaped circles shrink by "
                             "a·σ²/2)")

    def check_nyquist(self, period: float) -> None:
        """A frequency the controller period cannot shape (at or above its Nyquist rate
        ``1/(2T)``) is refused, naming the axis."""
        for name in ("x", "y"):
            s = getattr(self, name)
            if s.frequency is not None and s.frequency >= 0.5 / period:
                raise ConfigError(f"shaper.{name}.frequency", f"{s.frequency:g} Hz is at or "
                                  f"above the Nyquist rate of the controller period "
                                  f"({0.5 / period:g} Hz at {period * 1e3:g} ms)")


def split_profile(text: str, field: str = "profile") -> tuple[str, str | None]:
    """``"law"`` or ``"law+shaper"`` → (law, shaper or None); the one parser of the syntax.

    Raises
    ------
    ConfigError
        Naming ``field``: an unknown law or shaper, or more than one ``+``.
    """
    parts = [p.strip().lower() for p in str(text).split("+")]
    if len(parts) > 2 or not parts[0]:
        raise ConfigError(field, f"expected LAW or LAW+SHAPER (e.g. trapezoid+mzv), got "
                          f"{text!r}")
    law = parts[0].replace("_", "-")
    if law not in _LAWS:
        raise ConfigError(field, f"unknown law {parts[0]!r} in {text!r}; one of "
                          f"{', '.join(_LAWS)}")
    if len(parts) == 1:
        return law, None
    shaper = parts[1].replace("_", "-")
    if shaper not in SHAPER_TYPES:
        raise ConfigError(field, f"unknown shaper {parts[1]!r} in {text!r}; one of "
                          f"{', '.join(SHAPER_TYPES)}")
    return law, shaper


def shaper_overrides(name: str, field: str = "shaper") -> dict[str, Any]:
    """The machine overrides that put shaper ``name`` (``SHAPER_TYPES``) on both axes.

    Raises
    ------
    ConfigError
        Naming ``field``: an unknown shaper.
    """
    shaper = str(name).strip().lower().replace("_", "-")
    if shaper not in SHAPER_TYPES:
        raise ConfigError(field, f"unknown shaper {name!r}; one of {', '.join(SHAPER_TYPES)}")
    return {f"controller.shaper.{a}.type": shaper for a in ("x", "y")}


def profile_overrides(text: str, field: str = "profile") -> dict[str, Any]:
    """The machine overrides ``text`` (``split_profile``) stands for: the law, and the
    shaper type of both axes when one is named."""
    law, shaper = split_profile(text, field)
    out: dict[str, Any] = {"controller.profile": law}
    if shaper is not None:
        out.update(shaper_overrides(shaper, field))
    return out
