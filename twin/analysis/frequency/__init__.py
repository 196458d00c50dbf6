"""Frequency-response measurement of one axis (``twin measure``): what drive engineers
measure with (SINUMERIK's measuring functions, TwinCAT's validation Bode plot, Klipper's
resonance test).

``measure`` excites one axis through ``MachineIO`` (the twin, or real I/O), with a
multisine or a PRBS about a speed offset (or, on the twin, strikes its table with a modal
hammer while the drives hold: ``twin.analysis.frequency.hammer``), averages whole periods
and returns a ``FrequencyResponse``: the response with its coherence, the linearised
prediction of the controller's belief, the resonances the sensor saw (``Resonance``), the
position loop's margins, and the modes the sensor cannot see.
"""

from twin.analysis.frequency.result import (
    LOOPS,
    SENSORS,
    FrequencyResponse,
    Margins,
    Resonance,
)

__all__ = ["EXCITATIONS", "LOOPS", "SENSORS", "FrequencyResponse", "Margins", "Resonance",
           "measure"]

EXCITATIONS = ("multisine", "prbs", "hammer")


def measure(machine, *, driver: str = "sim", axis: str = "x", loop: str = "mechanics",
            sensor: str = "accelerometer", amplitude: float | None = None,
            offset: float | None = None, averages: int = 8, periods: int | None = None,
            f_min: float | None = None, f_max: float | None = None,
            excitation: str = "multisine", out_dir=None, controller_model=None,
            noise: bool = True, hammer_force: float | None = None,
            hammer_duration: float | None = None, progress=None) -> FrequencyResponse:
    """Measure the frequency response of one axis (see the module docstring).

    Parameters
    ----------
    machine : str, Path or MachineConfig
        The machine: its I/O, limits and controller settings (and, on ``sim``, the
        physics).
    driver : str
        ``sim`` (the twin of ``machine``), ``sim:FILE`` (the twin of another machine file,
        a stand-in for a real machine), or ``modbus://HOST:PORT`` (real I/O, or
        ``twin hil-server``).
    axis : {"x", "y"}
    loop : {"mechanics", "speed", "position"}
        ``LOOPS``.
    sensor : {"accelerometer", "motor"}
        On ``sim`` an accelerometer is mounted on the table for the measurement when the
        machine file has none; over Modbus the module must serve one.
    amplitude : float, optional
        Peak of the excitation as table speed (m/s); default 25 % of the axis' speed limit.
    offset : float, optional
        Table speed the axis keeps meanwhile (m/s), so that friction does not reverse;
        default 50 % of the speed limit.
    averages : int
        Multisine: realisations (random phases), each a period to settle and ``periods``
        measured, each running the other way from the one before (the travel does not grow
        with the averaging); PRBS: periods averaged after one that settles.
    periods : int, optional
        Multisine: periods measured per realisation; default 8 where the accelerometer
        measures (its noise: at 1 the first mode of laser_belt came out 1–5 % off), else 1.
    f_min, f_max : float, optional
        The band (Hz): ``f_min`` sets the resolution (default 1 Hz); ``f_max`` at most the
        loop's Nyquist frequency (the accelerometer's, for what an accelerometer sees;
        default 0.75/T there, else the controller's Nyquist frequency).
    excitation : {"multisine", "prbs", "hammer"}
        ``hammer``: an impact test (``twin.analysis.frequency.hammer``): the table struck
        ``averages`` times while the drives hold position, the response the accelerance
        A/F ((m/s²)/N, ``loop`` mechanics, ``sensor`` accelerometer); ``sim`` drivers only
        (over Modbus it is refused: the twin cannot strike a real machine).
    out_dir : path, optional
        Where ``measure-<id>/`` goes (JSON, Bode PNG, ``.rrd``); None: nothing written.
    controller_model : str or Path, optional
        The machine as the controller believes it (its gains and the prediction); default
        ``machine``.
    noise : bool
        ``sim`` drivers: the machine file's sensor noise.
    hammer_force : float, optional
        ``hammer``: peak force of a blow (N); default 2000 N.
    hammer_duration : float, optional
        ``hammer``: length of a blow (s); default 2 ms.
    progress : callable(str), optional

    Raises
    ------
    ConfigError
        A bad option, naming it (an amplitude that leaves the work zone, a frequency above
        the Nyquist frequency).
    ExperimentAborted
        A safety stop (limit switch, following error, the table leaving its room, a drive
        fault); the machine was stopped.
    """
    from twin.analysis.frequency.measure import measure as run

    return run(machine, driver=driver, axis=axis, loop=loop, sensor=sensor,
               amplitude=amplitude, offset=offset, averages=averages, periods=periods,
               f_min=f_min,
               f_max=f_max, excitation=excitation, out_dir=out_dir,
               controller_model=controller_model, noise=noise, hammer_force=hammer_force,
               hammer_duration=hammer_duration, progress=progress)
