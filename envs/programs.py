"""Test programs for tuning runs: the library's built-in programs (``twin.controller.library``).

A tuning run must exercise what the gains act on — accelerations from rest, speed changes
between spline sections, a corner, a circle (axis reversals), a rapid — but every run costs
wall time. ``"compact"`` is the default program (``twin.controller.library.default_program``)
shrunk about its start point by ``COMPACT_SCALE``: the same feeds, accelerations and jerk
phases, about a twentieth of the path, so one run takes a few simulated seconds instead of
a minute; ``"tiny"`` shrinks it to 1 % for tests and smoke runs. ``"default"`` is the full
program, the one the acceptance figures are quoted on. Every one of them is also a
``twin run --builtin`` program.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from twin.config import MachineConfig
from twin.controller.library import (
    COMPACT_SCALE,
    TINY_SCALE,
    build_program,
    scale_segment,
    scaled_program,
)
from twin.controller.library import PROGRAMS as LIBRARY
from twin.errors import ConfigError

__all__ = ["COMPACT_SCALE", "PROGRAMS", "TINY_SCALE", "scale_segment", "scaled_program",
           "tuning_program"]

PROGRAMS = tuple(LIBRARY)
"""Program names a tuning run accepts: the library's (``default``, ``compact``, ``tiny``,
``spline_line``, ``corner``)."""


def tuning_program(name: str, cfg: MachineConfig, start: Sequence[float]) -> list[Any]:
    """The motion items of program ``name`` on machine ``cfg`` starting at ``start`` (m).

    Raises
    ------
    ConfigError
        For an unknown name (listing the valid ones).
    """
    if name in LIBRARY:
        return build_program(name, cfg, start)
    raise ConfigError("program", f"unknown tuning program {name!r}; valid: "
                      f"{', '.join(PROGRAMS)}")
