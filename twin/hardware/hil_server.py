"""The HIL module served: ``serve_hil`` runs a ``HilModule`` behind a pymodbus
``ModbusTcpServer`` (asyncio, one thread: no locks) until SIGINT/SIGTERM, advancing the
physics between requests. It binds 127.0.0.1 unless told otherwise. ``hil_plant`` makes the
plant it serves.
"""

from __future__ import annotations

import asyncio
import gc
import signal
from collections.abc import Callable

import numpy as np
from pymodbus.server import ModbusTcpServer

from twin.config import MachineConfig
from twin.hardware.hil import OUTPUT_WINDOW, HilModule, HilStats
from twin.hardware.register_map import RegisterMap
from twin.plant import Plant

__all__ = ["hil_plant", "serve_hil"]


async def _serve(module: HilModule, host: str, port: int,
                 on_ready: Callable[[str, int], None] | None) -> None:
    server = ModbusTcpServer(module.sim_device(), address=(host, port))
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
              on_ready: Callable[[str, int], None] | None = None) -> HilStats:
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

    Returns
    -------
    HilStats
    """
    module = HilModule(plant, register_map, watchdog=watchdog, sync_phase=sync_phase,
                       output_window=output_window)
    asyncio.run(_serve(module, host, port, on_ready))
    return module.stats()
