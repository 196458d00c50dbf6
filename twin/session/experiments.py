"""Typical experiments (seed 000's rig had a mode for them): a step or a ramp applied to the
position loop of one axis, or with ``open_loop`` straight to the drive's speed reference,
and the figures of the response: rise time, overshoot, settling time, steady-state error, and
the elastic mode seen in the screw deflection.

The closed-loop experiment is the controller itself (``Controller.test_signal``: the raw
step or ramp in place of the planned program) behind ``SimDriver``, ticked by the one tick
loop (``twin.session.loop.TickLoop``): the same encoder unwrapper, safety checks, regulator
with the machine's gains and DCU order (derived from the controller's model of the machine)
and timing as a program run. The output computed from the sample of tick k reaches the drive
at tick k + 1 (compute ahead, the one-period delay the gains and the DCU are derived for).
So it shows the loop the controller really closes, with a reference the planner would never
produce; a step that trips the following-error limit is refused, naming the setting. Each
record row holds what the regulator compared at its tick: the reference and the encoder
position of the same sample, and the twin's state at that instant. The open-loop
experiment puts its DAC source in the controller's place in the same loop. The screw
deflection is sampled every drive interval (not every controller period), so elastic modes
above the controller's Nyquist rate still show.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig
from twin.controller.controller import Controller
from twin.controller.io import Inputs, Outputs
from twin.controller.signals import SIGNALS
from twin.errors import ConfigError
from twin.plant import FINE_FIELDS, TRUTH_FIELDS
from twin.plant.model import axis_mechanics
from twin.session.loop import TickLoop
from twin.session.setup import wire
from twin.system.jsonio import output_dir, record_id, write_json_atomic
from twin.telemetry.channels import style_series, to_shown
from twin.telemetry.sink import NullSink, Sink

__all__ = ["ExperimentResult", "converter_lines", "describe", "dominant_frequency",
           "elastic_band", "record_experiment", "response_figures", "run_experiment"]

FINE_FIELDS_INDEX = tuple((name, k) for k, (name, _) in enumerate(FINE_FIELDS))
"""(field, index of its x column / 2) of the plant's drive-rate samples."""


FINE_DRAIN = 50
"""Ticks between drains of the twin's drive-rate samples (well inside its ring)."""


class _OpenLoop:
    """An open-loop test signal in the controller's place: the DAC volts of one axis, a
    step or a ramp from the first tick, written in the tick they are computed (no position
    loop, so no loop delay to keep), the drives enabled."""

    done = False
    read_ahead_in_tick = True    # nothing to read ahead: TickLoop's setting is kept, unused

    def __init__(self, axis: int, kind: str, amplitude: float, period: float):
        self.axis, self.kind, self.amplitude, self.period = axis, kind, amplitude, period
        self.out = Outputs()
        self.out.enable = True
        self.reference: list[float] = []
        """The volts written, one per tick."""

    def tick(self, _inputs: Inputs) -> Outputs:
        t = len(self.reference) * self.period
        u = self.amplitude if self.kind == "step" else self.amplitude * t
        self.out.dac_volts[self.axis] = u
        self.reference.append(u)
        return self.out

    def read_ahead(self) -> None:
        """No program: nothing to prepare."""


@dataclass(frozen=True)
class ExperimentResult:
    """Figures of a step or ramp response (SI; ``to_report`` gives µm, ms, Hz).

    Attributes
    ----------
    kind, axis : str
        "step" or "ramp"; "x" or "y".
    open_loop : bool
        True: applied to the drive reference (response = table speed); False: to the
        position loop (response = table position).
    amplitude : float
        Step height (m, or V open-loop) or ramp rate (m/s, or V/s open-loop).
    final_value : float
        Mean response over the last 10 % of the record (m or m/s).
    rise_time : float
        10 % → 90 % of the final value (s); NaN for a ramp.
    overshoot : float
        Peak beyond the final value over the final value's magnitude (1).
    settling_time : float
        Last time outside ±2 % of the final value (s).
    steady_state_error : float
        Reference minus response at the end (m or m/s; for a closed-loop ramp the
        following error).
    elastic_mode : float
        Dominant frequency of the screw deflection after the input (Hz).
    """

    kind: str
    axis: str
    open_loop: bool
    amplitude: float
    final_value: float
    rise_time: float
    overshoot: float
    settling_time: float
    steady_state_error: float
    elastic_mode: float

    def to_report(self) -> dict:
        """JSON-ready figures in engineering units."""
        unit = 1e6  # m → µm, m/s → µm/s
        return {**asdict(self), "final_value": self.final_value * unit,
                "steady_state_error": self.steady_state_error * unit,
                "rise_time_ms": self.rise_time * 1e3, "settling_time_ms":
                self.settling_time * 1e3, "overshoot_percent": self.overshoot * 100.0,
                "elastic_mode_hz": self.elastic_mode, "units": "µm or µm/s"}


def dominant_frequency(t: np.ndarray, signal: np.ndarray, *, f_min: float = 8.0,
                       exclude: tuple[float, ...] = (), width: float = 5.0,
                       f_max: float = math.inf) -> float:
    """Frequency (Hz) of the largest spectral peak above ``f_min`` of a uniformly sampled
    signal's derivative (detrended), refined by parabolic interpolation of the
    log-magnitude.

    ``f_min`` keeps the slow position-loop response (a few Hz) out of the search; both
    presets' first elastic modes (16 Hz belt, 90-160 Hz screws) lie well above it. Lines of
    a known forced excitation are left out within ``width`` (Hz) of each frequency in
    ``exclude``: a thyristor converter's torque pulses at p·f_mains and its harmonics drive
    the screw harder than the ringing of its mode, but they are not the mode. ``f_max``
    (Hz) bounds the search from above (:func:`elastic_band`)."""
    dt = float(t[1] - t[0])
    x = np.diff(signal) / dt     # weights the spectrum by f: the slow loop response fades
    x = x - np.polyval(np.polyfit(t[1:], x, 1), t[1:])
    x = x * np.hanning(len(x))
    n = 1 << (math.ceil(math.log2(len(x))) + 2)
    spec = np.abs(np.fft.rfft(x, n))
    freqs = np.fft.rfftfreq(n, dt)
    band = (freqs >= f_min) & (freqs <= f_max)
    for f in exclude:
        band &= np.abs(freqs - f) > width
    k = int(np.argmax(np.where(band, spec, 0.0)))
    if 0 < k < len(spec) - 1:
        a, b, c = np.log(spec[k - 1:k + 2] + 1e-300)
        shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
        return float((k + shift) * (freqs[1] - freqs[0]))
    return float(freqs[k])


def elastic_band(cfg: MachineConfig, axis: str) -> tuple[float, float]:
    """Where to look for the first elastic mode of ``axis`` (Hz): from half the machine
    file's lowest first mode over the travel (rotor locked, as the speed loop tends to hold
    it), but not below 8 Hz, to 1.5 times its highest (rotor free)
    (``twin.plant.model.axis_mechanics``; the screw stiffens towards the motor). A
    three-mass axis' second mode (the screw between gear and nut, 2.2 krad/s on tomsk_xy)
    lies above it, and so, on tomsk_xy, do the converter's 300 Hz torque pulses, whose
    skirt that mode amplifies beyond the lines' ±5 Hz."""
    travel = cfg.axes[axis].mechanics.travel
    chains = [axis_mechanics(cfg, axis, p) for p in (None, *travel)]
    low = min(c.locked_rotor_frequency for c in chains)
    high = max(c.free_rotor_frequency for c in chains)
    return max(8.0, 0.25 * low / math.pi), 0.75 * high / math.pi


def converter_lines(cfg: MachineConfig, axis: str, dt: float) -> tuple[float, ...]:
    """The frequencies (Hz) at which a pulse-level thyristor converter's torque pulses
    (p·f_mains and its harmonics), folded into the band a sample interval ``dt`` (s)
    resolves; none for a mean-value or PWM converter."""
    conv = cfg.axes[axis].converter
    if conv.kind != "thyristor" or conv.model != "pulse":
        return ()
    nyquist = 0.5 / dt
    base = conv.pulse_number * conv.mains_frequency
    lines = set()
    for h in range(1, 64):
        f = (h * base) % (2.0 * nyquist)
        lines.add(round(min(f, 2.0 * nyquist - f), 9))
    return tuple(sorted(lines))


def response_figures(t: np.ndarray, response: np.ndarray, reference: np.ndarray, *,
                     kind: str) -> dict[str, float]:
    """Rise time, overshoot, settling time (±2 %) and steady-state error of a response
    that starts at 0 (time from the input instant t[0] = 0)."""
    tail = max(1, len(t) // 10)
    final = float(np.mean(response[-tail:]))
    err = float(reference[-1] - response[-1])
    if kind == "ramp" or final == 0.0:
        return {"final_value": final, "rise_time": math.nan, "overshoot": 0.0,
                "settling_time": math.nan, "steady_state_error": err}
    y = response / final
    rise = math.nan
    i10 = np.flatnonzero(y >= 0.1)
    i90 = np.flatnonzero(y >= 0.9)
    if i10.size and i90.size:
        rise = float(t[i90[0]] - t[i10[0]])
    overshoot = max(0.0, float(np.max(y) - 1.0))
    outside = np.flatnonzero(np.abs(y - 1.0) > 0.02)
    settling = float(t[outside[-1] + 1]) if outside.size and outside[-1] + 1 < len(t) \
        else (0.0 if not outside.size else math.nan)
    return {"final_value": final, "rise_time": rise, "overshoot": overshoot,
            "settling_time": settling, "steady_state_error": err}


def run_experiment(cfg: MachineConfig, *, kind: str, axis: str, amplitude: float,
                   duration: float = 1.0, open_loop: bool = False,
                   sink: Sink | None = None, belief: MachineConfig | None = None
                   ) -> tuple[ExperimentResult, dict[str, np.ndarray]]:
    """Apply a step or ramp to one axis of the twin and measure the response.

    Parameters
    ----------
    cfg : MachineConfig
        The machine (the plant, and the controller's settings).
    kind : {"step", "ramp"}
    axis : {"x", "y"}
    amplitude : float
        Closed loop: step height (m) or ramp rate (m/s). Open loop: DAC step (V) or ramp
        rate (V/s).
    duration : float
        Length of the record after the input (s).
    open_loop : bool
        Drive reference instead of the position loop.
    sink : Sink, optional
        Telemetry (scalars on ``axes/<axis>/...``).
    belief : MachineConfig, optional
        The controller's model of the machine (its gains and DCU come from it); default
        ``cfg``.

    Returns
    -------
    (ExperimentResult, record)
        ``record`` has, per controller tick, ``t`` (the sample instant), ``reference`` and
        the encoder ``position`` the regulator compared then, the table's true
        ``velocity``, the ``dac_volts`` written at that tick and the ``armature_current``;
        and ``fine_t``, ``screw_deflection`` per drive interval (fine enough for the elastic
        mode), for the axis (SI).
    """
    if kind not in SIGNALS:
        raise ConfigError("kind", f"must be one of {SIGNALS}, got {kind!r}")
    if axis not in AXES:
        raise ConfigError("axis", f"must be one of {AXES}, got {axis!r}")
    if not (math.isfinite(amplitude) and amplitude != 0.0):
        raise ConfigError("amplitude", f"must be a non-zero number, got {amplitude!r}")
    if not (math.isfinite(duration) and 0.0 < duration <= 600.0):
        raise ConfigError("duration", f"must be a time in (0, 600] s, got {duration!r}")
    k = AXES.index(axis)
    period = cfg.controller.period
    n = round(duration / period)
    start = np.array([0.5 * (ax.switches.limit_min + ax.switches.limit_max)
                      for ax in cfg.axes.values()])
    lo, hi = cfg.axes[axis].switches.limit_min, cfg.axes[axis].switches.limit_max
    if not open_loop:
        far = start[k] + (amplitude if kind == "step" else amplitude * (n - 1) * period)
        if not lo < far < hi:
            raise ConfigError("amplitude", f"the reference would reach {far * 1e3:.4g} mm, "
                              f"outside the travel between the limit switches "
                              f"({lo * 1e3:.4g} … {hi * 1e3:.4g} mm)")
    wired = wire(cfg, None, belief=belief, start=start)
    plant = wired.plant
    assert plant is not None
    if open_loop:
        source: Controller | _OpenLoop = _OpenLoop(k, kind, amplitude, period)
    else:
        source = wired.controller
        source.test_signal(axis, kind, amplitude)
    truth = [plant.truth_row()]          # the state at each sample instant
    fine: list[np.ndarray] = []
    t_fine = plant.time
    loop = TickLoop(source, wired.driver, after_tick=lambda: truth.append(plant.truth_row()),
                    every=FINE_DRAIN, checkpoint=lambda: fine.append(plant.drain_fine()))
    loop.run(n)
    fine.append(plant.drain_fine())
    plant.enable(False)
    if loop.ticks < n:  # the controller stopped the machine: a fault latched
        status = source.status.name  # type: ignore[union-attr]
        raise ConfigError("amplitude", f"the controller stopped the {kind} on axis {axis} "
                          f"with {status} after {loop.ticks * period:.3f} s (following "
                          f"error limit controller.regulator.following_error_limit = "
                          f"{cfg.controller.regulator.following_error_limit * 1e3:g} mm): "
                          "choose a smaller amplitude")
    state = np.array(truth[:n])
    col = {name: 2 * i + k for i, (name, _) in enumerate(TRUTH_FIELDS)}
    t = period * np.arange(n)
    if open_loop:
        reference = np.array(source.reference[:n])
        measured = state[:, col["table_velocity"]]
        dac = reference
    else:
        r = source.record.as_arrays()
        reference = r["ref_position"][:n, k] - start[k]
        measured = r["position"][:n, k] - start[k]
        dac = r["dac_volts"][:n, k]
    rec = {"t": t, "reference": reference, "position": measured,
           "velocity": state[:, col["table_velocity"]], "dac_volts": np.array(dac),
           "armature_current": state[:, col["armature_current"]]}
    rows = np.concatenate(fine)
    rec["fine_t"] = t_fine + plant.drive_dt * np.arange(1, len(rows) + 1)
    rec["screw_deflection"] = rows[:, 2 * dict(FINE_FIELDS_INDEX)["screw_deflection"] + k]
    response = rec["velocity"] if open_loop else rec["position"]
    if open_loop:  # the steady speed the drive should reach: U/K_C·r
        ratio = cfg.axes[axis].transmission.ratio / cfg.axes[axis].tacho.gain
        ref_speed = rec["reference"] * ratio
    else:
        ref_speed = rec["reference"]
    figs = response_figures(rec["t"], response, ref_speed, kind=kind)
    low, high = elastic_band(cfg, axis)
    mode = dominant_frequency(rec["fine_t"], rec["screw_deflection"], f_min=low, f_max=high,
                              exclude=converter_lines(cfg, axis, plant.drive_dt))
    result = ExperimentResult(kind=kind, axis=axis, open_loop=open_loop,
                              amplitude=float(amplitude), elastic_mode=mode, **figs)
    if sink is not None and not isinstance(sink, NullSink):
        _record(sink, axis, rec, open_loop)
    return result, rec


def _record(sink: Sink, axis: str, rec: dict, open_loop: bool) -> None:
    """Send an experiment's record to ``sink`` in the recorded units (``SERIES``): closed
    loop, the reference and the position (mm from the start); the table's velocity, the
    DAC volts (open loop: the input) and armature current, the screw deflection."""
    base = f"axes/{axis}"
    cols = {f"{base}/velocity/actual": to_shown("mm/min", rec["velocity"]),
            f"{base}/drive/dac_volts": np.asarray(rec["dac_volts"], dtype=np.float64),
            f"{base}/drive/armature_current": np.asarray(rec["armature_current"])}
    if not open_loop:      # open loop, the record's "position" is the response: a speed
        cols[f"{base}/position/reference"] = to_shown("mm", rec["reference"])
        cols[f"{base}/position/actual"] = to_shown("mm", rec["position"])
    style_series(sink, [*cols, f"{base}/screw_deflection_um"])
    sink.scalars(rec["t"], cols)
    sink.scalars(rec["fine_t"], {f"{base}/screw_deflection_um":
                                 to_shown("µm", rec["screw_deflection"])})


def describe(kind: str, axis: str, amplitude: float, open_loop: bool) -> str:
    """The experiment in the words of the command line: ``step x 1 mm, closed loop``
    (``amplitude`` in SI: m or m/s closed loop, V or V/s open loop)."""
    if open_loop:
        return f"{kind} {axis} {amplitude:.6g} V{'/s' if kind == 'ramp' else ''}, open loop"
    return f"{kind} {axis} {amplitude * 1e3:.6g} mm{'/s' if kind == 'ramp' else ''}, closed loop"


def record_experiment(cfg: MachineConfig, *, out_dir: str | Path, rerun: str = "file",
                      run_id: str | None = None, belief: MachineConfig | None = None,
                      **experiment: Any) -> tuple[ExperimentResult, dict[str, Any]]:
    """``run_experiment`` with its records, as every command leaves them: ``<run_id>.json``
    (the figures, in ``to_report``'s units) and the ``.rrd`` that ``rerun`` names (file:
    ``out_dir/<run_id>.rrd``, with the experiment's layout). An experiment refused (an
    amplitude outside the travel, a trip) writes nothing. Returns (result, summary)."""
    from twin.session.record import make_sink
    from twin.telemetry.blueprint import experiment_blueprint

    result, rec = run_experiment(cfg, belief=belief, **experiment)   # refused: no file
    run_id = run_id or record_id()
    out = output_dir(out_dir)
    axis = experiment["axis"]
    open_loop = experiment.get("open_loop", False)
    sink, recording = make_sink(rerun, out, run_id,
                                blueprint=lambda extents: experiment_blueprint(axis, extents))
    what = describe(experiment["kind"], axis, experiment["amplitude"], open_loop)
    _record(sink, axis, rec, open_loop)
    summary = {"run_id": run_id, "status": "FINISHED", "experiment": what,
               "machine": cfg.name, "controller_model": (belief or cfg).name,
               "recording": recording, **result.to_report(),
               "spec": {"program": None, "builtin": None, "experiment": what}}
    finish = getattr(sink, "finish", None)
    if finish is not None:
        finish()
    write_json_atomic(out / f"{run_id}.json", summary)   # the summary first, then the .rrd
    sink.close()
    return result, summary
