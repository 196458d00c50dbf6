"""Where the file of a called subroutine comes from, and how it is opened.

``O<name> call`` of a name the program does not define runs ``name.ngc`` from the program's
own folder or, after it, from the subroutine folders (``controller.gcode.subroutine_path``),
the first found, as LinuxCNC's ``[RS274NGC] SUBROUTINE_PATH``. Nothing outside these
folders is ever read:

* a name that is not a plain file name (a path separator, ``..``, a colon, NUL) is refused
  before anything is looked up;
* a file found in a folder is resolved (symlinks followed) and must lie inside one of the
  folders; one that leads out of them counts as no file at all, so the message is the same
  whether a file outside exists or not;
* the file is opened by its resolved path and must still be the file that was checked
  (device and inode) every time a call opens it.

The runner (``twin.controller.gcode.flow``) reads a called file line by line from where its
body begins (``SubFile.offset``), like the main program, so a called file of any length runs
in constant memory.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import IO, NamedTuple

__all__ = ["Folders", "SubFile", "name_problem", "open_body"]

_FORBIDDEN = ("/", "\\", ":", "\0", "..")
"""What a subroutine name may not hold: it names a file in a folder, nothing else."""


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a subroutine file (None: it can)."""
    if not name:
        return "an empty subroutine name"
    bad = [part for part in _FORBIDDEN if part in name]
    if bad:
        shown = ", ".join(repr(part) if part != "\0" else "NUL" for part in bad)
        return (f"a subroutine name is a file name in the subroutine folders: it may not "
                f"hold {shown}")
    return None


class SubFile(NamedTuple):
    """A called subroutine's file, checked."""

    path: str
    """As found in its folder (for messages)."""
    real: str
    """Resolved: what is opened."""
    identity: tuple[int, int]
    """Device and inode of the file checked."""
    offset: int = 0
    """Where the body begins (a text-file position, after the ``O<name> sub`` line)."""
    first_line: int = 1
    """Line number of the body's first line."""


class Folders:
    """The folders a called file may come from, in search order.

    Parameters
    ----------
    folders : sequence of str
        The program's folder first, then the subroutine folders; those that do not exist
        are left out.
    """

    def __init__(self, folders: Sequence[str]):
        seen: dict[str, str] = {}
        for folder in folders:
            if folder and os.path.isdir(folder):
                seen.setdefault(os.path.realpath(folder), folder)
        self._real = list(seen)
        self.shown = list(seen.values())
        """The folders as given, for messages."""

    def describe(self) -> str:
        """The folders for a message."""
        return ", ".join(self.shown) or "no folder (controller.gcode.subroutine_path)"

    def _inside(self, real: str) -> bool:
        return any(real == folder or os.path.commonpath((real, folder)) == folder
                   for folder in self._real)

    def find(self, name: str) -> SubFile | None:
        """``name.ngc`` from the first folder that has it inside the folders; None when
        none has (missing, not a file, or a symlink that leads out: the same answer).
        ``name`` must pass ``name_problem``."""
        for folder in self._real:
            candidate = os.path.join(folder, f"{name}.ngc")
            try:
                real = os.path.realpath(candidate, strict=True)
                status = os.stat(real)
            except (OSError, ValueError):
                continue
            if not self._inside(real) or not os.path.isfile(real):
                continue
            shown = os.path.join(self.shown[self._real.index(folder)], f"{name}.ngc")
            return SubFile(shown, real, (status.st_dev, status.st_ino))
        return None


def open_body(sub: SubFile) -> IO[str]:
    """The file of ``sub`` opened at ``sub.offset`` (its text, line breaks as read by
    Python's universal newlines, bytes that are not UTF-8 as U+FFFD).

    Raises
    ------
    OSError
        It cannot be opened, or it is no longer the file that was checked (``ENOENT``)."""
    handle = open(sub.real, encoding="utf-8", errors="replace", newline=None)
    try:
        status = os.fstat(handle.fileno())
        if (status.st_dev, status.st_ino) != sub.identity:
            raise FileNotFoundError(f"{sub.path} was replaced while the program ran")
        if sub.offset:
            handle.seek(sub.offset)
    except BaseException:
        handle.close()
        raise
    return handle
