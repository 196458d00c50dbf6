"""The machine-file fuzz: every leaf of every shipped machine file, mutated, then loaded and
run through the real command line (``twin run``) in one long-lived process.

``python -m tests.config_fuzz`` reads cases (JSON lines: ``{"i", "file", "text", "leaf",
"fields"}``) on stdin and answers each with JSON lines on stdout: ``{"i", "start"}`` when it
begins (so the parent can tell which case hung) and then ``{"i", "load", "exit", "output",
"traceback", "status", "seconds"}``. The parent (``tests/test_config_fuzz.py``) kills and
restarts it when a case runs over its time limit.
"""

from __future__ import annotations

import copy
import json
import math
import os
import sys
import tempfile
import time
import tomllib
import traceback
from collections.abc import Iterator
from pathlib import Path
from typing import Any

MUTATIONS = ("wrong type", "negative", "0", "nan", "inf", "1e300", "1e-300", "2^62", "missing",
             "unknown sibling", "range low", "range high")
"""The issue's ten mutations, then the two ends of the field's range in the schema (a value
in range must run)."""

PROGRAM = """%
(config fuzz: a short line, a full circle and a dwell, relative to wherever the table is)
G21 G91 G17
G1 X2 Y1 F300
G2 X0 Y0 I1 J0 F300
G4 P0.1
G90
M30
%
"""


# ------------------------------------------------------------------ the cases
def leaves(doc: dict[str, Any], prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """Dotted paths of every value that is not a table (arrays are leaves)."""
    for key, value in doc.items():
        if isinstance(value, dict):
            yield from leaves(value, (*prefix, key))
        else:
            yield (*prefix, key)


def bound(path: tuple[str, ...], kind: str, old: Any) -> float | int | None:
    """The low or high end of the field's range (just inside an open end); None if the
    field has no range."""
    from twin.config.schema import field_meta

    meta = field_meta(fields(path)[0])
    if kind == "range low":
        if meta.get("ge") is not None:
            value = meta["ge"]
        elif meta.get("gt") is not None:
            value = meta["gt"] + max(abs(meta["gt"]) * 1e-6, 1e-6)
        else:
            return None
    else:
        if meta.get("le") is None:
            return None
        value = meta["le"]
    return int(value) if isinstance(old, int) and not isinstance(old, bool) else float(value)


def mutate(doc: dict[str, Any], path: tuple[str, ...], kind: str) -> dict[str, Any] | None:
    """A copy of ``doc`` with the leaf at ``path`` mutated; None if ``kind`` does not apply
    (a number mutation of a string or a flag, a range end of a field without one)."""
    out = copy.deepcopy(doc)
    node = out
    for key in path[:-1]:
        node = node[key]
    leaf = path[-1]
    old = node[leaf]
    if kind == "missing":
        del node[leaf]
        return out
    if kind == "unknown sibling":
        node["bogus_key"] = 1.0
        return out
    if kind == "wrong type":
        node[leaf] = "text" if not isinstance(old, str) else 1.5
        return out
    numbers: dict[str, Any] = {"0": 0, "nan": math.nan, "inf": math.inf, "1e300": 1e300,
                               "1e-300": 1e-300, "2^62": 2**62}
    if isinstance(old, bool | str):
        return None
    if kind.startswith("range"):
        first = old
        while isinstance(first, list) and first:
            first = first[0]
        numbers[kind] = bound(path, kind, first)
        if numbers[kind] is None:
            return None
    if isinstance(old, list):                       # an array: mutate its first number
        flat = old
        while flat and isinstance(flat[0], list):
            flat = flat[0]
        if not flat or not isinstance(flat[0], int | float):
            return None
        flat[0] = -abs(flat[0]) - 1.0 if kind == "negative" else numbers[kind]
        return out
    node[leaf] = -abs(old) - 1 if kind == "negative" else numbers[kind]
    return out


def fields(path: tuple[str, ...]) -> list[str]:
    """The dotted configuration fields a document path stands for (``axis_defaults`` means
    both axes)."""
    if path[0] == "axis_defaults":
        return [".".join(("axes", ax, *path[1:])) for ax in ("x", "y")]
    if path[0] == "machine":
        return [".".join(path), path[-1]]
    return [".".join(path)]


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v).__name__)


def to_toml(doc: dict[str, Any]) -> str:
    """TOML text of a document (inline tables for the stiffness components)."""
    out: list[str] = []

    def table(name: str, node: dict[str, Any]) -> None:
        scalars = {k: v for k, v in node.items() if not isinstance(v, dict) or k == "stiffness"}
        if name and (scalars or not node):      # an emptied table stays, empty
            out.append(f"[{name}]")
        out.extend(f"{k} = {_value(v)}" for k, v in scalars.items())
        for k, v in node.items():
            if isinstance(v, dict) and k != "stiffness":
                table(f"{name}.{k}" if name else k, v)

    table("", doc)
    return "\n".join(out) + "\n"


def cases(machine_files: list[Path]) -> list[dict[str, Any]]:
    """Every leaf of every file × every mutation that applies."""
    out = []
    for path in machine_files:
        doc = tomllib.loads(path.read_text())
        for leaf in leaves(doc):
            for kind in MUTATIONS:
                mutated = mutate(doc, leaf, kind)
                if mutated is None:
                    continue
                out.append({"i": len(out), "file": path.stem, "leaf": ".".join(leaf),
                            "kind": kind, "fields": fields(leaf), "text": to_toml(mutated)})
    return out


# ------------------------------------------------------------------ the runner
def run_case(case: dict[str, Any], work: Path) -> dict[str, Any]:
    """Load the mutated file, then run the program through the command line."""
    from typer.testing import CliRunner

    from twin.cli import app
    from twin.config import load_machine
    from twin.errors import ConfigError

    machine = work / f"{case['file']}_{case['i']}.toml"
    machine.write_text(case["text"])
    program = work / "fuzz.ngc"
    if not program.exists():
        program.write_text(PROGRAM)
    t0 = time.perf_counter()
    answer: dict[str, Any] = {"i": case["i"]}
    try:
        load_machine(machine)
        answer["load"] = "ok"
    except ConfigError as exc:
        answer["load"] = f"{exc.field}: {exc.message}"
    except Exception:
        answer["load"] = "TRACEBACK " + traceback.format_exc()
    out = work / f"runs_{case['i']}"
    result = CliRunner().invoke(app, ["run", str(program), "--machine", str(machine),
                                      "--out", str(out), "--rerun", "none", "--json"])
    answer["exit"] = result.exit_code
    answer["output"] = result.output[-1500:]
    answer["traceback"] = (None if result.exception is None
                           or isinstance(result.exception, SystemExit)
                           else "".join(traceback.format_exception(result.exception))[-3000:])
    status = None
    for f in out.glob("*.json") if out.is_dir() else ():
        status = json.loads(f.read_text()).get("status")
    answer["status"] = status
    answer["seconds"] = round(time.perf_counter() - t0, 3)
    for f in out.glob("*") if out.is_dir() else ():
        f.unlink()
    machine.unlink()
    return answer


def main() -> None:
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        # Compile everything once before the first case (numba's cache is cold on a fresh
        # clone): the per-case limit then measures the case, not the compiler.
        from twin.config.loader import MACHINES_DIR

        run_case({"i": -1, "file": "warm_up", "text": (MACHINES_DIR / "tomsk_xy.toml")
                  .read_text()}, work)
        for line in sys.stdin:
            case = json.loads(line)
            print(json.dumps({"i": case["i"], "start": True}), flush=True)
            print(json.dumps(run_case(case, work)), flush=True)


if __name__ == "__main__":
    main()
