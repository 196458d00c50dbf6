"""Chord independence: a circle's cycle time as a G3 arc and as the chords CAM writes (issue 30).

Full circles of r = 0.5 … 20 mm (`cam.circle`) as a G3 arc, as chords of 0.001 … 0.5 mm
written exactly (9 decimals: the geometry of chording alone) and as chords within a chordal
tolerance of 0.001 … 0.02 mm written with 3 decimals, as CAM posts write them (the rounding
tilts every chord a little). A polygon whose sagitta exceeds the blend tolerance is not
that circle within tolerance and is left out. Per law and radius: the feed moves' planned
cycle time of each representation (s) and the spread, max/min − 1. Issue 30 asks ≤ 5 %
for every law. Used by ``bench/planner_bound.py`` and the ``laws_on_cam`` study.
"""

from __future__ import annotations

from typing import Any

from twin.analysis.studies import cam
from twin.analysis.studies.nest import chord_length
from twin.controller.gcode import parse
from twin.controller.planner import Planner

__all__ = ["CHORDS", "RADII", "TOLERANCES", "chord_independence", "circle_time"]

RADII = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
"""Circle radii (mm)."""
CHORDS = (0.001, 0.01, 0.1, 0.5)
"""Chord lengths (mm), written with 9 decimals: the geometry of chording alone."""
TOLERANCES = (0.001, 0.005, 0.01, 0.02)
"""Chordal tolerances (mm), written with 3 decimals as CAM posts write them: the rounding
tilts every chord a little, so the blends' radii scatter unless the chords are faired
(`twin.controller.fair`)."""


def circle_time(cfg, text: str, law: str) -> float:
    """The feed moves' planned cycle time of a circle program on machine ``cfg`` (s)."""
    planner = Planner.from_settings(cfg.controller, cfg.axes, law=law, work_zone=None)
    return cam.planned_time(planner.plan(parse(text, start=(0.01, 0.01))), True)


def chord_independence(cfg, laws, radii=RADII) -> dict[str, Any]:
    """Per law and radius, the circle's cycle time as G3 and as chords (s), and the spread
    (max/min − 1); per law the worst spread. ``c…``: chords of that length (mm); ``t…``:
    chords within that chordal tolerance (mm), 3 decimals."""
    blend_tol = cfg.controller.contour_tolerance * cfg.controller.corner_blend * 1e3   # mm
    out: dict[str, Any] = {}
    for law in laws:
        rows = {}
        for r in radii:
            times = {"G3": circle_time(cfg, cam.circle(r), law)}
            for chord in CHORDS:
                if chord * chord / (8.0 * r) <= blend_tol:
                    times[f"c{chord:g}"] = circle_time(cfg, cam.circle(r, chord=chord), law)
            for tol in TOLERANCES:
                if tol <= blend_tol:
                    times[f"t{tol:g}"] = circle_time(cfg, cam.circle(
                        r, chord=chord_length(r, tol), decimals=3), law)
            v = list(times.values())
            rows[f"r{r:g}"] = {"s": {k: round(x, 4) for k, x in times.items()},
                               "spread": round(max(v) / min(v) - 1.0, 4)}
        out[law] = {"radii": rows, "worst_spread": max(x["spread"] for x in rows.values())}
    return out
