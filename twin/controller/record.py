"""The controller's own record of every period: preallocated, chunk-growing numpy storage.

Seed 000's rig saved each experiment's arrays (set-point and actual position, velocities,
errors, the digital correction signals) for display and analysis; ``Record`` is that store.
One row per period is written with a single slice assignment into a preallocated float64
chunk (no per-tick allocation); when a chunk is full the next one is allocated, so memory
grows in steps and a long run never copies what it already recorded. ``as_arrays`` joins
the chunks once, at the end, into named arrays.

Typical use::

    >>> rec = Record([("t", 1), ("position", 2), ("terms", (2, 5)), ("status", 1)],
    ...              integer=("status",))
    >>> rec.append((0.005, 1e-6, 2e-6, *range(10), 0))
    >>> arrays = rec.as_arrays()
    >>> {name: a.shape for name, a in arrays.items()}, arrays["status"].dtype.name
    ({'t': (1,), 'position': (1, 2), 'terms': (1, 2, 5), 'status': (1,)}, 'int64')
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Sequence

import numpy as np

from twin.errors import ConfigError

__all__ = ["BLOCK", "Record"]

BLOCK = 256
"""Rows converted to float64 at a time (see ``Record.append``)."""


class Record:
    """Rows of named float64 columns, appended once per period.

    Parameters
    ----------
    fields : sequence of (str, int or tuple of int)
        Field names and shapes, in row order. A field of width 1 comes out of ``as_arrays``
        with shape (n,), one of width w with shape (n, w), one of shape (a, b) with shape
        (n, a, b); in a row its values come flattened in C order.
    integer : iterable of str
        Fields that hold integers (block index, line, status codes); ``as_arrays`` returns
        them as int64. Stored as float64, which is exact up to 2^53.
    capacity : int
        Rows preallocated in the first chunk (and in each further chunk; a changed
        ``capacity`` applies to the chunks allocated after the change).
    """

    __slots__ = ("_chunk", "_chunks", "_fields", "_i", "_integer", "_pending", "_shapes",
                 "_slices", "_starts", "capacity", "width")

    def __init__(self, fields: Sequence[tuple[str, int | tuple[int, ...]]], *,
                 integer: Iterable[str] = (), capacity: int = 65536):
        if capacity < 1:
            raise ConfigError("capacity", f"must be >= 1 row, got {capacity}")
        names = [name for name, _ in fields]
        if len(set(names)) != len(names):
            raise ConfigError("fields", f"duplicate field names in {names}")
        self._shapes = {str(name): (int(shape),) if np.isscalar(shape) else
                        tuple(int(n) for n in shape) for name, shape in fields}
        self._fields = [(name, math.prod(shape)) for name, shape in self._shapes.items()]
        if any(min(shape, default=0) < 1 for shape in self._shapes.values()):
            raise ConfigError("fields", f"every size must be >= 1, got {self._shapes}")
        self._integer = frozenset(integer)
        unknown = self._integer.difference(names)
        if unknown:
            raise ConfigError("integer", f"not a field: {sorted(unknown)}")
        self._slices: dict[str, slice | int] = {}
        col = 0
        for name, width in self._fields:
            self._slices[name] = col if width == 1 else slice(col, col + width)
            col += width
        self.width = col
        """int: values per row."""
        self.capacity = int(capacity)
        """int: rows per chunk."""
        self._chunks: list[np.ndarray] = []
        self._starts: list[int] = []     # the row number of each chunk's first row
        self._pending: list[Sequence[float]] = []
        self._i = 0
        self._new_chunk()

    def _new_chunk(self) -> None:
        start = self._starts[-1] + self._i if self._starts else 0
        self._chunk = np.empty((self.capacity, self.width))
        self._chunks.append(self._chunk)
        self._starts.append(start)
        self._i = 0

    @property
    def first(self) -> int:
        """The first row still held (0 unless rows were released)."""
        return self._starts[0]

    @property
    def fields(self) -> list[tuple[str, tuple[int, ...]]]:
        """Field names and shapes, in row order."""
        return list(self._shapes.items())

    def __len__(self) -> int:
        return self._starts[-1] + self._i + len(self._pending)

    def append(self, row: Sequence[float]) -> None:
        """Store one row of ``width`` values (in field order, wide fields flattened).

        Rows wait in a short list and go into the float64 chunks ``BLOCK`` at a time: one
        conversion of a block costs a fraction of converting each row on its own, and this
        runs once per controller period. Every reader sees the waiting rows.
        """
        pending = self._pending
        pending.append(row)
        if len(pending) >= BLOCK:
            self._commit()

    def slot(self) -> tuple[np.ndarray, int]:
        """Where the next row goes, for a writer that fills it in place (the compiled tick):
        ``(chunk, i)``, the row ``chunk[i]``; ``advance()`` then counts it. Waiting rows are
        moved in first, so the order of rows is kept."""
        if self._pending:
            self._commit()
        if self._i == len(self._chunk):
            self._new_chunk()
        return self._chunk, self._i

    def advance(self) -> None:
        """Count the row written at ``slot()``."""
        self._i += 1

    def _commit(self) -> None:
        """Move the waiting rows into the chunks."""
        if not self._pending:
            return
        rows = np.array(self._pending, dtype=np.float64)
        if rows.ndim != 2 or rows.shape[1] != self.width:
            self._pending.clear()
            raise ConfigError("row", f"each row must hold {self.width} values, got rows of "
                              f"shape {rows.shape[1:]}")
        self._pending.clear()
        i = 0
        while i < len(rows):
            if self._i == len(self._chunk):
                self._new_chunk()
            k = min(len(rows) - i, len(self._chunk) - self._i)
            self._chunk[self._i:self._i + k] = rows[i:i + k]
            self._i += k
            i += k

    def clear(self) -> None:
        """Forget every row and keep one chunk."""
        self._chunks = [self._chunk]
        self._starts = [0]
        self._i = 0
        self._pending.clear()

    def release(self, upto: int) -> None:
        """Free the chunks whose rows all lie before row ``upto`` (the current chunk is
        kept). Row numbers do not change; rows before :attr:`first` can no longer be read.
        A run that streams its record (telemetry, a running summary) releases what it has
        consumed, so its memory does not grow with its length."""
        keep = 0
        while keep < len(self._chunks) - 1 and self._starts[keep + 1] <= upto:
            keep += 1
        if keep:
            del self._chunks[:keep], self._starts[:keep]

    def table(self, start: int = 0) -> np.ndarray:
        """Rows ``start`` … end as one (n − start, width) float64 array (a copy).

        Only the chunks that hold those rows are touched, so reading what was appended since
        the last read (``start = previous length``) costs the new rows, not the whole run.

        Raises
        ------
        ValueError
            If ``start`` lies before :attr:`first` (those rows were released).
        """
        self._commit()
        start = max(int(start), 0)
        if start < self.first:
            raise ValueError(f"rows before {self.first} were released; asked from {start}")
        if start >= len(self):
            return np.empty((0, self.width))
        first = bisect.bisect_right(self._starts, start) - 1
        parts = [*self._chunks[first:-1], self._chunk[: self._i]]
        parts[0] = parts[0][start - self._starts[first]:]
        if len(parts) == 1:
            return parts[0].copy()
        return np.concatenate(parts, axis=0)

    def as_arrays(self, start: int = 0) -> dict[str, np.ndarray]:
        """Every field as its own array, shape (n, *shape) or (n,); integer fields int64.

        Parameters
        ----------
        start : int
            First row to return (default all rows).
        """
        table = self.table(start)
        out: dict[str, np.ndarray] = {}
        for name, width in self._fields:
            col = table[:, self._slices[name]]
            if width > 1 and len(self._shapes[name]) > 1:
                col = col.reshape(len(table), *self._shapes[name])
            out[name] = (col.astype(np.int64) if name in self._integer
                         else np.ascontiguousarray(col))
        return out
