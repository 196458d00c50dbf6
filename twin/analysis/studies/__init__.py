"""Reproductions of the seeds' measured results on the twin (``bench/reproduce.py``).

Each study module has ``run_study(*, quick=False) -> dict`` (JSON-ready, with the seed's
figures next to the twin's); ``twin.analysis.studies.results`` renders them as ``docs/RESULTS.md``.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

__all__ = ["STUDIES", "run_study"]

STUDIES = ("seed000_dcu", "seed000_laws", "seed001_corner", "seed001_laser", "seed004_feed",
           "seed002_steps", "seed000_dcu_as_built", "laws_on_cam", "shaping_laser")
"""Study names, each a module of this package."""


def run_study(name: str, *, quick: bool = False) -> dict[str, Any]:
    """Run the study ``name`` (one of ``STUDIES``); ``quick`` runs its short version."""
    if name not in STUDIES:
        raise ValueError(f"unknown study {name!r}; valid: {', '.join(STUDIES)}")
    return import_module(f"twin.analysis.studies.{name}").run_study(quick=quick)
