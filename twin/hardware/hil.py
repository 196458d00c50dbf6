"""The twin standing in for the I/O module: a Modbus/TCP server whose registers are the
plant's I/O, with the physics advanced in real time and the module's watchdog.

``HilModule`` is the module: a process image over a ``Plant`` laid out by a register map
(``twin.hardware.register_map``). Its clock is the wall clock. Before every access the
plant is caught up with it in whole drive intervals (``advance``), so an input read at
wall time t shows the plant at the last drive-interval boundary ≤ t (at most one interval
old), and an output written at t drives the plant from that boundary on. Between requests
a background task keeps advancing, so the table moves (and the watchdog runs) whether or not
anybody asks.

Phase lock: like a fieldbus module whose inputs are latched on a clock synchronised to the
master's cycle, the module steers its drive-interval grid so that the client's counter
reads arrive a quarter interval (``sync_phase``) after a boundary: each read nudges the
grid a fifth (``sync_gain``) of the way. A controller then sees exactly what the lock-step
twin shows it: the sample at k·T, and the new reference applied from k·T on, as long as its
write arrives within the output window. With a free-running grid (``sync_phase=None``) the
read lands anywhere in an interval: about one drive interval of extra delay (1 ms on the
Tomsk rig, a fifth of its 5 ms period), which moved the contour errors of the corner
program by 14 %.

Output window: a counter read catches the plant up with the clock; between reads the
physics runs ``output_window`` (rounded up to whole drive intervals) behind it, as a
synchronous fieldbus applies outputs at a fixed point of the cycle, not whenever they
arrive. A DAC write that arrives within the window after the end of its read's interval
therefore still takes effect from the read's boundary, like the lock-step twin's; the next
read cannot come before that write (a controller reads, computes, writes), so a wide window
costs nothing. Over pymodbus on loopback a tick's read, compute and write take about a
millisecond: without a window half the writes landed a Tomsk drive interval late and the
corner program's contour error moved by up to 14 % from run to run, and on laser_belt
(0.25 ms intervals) nearly all did, 25 % below the lock-step contour error. The default
2 ms window leaves none. ``HilStats.late_writes`` counts the writes that missed it.

Watchdog: writing the watchdog holding register with a new value restarts the timer. When
it expires while the outputs are live (enable set or a DAC register non-zero), the module
zeroes the DAC registers, clears the enable coil, disables the drives and sets the
``watchdog_tripped`` input, at the plant instant of expiry (even if the check runs later).
The trip is latched until the enable coil is written 0: until then DAC writes are dropped
and a write of enable 1 is refused with Modbus exception 4 (device failure).

Outputs off until fed, one owner: like a safety I/O module, the module drives nothing until
a client feeds the watchdog, and that client (its connection, ``CLIENT``) then owns the
outputs until it disconnects or the watchdog trips. Before any feed a non-zero reference or
enable 1 is refused with exception 4 and the outputs stay zero (a write of several
registers feeds first, so a controller's first tick, references and life counter in one
request, is taken). While a client owns the outputs, another client's writes of outputs
(references, watchdog, enable) get exception 6, device busy; reads stay open to everybody.
When the owner disconnects, nobody owns the outputs; they stay as they are, guarded by
the watchdog, so a controller that reconnects (and feeds in time) carries on. Who may claim
them is first come unless an access list says otherwise (``twin.hardware.owners``): a
client it does not list gets exception 1 (illegal function) on every output write.

``twin.hardware.hil_server`` serves the module over Modbus/TCP.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np
from pymodbus.constants import ExcCodes

from twin.config import AXES
from twin.controller.io import Inputs
from twin.errors import ConfigError, SimulationError
from twin.hardware.owners import Owners, client_host
from twin.hardware.register_map import (
    RegisterMap,
    accelerometer_words,
    check_dacs,
    counter_to_words,
    dac_volts,
    volts_to_word,
)
from twin.plant import Plant

__all__ = ["CLIENT", "OUTPUT_WINDOW", "HilModule", "HilStats", "Refused"]

CLIENT: ContextVar[object | None] = ContextVar("hil_client", default=None)
"""The connection the request being served came on (the server sets it per request; None
for direct calls)."""
_NOBODY = object()
"""``HilModule.owner`` when no client owns the outputs."""


class Refused(Exception):
    """A write the module refuses, with the Modbus exception code it answers."""

    def __init__(self, code: ExcCodes, why: str):
        super().__init__(why)
        self.code = code

OUTPUT_WINDOW = 2e-3
"""Default output window (s): twice a tick's read-compute-write over pymodbus on loopback."""



@dataclass(frozen=True)
class HilStats:
    """What the module did.

    Attributes
    ----------
    requests : int
        Register accesses served.
    intervals : int
        Drive intervals the plant advanced.
    max_catch_up : int
        Most drive intervals advanced at once (1–2 when the physics keeps up, plus the
        output window).
    watchdog_trips : int
        Times the watchdog zeroed the outputs.
    sim_time, wall_time : float
        Plant time and wall time since the start (s).
    fault : str or None
        Why the module stopped answering (the plant diverged), if it did.
    dac_writes : int
        DAC reference writes received.
    late_writes : int
        Of those, the ones that arrived in a later drive interval than the counter read
        before them: the reference took effect one or more intervals later than the
        lock-step twin applies it (the client's read-compute-write took too long).
    refused : int
        Output writes refused: before the watchdog was fed, or from a client other than
        the one that owns the outputs.
    direct : int
        Requests of a tick's kinds answered by the server itself (``hil_server``'s
        ``tick_answer``); pymodbus answered the others.
    """

    requests: int
    intervals: int
    max_catch_up: int
    watchdog_trips: int
    sim_time: float
    wall_time: float
    fault: str | None = None
    dac_writes: int = 0
    late_writes: int = 0
    refused: int = 0
    direct: int = 0


class HilModule:
    """The plant's I/O as a Modbus process image (see the module docstring).

    Parameters
    ----------
    plant : Plant
        The twin, at its start state (drives are disabled until the enable coil is set).
    register_map : RegisterMap
    watchdog : float
        Watchdog timeout (s).
    sync_phase : float or None
        Where in a drive interval the client's counter reads are steered (fraction of an
        interval, 0 … 1); None: a free-running grid.
    sync_gain : float
        Fraction of the phase error corrected at each counter read (0 … 1].
    output_window : float
        How late after its read's interval a DAC write may arrive and still act from the
        read's boundary (s, 0 … 0.05; see the module docstring).
    clock : callable
        Wall clock (s); injected for tests.
    owners : Owners, optional
        The clients that may claim the outputs (default: any, first come).

    Attributes
    ----------
    dt : float
        Drive interval of the plant (s): the grain of the physics and of the outputs.
    enabled, tripped : bool
        The enable coil; the latched watchdog trip.
    fault : str or None
        Set when the plant diverged; every access then answers Modbus exception 4.
    """

    def __init__(self, plant: Plant, register_map: RegisterMap, *, watchdog: float = 0.1,
                 sync_phase: float | None = 0.25, sync_gain: float = 0.2,
                 output_window: float = OUTPUT_WINDOW,
                 clock: Callable[[], float] = time.perf_counter,
                 owners: Owners | None = None):
        if not (math.isfinite(watchdog) and watchdog > 0):
            raise ConfigError("watchdog", f"must be > 0 s, got {watchdog}")
        if sync_phase is not None and not 0.0 <= sync_phase < 1.0:
            raise ConfigError("sync_phase", f"must be in [0, 1), got {sync_phase}")
        if not 0.0 < sync_gain <= 1.0:
            raise ConfigError("sync_gain", f"must be in (0, 1], got {sync_gain}")
        if not (isinstance(output_window, int | float) and 0.0 <= output_window <= 0.05):
            raise ConfigError("output_window", f"must be 0 … 0.05 s, got {output_window!r}")
        self.hold = math.ceil(output_window / plant.drive_dt - 1e-9)
        """int: the output window in whole drive intervals."""
        self.plant, self.map, self.watchdog = plant, register_map, watchdog
        self.sync_phase, self.sync_gain = sync_phase, sync_gain
        self.dt = plant.drive_dt
        self._clock = clock
        m = register_map.module
        self._fs_tacho, self._order = m.tacho_full_scale, m.word_order
        dacs = {a: plant.config.axes[a].dac for a in AXES}
        check_dacs(dacs)
        self._dacs = [(dacs[a].full_scale, dacs[a].bits) for a in AXES]
        """Each axis' DAC (full scale, bits): the machine's, the one setting of it."""
        self._dac_addr = [register_map.axes[a].dac for a in AXES]
        self._hr = {addr: 0 for addr in (*self._dac_addr, m.watchdog)}
        if m.control is not None:
            self._hr[m.control] = 0
        self._u = np.zeros(2)
        self._zero = np.zeros(2)
        self.enabled = False
        self.tripped = False
        self.fault: str | None = None
        self.owners = owners or Owners()
        """The clients that may claim the outputs."""
        self.owner: object = _NOBODY
        """The connection that owns the outputs (``_NOBODY``: none; see the module
        docstring)."""
        self.refused = 0
        """Writes refused (not fed, or another client's while one owns the outputs)."""
        self.direct = 0
        """Requests answered without pymodbus (see ``HilStats.direct``)."""
        self._last_feed = -math.inf
        self._steps = 0
        self._sampled = -1
        self._last_reading = plant.read()
        self._requests = self._trips = self._max_catch_up = 0
        self._read_step = -1  # the drive interval of the last counter read
        self._dac_writes = self._late_writes = 0
        plant.enable(False)
        self._t0 = clock()

    # ------------------------------------------------------------------ physics
    def start(self) -> None:
        """Restart the module clock at zero (before the first interval only): call when
        the server starts listening, so that start-up time is not physics to catch up."""
        if self._steps == 0:
            self._t0 = self._clock()

    @property
    def now(self) -> float:
        """Module time: wall time since the start (s)."""
        return self._clock() - self._t0

    def advance(self, now: float | None = None) -> int:
        """Catch the plant up with module time ``now`` (s; default: the clock) in whole
        drive intervals and run the watchdog. Returns the intervals advanced. A diverged
        plant sets ``fault``."""
        if self.fault is not None:
            return 0
        now = self.now if now is None else now
        target = math.floor(now / self.dt + 1e-9)
        if target <= self._steps:
            return 0
        n = target - self._steps
        expiry = self._last_feed + self.watchdog
        try:
            if self._live() and math.isfinite(expiry) and expiry <= now:
                k = min(max(math.ceil(expiry / self.dt - 1e-9) - self._steps, 0), n)
                self._step(k)
                self._trip()
                self._step(n - k)
            else:
                self._step(n)
        except SimulationError as exc:
            self.fault = str(exc)
        self._max_catch_up = max(self._max_catch_up, n)
        return n

    def advance_between_reads(self) -> int:
        """``advance`` to the output window behind the clock: what every access but a
        counter read does, and the background task (see the module docstring)."""
        return self.advance(self.now - self.hold * self.dt)

    def synchronise(self) -> None:
        """A counter sample arrives now: pull the drive-interval grid a fraction
        ``sync_gain`` of the way toward putting this instant at ``sync_phase`` of an
        interval (a phase-locked loop on the client's sampling; nothing with ``sync_phase``
        None)."""
        if self.sync_phase is None:
            return
        x = self.now / self.dt
        error = x - math.floor(x) - self.sync_phase
        error -= round(error)  # wrapped to [-1/2, 1/2] of an interval
        self._t0 += self.sync_gain * error * self.dt

    def _step(self, n: int) -> None:
        if n > 0:
            self.plant.step(self._u if self.enabled else self._zero, n * self.dt)
            self._steps += n

    def _live(self) -> bool:
        return self.enabled or any(self._hr[a] for a in self._dac_addr)

    def _trip(self) -> None:
        """Outputs zero, drives disabled, the trip latched; nobody owns the outputs."""
        for a in self._dac_addr:
            self._hr[a] = 0
        self._u[:] = 0.0
        self._set_enable(False)
        self.owner = _NOBODY
        self.tripped = True
        self._trips += 1

    def release(self, client: object | None) -> None:
        """``client``'s connection is gone: if it owned the outputs, nobody does now. The
        outputs stay as they were, guarded by the watchdog: a controller whose connection
        was re-opened (a driver's reconnect) feeds again in time and carries on; one that
        is gone for good trips it within the timeout."""
        if self.owner is client:
            self.owner = _NOBODY

    def _claim(self, what: str) -> None:
        """Refuse an output write of a client the access list does not name, or of a
        client other than the owner."""
        client = CLIENT.get()
        if not self.owners.allows(client_host(client)):
            self.refused += 1
            raise Refused(ExcCodes.ILLEGAL_FUNCTION, f"{what}: this client may not drive "
                          f"the outputs (owners: {self.owners.describe()})")
        if self.owner is not _NOBODY and self.owner is not client:
            self.refused += 1
            raise Refused(ExcCodes.DEVICE_BUSY, f"{what}: the outputs are held by another "
                          "client")

    def _set_enable(self, flag: bool) -> None:
        self.enabled = flag
        self.plant.enable(flag)
        if self.map.module.control is not None:   # the control register mirrors the enable
            self._hr[self.map.module.control] = int(flag)

    # ------------------------------------------------------------------ process image
    def input_registers(self, *, accelerometer: bool = True) -> dict[int, int]:
        """Counters and tachos now: {address: register value}; with a mapped accelerometer
        and ``accelerometer``, its FIFO, which this empties (False: not read)."""
        r = self._reading()
        words: dict[int, int] = {}
        for k, a in enumerate(AXES):
            ax = self.map.axes[a]
            words[ax.encoder], words[ax.encoder + 1] = counter_to_words(
                int(r.encoder_counts[k]), self._order)
            if ax.tacho is not None:
                words[ax.tacho] = volts_to_word(float(r.tacho_volts[k]), self._fs_tacho)
        if self.map.module.status is not None:
            words[self.map.module.status] = sum(
                1 << address for address, on in self.discrete_inputs().items() if on)
        m = self.map.module
        if m.accelerometer is not None and accelerometer:
            words.update(enumerate(self._accelerometer_words(), start=m.accelerometer))
        return words

    def _accelerometer_words(self) -> list[int]:
        """The accelerometer's registers: its FIFO, emptied (no samples without one)."""
        m, sensor = self.map.module, self.plant.accelerometer
        block = m.accelerometer_block
        if sensor is None:
            return accelerometer_words(0, 0, False, np.zeros((block, 2)),
                                       m.accelerometer_lsb, block)
        fifo = np.zeros((sensor.config.block, 2))
        count, first, lost = sensor.pop(fifo)
        if count > block:                 # the map holds fewer than the sensor's FIFO
            fifo[:block] = fifo[count - block:count]
            first, count, lost = first + count - block, block, True
        clock = self.plant.time * sensor.config.sample_rate
        return accelerometer_words(count, first, lost, fifo, m.accelerometer_lsb, block,
                                   phase=max(0.0, clock - (first + count - 1)))

    def reads_accelerometer(self, address: int, count: int) -> bool:
        """Whether input registers [address, address + count) include the
        accelerometer's."""
        m = self.map.module
        return m.accelerometer is not None and address < m.accelerometer + \
            m.accelerometer_words and m.accelerometer < address + count

    def discrete_inputs(self) -> dict[int, bool]:
        """Switches, drive ready and the watchdog trip now: {address: state}."""
        r = self._reading()
        fault = self.plant.drives.fault
        bits: dict[int, bool] = {}
        for k, a in enumerate(AXES):
            ax = self.map.axes[a]
            bits[ax.limit_min], bits[ax.limit_max] = bool(r.limit_min[k]), bool(r.limit_max[k])
            if ax.home is not None:
                bits[ax.home] = bool(r.home[k])
            if ax.drive_ready is not None:
                bits[ax.drive_ready] = not fault[k]
        if self.map.module.watchdog_tripped is not None:
            bits[self.map.module.watchdog_tripped] = self.tripped
        return bits

    def _reading(self) -> Inputs:
        """The plant's sensor reading, sampled once per drive interval (the counter and
        switch reads of one tick share it)."""
        if self._sampled != self._steps:   # the accelerometer is read by its registers
            self._last_reading = self.plant.read(accelerometer=False)
            self._sampled = self._steps
        return self._last_reading

    def holding_registers(self) -> dict[int, int]:
        """DAC references, the watchdog and the control register: {address: value}."""
        return dict(self._hr)

    def coils(self) -> dict[int, bool]:
        """The enable coil: {address: state}."""
        return {self.map.module.enable: self.enabled}



    def write_holding(self, address: int, word: int) -> int:
        """Write one holding register (a DAC reference or the watchdog); returns the value
        the register holds afterwards (a DAC write is dropped while a trip is latched).
        Raises ``Refused``: another client owns the outputs, or a non-zero reference
        before anybody fed the watchdog."""
        if address == self.map.module.control:
            self._claim("enable")
            flag = bool(word & 1)
            if flag and self.owner is _NOBODY:
                self.refused += 1
                raise Refused(ExcCodes.DEVICE_FAILURE, "enable before the watchdog was fed: "
                              "the drives stay off")
            if flag and self.tripped:       # dropped while a trip is latched
                self._hr[address] = 0
                return 0
            if not flag:
                self.tripped = False
            self._set_enable(flag)
            return self._hr[address]
        if address == self.map.module.watchdog:
            self._claim("watchdog")
            if word != self._hr[address]:
                self._last_feed = self.now
                if self.owner is _NOBODY:
                    self.owner = CLIENT.get()
            self._hr[address] = word
        elif address in self._hr:
            self._claim("reference")
            if self.owner is _NOBODY and word != 0 and not self.tripped:
                self.refused += 1
                raise Refused(ExcCodes.DEVICE_FAILURE, "reference before the watchdog was "
                              "fed: the outputs stay off")
            k = self._dac_addr.index(address)
            if k == 0:  # one count per reference write (the DAC registers go together)
                self._dac_writes += 1
                self._late_writes += self._read_step >= 0 and self._steps > self._read_step
            self._hr[address] = 0 if self.tripped else word
            # the code's exact level: the plant's DAC stage finds the same code again
            self._u[k] = dac_volts(self._hr[address], *self._dacs[k])
        return self._hr.get(address, 0)

    def write_coil(self, address: int, flag: bool) -> bool:
        """Write the enable coil; False if refused (enable while a trip is latched, or
        before anybody fed the watchdog). Writing 0 acknowledges a trip. Raises
        ``Refused`` when another client owns the outputs."""
        if address != self.map.module.enable:
            return True
        self._claim("enable")
        if flag and (self.tripped or self.owner is _NOBODY):
            self.refused += 1
            return False
        if not flag:
            self.tripped = False
        self._set_enable(bool(flag))
        return True

    def stats(self) -> HilStats:
        """What the module did so far."""
        return HilStats(self._requests, self._steps, self._max_catch_up, self._trips,
                        self._steps * self.dt, self.now, self.fault, self._dac_writes,
                        self._late_writes, self.refused, self.direct)

    # ------------------------------------------------------------------ serving
    def tables(self) -> dict[int, tuple[int, int]]:
        """The address range [lo, hi) of each table, by the function code that reads it
        (1 coils, 2 discrete inputs, 3 holding registers, 4 input registers): from the
        lowest to the highest address the map uses."""
        ir, hr, di, co = self.map.signals()
        return {code: (min(a for _, a, _ in entries), max(a + w for _, a, w in entries))
                for code, entries in ((1, co), (2, di), (3, hr), (4, ir))}

    def begin(self, function_code: int) -> ExcCodes | None:
        """What comes before every access: count it, catch the plant up (a counter read
        also steers the grid and marks its interval), and answer device failure once the
        plant has diverged."""
        self._requests += 1
        if function_code == 4:
            self.synchronise()
            self.advance()
        else:
            self.advance_between_reads()
        if self.fault is not None:
            return ExcCodes.DEVICE_FAILURE
        if function_code == 4:
            self._read_step = self._steps
        return None

    def write_registers(self, address: int, values: list[int]) -> ExcCodes | None:
        """Write consecutive holding registers from ``address``, the watchdog first (a
        request that feeds and sets references, a controller's tick, is taken whole);
        each entry of ``values`` becomes what its register holds afterwards. Returns the
        exception code of a refused write (the ones before it stay written)."""
        order = sorted(range(len(values)), key=lambda i: address + i != self.map.module.watchdog)
        try:
            for i in order:
                values[i] = self.write_holding(address + i, int(values[i]))
        except Refused as exc:
            return exc.code
        return None
