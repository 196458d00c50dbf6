"""Reproduce the seeds' measured results on the twin; print one JSON object.

    python bench/reproduce.py                       # every study, full size (~5 min, 2 cores)
    python bench/reproduce.py --study seed001_corner
    python bench/reproduce.py --quick               # the short versions (tests use them)

Full-size results are written to ``docs/results/<study>.json`` and ``docs/RESULTS.md`` is
re-rendered from every JSON there (``twin.analysis.studies.results``). ``--quick`` writes nothing
unless ``--out`` is given. Stdout: ``{"studies": {name: result, ...}, "quick": bool}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("RERUN_ANALYTICS", "0")
os.environ.setdefault("MPLBACKEND", "Agg")

from twin.analysis.studies import STUDIES, run_study
from twin.analysis.studies.results import load_results, render
from twin.system.jsonio import write_json_atomic

ROOT = Path(__file__).resolve().parent.parent


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", action="append", choices=STUDIES,
                        help="run only this study (repeatable); default all")
    parser.add_argument("--quick", action="store_true", help="short versions")
    parser.add_argument("--out", type=Path, default=None,
                        help="directory for <study>.json (default docs/results, full runs)")
    parser.add_argument("--results-doc", type=Path, default=ROOT / "docs" / "RESULTS.md",
                        help="Markdown document re-rendered from the JSON directory")
    args = parser.parse_args(argv)
    out = args.out or (None if args.quick else ROOT / "docs" / "results")
    results = {}
    for name in args.study or STUDIES:
        print(f"running {name}{' (quick)' if args.quick else ''} …", file=sys.stderr)
        results[name] = run_study(name, quick=args.quick)
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            write_json_atomic(out / f"{name}.json", results[name])
    if out is not None:
        args.results_doc.write_text(render(load_results(out)), encoding="utf-8")
    sys.stdout.write(json.dumps({"studies": results, "quick": args.quick}) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
