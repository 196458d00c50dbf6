"""``twin identify``: calibrate the twin from a machine's own I/O.

Excite the axes through ``MachineIO`` (the controller's port: the twin, or real I/O), fit
the twin's physical parameters by replaying its own drive and mechanics against what was
measured, and write BASE with the identified fields replaced.

- ``plan``: the experiments (speed steps, PRBS, coast-downs, slow reversals, closed-loop
  ramps held out of the fit, home-switch crossings);
- ``experiments``: running them safely through a driver;
- ``log``: their record (JSON), checked against the machine it is fitted to;
- ``replay`` and ``fit``: the twin with candidate parameters and the staged fit;
- ``report``: the calibrated file, the PNG, the rerun recording;
- ``identify`` (here): the whole job, as the CLI runs it.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from twin.config import AXES, MachineConfig, load_machine, machine_from_toml_dict
from twin.errors import ConfigError, ExperimentAborted, FitError
from twin.system.jsonio import output_dir, record_id, write_json_atomic, write_text_atomic

__all__ = ["identify", "open_identification_driver"]


def open_identification_driver(url: str, base: MachineConfig, *, noise: bool = True):
    """The machine I/O ``url`` names and whether it is paced
    (``twin.session.machine_io.open_experiment_driver``). Returns (driver, paced)."""
    from twin.session.machine_io import open_experiment_driver

    return open_experiment_driver(url, base, noise=noise)


def identify(machine: str, output: str | Path, *, driver: str = "sim",
             controller_model: str | None = None, amplitude: float = 1.0,
             from_log: str | Path | None = None, out_dir: str | Path = "runs",
             noise: bool = True, rt_priority: int = 0, axes: str = "xy",
             progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run (or read) the experiments, fit, and write the calibrated machine file.

    Parameters
    ----------
    machine : str
        BASE: preset name or TOML file; the model the plan is scaled with and whose fields
        the fit replaces.
    output : path
        The calibrated machine file (written only when the fit converged).
    driver : str
        ``sim``, ``sim:FILE`` or ``modbus://HOST:PORT``.
    controller_model : str, optional
        The controller's model for the closed-loop experiments (default BASE).
    amplitude : float
        Scales every experiment's speeds (0, 1].
    from_log : path, optional
        Fit the experiments recorded in this directory (or file) instead of running them.
    out_dir : path
        Where the experiments' record directory ``identify-<id>/`` goes.
    noise : bool
        ``sim`` drivers: the machine file's sensor noise.
    rt_priority : int
        Real I/O: SCHED_FIFO priority of the experiments' loop (best effort; 0: none).
    axes : str
        The axes to identify (``x``, ``y``, ``xy``); the other is held in position and
        keeps BASE's values. A log says which axes it excited: with ``from_log`` this
        must name them or a subset of them.
    progress : callable(str), optional

    Returns
    -------
    dict
        The figures (``report.summary``) and the paths written.

    Raises
    ------
    ConfigError
        Bad options, or a log of another machine or an incomplete one.
    ExperimentAborted
        A safety stop during the experiments (the partial log is kept).
    FitError
        The fit did not converge; nothing is written under ``output``.
    """
    from twin.hardware.realtime import fifo_priority
    from twin.identify import report
    from twin.identify.experiments import run_plan, timing
    from twin.identify.fit import fit
    from twin.identify.log import IdentLog
    from twin.identify.plan import default_plan, parse_axes

    say = progress or (lambda _m: None)
    chosen = parse_axes(axes)
    base = load_machine(machine)
    output = Path(output)
    if output.suffix.lower() != ".toml":
        raise ConfigError("output", f"the calibrated machine file must end in .toml, got "
                          f"{str(output)!r}")
    output_dir(output.parent, "output")     # both folders writable before anything moves
    if from_log is None:
        output_dir(out_dir)
    if from_log is not None:
        log = IdentLog.load(from_log)   # checked against BASE by the fit
        absent = [a for a in chosen if a not in log.axes]
        if absent and chosen != tuple(AXES):
            raise ConfigError("axes", f"the log did not excite axis {', '.join(absent)} "
                              f"(it holds {''.join(log.axes)})")
        log.axes = [a for a in log.axes if a in chosen]
        where = Path(from_log)
        where = where if where.is_dir() else where.parent
    else:
        belief = load_machine(controller_model) if controller_model else base
        plan = default_plan(min(base.controller.limits.max_velocity,
                                *(base.axes[a].limits.max_velocity for a in AXES)),
                            amplitude=amplitude,
                            home_width=max(base.axes[a].switches.home_width for a in AXES))
        io, paced = open_identification_driver(driver, base, noise=noise)
        where = Path(out_dir) / record_id("identify-")
        where.mkdir(parents=True, exist_ok=False)
        say(f"experiments on {driver} ({'paced' if paced else 'lock-step'}), "
            f"record in {where}")
        try:
            with fifo_priority(rt_priority if paced else 0):
                log = run_plan(io, base, plan, belief=belief, paced=paced,
                               driver_name=driver, axes=chosen)
        except ExperimentAborted as exc:
            partial = getattr(exc, "log", None)
            if partial is not None:
                partial.save(where / "experiments.aborted.json")
            raise
        finally:
            io.close()
        log.save(where / "experiments.json")
        say(f"experiments: {log.ticks * base.controller.period:.1f} s of machine time")
    result = None
    try:
        result = fit(base, log, progress=say)
    except FitError as exc:
        when = timing(log.notes)
        if when:
            raise FitError(f"{exc} ({when})") from exc
        raise
    finally:
        if from_log is None:   # the experiments' recording, with the fitted twin if it fit
            report.record(log, base, where / "experiments.rrd", result)
    text = report.calibrated_toml(result, base, log, str(where))
    load_check = _write_checked(text, output)
    png = report.plot_report(result, log, where / "fit.png")
    out = report.summary(result, base, log)
    out.update({"calibrated": str(output), "record": str(where), "report": str(png),
                "calibrated_name": load_check.name})
    write_json_atomic(where / "fit.json", out)
    return out


def _write_checked(text: str, output: Path) -> MachineConfig:
    """Check that the calibrated file's text reads back to a valid machine, then write it
    atomically."""
    cfg = machine_from_toml_dict(tomllib.loads(text), source=str(output))
    write_text_atomic(output, text)
    return cfg
