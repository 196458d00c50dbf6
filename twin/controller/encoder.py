"""Encoder counters: unwrapping of the hardware counter and counts ↔ metres.

The reference rig counts encoder pulses in 32-bit hardware counters that wrap around
(seed 000). The controller never uses a raw counter value as a position: it accumulates the
*difference* of two successive samples, taken modulo the counter width,

    delta = ((raw − last + 2^(b−1)) mod 2^b) − 2^(b−1),

which is correct as long as the axis moves less than half the counter range (2^31 counts,
about 430 m on the rig) in one period. Counts become metres exactly once, here.

Typical use (y's 32-bit counter wraps between the two samples, and is unwrapped)::

    >>> import numpy as np
    >>> enc = EncoderUnwrapper(counts_per_metre=(5e6, 5e6), bits=32)
    >>> enc.reset(np.array([100, 2**32 - 50]), position=(0.0, 0.0))
    >>> enc.update(np.array([600, 50])).tolist()     # (2,) m, every period
    [0.0001, 2e-05]
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from twin.errors import ConfigError

__all__ = [
    "EncoderUnwrapper",
    "counts_to_metres",
    "metres_to_counts",
    "unwrap_delta",
]


def unwrap_delta(raw: int, last: int, bits: int = 32) -> int:
    """Signed difference of two samples of a ``bits``-wide wrapping counter (counts).

    Parameters
    ----------
    raw, last : int
        The new and the previous counter value (counts); any integers, taken modulo 2^bits.
    bits : int
        Counter width (bit).

    Returns
    -------
    int
        ``((raw − last + 2^(b−1)) mod 2^b) − 2^(b−1)``, in [−2^(b−1), 2^(b−1)).
    """
    half = 1 << (bits - 1)
    return ((int(raw) - int(last) + half) % (half << 1)) - half


def counts_to_metres(counts: float | np.ndarray, counts_per_metre: float | np.ndarray
                     ) -> float | np.ndarray:
    """Convert encoder counts to table position (m)."""
    return np.asarray(counts, dtype=float) / counts_per_metre


def metres_to_counts(position: float | np.ndarray, counts_per_metre: float | np.ndarray
                     ) -> np.ndarray:
    """Convert a table position (m) to the nearest whole encoder count (counts, int64)."""
    return np.rint(np.asarray(position, dtype=float) * counts_per_metre).astype(np.int64)


class EncoderUnwrapper:
    """Turns raw wrapping counter samples of all axes into continuous positions (m).

    Parameters
    ----------
    counts_per_metre : sequence of float, one per axis
        Encoder counts per metre of table travel (counts/m).
    bits : int or sequence of int
        Counter width per axis (bit), 8 … 64.

    Notes
    -----
    The state is two small arrays the compiled tick (``cyclic.steady_tick``) shares:
    ``state_int`` (3, n) int64 holds the last raw sample, the unwrapped count and the counter
    width, ``state_float`` (2, n) the origin (m) and counts per metre. The count is int64:
    it overflows after 2^63 counts, 1.8·10^12 m at the rig's resolution. The last sample is
    kept modulo 2^bits in int64's signed range (only its residue matters). The position is
    ``origin + count / counts_per_metre``. ``update`` is on the cyclic path and uses scalar
    arithmetic only (no array allocation beyond the result).
    """

    __slots__ = ("_bits", "_cpm", "_ready", "position", "state_float", "state_int")

    def __init__(self, counts_per_metre: Sequence[float], *, bits: int | Sequence[int] = 32):
        cpm = [float(c) for c in counts_per_metre]
        if not cpm or any(not np.isfinite(c) or c <= 0 for c in cpm):
            raise ConfigError("counts_per_metre", f"must be finite and > 0, got {cpm}")
        n = len(cpm)
        bit_list = [int(bits)] * n if np.isscalar(bits) else [int(b) for b in bits]
        if len(bit_list) != n:
            raise ConfigError("bits", f"needs one width per axis ({n}), got {len(bit_list)}")
        for b in bit_list:
            if not 8 <= b <= 64:
                raise ConfigError("bits", f"must be in 8 … 64, got {b}")
        self._cpm = cpm
        self._bits = bit_list
        self.state_int = np.zeros((3, n), dtype=np.int64)
        """ndarray (3, n) int64: last raw sample, unwrapped count, counter width (bit)."""
        self.state_int[2] = bit_list
        self.state_float = np.zeros((2, n))
        """ndarray (2, n): origin (m), counts per metre."""
        self.state_float[1] = cpm
        self._ready = False
        self.position = np.zeros(n)
        """ndarray, shape (n,): the latest unwrapped position (m), updated in place."""

    @property
    def counts_per_metre(self) -> tuple[float, ...]:
        """Encoder counts per metre, per axis (counts/m)."""
        return tuple(self._cpm)

    @property
    def ready(self) -> bool:
        """True once a first sample has been taken (by ``reset`` or ``update``)."""
        return self._ready

    @property
    def counts(self) -> tuple[int, ...]:
        """Unwrapped counts accumulated since ``reset`` (counts)."""
        return tuple(int(c) for c in self.state_int[1])

    def reset(self, raw: Sequence[int], *, position: Sequence[float] | None = None) -> None:
        """Take ``raw`` as the reference sample and declare the table to be at ``position``.

        Parameters
        ----------
        raw : sequence of int
            Current raw counter values (counts).
        position : sequence of float, optional
            Table position at this sample (m); default zero on every axis.
        """
        n = len(self._cpm)
        pos = [0.0] * n if position is None else [float(p) for p in position]
        st = self.state_int
        for k in range(n):
            last = int(raw[k]) % (1 << self._bits[k])
            st[0, k] = last - (1 << 64) if last >= 1 << 63 else last
            st[1, k] = 0
            self.state_float[0, k] = pos[k]
            self.position[k] = pos[k]
        self._ready = True

    def rebase(self, offset: Sequence[float]) -> None:
        """Shift the coordinate frame by ``offset`` (m): every later position is larger by it.

        Used by homing: the position latched when the home switch closed is declared to be
        the configured home position.
        """
        for k in range(len(self._cpm)):
            self.state_float[0, k] += float(offset[k])
            self.position[k] += float(offset[k])

    def update(self, raw: Sequence[int]) -> np.ndarray:
        """Accumulate a new sample and return the position of every axis (m).

        The first call without a prior ``reset`` takes ``raw`` as the zero position.

        Parameters
        ----------
        raw : sequence of int
            Raw counter values (counts), as read from the hardware.

        Returns
        -------
        ndarray, shape (n,)
            ``self.position``, updated in place (m).
        """
        if not self._ready:
            self.reset(raw)
            return self.position
        pos, st, origin = self.position, self.state_int, self.state_float[0]
        for k in range(len(self._cpm)):
            r = int(raw[k])
            half = 1 << (self._bits[k] - 1)
            count = int(st[1, k]) + ((r - int(st[0, k]) + half) % (half << 1)) - half
            st[1, k] = count
            st[0, k] = r
            pos[k] = float(origin[k]) + count / self._cpm[k]
        return pos
