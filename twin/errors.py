"""Typed exceptions of xy-twin. Every one subclasses a built-in so callers may catch either.
``byte_place`` finds where in a file a bad byte is, for the message that names it."""

from __future__ import annotations

__all__ = [
    "ConfigError",
    "DeadlineFault",
    "DriverError",
    "ExperimentAborted",
    "FitError",
    "GCodeError",
    "PlanningError",
    "SimulationError",
    "TwinError",
    "ViewerError",
    "byte_place",
]


class TwinError(Exception):
    """Base of every xy-twin error."""


class ConfigError(TwinError, ValueError):
    """A configuration value is missing or invalid.

    Parameters
    ----------
    field : str
        Dotted path of the offending field, e.g. ``axes.x.mechanics.carriage_mass``.
    message : str
        What is wrong with it.
    """

    def __init__(self, field: str, message: str):
        self.field = field
        self.message = message
        super().__init__(f"{field}: {message}")


class GCodeError(TwinError, ValueError):
    """An error in a G-code program, with its place.

    Attributes
    ----------
    line : int
        1-based line number.
    column : int
        1-based column of the offending word (1 when the whole block is at fault).
    code : str
        Short machine-readable code, e.g. ``"modal-conflict"``.
    source : str
        The text of the offending line.
    file : str or None
        The file the line is in when it is not the program itself (a called subroutine's
        ``name.ngc``); None for the program.
    """

    def __init__(self, line: int, column: int, message: str, *, code: str = "syntax",
                 source: str = "", file: str | None = None):
        self.line = line
        self.column = column
        self.code = code
        self.source = source
        self.message = message
        self.file = file
        text = f"line {line}, col {column}: {message}"
        if file is not None:
            text = f"{file}, {text}"
        if source:
            shown, at = _excerpt(source.rstrip(), max(column - 1, 0))
            text += f"\n    {shown}\n    {' ' * at}^"
        super().__init__(text)


EXCERPT = 255
"""Longest source line an error shows whole (LinuxCNC's longest line); of a longer one it
shows this many characters around the column (a line of 100 000 brackets is not printed
back)."""


def _excerpt(source: str, at: int) -> tuple[str, int]:
    """The part of ``source`` an error shows, and where character ``at`` is in it."""
    if len(source) <= EXCERPT:
        return source, at
    lo = max(0, min(at - EXCERPT // 2, len(source) - EXCERPT))
    hi = lo + EXCERPT
    shown = ("…" if lo else "") + source[lo:hi] + ("…" if hi < len(source) else "")
    return shown, at - lo + (1 if lo else 0)


class PlanningError(TwinError, ValueError):
    """A motion cannot be planned within the given limits."""


class ViewerError(TwinError, RuntimeError):
    """A live rerun viewer or server cannot be started or reached (a port taken by another
    process, no display)."""


class SimulationError(TwinError, RuntimeError):
    """The simulation reached a state it cannot continue from (NaN, divergence)."""


class DriverError(TwinError, RuntimeError):
    """A hardware driver failed: timeout, lost connection, malformed response."""


class DeadlineFault(TwinError, RuntimeError):
    """A paced loop missed its deadlines beyond the machine's policy
    (``controller.deadlines``)."""


class ExperimentAborted(TwinError, RuntimeError):
    """An experiment on the machine was stopped for safety (an end switch, the drives not
    ready, the table leaving the room the experiment was given, a following error); the
    machine was brought to a safe stop."""


class FitError(TwinError, RuntimeError):
    """A fit of the twin to measurements did not converge or is not trustworthy."""


def byte_place(data: bytes, offset: int) -> tuple[int, int]:
    """Line and column (1-based) of byte ``offset`` in ``data``: where a bad byte of a
    file is, for the message that names it."""
    line = data.count(b"\n", 0, offset) + 1
    return line, offset - (data.rfind(b"\n", 0, offset) + 1) + 1
