"""``twin hil-server``: the twin as a Modbus/TCP I/O module (hardware in the loop).

Another process (``twin run --driver modbus://127.0.0.1:5020``, or any Modbus client) then
drives the twin over a real socket exactly as it would drive a real module; the physics runs
in real time in this process.
"""

from __future__ import annotations

import dataclasses
import os
import socket
import sys
from pathlib import Path

import typer
from rich.table import Table

from twin.cli.common import err, fail, parse_position
from twin.config.overrides import SET_HELP
from twin.errors import ConfigError, TwinError
from twin.hardware.realtime import set_fifo_priority
from twin.system.jsonio import json_text

__all__ = ["hil_server", "register"]



def hil_server(
    machine: str = typer.Option("tomsk_xy", "--machine", "-m",
                                help="Machine preset name or TOML file."),
    host: str = typer.Option("127.0.0.1", "--host", help="Interface to bind (0.0.0.0 "
                             "exposes the twin to the network)."),
    port: int = typer.Option(5020, "--port", min=0, max=65535,
                             help="TCP port; 0 picks a free one."),
    watchdog_ms: float = typer.Option(100.0, "--watchdog-ms", min=0.001,
                                      help="Outputs zeroed when no new watchdog value "
                                      "arrives for this long (ms)."),
    register_map: Path | None = typer.Option(None, "--map", help="Register map TOML "
                                             "(default: the documented default map)."),
    sets: list[str] = typer.Option([], "--set", help=SET_HELP),
    start: str | None = typer.Option(None, "--from", help="Table position at the start, "
                                     "X,Y in mm (default: the home keyframe)."),
    sync_phase: float = typer.Option(0.25, "--sync-phase", min=0.0, max=0.999,
                                     help="Steer the client's counter reads to this "
                                     "fraction of a drive interval (phase lock)."),
    no_sync: bool = typer.Option(False, "--no-sync", help="Free-running drive-interval "
                                 "grid instead (no phase lock)."),
    window_ms: float = typer.Option(2.0, "--output-window-ms", min=0.0, max=50.0,
                                    help="A DAC write arriving up to this late after its "
                                    "counter read's drive interval still acts from that "
                                    "interval (ms)."),
    noise: bool = typer.Option(True, "--noise/--no-noise", help="The machine file's sensor "
                               "noise (tacho, encoder); --no-noise silences it."),
    rt_priority: int = typer.Option(0, "--rt-priority", min=0, max=99,
                                    help="Serve under SCHED_FIFO at this priority (Linux, "
                                    "needs CAP_SYS_NICE); 0: normal scheduling."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object on stdout "
                                 "once listening (host, port, ...)."),
    fast: bool = typer.Option(True, "--fast/--pymodbus-only", help="Answer a tick's reads "
                              "and writes directly (a few µs instead of pymodbus' ~150); "
                              "--pymodbus-only lets pymodbus serve every request."),
    owner: list[str] = typer.Option([], "--owner", help="Only this client may claim the "
                                    "outputs (a host, an address or a network such as "
                                    "10.0.0.0/24; repeatable; replaces the machine's "
                                    "hil.owners); others may only read. Default: the first "
                                    "client to feed the watchdog."),
) -> None:
    """Serve the twin as a Modbus/TCP I/O module until Ctrl-C or SIGTERM."""
    import numpy as np

    from twin.config import load_machine
    from twin.config.overrides import parse_sets
    from twin.hardware.hil_server import hil_plant, serve_hil
    from twin.hardware.owners import Owners
    from twin.hardware.register_map import load_register_map

    try:
        cfg = load_machine(machine).with_overrides(parse_sets(sets))
        owners = Owners(owner, field="--owner") if owner else Owners(cfg.hil.owners)
        rmap = load_register_map(register_map)
        position = parse_position(start)
        try:
            plant = hil_plant(cfg, start=None if position is None else np.asarray(position),
                              noise=noise)
        except ConfigError as exc:
            raise ConfigError("--from", exc.message) from None
    except TwinError as exc:
        fail(exc, as_json)

    if rt_priority and not set_fifo_priority(rt_priority):
        err.print("[yellow]warning:[/] SCHED_FIFO not permitted here; serving with normal "
                  "scheduling", highlight=False)

    def ready(bound_host: str, bound_port: int) -> None:
        info = {"host": bound_host, "port": bound_port, "machine": cfg.name,
                "realtime": os.sched_getscheduler(0) == os.SCHED_FIFO,
                "watchdog_ms": watchdog_ms, "drive_interval_s": plant.drive_dt,
                "register_map": rmap.source, "owners": list(owners.entries)}
        if as_json:
            sys.stdout.write(json_text(info) + "\n")
            sys.stdout.flush()
            return
        table = Table(title=f"register map ({rmap.source})")
        for col in ("table", "address", "signal", "encoding"):
            table.add_column(col)
        for row in rmap.describe():
            table.add_row(*row)
        err.print(table)
        err.print(f"HIL server: {cfg.name} on modbus://{bound_host}:{bound_port} (unit "
                  f"{rmap.module.device_id}), drive interval {plant.drive_dt * 1e3:g} ms, "
                  f"watchdog {watchdog_ms:g} ms; outputs: {owners.describe()}; Ctrl-C stops",
                  highlight=False)

    try:
        socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        fail(ConfigError("--host", f"cannot bind {host!r}: {exc}"), as_json)
    try:
        stats = serve_hil(plant, rmap, host=host, port=port, watchdog=watchdog_ms * 1e-3,
                          sync_phase=None if no_sync else sync_phase,
                          output_window=window_ms * 1e-3,
                          on_ready=ready, fast=fast, owners=owners)
    except (OSError, RuntimeError) as exc:   # pymodbus: "Could not start listen" (in use)
        if "listen" not in str(exc) and not isinstance(exc, OSError):
            raise
        fail(ConfigError("--port", f"cannot listen on {host}:{port}: {exc}"), as_json)
    if as_json:  # stdout carried the one ready object; the statistics go to stderr
        sys.stderr.write(json_text({"hil_stats": dataclasses.asdict(stats)}) + "\n")
        return
    err.print(f"served {stats.requests} requests; {stats.sim_time:.3f} s of physics in "
              f"{stats.wall_time:.3f} s; most drive intervals caught up at once: "
              f"{stats.max_catch_up}; watchdog trips: {stats.watchdog_trips}; DAC writes "
              f"that missed their drive interval: {stats.late_writes} of {stats.dac_writes}"
              + (f"; fault: {stats.fault}" if stats.fault else ""), highlight=False,
              soft_wrap=True)


def register(app: typer.Typer) -> None:
    """Add ``hil-server`` to the ``twin`` app."""
    app.command("hil-server")(hil_server)
