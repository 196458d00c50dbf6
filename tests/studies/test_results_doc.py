"""docs/RESULTS.md is what the renderer makes of docs/results/*.json, and that JSON is what
the code computes today.

The document is generated from the JSON, so comparing the two alone would pass whatever the
studies now compute. The fast, deterministic studies (integer step interpolators, the
interface's feed stability) are therefore run again at full size here and must give the
committed figures exactly; the twin-based ones take minutes at full size and are checked
by their own tests on their short versions (tests/studies/test_seed00*.py).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from twin.analysis.studies import STUDIES, run_study
from twin.analysis.studies.results import load_results, render

DOCS = Path(__file__).resolve().parents[2] / "docs"


def test_results_doc_agrees_with_the_study_json():
    results = load_results(DOCS / "results")
    assert set(results) == set(STUDIES)
    for name, r in results.items():
        assert r["study"] == name and r["quick"] is False
    assert (DOCS / "RESULTS.md").read_text(encoding="utf-8") == render(results)


def _figures(result: dict) -> dict:
    return {k: v for k, v in result.items() if k != "wall_time_s"}


@pytest.mark.parametrize("name", ["seed002_steps", "seed004_feed"])
def test_the_committed_figures_are_what_the_code_computes_now(name):
    committed = load_results(DOCS / "results")[name]
    assert _figures(run_study(name)) == _figures(committed), (
        f"docs/results/{name}.json is stale: run python bench/reproduce.py --study {name}")
