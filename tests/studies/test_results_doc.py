"""docs/RESULTS.md is exactly what the renderer makes of docs/results/*.json."""

from __future__ import annotations

from pathlib import Path

from twin.analysis.studies import STUDIES
from twin.analysis.studies.results import load_results, render

DOCS = Path(__file__).resolve().parents[2] / "docs"


def test_results_doc_agrees_with_the_study_json():
    results = load_results(DOCS / "results")
    assert set(results) == set(STUDIES)
    for name, r in results.items():
        assert r["study"] == name and r["quick"] is False
    assert (DOCS / "RESULTS.md").read_text(encoding="utf-8") == render(results)
