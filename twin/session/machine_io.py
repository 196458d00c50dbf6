"""Experiments on a machine through ``MachineIO``: open the machine a driver URL names, and
move it with the controller's own planned jog. Shared by ``twin identify`` and
``twin measure``, which run the same way on the twin (lock-step) and on real I/O (paced).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from twin.config import AXES, MachineConfig, load_machine
from twin.controller.controller import Controller, ControllerStatus
from twin.controller.io import Inputs, MachineIO, Outputs
from twin.errors import ConfigError, ExperimentAborted
from twin.session.loop import TickLoop
from twin.session.setup import measured_position, model_options

__all__ = ["check_safe", "io_signature", "move_to", "open_experiment_driver", "safe_stop"]


def io_signature(cfg: MachineConfig) -> dict:
    """What a stand-in machine (and a log) must agree on with the machine the experiments
    are planned with: the I/O and the period."""
    return {
        "period": cfg.controller.period,
        "counts_per_metre": [cfg.axes[a].counts_per_metre for a in AXES],
        "encoder_bits": [cfg.axes[a].encoder.bits for a in AXES],
        "dac_full_scale": [cfg.axes[a].dac.full_scale for a in AXES],
    }


def open_experiment_driver(url: str, base: MachineConfig, *, noise: bool = True,
                           accelerometer: bool = False) -> tuple[MachineIO, bool]:
    """The machine I/O ``url`` names and whether it is paced: ``sim`` (the twin of BASE),
    ``sim:FILE`` (the twin of another machine file or preset: a stand-in for a real one),
    ``modbus://HOST:PORT`` (real I/O, or the HIL server). ``accelerometer``: on the twin,
    mount the table accelerometer (``[accelerometer]``) if the file has none, as an engineer
    clamps one on for a test. Returns (driver, paced)."""
    from twin.hardware.sim import SimDriver
    from twin.plant import Plant

    if url == "sim" or url.startswith("sim:"):
        machine = base if url == "sim" else load_machine(url[4:])
        if url != "sim" and io_signature(machine) != io_signature(base):
            raise ConfigError("driver", f"{url}: its I/O (counts per metre, counter "
                              f"width, period, DAC range) differs from {base.name}'s")
        if accelerometer and not machine.accelerometer.mounted:
            machine = dataclasses.replace(machine, accelerometer=dataclasses.replace(
                machine.accelerometer, mounted=True))
        plant = Plant.from_machine(machine, noise=noise)
        plant.reset()
        return SimDriver(plant, machine.controller.period), False
    from twin.hardware.drivers import open_driver

    return open_driver(url, base), True


def move_to(driver: MachineIO, base: MachineConfig, belief: MachineConfig,
            target: np.ndarray, paced: bool) -> None:
    """The controller's own planned jog to ``target`` (m), run to FINISHED.

    Raises
    ------
    ExperimentAborted
        The jog did not finish (a safety stop of the controller).
    """
    here = measured_position(driver.read().encoder_counts, base)
    if np.allclose(here, target, atol=2.0 / min(base.axes[a].counts_per_metre for a in AXES)):
        return
    ctrl = Controller.from_machine(base, None, start=here, **model_options(belief))
    ctrl.jog(list(target))
    loop = TickLoop(ctrl, driver)
    limit = round(120.0 / base.controller.period)  # two minutes: a jog never needs more
    if paced:
        loop.run_paced(base.controller.period, max_ticks=limit)
    else:
        loop.run(limit)
    if ctrl.status != ControllerStatus.FINISHED:
        raise ExperimentAborted(f"the move to the experiments' start point ended "
                                f"{ctrl.status.name}: {ctrl.error or ''}".rstrip(": "))


def check_safe(inputs: Inputs, pos: np.ndarray, window: np.ndarray, where: str, *,
               room: str, drives: bool = True) -> None:
    """The guard of an open-loop experiment (identification, measurement) each tick: an end
    limit switch, drives not ready (unless ``drives`` is False, as on a coast-down), or an
    axis outside ``window`` ((2, 2) low/high, m) aborts it, naming ``where``.

    Raises
    ------
    ExperimentAborted
    """
    if np.any(inputs.limit_min) or np.any(inputs.limit_max):
        raise ExperimentAborted(f"an end limit switch closed {where}")
    if drives and not inputs.drive_ready:
        raise ExperimentAborted(f"the drives reported not ready {where}")
    for k, (lo, hi) in enumerate(window):
        if not lo <= pos[k] <= hi:
            raise ExperimentAborted(
                f"axis {AXES[k]} left the room given to {room} "
                f"({1e3 * lo:.3f} … {1e3 * hi:.3f} mm) {where}")


def safe_stop(driver: MachineIO, out: Outputs) -> None:
    """Safe stop: outputs zero, drives disabled (best effort: the caller reports what
    failed)."""
    out.dac_volts[:] = 0.0
    out.enable = False
    try:
        driver.write(out)
    except Exception:  # the stop is best effort; the caller reports what failed
        pass
