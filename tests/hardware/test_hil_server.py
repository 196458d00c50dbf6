"""``twin hil-server`` as a real subprocess on a real socket (127.0.0.1, ephemeral port):
an independent pymodbus client reads the documented registers, the watchdog, a program run
end to end against the lock-step twin, and the faults (server killed, limit switch).

The paced runs ask for SCHED_FIFO (client thread and server) where the OS allows it, as a
real-time controller would; without it they still run, with a worse deadline report."""

from __future__ import annotations

import contextlib
import json
import re
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import rerun.chunk as rc
from pymodbus.client import ModbusTcpClient

from twin.hardware.hil_process import spawn_hil_server
from twin.hardware.realtime import fifo_priority
from twin.session.run import RunSpec, prepare, run
from twin.telemetry.spectra import spectrum_entity

UNIT = 1
TRUTH_ONLY = {*(f"/axes/{a}/{n}" for a in "xy" for n in
                ("drive/armature_current", "drive/converter_voltage", "drive/conduction",
                 "drive/motor_speed", "screw_deflection_um", "velocity/actual")),
              "/feed/actual",
              *("/" + spectrum_entity("screw_deflection", a, mode=m)
                for a in "xy" for m in (False, True))}


@contextlib.contextmanager
def client(port: int) -> Iterator[ModbusTcpClient]:
    c = ModbusTcpClient("127.0.0.1", port=port, timeout=1.0)
    assert c.connect()
    try:
        yield c
    finally:
        c.close()


def hil_server(*args: str, watchdog_ms: float = 100.0):
    return spawn_hil_server("--rt-priority", "10", "--watchdog-ms", str(watchdog_ms), *args)


def _int16(word: int) -> int:
    return word - 0x10000 if word & 0x8000 else word


def _entities(path: str) -> set[str]:
    return {c.entity_path for c in rc.RrdReader(Path(path)).stream().to_chunks()}


def test_an_independent_client_reads_the_documented_registers():
    with hil_server("--from", "50,20") as server, client(server.info["port"]) as c:
        # Documented: counters at input registers 0-3, X then Y, high word first; 5 counts
        # per µm on the Tomsk rig; tachos at 4, 5.
        ir = c.read_input_registers(0, count=6, device_id=UNIT).registers
        x0, y0 = (ir[0] << 16) | ir[1], (ir[2] << 16) | ir[3]
        assert abs(x0 - 250_000) <= 1 and abs(y0 - 100_000) <= 1
        assert ir[4:] == [0, 0]
        di = c.read_discrete_inputs(0, count=9, device_id=UNIT).bits[:9]
        assert di == [False] * 6 + [True, True, False]   # no switch, drives ready, no trip
        assert c.read_coils(0, count=1, device_id=UNIT).bits[0] is False
        assert c.read_holding_registers(0, count=3, device_id=UNIT).registers == [0, 0, 0]
        # +1 V on X (int16, 32767 = 10 V), the watchdog fed every 10 ms.
        assert not c.write_registers(0, [3277, 0, 1], device_id=UNIT).isError()
        assert not c.write_coil(0, True, device_id=UNIT).isError()
        for feed in range(2, 40):
            time.sleep(0.01)
            c.write_register(2, feed, device_id=UNIT)
        ir = c.read_input_registers(0, count=6, device_id=UNIT).registers
        c.write_coil(0, False, device_id=UNIT)
    x1, y1 = (ir[0] << 16) | ir[1], (ir[2] << 16) | ir[3]
    assert x1 - x0 > 1000 and abs(y1 - y0) < 50          # X moved forward, Y held
    assert _int16(ir[4]) * 10.24 / 32767 > 0.5           # X tacho follows the reference


def test_watchdog_zeroes_the_outputs_within_its_timeout():
    timeout = 0.1
    with hil_server(watchdog_ms=timeout * 1e3) as server, client(server.info["port"]) as c:
        sent = time.perf_counter()
        c.write_registers(0, [3277, 3277, 1], device_id=UNIT)   # the last feed
        fed = time.perf_counter()
        c.write_coil(0, True, device_id=UNIT)
        zeroed = None
        while zeroed is None and time.perf_counter() - fed < 2.0:
            hr = c.read_holding_registers(0, count=2, device_id=UNIT).registers
            coil = c.read_coils(0, count=1, device_id=UNIT).bits[0]
            done = time.perf_counter()
            if hr == [0, 0] and not coil:
                zeroed = done
            else:   # a read answered before the earliest possible expiry must see them live
                assert (hr == [3277, 3277] and coil) or done >= sent + timeout
            time.sleep(0.002)
        assert zeroed is not None and zeroed - fed <= timeout + 0.03
        assert c.read_discrete_inputs(8, count=1, device_id=UNIT).bits[0]   # latched trip
        refused = c.write_coil(0, True, device_id=UNIT)
        assert refused.isError() and refused.exception_code == 4
        assert not c.write_coil(0, False, device_id=UNIT).isError()       # acknowledge
        assert not c.read_discrete_inputs(8, count=1, device_id=UNIT).bits[0]
        stats = server.stop()
    assert stats["watchdog_trips"] == 1 and stats["fault"] is None


def test_a_program_through_the_server_matches_the_lockstep_twin(tmp_path):
    ref = run(RunSpec(builtin="corner"), out_dir=tmp_path, run_id="lockstep")
    # A stall of the test machine long enough to skip a tick changes the motion itself, as
    # it would on a real machine; what is compared is the module against the lock-step twin
    # when the controller kept its period, so such a run is repeated (at most twice; a
    # machine that never keeps it fails, and says so).
    for attempt in range(3):
        with hil_server() as server, fifo_priority():
            hil = run(RunSpec(builtin="corner", driver=server.url), out_dir=tmp_path,
                      run_id=f"hil-{attempt}")
            module = server.stop()
        if hil.summary["ticks"]["skipped"] == 0:
            break
    s, r = hil.summary, ref.summary
    assert s["status"] == "FINISHED" and s["aborted"] is None, s.get("aborted")
    # Contour errors within 10 % (the phase-locked module samples like the lock-step twin and
    # applies a write from its read's interval; what remains is timing: late ticks). On an
    # idle machine they agree to 0.5 %.
    for key in ("max_contour_error_um", "rms_contour_error_um"):
        assert s[key] == pytest.approx(r[key], rel=0.10), (key, attempt, s["ticks"], module)
    ticks = s["ticks"]
    assert ticks["paced"] and ticks["due"] == ticks["on_time"] + ticks["late"] + \
        ticks["skipped"]
    # every slot that ran recorded a row, but the last: it found the program done
    assert len(hil.record["t"]) == ticks["due"] - ticks["skipped"]
    assert json.loads((tmp_path / f"hil-{attempt}.json").read_text())["ticks"] == ticks
    # The recording has every channel of a simulated run's but the twin's truth.
    lockstep, paced = _entities(r["recording"]), _entities(s["recording"])
    assert paced == lockstep - TRUTH_ONLY and TRUTH_ONLY <= lockstep


class _Timed:
    """A driver proxy that notes when each read/write started and ended, and how."""

    def __init__(self, driver):
        self.driver, self.calls = driver, []

    def _call(self, name, *args):
        start = time.perf_counter()
        try:
            out = getattr(self.driver, name)(*args)
        except Exception:
            self.calls.append((start, time.perf_counter(), False, name))
            raise
        self.calls.append((start, time.perf_counter(), True, name))
        return out

    def read(self):
        return self._call("read")

    def write(self, outputs):
        return self._call("write", outputs)

    def close(self):
        self.driver.close()


def test_killing_the_server_mid_run_stops_within_a_period_and_keeps_the_record(tmp_path):
    with hil_server() as server:
        proc, url = server.process, server.url
        spec = RunSpec(builtin="corner", driver=url)
        p = prepare(spec)
        p.driver = timed = _Timed(p.driver)
        killed: list[float] = []

        def kill():
            killed.append(time.perf_counter())
            proc.kill()
            proc.wait()
            killed.append(time.perf_counter())   # reaped: its sockets are closed

        killer = threading.Timer(1.0, kill)
        killer.start()
        with fifo_priority():
            result = run(spec, out_dir=tmp_path, run_id="killed", prepared=p)
        killer.join()
    s = json.loads((tmp_path / "killed.json").read_text())
    # A dying process answers nothing; the driver notices the closed connection, or the
    # silence if its answer timeout comes first (the teardown of the server takes ms).
    assert s["status"] == "FAULT" and s["fault"] == "DRIVER" and s["aborted"] is None
    assert re.match(rf"driver fault: {url}: (connection lost during|no valid response to) ",
                    s["error"]), s["error"]
    period, timeout = p.cfg.controller.period, p.driver.driver.timeout
    failed = [c for c in timed.calls if not c[2]]
    assert len(failed) == 1 and timed.calls[-1] is failed[0]
    kill_at, gone_at = killed
    assert not [c for c in timed.calls if c[2] and c[0] > gone_at]   # nothing ran after
    # stopped at the first I/O after the server was gone, at most one period later
    assert failed[0][1] - kill_at <= min(gone_at - kill_at, timeout) + period + 0.02
    assert 0.5 < s["sim_time_s"] < 2.0
    # The tick whose request met the dead server ran (it is due). Its row is recorded if the
    # read succeeded (the controller logs each tick it computes; the write then failed).
    ran = s["ticks"]["due"] - s["ticks"]["skipped"]
    assert len(result.record["t"]) == (ran - 1 if failed[0][3] == "read" else ran)
    assert "/axes/x/position/actual" in _entities(s["recording"])
    assert not list(tmp_path.glob("*.partial"))


def test_a_limit_switch_during_a_run_disables_the_drive_and_keeps_the_record(tmp_path):
    program = tmp_path / "x_to_40mm.nc"
    program.write_text("G90 G21\nG1 X40 F600\nM2\n", encoding="utf-8")   # from X = 10 mm
    # The module's X end switch sits at 20 mm, inside the controller's work zone: a switch
    # that actuates during the run.
    with hil_server("--set", "axes.x.switches.limit_max=20mm") as server:
        with fifo_priority():
            result = run(RunSpec(program=str(program), driver=server.url), out_dir=tmp_path,
                         run_id="limit")
        with client(server.info["port"]) as c:
            coil = c.read_coils(0, count=1, device_id=UNIT).bits[0]
            limit = c.read_discrete_inputs(1, count=1, device_id=UNIT).bits[0]
    s = json.loads((tmp_path / "limit.json").read_text())
    assert s["status"] == "FAULT" and s["fault"] == "LIMIT_TRIP" and s["aborted"] is None
    assert coil is False and limit is True
    rec = result.record
    assert rec["enable"][-1] == 0                        # the controller disabled the drive
    assert 19.9 < rec["position"][-1][0] * 1e3 < 21.0    # stopped at the switch
    assert len(rec["t"]) == s["ticks"]["due"] - s["ticks"]["skipped"]
    assert "/axes/x/position/actual" in _entities(s["recording"])


@pytest.mark.parametrize(("args", "words"), [
    (("--machine", "no_such_machine"), "machine: no machine file"),
    (("--from", "999,5"), "--from: must be 2 positions within the travel"),
    (("--map", "missing.toml"), "register_map: no such file"),
    (("--set", "axes.x.mechanics.carriage_mass=-1"), "axes.x.mechanics.carriage_mass"),
])
def test_bad_options_stop_the_server_naming_the_place(args, words):
    with pytest.raises(RuntimeError) as info, spawn_hil_server(*args):
        pass
    assert "(exit 2): error:" in str(info.value) and words in str(info.value)


def test_the_module_survives_bad_clients_and_serves_its_owner():
    """A DAC-first write, a second writer and a flood of malformed frames, with the server's
    stderr a pipe that nobody reads: the owner is still served, the intruder refused."""
    import socket
    import struct

    with spawn_hil_server("--rt-priority", "10", "--watchdog-ms", "2000",
                          unread_stderr=True) as server:
        port = server.info["port"]
        with client(port) as owner, client(port) as intruder:
            first = owner.write_register(0, 3277, device_id=UNIT)      # before any feed
            assert first.isError() and first.exception_code == 4
            assert owner.read_holding_registers(0, count=3, device_id=UNIT).registers == \
                [0, 0, 0]
            assert not owner.write_registers(0, [3277, 0, 1], device_id=UNIT).isError()
            assert not owner.write_coil(0, True, device_id=UNIT).isError()
            for request in (lambda: intruder.write_register(0, 32767, device_id=UNIT),
                            lambda: intruder.write_register(2, 99, device_id=UNIT),
                            lambda: intruder.write_coil(0, False, device_id=UNIT)):
                answer = request()
                assert answer.isError() and answer.exception_code == 6       # device busy
            assert not intruder.read_input_registers(0, count=6, device_id=UNIT).isError()
            # a flood of bad frames, each waiting for its answer as a misbehaving client
            # would: requests to a device that is not there, which pymodbus logs at ERROR
            # with a traceback (about 1.1 KB each): 1000 of them are 17 times what a pipe
            # holds, and a server that wrote them all would block on it
            with socket.create_connection(("127.0.0.1", port), timeout=0.05) as raw:
                answered = 0
                for k in range(1000):
                    raw.sendall(struct.pack(">HHHBBHH", k, 0, 6, 9, 4, 0, 1))
                    with contextlib.suppress(TimeoutError):
                        answered += bool(raw.recv(256))
                    if k % 50 == 0:
                        assert not owner.write_register(2, 1000 + k, device_id=UNIT).isError()
            assert answered == 1000
            for feed in range(2, 30):        # the owner is served on time throughout
                t0 = time.perf_counter()
                assert not owner.write_register(2, feed, device_id=UNIT).isError()
                ir = owner.read_input_registers(0, count=6, device_id=UNIT)
                assert not ir.isError() and time.perf_counter() - t0 < 0.05
                time.sleep(0.01)
            hr = owner.read_holding_registers(0, count=3, device_id=UNIT).registers
            assert hr[0] == 3277 and owner.read_coils(0, count=1, device_id=UNIT).bits[0]
        stats = server.stop()
    assert stats["fault"] is None and stats["refused"] == 4 and stats["watchdog_trips"] == 0


def test_the_packed_map_status_and_control_registers_follow_the_coil_rules():
    """``--map packed``: input register 6 mirrors the discrete inputs bit for bit; holding
    register 3 is the enable, written with the references, under the coil's rules (refused
    before the watchdog is fed, dropped while a trip is latched, 0 acknowledges)."""
    with hil_server("--map", "packed", "--from", "50,20", watchdog_ms=100.0) as server, \
            client(server.info["port"]) as c:
        ir = c.read_input_registers(0, count=7, device_id=UNIT).registers
        di = c.read_discrete_inputs(0, count=9, device_id=UNIT).bits[:9]
        assert [bool(ir[6] >> n & 1) for n in range(9)] == di
        assert ir[6] == 1 << 6 | 1 << 7                  # both drives ready, nothing else
        early = c.write_registers(3, [1], device_id=UNIT)
        assert early.isError() and early.exception_code == 4     # not fed yet
        assert not c.write_registers(0, [3277, 0, 1, 1], device_id=UNIT).isError()
        assert c.read_coils(0, count=1, device_id=UNIT).bits[0] is True   # the same enable
        assert c.read_holding_registers(3, count=1, device_id=UNIT).registers == [1]
        time.sleep(0.3)                                   # no feed: the watchdog trips
        hr = c.read_holding_registers(0, count=4, device_id=UNIT).registers
        ir = c.read_input_registers(0, count=7, device_id=UNIT).registers
        assert hr[0] == 0 and hr[3] == 0 and ir[6] >> 8 & 1
        c.write_registers(0, [3277, 0, 2, 1], device_id=UNIT)   # dropped while latched
        assert c.read_holding_registers(0, count=4, device_id=UNIT).registers[3] == 0
        c.write_registers(0, [0, 0, 3, 0], device_id=UNIT)      # acknowledge
        assert not c.read_input_registers(6, count=1, device_id=UNIT).registers[0] >> 8 & 1
        stats = server.stop()
    assert stats["watchdog_trips"] == 1


def test_a_program_through_the_packed_map_is_two_requests_per_tick(tmp_path):
    ref = run(RunSpec(builtin="corner"), out_dir=tmp_path, run_id="lockstep")
    with hil_server("--map", "packed") as server, fifo_priority():
        spec = RunSpec(builtin="corner", driver=f"{server.url}?map=packed")
        p = prepare(spec)
        before = p.driver.requests
        hil = run(spec, out_dir=tmp_path, run_id="packed", prepared=p)
        module = server.stop()
    s, r = hil.summary, ref.summary
    assert s["status"] == "FINISHED" and s["aborted"] is None, s.get("aborted")
    for key in ("max_contour_error_um", "rms_contour_error_um"):
        assert s[key] == pytest.approx(r[key], rel=0.10), (key, s["ticks"], module)
    ran = s["ticks"]["due"] - s["ticks"]["skipped"]
    per_tick = (p.driver.requests - before) / ran
    print(f"\npacked map: {per_tick:.4f} requests per tick over {ran} ticks, "
          f"ticks {s['ticks']}")
    assert 2.0 <= per_tick <= 2.0 + 4 / ran          # a read and a write; the close's write


def _frames(ir_count: int) -> list[tuple[str, bytes]]:
    """(connection, request) pairs: a tick's kinds of request, in range and out of it, the
    writes the module refuses, and requests only pymodbus serves."""
    import struct

    def frame(tid: int, unit: int, code: int, body: bytes) -> bytes:
        return struct.pack(">HHHBB", tid, 0, len(body) + 2, unit, code) + body

    def span(address: int, count: int) -> bytes:
        return struct.pack(">HH", address, count)

    def words(address: int, values: list[int]) -> bytes:
        return struct.pack(f">HHB{len(values)}H", address, len(values), 2 * len(values),
                           *values)

    return [
        ("a", frame(1, UNIT, 4, span(0, ir_count))),
        ("a", frame(2, UNIT, 4, span(1, 3))),
        ("a", frame(3, UNIT, 2, span(0, 9))),
        ("a", frame(4, UNIT, 2, span(2, 5))),
        ("a", frame(5, UNIT, 16, words(0, [3277]))),          # before the feed: refused (4)
        ("a", frame(6, UNIT, 16, words(0, [3277, 0, 1]))),    # feeds and sets: taken
        ("a", frame(7, UNIT, 4, span(0, ir_count))),
        ("a", frame(8, UNIT, 4, span(100, 2))),                # out of the table
        ("a", frame(9, UNIT, 4, span(0, 0))),                  # no register
        ("a", frame(10, UNIT, 16, words(200, [1, 2]))),         # out of the table
        ("a", frame(11, 9, 4, span(0, 2))),                    # another device
        ("a", frame(12, UNIT, 3, span(0, 3))),                 # pymodbus' own
        ("b", frame(13, UNIT, 16, words(0, [5]))),             # not the owner: busy (6)
        ("b", frame(14, UNIT, 4, span(0, ir_count))),          # reads stay open
        ("a", frame(15, UNIT, 16, words(0, [0, 0, 2]))),
        ("a", frame(16, UNIT, 3, span(0, 3))),
    ]


@pytest.mark.parametrize(("register_map", "ir_count"), [("default", 6), ("packed", 7)])
def test_the_tick_requests_are_answered_byte_for_byte_as_pymodbus_answers_them(
        register_map, ir_count):
    """The server answers a tick's requests itself (``hil_server.tick_answer``), not
    through pymodbus, which costs about 150 µs a request. The same requests, sent to a
    server that lets pymodbus answer everything, must get the same bytes back."""
    import socket

    answers = {}
    for mode in ("--fast", "--pymodbus-only"):
        with spawn_hil_server("--map", register_map, "--from", "50,20", "--no-noise",
                              "--watchdog-ms", "5000", mode) as server:
            port = server.info["port"]
            conns = {k: socket.create_connection(("127.0.0.1", port), timeout=1.0)
                     for k in "ab"}
            got = []
            try:
                for who, request in _frames(ir_count):
                    conns[who].sendall(request)
                    try:
                        got.append(conns[who].recv(512))
                    except TimeoutError:
                        got.append(b"(no answer)")
            finally:
                for c in conns.values():
                    c.close()
            stats = server.stop()
        answers[mode] = got
        assert stats["refused"] == 2 and stats["fault"] is None
        # the in-range requests of a tick's kinds to the module's device: 10 of the 16
        assert stats["direct"] == (10 if mode == "--fast" else 0)
    for k, (fast, reference) in enumerate(zip(answers["--fast"], answers["--pymodbus-only"],
                                              strict=True)):
        assert fast == reference, (k, _frames(ir_count)[k], fast.hex(" "),
                                   reference.hex(" "))
    codes = [a[7] for a in answers["--fast"] if len(a) > 7]
    assert 0x90 in codes and 0x84 in codes     # refusals and an error answer were checked
