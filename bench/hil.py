"""Benchmark: the default program through ``twin hil-server`` over loopback, at 200 Hz and
1 kHz, against the lock-step twin.

For each rate: the lock-step run (the reference), then the same run with the controller in
this process paced by ``RealTimeLoop`` and talking Modbus/TCP to a ``twin hil-server``
subprocess whose physics runs in real time. Reported per rate:

* ``ticks``: the deadline report (due, on time, late, skipped, jitter p50/p99/max in µs,
  on_time_ratio; on time = started within 10 % of the period);
* ``contour`` / ``coordinate``: max and RMS contour error and max coordinate errors (µm) of
  both runs and their ratio HIL / lock-step (issue 7: within 10 % at 200 Hz);
* ``requests_per_tick`` and the server's statistics (requests; most drive intervals caught
  up at once: 1–2 when the physics keeps up, plus the output window; watchdog trips; DAC
  writes, and the late ones that missed the output window, ``--output-window-ms``).

The client thread and the server run under SCHED_FIFO where the OS grants it (``--no-rt``
turns that off, to see what a plain time-shared process achieves), both on one CPU when
there are two (``--no-pin`` leaves them to the OS); ``--no-sync`` runs the
server's drive-interval grid free instead of phase-locked to the controller's reads. The
machine's load average is reported next to the figures: other work on the two cores shows
up as late ticks. Prints one JSON object.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import tempfile
import time
from collections.abc import Iterator

os.environ.setdefault("RERUN_ANALYTICS", "0")
os.environ.setdefault("NUMBA_CACHE_DIR", os.path.join(os.getcwd(), ".cache", "numba"))

from twin.hardware.hil_process import spawn_hil_server
from twin.hardware.realtime import fifo_priority
from twin.session.run import RunSpec, prepare, run


def _errors(summary: dict) -> dict:
    return {"max_contour_um": summary["max_contour_error_um"],
            "rms_contour_um": summary["rms_contour_error_um"],
            "max_coordinate_um": summary["max_coordinate_error_um"]}


@contextlib.contextmanager
def _pinned(server_pid: int, pin: bool) -> Iterator[dict | None]:
    """With ``pin`` and two CPUs or more (Linux): the server and this thread (the controller's
    loop) together on the last CPU, everything else left to the others; this thread is
    unpinned again afterwards. Yields the placement.

    One CPU for both, not one each: a request and its answer then hand the CPU over
    directly, while between two CPUs each hand-over waits for the other to wake (on this
    VM a 1 kHz tick's read and write took 325 µs at the median that way, against 199 µs
    on one CPU and 336 µs unpinned, where stalls of several ms also occurred)."""
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    if not pin or len(cpus) < 2:
        yield None
        return
    os.sched_setaffinity(server_pid, {cpus[-1]})
    os.sched_setaffinity(0, {cpus[-1]})
    try:
        yield {"server_cpu": cpus[-1], "client_cpu": cpus[-1]}
    finally:
        os.sched_setaffinity(0, set(cpus))


def _rate(args: argparse.Namespace, period: float, out: str) -> dict:
    overrides = {} if args.max_skipped is None else {
        "controller.deadlines.max_skipped_in_a_row": args.max_skipped}
    spec = RunSpec(machine=args.machine, builtin=args.program, period=period,
                   overrides=overrides)
    ref = run(spec, out_dir=out, rerun="none").summary
    server_args = ["--machine", args.machine, "--rt-priority", "0" if args.no_rt else "10"]
    if args.no_sync:
        server_args.append("--no-sync")
    server_args += ["--output-window-ms", str(args.output_window_ms), "--map", args.map]
    with spawn_hil_server(*server_args) as server:
        hil_spec = RunSpec(machine=args.machine, builtin=args.program, period=period,
                           driver=f"{server.url}?map={args.map}", overrides=overrides)
        p = prepare(hil_spec)
        requests0 = p.driver.requests
        with _pinned(server.process.pid, args.pin) as pinned, \
                fifo_priority(0 if args.no_rt else 10) as client_rt:
            hil = run(hil_spec, out_dir=out, rerun=args.rerun, prepared=p).summary
        ran = hil["ticks"]["due"] - hil["ticks"]["skipped"]
        per_tick = (p.driver.requests - requests0) / max(ran, 1)
        stats = server.stop()
    h, r = _errors(hil), _errors(ref)
    return {
        "period_s": period,
        "status": hil["status"],
        "aborted": hil["aborted"],
        "realtime": {"client": client_rt, "server": server.info["realtime"]},
        "pinned": pinned,
        "ticks": hil["ticks"],
        "hil": h,
        "lockstep": r,
        "ratio_max_contour": h["max_contour_um"] / r["max_contour_um"],
        "ratio_rms_contour": h["rms_contour_um"] / r["rms_contour_um"],
        "requests_per_tick": per_tick,
        "wall_time_s": hil["wall_time_s"],
        "server": stats,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machine", default="tomsk_xy")
    parser.add_argument("--program", default="default", help="built-in program (the CI-size "
                        "check uses corner)")
    parser.add_argument("--rates", default="200,1000", help="controller rates (Hz)")
    parser.add_argument("--rerun", default="file", help="telemetry of the HIL run: file "
                        "(as twin run) or none")
    parser.add_argument("--map", default="default", help="register map: default (three "
                        "requests per tick), packed (two) or a TOML file")
    parser.add_argument("--no-rt", action="store_true", help="normal scheduling")
    parser.add_argument("--no-sync", action="store_true", help="free-running server grid")
    parser.add_argument("--max-skipped", type=int, default=None, help="the deadline "
                        "policy's controller.deadlines.max_skipped_in_a_row for the runs "
                        "(default: the machine's); a shared VM stalls a few ms at times")
    parser.add_argument("--no-pin", dest="pin", action="store_false", help="leave the "
                        "server and the controller's loop to the OS's placement (default: "
                        "both on the last CPU, when there are two)")
    parser.add_argument("--output-window-ms", type=float, default=2.0, help="the server's "
                        "output window (0: a write must land in its read's interval)")
    args = parser.parse_args()
    load = os.getloadavg()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as out:
        rates = {f"{hz:g}_hz": _rate(args, 1.0 / hz, out)
                 for hz in (float(v) for v in args.rates.split(","))}
    print(json.dumps({
        "machine": args.machine,
        "program": args.program,
        "phase_lock": not args.no_sync,
        "output_window_ms": args.output_window_ms,
        "register_map": args.map,
        "max_skipped_in_a_row": args.max_skipped,
        "cpus": os.cpu_count(),
        "load_average_before": load,
        "load_average_after": os.getloadavg(),
        "bench_wall_s": time.perf_counter() - t0,
        "rates": rates,
    }))


if __name__ == "__main__":
    main()
