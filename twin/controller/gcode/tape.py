"""The lines of a program, read forward, with the jumps back its loops need.

A ``Tape`` keeps lines in memory only from the oldest held mark on (the start of a loop that
is running), so a program without loops streams in constant memory.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["Tape"]


class Tape:
    """Lines of a program, read forward, that can go back to any line still ``mark``-ed.

    Lines are kept from the oldest mark on, and only while a mark is held.
    """

    __slots__ = ("_base", "_buffer", "_last", "_lines", "_marks", "first_line", "pos")

    def __init__(self, lines: Iterable[str], first_line: int = 1):
        self._lines = iter(lines)
        self._buffer: list[str] = []
        self._base = 0
        self._marks: list[int] = []
        self._last = ""
        self.pos = 0
        """Index of the next line."""
        self.first_line = first_line
        """Line number of index 0."""

    def next(self) -> str | None:
        """The next line without its line break; None at the end."""
        pos, base = self.pos, self._base
        if pos < base + len(self._buffer):
            text = self._buffer[pos - base]
        else:
            raw = next(self._lines, None)
            if raw is None:
                return None
            text = raw.rstrip("\r\n")
            if self._marks:
                self._buffer.append(text)
            else:
                if self._buffer:
                    self._buffer.clear()
                self._base = pos + 1
        self._last = text
        self.pos = pos + 1
        return text

    def mark(self, pos: int) -> None:
        """Hold line ``pos`` (the line read last, or a later one) for a later ``seek``."""
        if not self._marks and not self._buffer:
            self._base = self.pos
        if pos == self._base - 1 == self.pos - 1:
            self._buffer.insert(0, self._last)
            self._base = pos
        if pos < self._base:
            raise RuntimeError("a tape can only mark lines it still holds")
        self._marks.append(pos)

    def release(self, pos: int) -> None:
        self._marks.remove(pos)
        keep = min(self._marks, default=self.pos)
        if keep > self._base:
            del self._buffer[:keep - self._base]
            self._base = keep

    def seek(self, pos: int) -> None:
        if not self._base <= pos <= self._base + len(self._buffer):
            raise RuntimeError("seek to a line the tape does not hold")
        self.pos = pos

    @property
    def line(self) -> int:
        """Line number of the line read last."""
        return self.first_line + self.pos - 1
