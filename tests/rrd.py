"""Recordings as rerun itself reads them: ``rerun rrd verify`` (footers included) and the
chunks back through ``rerun.chunk.RrdReader``."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import rerun.chunk as rc

RERUN = Path(sys.executable).with_name("rerun")


def assert_verified(rrd: Path, where: str = "") -> None:
    """The recording passes ``rerun rrd verify`` (with footers) and has chunks."""
    done = subprocess.run([str(RERUN), "rrd", "verify", str(rrd)], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, f"{where}: {rrd.name}: {done.stderr[-2000:]}"
    assert list(rc.RrdReader(rrd).stream().to_chunks()), f"{where}: {rrd.name} is empty"


def layout_views(rrd: Path) -> list[dict]:
    """The views of a recording's active layout (its last blueprint), read back with
    ``RrdReader``: per view its ``name``, ``kind`` (rerun's class identifier), ``contents``,
    ``origin``, and, where the layout sets them, ``y_range`` (ScalarAxis), ``legend``
    (PlotLegend visible), ``time`` (the time axis' view range, s) and ``bounds``
    (VisualBounds2D: x and y range)."""
    reader = rc.RrdReader(rrd)

    def sent(store) -> int:          # when the layout was sent: its chunks' log time
        return max(int(c.to_record_batch().column("log_time").cast("int64").to_numpy().max())
                   for c in reader.stream(store=store).to_chunks())

    store = max(reader.blueprints(), key=sent)     # each one sent becomes the active one
    views: dict[str, dict] = {}
    for chunk in reader.stream(store=store).to_chunks():
        parts = chunk.entity_path.strip("/").split("/")
        if parts[0] != "view":
            continue
        view = views.setdefault(parts[1], {})
        rb = chunk.to_record_batch()
        cols = {n: rb.column(n).to_pylist()[-1] for n in rb.schema.names if ":" in n}
        for name, value in cols.items():
            if value is None:
                continue
            v = value[0] if len(value) == 1 else value
            key = {"ViewBlueprint:display_name": "name",
                   "ViewBlueprint:class_identifier": "kind",
                   "ViewBlueprint:space_origin": "origin", "ViewContents:query": "contents",
                   "ScalarAxis:range": "y_range", "PlotLegend:visible": "legend",
                   "TimeAxis:view_range": "time", "VisualBounds2D:range": "bounds"}.get(name)
            if key == "contents":
                v = list(value)
            if key == "time":
                v = tuple(None if v.get(k) is None else v[k] * 1e-9 for k in ("start", "end"))
            if key is not None:
                view[key] = v
    return list(views.values())


def rrd_spectra(rrd: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every series on the spectra's timeline (``twin.telemetry.spectra.FREQUENCY``):
    {entity: (frequency (Hz), values)}."""
    from twin.telemetry.spectra import FREQUENCY

    out = {}
    for chunk in rc.RrdReader(rrd).stream().to_chunks():
        rb = chunk.to_record_batch()
        if FREQUENCY not in rb.schema.names or "Scalars:scalars" not in rb.schema.names:
            continue
        f = rb.column(FREQUENCY).cast("int64").to_numpy()
        v = np.array([row[0] for row in rb.column("Scalars:scalars").to_pylist()])
        out[chunk.entity_path.lstrip("/")] = (f, v)
    return out


def labelled(lo: float, hi: float, *, height: float = 110.0, spacing: float = 20.0) -> int:
    """How many values rerun's plots label on a y range ``lo … hi`` drawn ``height`` screen
    points tall: egui_plot writes the multiples of the powers of ten whose steps are more
    than ``spacing`` points apart (brute force over the powers of ten)."""
    best = 0
    for k in range(-12, 13):
        s = 10.0 ** k
        if s * height / (hi - lo) <= spacing:
            continue
        best = max(best, math.floor(hi / s + 1e-9) - math.ceil(lo / s - 1e-9) + 1)
    return best
