"""Benchmark: the G-code lexer on long blank runs and comments (issue: linear lexing).

For blank runs of 64 KiB and 1 MiB inside one line — a comment (blanked to spaces before
the words are read), a ``;`` comment, plain spaces between two words, and the same with a
bad character at the end (the error path) — the wall time of ``lex`` on that line, best of
``--repeat``. A quadratic lexer takes seconds at 64 KiB and minutes at 1 MiB; the goal is
under 0.5 s for 1 MiB. Also the ratio of the 1 MiB time to 16× the 64 KiB time (≈ 1 when
linear). Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

from twin.controller.gcode.lexer import lex
from twin.errors import GCodeError

SHAPES = {
    "paren_comment": lambda n: "G1 X1 (" + " " * n + ") Y2",
    "semicolon_comment": lambda n: "G1 X1 ;" + " " * n,
    "blank_run": lambda n: "G1 X1" + " " * n + "Y2",
    "blank_run_bad_end": lambda n: "G1 X1" + " " * n + "?",
}


def _time(line: str, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        try:
            lex(line)
        except GCodeError:
            pass
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    out: dict = {"sizes_bytes": [64 * 1024, 1024 * 1024]}
    for name, make in SHAPES.items():
        small, large = (_time(make(n), args.repeat) for n in out["sizes_bytes"])
        out[name] = {"64KiB_s": small, "1MiB_s": large, "linearity": large / (16 * small)}
    out["worst_1MiB_s"] = max(v["1MiB_s"] for k, v in out.items() if isinstance(v, dict))
    out.update({"cpus": os.cpu_count(), "python": platform.python_version()})
    print(json.dumps(out))


if __name__ == "__main__":
    main()
