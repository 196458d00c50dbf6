"""``measure``: the whole frequency-response measurement of one axis (see the package
docstring): options checked, the axis moved to where the excitation has room, the
excitation run, the response estimated and compared with the linearised twin of the
controller's belief, the record written."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from twin.analysis.frequency import estimate, hammer, modes
from twin.analysis.frequency.excitation import (
    Excitation,
    multisine,
    period_length,
    prbs,
)
from twin.analysis.frequency.prediction import (
    closed_loop_modes,
    design_loop,
    predict,
)
from twin.analysis.frequency.record import run_excitation
from twin.analysis.frequency.result import LOOPS, SENSORS, FrequencyResponse
from twin.config import AXES, MachineConfig, load_machine
from twin.controller.loop_defaults import loop_gains
from twin.errors import ConfigError
from twin.hardware.register_map import MAPS
from twin.session.machine_io import move_to, open_experiment_driver
from twin.session.setup import axis_models, measured_position

__all__ = ["EXCITATIONS", "MARGIN", "measure", "plan_room"]

EXCITATIONS = ("multisine", "prbs", "hammer")
MARGIN = 1e-3
"""Room kept between the measurement and the end switches (m)."""
HOLD = 0.2e-3
"""How far the axis that is not measured may move from where it is held (m)."""
MAX_PERIOD = 2**16
"""Most controller periods in one period of the excitation (the lowest f_min)."""
PERIODS = 8
"""Multisine periods measured per realisation where the accelerometer measures: its noise
(an ADXL345's 400 µg/√Hz) against the small acceleration a one-signed speed allows; with one
period laser_belt's first mode came out 1–5 % off over accelerometer seeds 0–5, with
four within 1.2 % but 8° off the model on lines of γ² ≥ 0.9, with eight within 0.9 % and
4.2°."""
UNITS = {"mechanics": "m/(s²·V)", "speed": "m/(s·V)", "position": "1"}


def _machine(machine) -> MachineConfig:
    return machine if isinstance(machine, MachineConfig) else load_machine(machine)


def _choice(name: str, value: str, valid: tuple[str, ...]) -> None:
    if value not in valid:
        raise ConfigError(name, f"must be one of {', '.join(valid)}, got {value!r}")


def nyquist(cfg: MachineConfig, loop: str, sensor: str) -> float:
    """The highest frequency the measurement can reach (Hz): the accelerometer's Nyquist
    frequency for what it sees, else the controller's."""
    if sensor == "accelerometer" and loop != "position":
        return 0.5 * cfg.accelerometer.sample_rate
    return 0.5 / cfg.controller.period


def plan_room(cfg: MachineConfig, axis: str, excursion: tuple[float, float],
              here: np.ndarray) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Where the measurement starts and each axis' window: the point nearest ``here`` (m)
    from which the measured axis' ``excursion`` (lowest, highest travel from the start, m)
    stays ``MARGIN`` inside the end switches; the other axis is held where it is.

    Raises
    ------
    ConfigError
        ``amplitude``: the work zone has no room for the excursion.
    """
    target = np.array(here, dtype=float)
    window = []
    lo, hi = excursion
    for k, a in enumerate(AXES):
        if a != axis:
            window.append((here[k] - HOLD, here[k] + HOLD))
            continue
        sw = cfg.axes[a].switches
        safe_lo, safe_hi = sw.limit_min + MARGIN, sw.limit_max - MARGIN
        if safe_hi - safe_lo < hi - lo:
            raise ConfigError("amplitude", f"axis {a}: the measurement travels "
                              f"{1e3 * (hi - lo):.1f} mm, the work zone holds "
                              f"{1e3 * (safe_hi - safe_lo):.1f} mm; lower --amplitude, "
                              "--offset, --averages or raise --f-min")
        target[k] = min(max(here[k], safe_lo - lo), safe_hi - hi)
        window.append((max(target[k] + lo - 0.5 * MARGIN, sw.limit_min),
                       min(target[k] + hi + 0.5 * MARGIN, sw.limit_max)))
    return target, window


def _excitations(kind: str, cfg: MachineConfig, sensor: str, loop: str, f_min: float,
                 f_max: float, realisations: int) -> list[Excitation]:
    """The excitation's realisations: random-phase multisines of seeds 0, 1, … (one PRBS:
    its realisations would be shifts of one another)."""
    period = cfg.controller.period
    rate = (cfg.accelerometer.sample_rate if sensor == "accelerometer"
            and loop != "position" else None)
    top = min(f_max, 0.5 / period * 0.999)
    minimum = math.ceil(1.0 / (f_min * period) - 1e-9)
    if kind == "multisine":
        length = period_length(minimum, period, rate)
        return [multisine(length, period, f_min, top, seed=seed)
                for seed in range(realisations)]
    return [prbs(minimum, period, f_min, top)]


def _excursion(values: np.ndarray, period: float, amplitude: float, offset: np.ndarray,
               loop: str) -> tuple[float, float]:
    """Lowest and highest travel from the start (m) of the commanded speed over the run
    (``values``: the excitation, peak 1, and ``offset``: the speed kept (m/s), one of each
    per slot), with a fifth of the span and a millimetre added for the response's own
    excursions."""
    speed = offset + amplitude * values
    if loop == "position":   # the loop holds the excitation's travel down; the ramp stays
        speed = offset + 0.0 * speed
    travel = np.concatenate(([0.0], np.cumsum(speed) * period))
    lo, hi = float(travel.min()), float(travel.max())
    pad = 0.2 * (hi - lo) + 1e-3 * (amplitude > 0)
    return lo - pad, hi + pad


def _options(base: MachineConfig, belief: MachineConfig, axis: str, loop: str,
             sensor: str, excitation: str, averages: int, amplitude: float | None,
             offset: float | None, f_min: float | None, f_max: float | None
             ) -> tuple[float, float, float, float]:
    """The options checked and their defaults filled in: (amplitude, offset (m/s), f_min,
    f_max (Hz)).

    Raises
    ------
    ConfigError
        Naming the option.
    """
    _choice("axis", axis, AXES)
    _choice("loop", loop, LOOPS)
    _choice("sensor", sensor, SENSORS)
    if not (isinstance(averages, int) and 1 <= averages <= 1000):
        raise ConfigError("averages", f"must be a whole number 1 … 1000, got {averages!r}")
    period = base.controller.period
    top_limit = nyquist(base, loop, sensor)
    f_min = 1.0 if f_min is None else float(f_min)
    f_max = (min(top_limit, 0.75 / period) if sensor == "accelerometer" and loop != "position"
             else 0.999 * top_limit) if f_max is None else float(f_max)
    if not (math.isfinite(f_max) and 0.0 < f_max <= top_limit):
        who = "accelerometer" if top_limit > 0.5 / period else "controller"
        raise ConfigError("f_max", f"must lie in (0, {top_limit:g}] Hz, the Nyquist "
                          f"frequency of the {who}, got {f_max:g} Hz")
    lowest = 1.0 / (MAX_PERIOD * period)
    if not (math.isfinite(f_min) and lowest <= f_min < min(f_max, 0.5 / period)):
        raise ConfigError("f_min", f"must lie in [{lowest:.3g}, "
                          f"{min(f_max, 0.5 / period):g}) Hz, got {f_min:g} Hz")
    v_max = min(base.axes[axis].limits.max_velocity, base.controller.limits.max_velocity)
    amplitude = 0.25 * v_max if amplitude is None else float(amplitude)
    offset = 0.5 * v_max if offset is None else float(offset)
    if not (math.isfinite(amplitude) and 0.0 < amplitude <= v_max):
        raise ConfigError("amplitude", f"must lie in (0, {1e3 * v_max:g}] mm/s, the axis' "
                          f"speed limit, got {1e3 * amplitude:g} mm/s")
    if not (math.isfinite(offset) and abs(offset) + amplitude <= 1.5 * v_max):
        raise ConfigError("offset", f"|offset| + amplitude must stay within 1.5 × the "
                          f"speed limit ({1.5e3 * v_max:g} mm/s), got {1e3 * offset:g} mm/s")
    dac_peak = amplitude * belief.axes[axis].volts_per_speed + (
        0.0 if loop == "position" else abs(offset) * belief.axes[axis].volts_per_speed)
    if dac_peak > base.axes[axis].dac.full_scale:
        raise ConfigError("amplitude", f"needs {dac_peak:.2f} V at the DAC, beyond its "
                          f"{base.axes[axis].dac.full_scale:g} V")
    return amplitude, offset, f_min, f_max


def _settings_of(excitation: str, hammer_force: float | None, hammer_duration: float | None,
                 periods: int | None) -> None:
    """Refuse an unknown excitation, and a setting given to an excitation it is not of."""
    _choice("excitation", excitation, EXCITATIONS)
    for name, value in (("hammer_force", hammer_force), ("hammer_duration", hammer_duration)):
        if value is not None and excitation != "hammer":
            raise ConfigError(name, f"is a setting of the hammer: only with --excitation "
                              f"hammer, not {excitation}")
    if periods is not None and excitation != "multisine":
        raise ConfigError("periods", f"is a setting of the multisine (periods measured per "
                          f"realisation): only with --excitation multisine, not {excitation}")


def _periods(periods: int | None, sensor: str, loop: str) -> int:
    """Periods measured per multisine realisation: ``periods`` checked, or the default
    (``PERIODS`` where the accelerometer measures, else 1)."""
    if periods is None:
        return PERIODS if sensor == "accelerometer" and loop != "position" else 1
    if not (isinstance(periods, int) and 1 <= periods <= 100):
        raise ConfigError("periods", f"must be a whole number 1 … 100, got {periods!r}")
    return periods


def measure(machine, *, driver: str = "sim", axis: str = "x", loop: str = "mechanics",
            sensor: str = "accelerometer", amplitude: float | None = None,
            offset: float | None = None, averages: int = 8, periods: int | None = None,
            f_min: float | None = None, f_max: float | None = None,
            excitation: str = "multisine", out_dir=None, controller_model=None,
            noise: bool = True, hammer_force: float | None = None,
            hammer_duration: float | None = None,
            progress: Callable[[str], None] | None = None) -> FrequencyResponse:
    """See ``twin.analysis.frequency.measure``."""
    say = progress or (lambda _m: None)
    base = _machine(machine)
    belief = _machine(controller_model) if controller_model is not None else base
    _settings_of(excitation, hammer_force, hammer_duration, periods)
    if excitation == "hammer":
        return _tap_test(base, belief, driver, axis, loop, sensor, averages, hammer_force,
                         hammer_duration, f_min, f_max, out_dir, noise, say)
    amplitude, offset, f_min, f_max = _options(base, belief, axis, loop, sensor,
                                               excitation, averages, amplitude, offset,
                                               f_min, f_max)
    periods = _periods(periods, sensor, loop)
    period = base.controller.period
    excs = _excitations(excitation, base, sensor, loop, f_min, f_max, averages)
    exc = excs[0]
    values, speeds, measured = _schedule(excs, averages, periods, offset)
    lo, hi = _excursion(values, period, amplitude, speeds, loop)
    plan_room(base, axis, (lo, hi), _middle(base))   # room anywhere at all: before the machine
    if out_dir is not None:
        from twin.system.jsonio import output_dir
        output_dir(out_dir)
    io, paced = open_experiment_driver(driver, base, noise=noise,
                                       accelerometer=sensor == "accelerometer")
    try:
        if sensor == "accelerometer" and loop != "position" and paced and (
                io.map.module.accelerometer is None):   # type: ignore[attr-defined]
            raise ConfigError("sensor", "the I/O module's register map has no accelerometer "
                              "(module.accelerometer; e.g. ?map=" + str(MAPS["accelerometer"])
                              + "); or measure with --sensor motor")
        here = measured_position(io.read().encoder_counts, base)
        target, window = plan_room(base, axis, (lo, hi), here)
        say(f"{driver}: moving to x {1e3 * target[0]:.2f} mm, y {1e3 * target[1]:.2f} mm")
        move_to(io, base, belief, target, paced)
        volts = amplitude * belief.axes[axis].volts_per_speed * values
        say(f"{exc.kind}: {exc.length} ticks a period, {len(exc.lines)} lines from "
            f"{exc.lines[0] * exc.resolution:.2f} Hz, {len(values) // exc.length} periods "
            f"({len(values) * period:.1f} s)")
        rec = run_excitation(io, base, belief, axis=axis, loop=loop, volts=volts,
                             offset=speeds, window=window,
                             accelerometer=sensor == "accelerometer" and loop != "position",
                             paced=paced)
    finally:
        io.close()
    k = AXES.index(axis)
    position = float(0.5 * (rec.position.min() + rec.position.max())) if len(
        rec.position) else float(target[k])
    position = min(max(position, belief.axes[axis].mechanics.travel[0]),
                   belief.axes[axis].mechanics.travel[1])
    seen_by = "accelerometer" if sensor == "accelerometer" and loop != "position" else "motor"
    try:
        spec = estimate.spectra(rec, exc, loop=loop, sensor=seen_by, measured=measured,
                                ratio=belief.axes[axis].transmission.ratio,
                                tacho_gain=belief.axes[axis].tacho.gain,
                                sample_rate=base.accelerometer.sample_rate, f_max=f_max)
    except ValueError as exc_:
        from twin.errors import ExperimentAborted
        raise ExperimentAborted(f"the measurement is incomplete: {exc_}") from None
    response, coherence = spec.response()
    f = spec.frequency
    gains = loop_gains(base.controller, [base.axes[a] for a in AXES], axis_models(belief),
                       base.controller.regulator.dcu_order)
    prediction = predict(belief, axis, position, loop, seen_by, f, gains)
    rigid = predict(belief, axis, position, loop, seen_by, f, gains, rigid=True)
    good = coherence >= estimate.COHERENT
    resonances = modes.resonances(f, response, coherence, rigid, axis, seen_by,
                                  len(spec.dac))
    margins = None
    info: dict[str, Any] = {}
    if loop == "position":
        margins = estimate.margins(f[good], response[good])
        dense = np.linspace(f[0], f[-1], 2000)
        design = estimate.margins(dense, design_loop(axis_models(belief)[k], gains, axis,
                                                     period, dense))
        info["design_margins"] = design.to_dict()
    info["resonance_sd_hz"] = modes.jackknife(spec, resonances, rigid, axis, seen_by,
                                              averaged=True)
    info["accelerometer_rate_hz"] = (base.accelerometer.sample_rate
                                     if seen_by == "accelerometer" else None)
    top = float(f[good].max()) if good.any() else 0.0
    poles = closed_loop_modes(belief, axis, position)
    unseen = modes.unseen(belief, axis, position, seen_by, loop, top,
                          found=[r.frequency for r in resonances], poles=poles)
    info.update(_info(base, belief, driver, exc, amplitude, offset, averages,
                      len(measured), rec, f, response, prediction, good, axis, position,
                      poles))
    result = FrequencyResponse(f, response, coherence, prediction, resonances, margins,
                               unseen, loop, seen_by, axis, UNITS[loop], position, info)
    if out_dir is not None:
        from twin.analysis.frequency.report import write_record
        result = write_record(result, rec, Path(out_dir))
    return result


def _schedule(excs: list[Excitation], averages: int, periods: int, offset: float
              ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """The run, one value per slot: the excitation (peak 1), the speed kept (m/s) and the
    numbers of the periods measured. Each multisine realisation has a period to settle,
    then ``periods`` measured, and runs the other way from the one before (the speed kept
    changes sign in its settling period, where friction reverses), so the travel does not
    grow with the averaging; one PRBS settles, then runs ``averages`` periods one way."""
    if len(excs) == 1:
        values = np.tile(excs[0].values, 1 + averages)
        return values, np.full(len(values), offset), list(range(1, 1 + averages))
    n = excs[0].length
    values = np.concatenate([np.tile(e.values, 1 + periods) for e in excs])
    sign = np.repeat([(-1.0) ** i for i in range(len(excs))], n * (1 + periods))
    measured = [i * (1 + periods) + 1 + j for i in range(len(excs)) for j in range(periods)]
    return values, offset * sign, measured


def _middle(base: MachineConfig) -> np.ndarray:
    """The middle of each axis' travel (m)."""
    return np.array([0.5 * sum(base.axes[a].mechanics.travel) for a in AXES])


def _tap_test(base: MachineConfig, belief: MachineConfig, driver: str, axis: str, loop: str,
              sensor: str, averages: int, force: float | None, duration: float | None,
              f_min: float | None, f_max: float | None, out_dir, noise: bool,
              say: Callable[[str], None]) -> FrequencyResponse:
    """``--excitation hammer``: its settings checked, then the tap test at mid-travel
    (``twin.session.hammer``)."""
    _choice("axis", axis, AXES)
    if not (isinstance(averages, int) and 1 <= averages <= 1000):
        raise ConfigError("averages", f"must be a whole number 1 … 1000, got {averages!r}")
    opts = hammer.check(driver, loop, sensor, force, duration, f_min, f_max, averages,
                        base.accelerometer.sample_rate)
    target, window = plan_room(base, axis, hammer.REACH, _middle(base))
    return hammer.tap_test(base, belief, driver, axis, opts, target, window,
                           out_dir=out_dir, noise=noise, say=say)


def _info(base: MachineConfig, belief: MachineConfig, driver: str, exc: Excitation,
          amplitude: float, offset: float, averages: int, periods: int, rec,
          f: np.ndarray,
          response: np.ndarray, prediction: np.ndarray, good: np.ndarray, axis: str,
          position: float, poles: list[complex]) -> dict[str, Any]:
    return {
        "machine": base.name, "controller_model": belief.name, "driver": driver,
        "excitation": {"kind": exc.kind, "ticks_per_period": exc.length,
                       "resolution_hz": exc.resolution, "lines": len(exc.lines),
                       "amplitude_mm_s": 1e3 * amplitude, "offset_mm_s": 1e3 * offset,
                       "averages": averages, "periods_measured": periods},
        "machine_time_s": len(rec.slot) * exc.period,
        "accelerometer_samples_lost": int(rec.lost),
        **modes.compared(response, prediction, good, belief, axis, position, poles),
        "deadlines": None if rec.stats is None else rec.stats.to_dict(),
    }

