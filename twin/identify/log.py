"""The record of identification experiments: what was written and read, tick by tick.

``IdentLog`` holds, for every controller tick of the experiments, the DAC volts written,
the raw encoder counts and tacho volts read, the limit switches, the drive-ready flag and
the piece of the plan; and what the experiments ran on (the machine's I/O: counts per
metre, counter width, period, DAC range). It is saved as JSON (no pickle: a log may come
from anywhere) and checked on load, so that ``twin identify --from-log`` refuses a log of
another machine or one that stops short, naming what does not fit.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import AXES, MachineConfig
from twin.errors import ConfigError
from twin.identify.plan import EXPERIMENTS, Piece
from twin.session.machine_io import io_signature
from twin.system.jsonio import load_json, write_json_atomic

__all__ = ["COLUMNS", "FORMAT", "IdentLog", "io_signature"]

FORMAT = "xy-twin identification log 1"
COLUMNS = ("t", "dac_x", "dac_y", "enable", "counts_x", "counts_y", "tacho_x", "tacho_y",
           "home_x", "home_y", "limit", "ready", "piece")
"""Per-tick columns: time (s), DAC volts and drive enable (0/1) written, raw counter values,
tacho volts, home switches (0/1), any end switch closed (0/1), drive ready (0/1), index of
the plan's piece."""


@dataclass
class IdentLog:
    """A run of the identification plan.

    Attributes
    ----------
    machine : str
        Name of the machine model the experiments were planned with.
    signature : dict
        ``io_signature`` of that model.
    driver : str
        Where the experiments ran (``sim``, ``sim:FILE``, ``modbus://…``).
    plan : list of Piece
    data : dict of ndarray
        ``COLUMNS``, one entry per tick.
    start : list of float
        Table position when the experiments began (m, as measured).
    notes : dict
        Anything else worth keeping (wall times, the driver's deadline report).
    axes : list of str
        The axes the experiments excited (the other was held in position).
    """

    machine: str
    signature: dict[str, Any]
    driver: str
    plan: list[Piece]
    data: dict[str, np.ndarray]
    start: list[float] = field(default_factory=lambda: [0.0, 0.0])
    notes: dict[str, Any] = field(default_factory=dict)
    axes: list[str] = field(default_factory=lambda: list(AXES))

    @property
    def ticks(self) -> int:
        """Number of ticks recorded."""
        return len(self.data["t"])

    def experiment_mask(self, names: tuple[str, ...] | str) -> np.ndarray:
        """Ticks that belong to the experiments ``names`` (bool, (ticks,))."""
        names = (names,) if isinstance(names, str) else names
        of_piece = np.array([p.experiment in names for p in self.plan])
        return of_piece[self.data["piece"].astype(int)]

    def save(self, path: str | Path) -> Path:
        """Write the log as JSON, atomically (a reader never sees half a file)."""
        path = Path(path)
        doc = {"format": FORMAT, "machine": self.machine, "signature": self.signature,
               "driver": self.driver, "start": list(self.start), "notes": self.notes,
               "axes": list(self.axes),
               "plan": [p.to_dict() for p in self.plan],
               "data": {k: self.data[k].tolist() for k in COLUMNS}}
        return write_json_atomic(path, doc, indent=None)

    @classmethod
    def load(cls, path: str | Path) -> IdentLog:
        """Read a log written by :meth:`save` (a file, or a directory holding
        ``experiments.json``).

        Raises
        ------
        ConfigError
            Missing file, not a log, or a log with missing parts (naming them).
        """
        p = Path(path)
        if p.is_dir():
            p = p / "experiments.json"
        if not p.is_file():
            raise ConfigError("from_log", f"no identification log at {p}")
        try:
            doc = load_json(p.read_text(encoding="utf-8"), str(p))   # nesting bounded
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ConfigError(str(p), f"not a JSON identification log: {exc}") from None
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise ConfigError(str(p), f"not an identification log (format {FORMAT!r})")
        missing = [k for k in ("machine", "signature", "plan", "data") if k not in doc]
        if missing:
            raise ConfigError(str(p), f"the log lacks {', '.join(missing)}")
        data = doc["data"]
        absent = [c for c in COLUMNS if c not in data]
        if absent:
            raise ConfigError(str(p), f"the log lacks the columns {', '.join(absent)}")
        lengths = {len(data[c]) for c in COLUMNS}
        if len(lengths) != 1:
            raise ConfigError(str(p), "the log's columns have different lengths")
        try:
            plan = [Piece(**piece) for piece in doc["plan"]]
            arrays = {c: np.asarray(data[c], dtype=float) for c in COLUMNS}
        except (TypeError, ValueError) as exc:
            raise ConfigError(str(p), f"malformed plan or data: {exc}") from None
        for c, a in arrays.items():
            if not np.all(np.isfinite(a)):
                raise ConfigError(str(p), f"column {c} holds values that are not finite")
        axes = doc.get("axes", list(AXES))
        if not (isinstance(axes, list) and axes and set(axes) <= set(AXES)
                and len(set(axes)) == len(axes)):
            raise ConfigError(str(p), f"axes: must name some of {', '.join(AXES)} once each, "
                              f"got {axes!r}")
        return cls(str(doc["machine"]), dict(doc["signature"]), str(doc.get("driver", "")),
                   plan, arrays, list(doc.get("start", [0.0, 0.0])),
                   dict(doc.get("notes", {})), [a for a in AXES if a in axes])

    def check(self, base: MachineConfig) -> None:
        """Refuse a log that does not fit ``base``: other I/O or period, or experiments that
        did not run to their end.

        Raises
        ------
        ConfigError
            Naming the mismatch or the experiments that are missing.
        """
        mine = io_signature(base)
        for key, value in mine.items():
            theirs = self.signature.get(key)
            if theirs is None:
                raise ConfigError("from_log", f"the log does not say its {key}")
            a, b = np.atleast_1d(np.asarray(value, float)), np.atleast_1d(
                np.asarray(theirs, float))
            if a.shape != b.shape or not np.allclose(a, b, rtol=1e-9, atol=0.0):
                raise ConfigError("from_log", f"the log is of another machine: its {key} is "
                                  f"{theirs}, {base.name}'s is {value} (log of "
                                  f"{self.machine!r})")
        if not self.ticks:
            raise ConfigError("from_log", "the log holds no ticks")
        period = base.controller.period
        needed = {name: math.fsum(p.duration for p in self.plan if p.experiment == name
                                  and p.kind != "home") for name in EXPERIMENTS}
        pieces = self.data["piece"].astype(int)
        if pieces.min() < 0 or pieces.max() >= len(self.plan):
            raise ConfigError("from_log", "the log's piece indices do not fit its plan")
        # time covered, not ticks: a paced run may have skipped a late slot (its row holds
        # until the next)
        t = self.data["t"]
        dwell = np.minimum(np.diff(t, append=t[-1] + period), 10.0 * period)
        got = {name: 0.0 for name in EXPERIMENTS}
        for k, dt in zip(pieces, dwell, strict=True):
            got[self.plan[k].experiment] += float(dt)
        short = [f"{name} ({got[name]:.2f} of {needed[name]:.2f} s)" for name in EXPERIMENTS
                 if needed[name] > 0 and got[name] < needed[name] - 1.5 * period]
        if short:
            raise ConfigError("from_log", "the log is incomplete: it stops before the end "
                              "of " + ", ".join(short))
