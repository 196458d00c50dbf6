"""The HIL module served: ``serve_hil`` runs a ``HilModule`` behind a pymodbus
``ModbusTcpServer`` (asyncio, one thread: no locks) until SIGINT/SIGTERM, advancing the
physics between requests. ``sim_device`` and ``access`` are the pymodbus glue; a tick's
requests are answered without it (``tick_answer``). It binds 127.0.0.1 unless told
otherwise. ``hil_plant`` makes the plant it serves.

Each connection's requests run with ``hil.CLIENT`` set to that connection (its ``host``: the
client's address, for the access list of ``twin.hardware.owners``), so the module knows who
owns the outputs, and a connection that closes releases them. pymodbus' own log
goes through ``RateLimitedLog``: at most one line per connection and kind of fault per
``LOG_INTERVAL``, without tracebacks or frame dumps, queued to a thread that writes it, so
a flood of bad frames, or a stderr pipe that nobody reads, never stalls the serving loop.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import logging.handlers
import queue
import signal
import struct
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import DataType, SimData, SimDevice

from twin.config import MachineConfig
from twin.hardware.hil import CLIENT, OUTPUT_WINDOW, HilModule, HilStats, Refused
from twin.hardware.owners import Owners
from twin.hardware.register_map import RegisterMap
from twin.plant import Plant

__all__ = ["LOG_INTERVAL", "RateLimitedLog", "access", "hil_plant", "serve_hil", "sim_device",
           "tick_answer"]

LOG_INTERVAL = 5.0
"""At most one log line per connection and kind of fault in this many seconds."""


class RateLimitedLog(logging.Filter):
    """Lets one record per (connection, kind) through per ``interval`` seconds; the kind
    is the record's message template. Strips tracebacks and cuts long messages (a frame
    dump is kilobytes)."""

    def __init__(self, interval: float = LOG_INTERVAL, clock: Callable[[], float]
                 = time.monotonic, width: int = 200):
        super().__init__()
        self.interval, self.clock, self.width = interval, clock, width
        self._last: dict[tuple[int, str], float] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        key = (id(CLIENT.get()), str(record.msg)[:60])
        now = self.clock()
        if now - self._last.get(key, -float("inf")) < self.interval:
            return False
        if len(self._last) > 4096:   # many connections come and go: forget the old ones
            self._last = {k: t for k, t in self._last.items() if now - t < self.interval}
        self._last[key] = now
        message = _first_line(record.getMessage())
        record.msg = message if len(message) <= self.width else message[:self.width] + " …"
        record.args = None
        record.exc_info = record.exc_text = record.stack_info = None
        return True


def _first_line(message: str) -> str:
    """A log message without the traceback pymodbus writes into some of its texts
    (``Datastore unable to fulfill request: 22; Traceback (most recent call last): …``)."""
    message = message.split("Traceback (most recent call last)", 1)[0]
    lines = message.strip().splitlines()
    return lines[0].rstrip(" ;:") if lines else ""


class _DroppingQueueHandler(logging.handlers.QueueHandler):
    """A queue handler that drops a record when its bounded queue is full, never waits."""

    def enqueue(self, record: logging.LogRecord) -> None:
        try:
            self.queue.put_nowait(record)
        except queue.Full:
            pass


@contextmanager
def _quiet_log(level: int = logging.WARNING) -> Iterator[None]:
    """pymodbus' log, rate-limited and written by a thread of its own (see the module
    docstring), for the life of the server."""
    log = logging.getLogger("pymodbus")
    records: queue.Queue = queue.Queue(maxsize=1000)
    handler = _DroppingQueueHandler(records)
    handler.addFilter(RateLimitedLog())
    stream = logging.StreamHandler(sys.stderr)
    stream.setFormatter(logging.Formatter("hil-server: %(levelname)s %(message)s"))
    listener = logging.handlers.QueueListener(records, stream)
    saved = (log.level, log.handlers[:], log.propagate)
    log.handlers[:] = [handler]
    log.setLevel(level)
    log.propagate = False
    listener.start()
    try:
        yield
    finally:
        log.setLevel(saved[0])
        log.handlers[:] = saved[1]
        log.propagate = saved[2]
        listener.stop()


_READ_BITS = {1: "coils", 5: "coils", 15: "coils", 2: "discrete_inputs"}
_READ_WORDS = {3: "holding_registers", 6: "holding_registers", 16: "holding_registers",
               22: "holding_registers", 23: "holding_registers", 4: "input_registers"}
"""The table each function code reads or writes (22, mask write: read, then written)."""


def sim_device(module: HilModule) -> SimDevice:
    """A pymodbus device whose four tables are the module's image (bit addressing), with
    ``access`` before every access."""
    tables = module.tables()

    def block(code: int) -> list[SimData]:
        lo, hi = tables[code]
        bits = code in (1, 2)
        kind = DataType.BITS if bits else DataType.REGISTERS
        return [SimData(lo, count=hi - lo, values=False if bits else 0, datatype=kind)]

    async def action(function_code: int, start: int, address: int, _count: int,
                     registers: list[int], values: list[int] | list[bool] | None
                     ) -> ExcCodes | None:
        return access(module, function_code, start, address, registers, values)

    return SimDevice(module.map.module.device_id,
                     simdata=(block(1), block(2), block(3), block(4)), action=action)


def access(module: HilModule, function_code: int, start: int, address: int,
           registers: list[int], values: list[int] | list[bool] | None) -> ExcCodes | None:
    """pymodbus' hook before every access: ``HilModule.begin``, then apply a write or
    refresh the registers a read returns from the image (``registers`` is the table's block
    from ``start``; bit tables pack 16 bits per entry, bit 0 first)."""
    if function_code not in _READ_BITS and function_code not in _READ_WORDS:
        return ExcCodes.ILLEGAL_FUNCTION     # no table of this module answers it
    refused = module.begin(function_code)
    if refused is not None:
        return refused
    if values is not None:
        if function_code in _READ_BITS:
            try:
                for i, flag in enumerate(values):
                    if not module.write_coil(address + i, bool(flag)):
                        return ExcCodes.DEVICE_FAILURE
            except Refused as exc:
                return exc.code
            return None
        return module.write_registers(address, values)  # type: ignore[arg-type]
    if function_code in _READ_BITS:
        for a, flag in getattr(module, _READ_BITS[function_code])().items():
            i, bit = a // 16 - start, 1 << (a % 16)
            registers[i] = registers[i] | bit if flag else registers[i] & ~bit
    else:
        for a, word in getattr(module, _READ_WORDS[function_code])().items():
            registers[a - start] = word
    return None


_HEADER = struct.Struct(">HHHBB")       # MBAP header and function code
_SPAN = struct.Struct(">HH")             # start address, count


def tick_answer(module: HilModule, tables: dict[int, tuple[int, int]], frame: bytes
                ) -> bytes | None:
    """The answer to one whole request of the kinds a controller's tick sends — read input
    registers (4), read discrete inputs (2), write multiple registers (16) — to the
    module's own device id, built here; None for anything else (another function, a
    request pymodbus answers with an error of its own, several or partial frames): pymodbus
    then serves it.

    Why: pymodbus' server takes about 150 µs a request on this kind of machine, half the
    budget of a 1 kHz tick's read and write; this takes a few. The answers are byte for
    byte pymodbus' (``tests/hardware/test_hil_server.py``), and the module does the same
    work (``HilModule.begin``, ``write_registers``).
    """
    if len(frame) < 12:
        return None
    tid, proto, length, unit, code = _HEADER.unpack_from(frame)
    if proto != 0 or length + 6 != len(frame) or unit != module.map.module.device_id \
            or code not in (2, 4, 16):
        return None
    address, count = _SPAN.unpack_from(frame, 8)
    lo, hi = tables[3 if code == 16 else code]
    if not (lo <= address and address + count <= hi):
        return None
    values: list[int] = []
    if code == 16:
        if not (1 <= count <= 123 and length == 7 + 2 * count and frame[12] == 2 * count):
            return None
        values = list(struct.unpack_from(f">{count}H", frame, 13))
    elif length != 6 or not 1 <= count <= (125 if code == 4 else 2000):
        return None
    module.direct += 1
    refused = module.begin(code)
    if refused is None and code == 16:
        refused = module.write_registers(address, values)
    if refused is not None:
        return _HEADER.pack(tid, 0, 3, unit, code | 0x80) + bytes((refused,))
    if code == 16:
        return _HEADER.pack(tid, 0, 6, unit, code) + _SPAN.pack(address, count)
    if code == 4:
        words = module.input_registers(
            accelerometer=module.reads_accelerometer(address, count))
        data = struct.pack(f">B{count}H", 2 * count,
                           *(words.get(a, 0) for a in range(address, address + count)))
    else:
        bits = module.discrete_inputs()
        packed = bytearray((count + 7) // 8)
        for i in range(count):
            if bits.get(address + i, False):
                packed[i >> 3] |= 1 << (i & 7)
        data = bytes((len(packed),)) + bytes(packed)
    return _HEADER.pack(tid, 0, 2 + len(data), unit, code) + data


class _Connection(ServerRequestHandler):
    """One client connection: its requests run with ``hil.CLIENT`` set to it, and closing
    it releases the outputs it owned. A tick's requests are answered at once
    (``tick_answer``); the rest go through pymodbus."""

    module: HilModule
    tables: dict[int, tuple[int, int]]
    fast = True

    host: str | None = None
    """The client's address (``twin.hardware.owners``)."""

    def callback_connected(self) -> None:
        super().callback_connected()
        peer = self.transport.get_extra_info("peername") if self.transport else None
        self.host = str(peer[0]) if peer else None

    def data_received(self, data: bytes) -> None:
        if self.fast and not self.recv_buffer:
            token = CLIENT.set(self)
            try:
                answer = tick_answer(self.module, self.tables, data)
            finally:
                CLIENT.reset(token)
            if answer is not None:
                self.transport.write(answer)  # type: ignore[union-attr]
                return
        super().data_received(data)

    async def handle_request(self) -> None:
        token = CLIENT.set(self)
        try:
            await super().handle_request()
        finally:
            CLIENT.reset(token)

    def callback_disconnected(self, exc: Exception | None) -> None:
        super().callback_disconnected(exc)
        self.module.release(self)


class _Server(ModbusTcpServer):
    """pymodbus' TCP server with ``_Connection`` handlers (pymodbus 3.x:
    ``callback_new_connection`` makes the handler of a new connection)."""

    module: HilModule
    tables: dict[int, tuple[int, int]]
    fast: bool

    def callback_new_connection(self) -> ServerRequestHandler:
        handler = _Connection(self, self.trace_packet, self.trace_pdu, self.trace_connect)
        handler.module, handler.tables, handler.fast = self.module, self.tables, self.fast
        return handler


async def _serve(module: HilModule, host: str, port: int,
                 on_ready: Callable[[str, int], None] | None, fast: bool) -> None:
    server = _Server(sim_device(module), address=(host, port))
    server.module, server.tables, server.fast = module, module.tables(), fast
    await server.serve_forever(background=True)
    bound = server.transport.sockets[0].getsockname()  # type: ignore[union-attr]
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    gc.collect()
    gc.freeze()  # the start-up objects never need scanning again: shorter GC pauses
    module.start()
    if on_ready is not None:
        on_ready(bound[0], bound[1])
    try:
        while not stop.is_set():
            module.advance_between_reads()
            await asyncio.sleep(module.dt)
    finally:
        await server.shutdown()


def hil_plant(cfg: MachineConfig, *, start: np.ndarray | None = None,
              noise: bool = True) -> Plant:
    """A plant ready to serve: warmed up (the drive kernels are compiled by a first step,
    which must not happen on the clock) and reset to ``start`` (m; default: the home
    keyframe). ``ValueError`` if ``start`` is outside the travel. ``noise``: the machine
    file's sensor noise (False silences it)."""
    plant = Plant.from_machine(cfg, noise=noise)
    plant.enable(False)
    plant.step(np.zeros(2), plant.drive_dt)
    plant.reset(positions=start)
    return plant


def serve_hil(plant: Plant, register_map: RegisterMap, *, host: str = "127.0.0.1",
              port: int = 5020, watchdog: float = 0.1, sync_phase: float | None = 0.25,
              output_window: float = OUTPUT_WINDOW,
              on_ready: Callable[[str, int], None] | None = None,
              fast: bool = True, owners: Owners | None = None) -> HilStats:
    """Serve ``plant`` as a Modbus/TCP I/O module until SIGINT or SIGTERM.

    Parameters
    ----------
    plant : Plant
        The twin at its start state, warmed up (``hil_plant``).
    register_map : RegisterMap
    host : str
        Interface to bind (only this machine by default).
    port : int
        TCP port; 0 picks a free one (``on_ready`` gets it).
    watchdog : float
        Watchdog timeout (s).
    sync_phase : float or None
        Where in a drive interval the client's counter reads are steered (fraction of an
        interval; see ``HilModule``); None: a free-running grid.
    output_window : float
        Output window (s; see ``HilModule``).
    on_ready : callable(host, port), optional
        Called once the server listens.
    fast : bool
        Answer a tick's requests without pymodbus (``tick_answer``); False: pymodbus
        serves every request (the reference the fast answers are tested against).
    owners : Owners, optional
        The clients that may claim the outputs (default: first come).

    Returns
    -------
    HilStats
    """
    module = HilModule(plant, register_map, watchdog=watchdog, sync_phase=sync_phase,
                       output_window=output_window, owners=owners)
    with _quiet_log():
        asyncio.run(_serve(module, host, port, on_ready, fast))
    return module.stats()
