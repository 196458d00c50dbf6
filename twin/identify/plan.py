"""The identification experiments as a plan: what each axis is asked to do, tick by tick.

Every piece is either an open-loop speed reference (the DAC drives the speed loop directly)
or a closed-loop ramp of the position loop; levels are table speeds (m/s), turned into each
axis' DAC volts with the model's K_H when the plan runs. The default plan (``default_plan``)
has these experiments, run on every axis identified at once (the axes are uncoupled; an
axis left out is held in position meanwhile):

``steps``
    Open-loop speed steps of both signs at four levels (3.3 %, 13 %, 60 % and 95 % of the
    contour speed limit), each held 0.5 s. The steady speeds and tacho volts give the drive
    gain K_H, its offset and the tacho gain; the two large reversals run at the current
    limit for different times, whose acceleration and braking give the rotor inertia apart
    from how fast the current loop reaches its limit (the armature resistance); the start
    from rest shows the break-away.
``prbs``
    A pseudo-random binary sequence (7-bit maximal length, 20 ms bits) of ±6.7 % about
    ±13 % of the speed limit, on the speed reference: the speed loop's dynamics.
``reversals``
    Slow open-loop reversals (0.55 % of the limit, 0.5 s each way): at each, the motor
    crosses the lost motion before it takes the table's friction again. At these speeds a
    thyristor drive conducts in short pulses: without an adaptation to discontinuous
    conduction its current loop's gain collapses and the speed loop limit-cycles, which
    decides the current regulator's model (``drive_fit``).
``coast``
    The axis runs at ±60 % of the speed limit, then its drive is disabled and the rotor
    coasts to rest against friction alone: dω/dt = −(T_c·sign ω + B·ω)/J. With J from the
    current-limited reversals, the coast's shape separates Coulomb and viscous friction
    and its end shows the break-away, which the speed loop otherwise hides.
``ramps`` (held out of the fit)
    Closed-loop position ramps of ±13 % of the speed limit through the controller's own
    regulator: the experiment the fitted twin is judged on.
``crossings``
    The axis is moved just below its home switch, then crosses it slowly (0.2 mm/s, closed
    loop) up and back down. The switch sits on the table, the encoder on the motor: the
    motor positions at which the same switch edge is seen going up and coming down differ
    by the lost motion (plus the screw's friction preload both ways and the debounce),
    which the motor's own signals barely show (the table's friction is a few percent of
    what the motor feels).

Every level scales with ``amplitude`` (0 < amplitude ≤ 1). The plan knows its worst-case
excursion (``excursion``), which the runner checks against the work zone first.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass

from twin.config import AXES
from twin.errors import ConfigError

__all__ = ["CROSSING_RUN", "CROSSING_SPEED", "EXPERIMENTS", "FIT_EXPERIMENTS", "HELD_OUT",
           "REPLAYED", "Piece", "default_plan", "excursion", "parse_axes", "phases", "prbs"]

EXPERIMENTS = ("steps", "prbs", "coast", "reversals", "ramps", "crossings")
FIT_EXPERIMENTS = ("steps", "prbs", "coast", "reversals")
HELD_OUT = "ramps"
REPLAYED = (*FIT_EXPERIMENTS, HELD_OUT)
"""The experiments the fit replays on the twin (the crossings are read off their edges)."""
CROSSING_SPEED = 0.2e-3
"""Speed of the home-switch crossings (m/s): one 5 ms tick is 1 µm of travel."""
CROSSING_RUN = 0.15e-3
"""Travel before and after the switch on each crossing (m)."""


@dataclass(frozen=True)
class Piece:
    """One piece of the plan (the same for both axes).

    Attributes
    ----------
    experiment : str
        Which experiment it belongs to (``EXPERIMENTS``).
    kind : str
        ``"speed"``: open-loop speed reference; ``"ramp"``: closed-loop position ramp
        (``value`` is the ramp's speed; 0 holds the position); ``"coast"``: the drives
        disabled, the rotors free; ``"home"``: move (the
        controller's jog, not recorded) until the table is ``value`` (m) from the lower
        edge of each axis' home switch.
    duration : float
        Length (s), a whole number of controller periods when run.
    value : float
        Table speed (m/s) as a fraction of the speed limit times that limit, signed.
    """

    experiment: str
    kind: str
    duration: float
    value: float

    def to_dict(self) -> dict:
        """Plain dict for the log."""
        return asdict(self)


def parse_axes(text: str) -> tuple[str, ...]:
    """The axes an ``--axes`` value names (``x``, ``y``, ``xy``; order and case free), in
    the machine's axis order.

    Raises
    ------
    ConfigError
        Naming the option, for anything else (unknown or repeated letters, nothing)."""
    letters = list(str(text).strip().lower())
    if not letters or any(c not in AXES for c in letters) or len(set(letters)) != len(letters):
        raise ConfigError("axes", f"must name the axes to identify as x, y or xy, got "
                          f"{text!r}")
    return tuple(a for a in AXES if a in letters)


def prbs(bits: int = 7, seed: int = 1) -> list[int]:
    """A maximal-length pseudo-random binary sequence of 2^bits − 1 values (±1), from a
    Fibonacci LFSR with taps x^7 + x^6 + 1 (bits = 7)."""
    if bits != 7:
        raise ConfigError("bits", f"only the 7-bit sequence is tabulated, got {bits}")
    state = seed & 0x7F or 1
    out = []
    for _ in range((1 << bits) - 1):
        new = ((state >> 6) ^ (state >> 5)) & 1
        out.append(1 if state & 1 else -1)
        state = ((state << 1) | new) & 0x7F
    return out


def default_plan(max_velocity: float, *, amplitude: float = 1.0,
                 home_width: float = 0.5e-3) -> list[Piece]:
    """The default identification plan for a machine whose contour speed limit is
    ``max_velocity`` (m/s) and whose home switches are ``home_width`` wide (m, the wider
    axis'); ``amplitude`` (0, 1] scales every level but the crossings'."""
    if not (math.isfinite(amplitude) and 0.0 < amplitude <= 1.0):
        raise ConfigError("amplitude", f"must lie in (0, 1], got {amplitude!r}")
    if not (math.isfinite(max_velocity) and max_velocity > 0.0):
        raise ConfigError("max_velocity", f"must be > 0 (m/s), got {max_velocity!r}")
    v = max_velocity * amplitude
    plan: list[Piece] = []
    for level in (0.033, 0.13, 0.6, 0.95):
        plan += [Piece("steps", "speed", 0.5, level * v),
                 Piece("steps", "speed", 0.5, -level * v)]
    plan.append(Piece("steps", "speed", 0.3, 0.0))
    for sign in (1.0, -1.0):
        plan += [Piece("prbs", "speed", 0.02, sign * (0.13 + 0.067 * b) * v) for b in prbs()]
    plan.append(Piece("prbs", "speed", 0.3, 0.0))
    for k in range(6):   # before the coasts: the drive model's choice replays them
        plan.append(Piece("reversals", "speed", 0.5, (1.0 if k % 2 == 0 else -1.0)
                          * 0.0055 * v))
    plan.append(Piece("reversals", "speed", 0.3, 0.0))
    for sign in (1.0, -1.0):
        plan += [Piece("coast", "speed", 0.6, sign * 0.6 * v),
                 Piece("coast", "coast", 2.0, 0.0)]
    plan += [Piece("ramps", "ramp", 1.0, 0.13 * v), Piece("ramps", "ramp", 0.3, 0.0),
             Piece("ramps", "ramp", 1.0, -0.13 * v), Piece("ramps", "ramp", 0.3, 0.0)]
    cross = (home_width + 2.0 * CROSSING_RUN) / CROSSING_SPEED
    plan += [Piece("crossings", "home", 0.0, -CROSSING_RUN),
             Piece("crossings", "ramp", cross, CROSSING_SPEED),
             Piece("crossings", "ramp", 0.3, 0.0),
             Piece("crossings", "ramp", cross, -CROSSING_SPEED),
             Piece("crossings", "ramp", 0.3, 0.0)]
    return plan


def excursion(plan: list[Piece], *, overshoot: float = 1.5,
              coast_travel: Callable[[float], float] | None = None) -> tuple[float, float]:
    """The lowest and highest table position the plan reaches relative to where it starts
    or where its last ``home`` piece put it (m), from its speeds, widened by ``overshoot``
    for a drive gain off the model's.

    A ``coast`` piece lets the table run on from the speed before it: ``coast_travel(v)``
    (m) bounds how far it coasts from table speed ``v`` (m/s) (the runner derives it from
    the model's inertia and friction); without it the coast is taken as an instant stop.
    """
    x = lo = hi = 0.0
    speed = 0.0
    for p in plan:
        if p.kind == "home":
            x = lo = hi = speed = 0.0
            continue
        if p.kind == "coast":
            if coast_travel is not None and speed != 0.0:
                x += math.copysign(coast_travel(abs(speed)), speed)
            speed = 0.0
        else:
            x += p.value * p.duration
            speed = p.value
        lo, hi = min(lo, x), max(hi, x)
    return overshoot * lo, overshoot * hi


def phases(plan: list[Piece]) -> list[list[Piece]]:
    """The plan cut at its ``home`` pieces: each part runs from one start point (the first
    from wherever the table is, each later one from its ``home`` piece's point)."""
    parts: list[list[Piece]] = [[]]
    for p in plan:
        if p.kind == "home" and parts[-1]:
            parts.append([])
        parts[-1].append(p)
    return parts
