"""The Modbus register map of a two-axis I/O module: which signal lives at which address,
how values are scaled, and how one tick's I/O packs into the fewest requests.

The map is a TOML file validated on load (every error a ``ConfigError`` naming the dotted
field); the default, ``register_map.toml`` beside this module, documents the layout as a
table. Both ends use this module: the driver (``twin.hardware.modbus``) and the twin standing
in for the module (``twin.hardware.hil``), so they cannot disagree on a scale or word order.

Encodings (the conversions to and from SI happen here, once):

* encoder counters: unsigned 32-bit in two consecutive input registers, high word first
  (``word_order = "high_first"``, "ABCD") or low word first;
* DAC outputs: the axis DAC's own code (``axes.<axis>.dac``: ``bits`` ≤ 16 and
  ``full_scale``, the one setting of it), left-justified in an int16 register as a DAC
  module holds it: word = code·2^(16 − bits), so ``−32768`` = ``−full_scale`` and the top
  code is one LSB below ``+full_scale``. The driver quantises the volts to that code, the
  only quantisation between the controller and the drive (``dac_word``, ``dac_volts``);
* tacho inputs: int16 two's complement, ``±32767`` = ``±tacho_full_scale`` volts (the
  module's ADC range), rounded to the nearest code and clipped to ``±32767``;
* switches, drive ready and the watchdog trip: discrete inputs, 1 = actuated / true;
  the drive enable: a coil.

Typical use::

    rmap = load_register_map()                      # the documented default
    rmap = load_register_map("my_module.toml")
    for start, count in rmap.input_spans():         # one read_input_registers each
        ...
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, from_dict, read_toml
from twin.errors import ConfigError

__all__ = [
    "DEFAULT_MAP",
    "INT16_FULL",
    "MAPS",
    "MAX_READ_BITS",
    "MAX_READ_REGISTERS",
    "MAX_WRITE_REGISTERS",
    "WORD_ORDERS",
    "AxisRegisters",
    "ModuleSettings",
    "RegisterMap",
    "accelerometer_samples",
    "accelerometer_words",
    "check_dacs",
    "counter_to_words",
    "dac_volts",
    "dac_word",
    "load_register_map",
    "register_map_from_dict",
    "volts_to_word",
    "word_to_volts",
    "words_to_counter",
]

DEFAULT_MAP = Path(__file__).resolve().with_name("register_map.toml")
"""The documented default map."""

INT16_FULL = 32767
"""Register value of +full scale (int16 codes; −32767 is −full scale)."""

MAX_READ_REGISTERS = 125
"""Modbus limit of one read of input or holding registers (function codes 3, 4)."""
MAX_READ_BITS = 2000
"""Modbus limit of one read of discrete inputs or coils (function codes 1, 2)."""
MAX_WRITE_REGISTERS = 123
"""Modbus limit of one write of multiple registers (function code 16)."""

WORD_ORDERS = ("high_first", "low_first")
"""Word orders of a 32-bit counter in two registers (each register is big-endian)."""

_ADDRESS_MAX = 65535


def _check_address(value: int | None, name: str, *, width: int = 1) -> None:
    if value is not None and not 0 <= value <= _ADDRESS_MAX - (width - 1):
        raise ConfigError(name, f"must be an address in 0 … {_ADDRESS_MAX - (width - 1)}, "
                          f"got {value}")


@dataclass(frozen=True)
class AxisRegisters:
    """Addresses of one axis's signals (0-based protocol addresses).

    Attributes
    ----------
    encoder : int
        Input registers ``encoder`` and ``encoder + 1``: the 32-bit counter (counts).
    dac : int
        Holding register: the analog speed reference (int16 code of volts).
    limit_min, limit_max : int
        Discrete inputs: end limit switches (1 = actuated).
    tacho : int or None
        Input register: tacho voltage (int16 code of volts); None: not wired (reads 0 V).
    home : int or None
        Discrete input: home switch; None: not wired (reads open).
    drive_ready : int or None
        Discrete input: the drive reports no fault; None: not wired (always ready).
    """

    encoder: int
    dac: int
    limit_min: int
    limit_max: int
    tacho: int | None = None
    home: int | None = None
    drive_ready: int | None = None

    def __post_init__(self) -> None:
        _check_address(self.encoder, "encoder", width=2)
        for name in ("dac", "limit_min", "limit_max", "tacho", "home", "drive_ready"):
            _check_address(getattr(self, name), name)


@dataclass(frozen=True)
class ModuleSettings:
    """Module-wide signals and encodings.

    Attributes
    ----------
    enable : int
        Coil: drive enable of both drives.
    watchdog : int
        Holding register the driver writes with a new value every tick (a life counter).
    device_id : int
        Modbus unit identifier, 0 … 247.
    word_order : {"high_first", "low_first"}
        Order of the two 16-bit words of a 32-bit counter.
    tacho_full_scale : float
        Volts at register value +32767 of the tacho inputs (V). The DAC outputs' scale is
        each axis' DAC (``axes.<axis>.dac``), not the map's.
    watchdog_tripped : int or None
        Discrete input: the module's watchdog zeroed the outputs (latched); None: not
        reported.
    status : int or None
        Input register that packs every discrete input as a bit (bit n = discrete input n,
        so those addresses must be 0 … 15): the driver reads the switches with the counters
        in one request. None: they are read from the discrete inputs.
    control : int or None
        Holding register whose bit 0 is the drive enable (the coil's twin): the driver
        writes it with the references and the watchdog in one request. None: the coil.
    accelerometer : int or None
        First of the table accelerometer's input registers (``[accelerometer]`` of the
        machine): its FIFO as one read takes it, which empties it. Register +0: the
        samples read (bits 0-14) and bit 15 set when samples were lost since the last
        read; +1: the sensor's sample number of the first of them (its low 16 bits); +2:
        where in the sensor's sample interval the read fell (0 … 65535 for 0 … 1, the
        time stamp that places the read on the sensor's clock); then
        ``accelerometer_block`` pairs x, y (int16, counts of ``accelerometer_lsb``).
        None: no accelerometer.
    accelerometer_block : int
        FIFO depth the registers hold (samples), 1 … 56 (one read of 125 registers).
    accelerometer_lsb : float
        m/s² per count of the accelerometer's registers.
    """

    enable: int
    watchdog: int
    device_id: int = 1
    word_order: str = "high_first"
    tacho_full_scale: float = 10.24
    watchdog_tripped: int | None = None
    status: int | None = None
    control: int | None = None
    accelerometer: int | None = None
    accelerometer_block: int = 32
    accelerometer_lsb: float = 0.0383

    def __post_init__(self) -> None:
        for name in ("enable", "watchdog", "watchdog_tripped", "status", "control"):
            _check_address(getattr(self, name), name)
        if not 1 <= self.accelerometer_block <= 56:
            raise ConfigError("accelerometer_block", f"must be 1 … 56 samples, got "
                              f"{self.accelerometer_block}")
        _check_address(self.accelerometer, "accelerometer", width=self.accelerometer_words)
        if not (math.isfinite(self.accelerometer_lsb) and self.accelerometer_lsb > 0):
            raise ConfigError("accelerometer_lsb", f"must be > 0 m/s², got "
                              f"{self.accelerometer_lsb}")
        if not 0 <= self.device_id <= 247:
            raise ConfigError("device_id", f"must be 0 … 247, got {self.device_id}")
        if self.word_order not in WORD_ORDERS:
            raise ConfigError("word_order", f"must be one of {', '.join(WORD_ORDERS)}, got "
                              f"{self.word_order!r}")
        value = self.tacho_full_scale
        if not (math.isfinite(value) and value > 0):
            raise ConfigError("tacho_full_scale", f"must be > 0 V, got {value}")

    @property
    def accelerometer_words(self) -> int:
        """Input registers the accelerometer takes: 3 + 2·block."""
        return 3 + 2 * self.accelerometer_block


_TABLES = ("input registers", "holding registers", "discrete inputs", "coils")
"""The four Modbus tables, in the order of ``RegisterMap.signals``."""


@dataclass(frozen=True)
class RegisterMap:
    """A validated register map (see the module docstring and ``register_map.toml``).

    Attributes
    ----------
    module : ModuleSettings
    axes : dict of str to AxisRegisters
        Exactly the axes ``x`` and ``y``.
    source : str
        Where the map came from (a path, or ``<dict>``).
    """

    module: ModuleSettings
    axes: dict[str, AxisRegisters]
    source: str = field(default="<dict>", compare=False)

    def __post_init__(self) -> None:
        if sorted(self.axes) != sorted(AXES):
            raise ConfigError("axes", f"must have exactly the axes {', '.join(AXES)}, got "
                              f"{', '.join(sorted(self.axes)) or 'none'}")
        for table, entries in zip(_TABLES, self.signals(), strict=True):
            owner: dict[int, str] = {}
            for name, address, width in entries:
                for a in range(address, address + width):
                    if a in owner:
                        raise ConfigError(name, f"{table[:-1]} {a} is already used by "
                                          f"{owner[a]}")
                    owner[a] = name
        if self.module.status is not None:
            for name, address, _ in self.signals()[2]:
                if address > 15:
                    raise ConfigError(name, f"discrete input {address} cannot be a bit of "
                                      "the status register (module.status packs inputs "
                                      "0 … 15)")

    def signals(self) -> tuple[list[tuple[str, int, int]], ...]:
        """Mapped signals per table (input registers, holding registers, discrete inputs,
        coils): lists of (dotted field name, first address, number of addresses)."""
        ir: list[tuple[str, int, int]] = []
        hr: list[tuple[str, int, int]] = []
        di: list[tuple[str, int, int]] = []
        for a in AXES:
            ax, p = self.axes[a], f"axes.{a}."
            ir.append((p + "encoder", ax.encoder, 2))
            if ax.tacho is not None:
                ir.append((p + "tacho", ax.tacho, 1))
            hr.append((p + "dac", ax.dac, 1))
            di += [(p + n, getattr(ax, n), 1) for n in ("limit_min", "limit_max", "home",
                                                        "drive_ready")
                   if getattr(ax, n) is not None]
        m = self.module
        hr.append(("module.watchdog", m.watchdog, 1))
        if m.status is not None:
            ir.append(("module.status", m.status, 1))
        if m.control is not None:
            hr.append(("module.control", m.control, 1))
        if m.accelerometer is not None:
            ir.append(("module.accelerometer", m.accelerometer, m.accelerometer_words))
        if m.watchdog_tripped is not None:
            di.append(("module.watchdog_tripped", m.watchdog_tripped, 1))
        return ir, hr, di, [("module.enable", m.enable, 1)]

    def input_spans(self) -> list[tuple[int, int]]:
        """(start, count) of the fewest input-register reads covering every mapped input
        register (a read spans the gaps between them)."""
        return _spans(self.signals()[0], MAX_READ_REGISTERS)

    def discrete_spans(self) -> list[tuple[int, int]]:
        """(start, count) of the fewest discrete-input reads covering the mapped inputs."""
        return _spans(self.signals()[2], MAX_READ_BITS)

    def holding_runs(self) -> list[tuple[int, tuple[str, ...]]]:
        """Contiguous runs of mapped holding registers, each one write_registers request:
        (start address, dotted names in address order). Gaps are never written."""
        runs: list[tuple[int, list[str]]] = []
        for name, address, _ in sorted(self.signals()[1], key=lambda s: s[1]):
            if runs and address == runs[-1][0] + len(runs[-1][1]) \
                    and len(runs[-1][1]) < MAX_WRITE_REGISTERS:
                runs[-1][1].append(name)
            else:
                runs.append((address, [name]))
        return [(start, tuple(names)) for start, names in runs]

    def describe(self) -> list[tuple[str, str, str, str]]:
        """The map as a table: (Modbus table, address(es), signal, encoding) rows."""
        m = self.module
        enc = {"encoder": f"uint32 counts, {m.word_order.replace('_', ' word ')}",
               "tacho": f"int16, ±{INT16_FULL} = ±{m.tacho_full_scale:g} V",
               "dac": "int16, the axis DAC's code·2^(16 − bits), −32768 = −full scale "
                      "(axes.<axis>.dac)",
               "watchdog": "uint16, a new value every tick",
               "enable": "1 = drives enabled", "watchdog_tripped": "1 = outputs zeroed",
               "status": "bit n = discrete input n", "control": "bit 0 = drive enable",
               "drive_ready": "1 = no drive fault",
               "accelerometer": f"count (bit 15: lost), first sample number, phase of "
                                f"the read in 1/65536 of a sample, then "
                                f"{m.accelerometer_block} × (x, y) int16 of "
                                f"{m.accelerometer_lsb:g} m/s²"}
        rows = []
        for table, entries in zip(_TABLES, self.signals(), strict=True):
            for name, address, width in sorted(entries, key=lambda s: s[1]):
                where = str(address) if width == 1 else f"{address}-{address + width - 1}"
                rows.append((table, where, name, enc.get(name.rsplit(".", 1)[1],
                                                         "1 = actuated")))
        return rows


def _spans(entries: list[tuple[str, int, int]], limit: int) -> list[tuple[int, int]]:
    """Greedy cover of the occupied addresses by reads of at most ``limit`` addresses (a
    signal is never split between two reads)."""
    spans: list[list[int]] = []
    for _, address, width in sorted(entries, key=lambda s: s[1]):
        if spans and address + width - spans[-1][0] <= limit:
            spans[-1][1] = max(spans[-1][1], address + width - spans[-1][0])
        else:
            spans.append([address, width])
    return [(s, c) for s, c in spans]


def register_map_from_dict(doc: dict[str, Any], *, source: str = "<dict>") -> RegisterMap:
    """Validate a parsed map document (``[module]``, ``[axes.x]``, ``[axes.y]``)."""
    names = {f.name for f in fields(RegisterMap) if f.name != "source"}
    for key in doc:
        if key not in names:
            raise ConfigError(key, f"unknown key; valid: {', '.join(sorted(names))}")
    module = doc.get("module")
    if isinstance(module, dict) and "dac_full_scale" in module:
        raise ConfigError("module.dac_full_scale", "the DAC's range is the machine's "
                          "(axes.<axis>.dac.full_scale and .bits), one setting per axis: "
                          "remove it from the register map")
    rmap = from_dict(RegisterMap, doc)
    return RegisterMap(rmap.module, rmap.axes, source)


MAPS = {"default": DEFAULT_MAP, "packed": DEFAULT_MAP.with_name("register_map_packed.toml"),
        "accelerometer": DEFAULT_MAP.with_name("register_map_accelerometer.toml")}
"""The shipped maps by name: ``default`` (three requests per tick), ``packed`` (two:
the switches in a status register, the enable in a control register) and
``accelerometer`` (the default with the table accelerometer's registers)."""


def load_register_map(path: str | Path | None = None) -> RegisterMap:
    """Load and validate a register map TOML file, or a shipped map by name (``MAPS``;
    default: the documented default map).

    Raises
    ------
    ConfigError
        If the file is missing or not TOML (field ``register_map``), or a field is missing,
        of the wrong type, out of range or overlapping another signal (its dotted name).
    """
    p = DEFAULT_MAP if path is None else MAPS.get(str(path), Path(path))
    if not p.is_file():
        raise ConfigError("register_map", f"no such file: {str(p)!r}")
    return register_map_from_dict(read_toml(p, "register_map"), source=str(p))


# ---------------------------------------------------------------------------- encodings
def volts_to_word(volts: float, full_scale: float) -> int:
    """Register value (0 … 65535, int16 two's complement) of ``volts`` (V): the nearest
    code, clipped to ±32767; NaN gives 0."""
    if not math.isfinite(volts):
        return 0 if math.isnan(volts) else (INT16_FULL if volts > 0 else -INT16_FULL) & 0xFFFF
    code = math.floor(volts * (INT16_FULL / full_scale) + 0.5)
    return max(-INT16_FULL, min(INT16_FULL, code)) & 0xFFFF


DAC_WORD_BITS = 16
"""Width of a DAC register: an axis DAC of up to this many bits fits."""


def check_dacs(dacs: dict[str, Any]) -> None:
    """Check that every axis' DAC (``{axis: DacConfig}``) fits a 16-bit DAC register.

    Raises
    ------
    ConfigError
        ``axes.<axis>.dac.bits``, when it does not."""
    for a, dac in dacs.items():
        if dac.bits > DAC_WORD_BITS:
            raise ConfigError(f"axes.{a}.dac.bits", f"a DAC of {dac.bits} bits does not fit "
                              f"the I/O module's {DAC_WORD_BITS}-bit DAC registers")


def dac_word(volts: float, full_scale: float, bits: int) -> int:
    """Register value (0 … 65535) of ``volts`` (V) on a ``bits``-bit DAC spanning
    ±``full_scale``: the nearest code ``floor(volts/lsb + 1/2)``, clipped to the DAC's range
    (NaN: code 0), left-justified: code·2^(16 − bits), int16 two's complement."""
    half = 1 << (bits - 1)
    if math.isnan(volts):
        code = 0
    elif math.isinf(volts):
        code = half - 1 if volts > 0 else -half
    else:
        code = max(-half, min(half - 1, math.floor(volts * (half / full_scale) + 0.5)))
    return (code << (DAC_WORD_BITS - bits)) & 0xFFFF


def dac_volts(word: int, full_scale: float, bits: int) -> float:
    """Volts (V) of a DAC register value (0 … 65535): its code times the LSB (the bits below
    the DAC's resolution are ignored, as a DAC module does)."""
    signed = word - 0x10000 if word & 0x8000 else word
    return (signed >> (DAC_WORD_BITS - bits)) * (full_scale / (1 << (bits - 1)))


def word_to_volts(word: int, full_scale: float) -> float:
    """Volts (V) of an int16 register value (0 … 65535)."""
    code = word - 0x10000 if word & 0x8000 else word
    return code * (full_scale / INT16_FULL)


def counter_to_words(count: int, word_order: str = "high_first") -> tuple[int, int]:
    """The two registers of a 32-bit counter value (taken modulo 2³²), in address order."""
    c = int(count) & 0xFFFFFFFF
    high, low = c >> 16, c & 0xFFFF
    return (high, low) if word_order == "high_first" else (low, high)


def words_to_counter(first: int, second: int, word_order: str = "high_first") -> int:
    """The unsigned 32-bit counter value (counts) of two registers in address order."""
    high, low = (first, second) if word_order == "high_first" else (second, first)
    return (high << 16) | low


def accelerometer_words(count: int, first: int, lost: bool, samples: np.ndarray,
                        lsb: float, block: int, phase: float = 0.0) -> list[int]:
    """The accelerometer's registers (``ModuleSettings.accelerometer``) for ``count``
    samples (m/s², rows x, y) from sample number ``first``, read at ``phase`` (0 … 1) of
    the sensor's sample interval."""
    words = [(count & 0x7FFF) | (0x8000 if lost else 0), first & 0xFFFF,
             min(int(phase * 65536.0), 0xFFFF)]
    codes = np.zeros((block, 2), dtype=np.int64)
    if count:
        codes[:count] = np.clip(np.rint(samples[:count] / lsb), -32768, 32767)
    words += [int(c) & 0xFFFF for c in codes.ravel()]
    return words


def accelerometer_samples(words: list[int], lsb: float, block: int
                          ) -> tuple[int, int, bool, float, np.ndarray]:
    """(count, the low 16 bits of the first sample number, samples lost, the read's phase
    (0 … 1), samples (block, 2) m/s²) from the accelerometer's registers."""
    head = int(words[0])
    codes = np.array(words[3:3 + 2 * block], dtype=np.int64).reshape(block, 2)
    codes = np.where(codes >= 0x8000, codes - 0x10000, codes)
    return (head & 0x7FFF, int(words[1]), bool(head & 0x8000), int(words[2]) / 65536.0,
            codes * lsb)
