"""``ModbusDriver``: a two-axis I/O module over Modbus/TCP behind the ``MachineIO`` port.

A PC-based retrofit reads encoder counters, tacho voltages and switches and writes analog
speed references through an I/O module; this driver talks to such a module (or to the twin
standing in for one, ``twin hil-server``) with the pymodbus client. Which signal lives where
is the register map (``twin.hardware.register_map``).

One tick is as few requests as the map allows — with the default map three, with the
``packed`` map (``?map=packed``: the switches in a status register, the enable in a control
register beside the references) two:

* ``read``: one ``read_input_registers`` (counters + tachos), one ``read_discrete_inputs``
  (switches, drive ready, watchdog trip);
* ``write``: one ``write_registers`` per contiguous run of holding registers (DACs + the
  watchdog life counter, incremented every tick), and the enable coil only when it changes
  (cleared before the references when disabling, set after them when enabling).

Failures are ``DriverError`` naming the request and what was wrong: no answer within
``timeout``, the connection lost (after ``reconnects`` attempts to re-establish it), a
Modbus exception response, or a garbled, short or mismatched answer. After a failure the
driver refuses further I/O; ``close`` still tries to leave the module safe (references zero,
drives disabled). Opening the driver puts the module in that safe state as well, which also
acknowledges a latched watchdog trip.

Typical use::

    drv = ModbusDriver("127.0.0.1", 5020, timeout=0.02)
    inputs = drv.read()
    drv.write(Outputs(dac_volts=np.array([0.5, 0.0]), enable=True))
    drv.close()
"""

from __future__ import annotations

import contextlib
import logging
import math
import socket
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any, NoReturn

import numpy as np
from pymodbus.client import ModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from twin.config import AXES, DacConfig
from twin.controller.io import Inputs, Outputs
from twin.errors import ConfigError, DriverError
from twin.hardware.register_map import (
    RegisterMap,
    accelerometer_samples,
    check_dacs,
    dac_word,
    load_register_map,
    word_to_volts,
    words_to_counter,
)

__all__ = ["ModbusDriver"]

_FC_READ_DISCRETE, _FC_READ_INPUT, _FC_WRITE_COIL, _FC_WRITE_REGISTERS = 2, 4, 5, 16


@contextlib.contextmanager
def _quiet_pymodbus() -> Iterator[None]:
    """Hold pymodbus's own error log while the driver retries (it reports failures itself
    as ``DriverError``)."""
    log = logging.getLogger("pymodbus.logging")
    level = log.level
    log.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        log.setLevel(level)


class ModbusDriver:
    """``MachineIO`` over Modbus/TCP (see the module docstring).

    Parameters
    ----------
    host : str
        Module address (``127.0.0.1`` for the twin on this machine).
    port : int
        TCP port (502 on a real module; 5020 for ``twin hil-server`` by default).
    register_map : RegisterMap, optional
        Default: the documented default map.
    timeout : float
        Time to wait for each answer (s). The loop cannot use an answer later than about a
        period, and a silent module must be noticed quickly.
    retries : int
        Re-sends of a request after a timeout within the same tick.
    reconnects : int
        Attempts to re-establish a lost connection before the request fails (0: fail at
        once; a position loop that lost its module should stop, not wait).
    connect_timeout : float
        How long opening keeps trying to connect (s): the module may still be starting.
    counts_per_s : sequence of 2 float, optional
        The fastest each counter may plausibly move (counts/s; ``open_driver`` gives twice
        the axis' top speed). A larger step between two reads is a ``DriverError`` naming
        the axis (Modbus/TCP carries no checksum). None: unchecked.
    counter_bits : sequence of 2 int
        Width of each counter (bits), for its wrap-around.
    dacs : sequence of 2 DacConfig, optional
        Each axis' DAC (``axes.<axis>.dac``: full scale and bits, the one setting of it):
        the volts written are quantised to its code here, once (``register_map.dac_word``).
        Default: the default DAC (±10 V, 12 bits).

    Attributes
    ----------
    map : RegisterMap
    timeout : float
        Answer timeout (s).
    reconnects : int
    requests : int
        Modbus requests sent so far (a tick of the default map costs three).
    url : str
        ``modbus://host:port``, for messages.

    Raises
    ------
    ConfigError
        An option out of range (naming it).
    DriverError
        The module cannot be reached within ``connect_timeout`` or refuses the safe state.

    Notes
    -----
    ``Inputs.time`` is this driver's clock: seconds since it connected.
    """

    def __init__(self, host: str, port: int = 502, *, register_map: RegisterMap | None = None,
                 timeout: float = 0.02, retries: int = 0, reconnects: int = 0,
                 connect_timeout: float = 2.0, counts_per_s: Sequence[float] | None = None,
                 counter_bits: Sequence[int] = (32, 32),
                 dacs: Sequence[DacConfig] | None = None):
        for name, value in (("timeout", timeout), ("connect_timeout", connect_timeout)):
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(name, f"must be > 0 s, got {value}")
        for name, count in (("retries", retries), ("reconnects", reconnects)):
            if count < 0:
                raise ConfigError(name, f"must be >= 0, got {count}")
        self.url = f"modbus://{host}:{port}"
        self._address = (host, port)
        self.map = register_map or load_register_map()
        dacs = list(dacs) if dacs is not None else [DacConfig(), DacConfig()]
        check_dacs(dict(zip(AXES, dacs, strict=True)))
        self._dacs = [(d.full_scale, d.bits) for d in dacs]
        self.timeout = timeout
        self.reconnects = reconnects
        self.requests = 0
        self._unit = self.map.module.device_id
        self._rx = b""  # what arrived since the last request was sent
        self._client = ModbusTcpClient(host, port=port, timeout=timeout, retries=retries,
                                       reconnect_delay=0.0, trace_packet=self._trace)
        self._failed: str | None = None
        self._closed = False
        self._enable: bool | None = None
        self._life = 0
        # plausibility of the counters: the fastest each may move (counts/s), its width
        self._rate = None if counts_per_s is None else [float(v) for v in counts_per_s]
        self._wrap = [1 << int(b) for b in counter_bits]
        self._last_counts: list[int] | None = None
        self._last_sent = 0.0   # when the last read's first request went out
        self._plan()
        self._connect(connect_timeout)
        self._t0 = time.perf_counter()
        try:
            self._write(np.zeros(2), False)  # a known, safe state (acknowledges a trip)
        except DriverError:
            self._client.close()
            raise

    # ------------------------------------------------------------------ MachineIO
    def read(self) -> Inputs:
        """Sample counters, tachos, switches and drive status in one pass of requests."""
        self._check_usable()
        sent = time.perf_counter()
        ir: dict[int, int] = {}
        for start, count in self._ir_spans:
            resp = self._request(f"read_input_registers({start}, count={count})",
                                 _FC_READ_INPUT, self._client.read_input_registers, start,
                                 count=count)
            words = resp.registers
            if len(words) != count:
                self._fail(f"short response to read_input_registers({start}, count={count}):"
                           f" {len(words)} registers")
            ir.update(zip(range(start, start + count), words, strict=True))
        di: dict[int, bool] = {}
        if self.map.module.status is not None:      # the switches packed in one register
            word = ir[self.map.module.status]
            di = {a: bool(word >> a & 1) for a in self._di_bits}
        for start, count in self._di_spans:
            resp = self._request(f"read_discrete_inputs({start}, count={count})",
                                 _FC_READ_DISCRETE, self._client.read_discrete_inputs,
                                 start, count=count)
            bits = resp.bits
            if len(bits) < count:
                self._fail(f"short response to read_discrete_inputs({start}, count={count}):"
                           f" {len(bits)} bits")
            di.update(zip(range(start, start + count), bits[:count], strict=True))
        m, order = self.map.module, self.map.module.word_order
        counts = np.empty(2, dtype=np.int64)
        tacho = np.zeros(2)
        flags = np.zeros((3, 2), dtype=bool)
        ready = m.watchdog_tripped is None or not di[m.watchdog_tripped]
        for k, a in enumerate(AXES):
            ax = self.map.axes[a]
            counts[k] = words_to_counter(ir[ax.encoder], ir[ax.encoder + 1], order)
            if ax.tacho is not None:
                tacho[k] = word_to_volts(ir[ax.tacho], m.tacho_full_scale)
            flags[0, k], flags[1, k] = di[ax.limit_min], di[ax.limit_max]
            flags[2, k] = ax.home is not None and di[ax.home]
            ready = ready and (ax.drive_ready is None or di[ax.drive_ready])
        now = time.perf_counter()
        if self._rate is not None:
            self._check_plausible(counts.tolist(), sent, now)
        inputs = Inputs(encoder_counts=counts, tacho_volts=tacho, limit_min=flags[0],
                        limit_max=flags[1], home=flags[2], drive_ready=bool(ready),
                        time=now - self._t0)
        if m.accelerometer is not None:
            self._accelerometer(ir, inputs)
        return inputs

    def _accelerometer(self, ir: dict[int, int], inputs: Inputs) -> None:
        """The accelerometer's FIFO into ``inputs`` (its sample numbers unwrapped from the
        registers' 16 bits: a read follows the last within 32768 samples)."""
        m = self.map.module
        words = [ir[a] for a in range(m.accelerometer, m.accelerometer
                                      + m.accelerometer_words)]
        count, low, lost, phase, samples = accelerometer_samples(
            words, m.accelerometer_lsb, m.accelerometer_block)
        last = self._accel_next
        first = low if last is None else last + ((low - last + 0x8000) & 0xFFFF) - 0x8000
        if count:
            self._accel_next = first + count
        inputs.accel_samples, inputs.accel_count = samples, count
        inputs.accel_sequence, inputs.accel_overrun = first, lost
        inputs.accel_clock = first + count - 1 + phase

    def _check_plausible(self, counts: list[int], sent: float, now: float) -> None:
        """(With ``counts_per_s``.) Modbus/TCP has no checksum: a flipped byte in a counter
        answer would be a jump of the table. A step larger than the axis can travel between
        the two samples (at ``counts_per_s``, over that time plus a millisecond, plus two
        counts) is taken for a corrupted answer: a fault naming the axis.

        The time between the samples is bounded from above by the time from sending the
        last read (``sent`` then) to receiving this one (``now``): the module latched each
        sample somewhere in between. Time stamps taken only on receipt were not safe: a
        loaded machine that held this process for a few milliseconds between an answer and
        its time stamp made the next honest step look too fast (CI saw 826 counts "in
        2.2 ms")."""
        last, self._last_counts = self._last_counts, counts
        dt, self._last_sent = now - self._last_sent, sent
        if last is None:
            return
        for k, a in enumerate(AXES):
            full = self._wrap[k]
            step = (counts[k] - last[k] + (full >> 1)) % full - (full >> 1)
            allowed = self._rate[k] * (dt + 1e-3) + 2.0
            if abs(step) > allowed:
                self._fail(f"axis {a}: implausible counter step of {step} counts in "
                           f"{dt * 1e3:.1f} ms, more than the axis can travel ({allowed:.0f} "
                           "counts at twice its top speed): a corrupted answer?")

    def write(self, outputs: Outputs) -> None:
        """Write the references and the watchdog life counter; the enable coil on change."""
        self._check_usable()
        self._write(outputs.dac_volts, bool(outputs.enable))

    def close(self) -> None:
        """Leave the module safe (references zero, drives disabled; best effort, also after
        a failure) and release the connection. Idempotent."""
        if self._closed:
            return
        self._closed = True
        with _quiet_pymodbus(), contextlib.suppress(DriverError, ModbusException, OSError):
            self._failed = None
            self._enable = None
            self._write(np.zeros(2), False)
        self._client.close()

    # ------------------------------------------------------------------ internals
    def _plan(self) -> None:
        """Requests of one tick, from the map (computed once)."""
        rmap = self.map
        self._ir_spans = rmap.input_spans()
        self._accel_next: int | None = None    # the accelerometer's next sample number
        packed = rmap.module.status is not None
        self._di_spans = [] if packed else rmap.discrete_spans()
        self._di_bits = [address for _, address, _ in rmap.signals()[2]]
        slots = {f"axes.{a}.dac": k for k, a in enumerate(AXES)}
        slots["module.watchdog"] = 2
        slots["module.control"] = 3
        self._hr_runs = [(start, [slots[n] for n in names])
                         for start, names in rmap.holding_runs()]

    def _connect(self, patience: float) -> None:
        host, port = self._address
        try:        # a name that does not resolve is said as such, not as a timeout
            socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except socket.gaierror as exc:
            raise DriverError(f"cannot connect to {self.url}: host {host!r} not found "
                              f"({exc.strerror})") from None
        deadline = time.monotonic() + patience
        with _quiet_pymodbus():
            while not self._client.connect():
                if time.monotonic() >= deadline:
                    raise DriverError(f"cannot connect to {self.url} within {patience:g} s")
                time.sleep(0.05)

    def _write(self, dac_volts: Any, enable: bool) -> None:
        (fs_x, bits_x), (fs_y, bits_y) = self._dacs
        self._life = (self._life + 1) & 0xFFFF
        values = (dac_word(float(dac_volts[0]), fs_x, bits_x),
                  dac_word(float(dac_volts[1]), fs_y, bits_y), self._life, int(enable))
        control = self.map.module.control is not None   # the enable rides with the words
        change = enable != self._enable and not control
        if change and not enable:
            self._write_enable(False)
        for start, slots in self._hr_runs:
            words = [values[s] for s in slots]
            what = f"write_registers({start}, {len(words)} values)"
            resp = self._request(what, _FC_WRITE_REGISTERS, self._client.write_registers,
                                 start, words)
            if resp.address != start or resp.count != len(words):
                self._fail(f"garbled response to {what}: echoed address {resp.address}, "
                           f"count {resp.count}")
        if change and enable:
            self._write_enable(True)
        if control:
            self._enable = enable

    def _write_enable(self, flag: bool) -> None:
        coil = self.map.module.enable
        what = f"write_coil({coil}, {flag})"
        resp = self._request(what, _FC_WRITE_COIL, self._client.write_coil, coil, flag)
        if resp.address != coil or bool(resp.bits and resp.bits[0]) != flag:
            self._fail(f"garbled response to {what}: echoed address {resp.address}, "
                       f"value {resp.bits[:1]}")
        self._enable = flag

    def _request(self, what: str, function_code: int, call: Callable[..., Any], *args: Any,
                 **kwargs: Any) -> Any:
        """One request with the timeout and reconnect policy; every failure → DriverError."""
        for attempt in range(self.reconnects + 1):
            self.requests += 1
            try:
                resp = call(*args, device_id=self._unit, **kwargs)
            except (ConnectionException, OSError) as exc:  # OSError: reset by the peer
                self._client.close()
                self._enable = None   # a new connection: the enable coil is written again
                if attempt < self.reconnects:
                    continue
                self._fail(f"connection lost during {what}: {exc}")
            except ModbusIOException as exc:
                if self._rx:
                    self._fail(f"garbled response to {what}: {len(self._rx)} bytes that are "
                               f"no valid answer ({self._rx[:16].hex(' ')}"
                               f"{' …' if len(self._rx) > 16 else ''})")
                self._fail(f"no valid response to {what} within {self.timeout * 1e3:g} ms "
                           f"({exc})")
            except (ModbusException, ValueError, TypeError, IndexError, KeyError) as exc:
                self._fail(f"garbled response to {what}: {type(exc).__name__}: {exc}")
            break
        if resp.isError():
            code = getattr(resp, "exception_code", 0)
            try:
                name = ExcCodes(code).name
            except ValueError:   # no module sends that: the answer itself was corrupted
                self._fail(f"garbled response to {what}: an exception answer with the "
                           f"undefined code {code}")
            self._fail(f"the module refused {what}: Modbus exception {code} ({name})")
        if resp.function_code != function_code:
            self._fail(f"garbled response to {what}: function code {resp.function_code}, "
                       f"expected {function_code}")
        return resp

    def _trace(self, sending: bool, data: bytes) -> bytes:
        """pymodbus packet hook: keep the bytes received for the current request (the
        receive buffer so far), so a timeout after garbage can say what arrived."""
        self._rx = b"" if sending else data
        return data

    def _fail(self, message: str) -> NoReturn:
        self._failed = message
        raise DriverError(f"{self.url}: {message}")

    def _check_usable(self) -> None:
        if self._closed:
            raise DriverError(f"{self.url}: the driver is closed")
        if self._failed is not None:
            raise DriverError(f"{self.url}: the driver failed earlier: {self._failed}")
