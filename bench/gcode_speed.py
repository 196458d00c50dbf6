"""Benchmark: the G-code reader against LinuxCNC's interpreter on the same CAM-style file.

Writes a CAM-style program of ``--lines`` lines (a G64 header, chords of a meandering path
at 3 decimals, an arc every 50 lines, a feed change every 500, comments now and then), then
measures in the same run, best of ``--repeat``:

* ``rs274 -g FILE``: LinuxCNC's standalone interpreter, printing its canonical calls to
  /dev/null, on both files (skipped, and said so, where ``rs274`` is not installed:
  ``make test-linuxcnc`` installs it);
* ``read_file`` streaming the file (constant memory), items counted;
* the same with expressions: every coordinate written as ``[#1 + …]``;
* parse + plan: ``Planner.plan(read_file(...))`` on laser_belt with the look-ahead, with
  laser_belt's own law and (``read_and_plan_lines_per_s_by_law``) with every law.

Prints one JSON object: lines per second of each, and the ratio of ours to LinuxCNC's (on
the plain file; the expressions also against LinuxCNC on the expression file).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import shutil
import subprocess
import tempfile
import time

import numpy as np

from twin.config import load_machine
from twin.controller.gcode import read_file
from twin.controller.planner import Planner
from twin.controller.profiles import LAWS


def cam_program(lines: int, *, expressions: bool) -> str:
    rng = np.random.default_rng(3)
    out = ["%", "(CAM-style test program)", "G21 G90 G17 G94 G40 G49 G80 G64 P0.01",
           "#1 = 0", "F1200", "G0 X10 Y10"]
    x = y = 10.0
    heading = 0.0

    def coord(value: float) -> str:
        return f"[#1 + {value:.3f}]" if expressions else f"{value:.3f}"

    while len(out) < lines - 2:
        n = len(out)
        if n % 500 == 0:
            out.append(f"F{rng.integers(600, 3000)}")
        elif n % 97 == 0:
            out.append(f"(contour {n})")
        elif n % 50 == 0:
            r = 0.5
            cx, cy = x + r, y
            ex, ey = cx + r * math.cos(2.5), cy + r * math.sin(2.5)
            out.append(f"G3 X{coord(ex)} Y{coord(ey)} I{r:.3f} J0")
            x, y = float(f"{ex:.3f}"), float(f"{ey:.3f}")
        else:
            heading += rng.normal(0.0, 0.2)
            x += 0.2 * math.cos(heading)
            y += 0.2 * math.sin(heading)
            if not 5.0 < x < 95.0 or not 5.0 < y < 95.0:
                heading += math.pi
                x, y = min(max(x, 5.0), 95.0), min(max(y, 5.0), 95.0)
            out.append(f"G1 X{coord(x)} Y{coord(y)}")
    out += ["M2", "%"]
    return "\n".join(out) + "\n"


def best(repeat: int, f) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = f()
        times.append(time.perf_counter() - t0)
    return min(times), result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--lines", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="20 000 lines, one repeat")
    args = ap.parse_args()
    if args.quick:
        args.lines, args.repeat = 20_000, 1
    rs274 = shutil.which("rs274")
    report: dict[str, object] = {"lines": args.lines, "python": platform.python_version()}
    with tempfile.TemporaryDirectory() as tmp:
        plain = os.path.join(tmp, "cam.ngc")
        with open(plain, "w") as f:
            f.write(cam_program(args.lines, expressions=False))
        exprs = os.path.join(tmp, "cam_expr.ngc")
        with open(exprs, "w") as f:
            f.write(cam_program(args.lines, expressions=True))

        def count(path: str) -> int:
            return sum(1 for _ in read_file(path, start=(0.01, 0.01)))

        if rs274 is not None:
            for key, path in (("linuxcnc", plain), ("linuxcnc_with_expressions", exprs)):
                # its own $HOME: rs274 truncates and maps $HOME/.tool.mmap, and another
                # rs274 running meanwhile (a test session) would crash on it (SIGBUS)
                seconds, _ = best(args.repeat, lambda path=path: subprocess.run(
                    [rs274, "-g", path], stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL, check=True, env={**os.environ, "HOME": tmp}))
                report[f"{key}_lines_per_s"] = round(args.lines / seconds)
        else:
            report["linuxcnc_lines_per_s"] = None
            report["linuxcnc"] = "rs274 not installed (make test-linuxcnc installs it)"
        seconds, items = best(args.repeat, lambda: count(plain))
        report["items"] = items
        report["read_lines_per_s"] = round(args.lines / seconds)
        seconds, _ = best(args.repeat, lambda: count(exprs))
        report["read_with_expressions_lines_per_s"] = round(args.lines / seconds)
        cfg = load_machine("laser_belt")
        planner = Planner.from_settings(cfg.controller, cfg.axes, work_zone=None)
        seconds, _ = best(1, lambda: sum(1 for _ in planner.plan(
            read_file(plain, start=(0.01, 0.01)))))
        report["read_and_plan_lines_per_s"] = round(args.lines / seconds)
        by_law = {}
        for law in LAWS:
            planner = Planner.from_settings(cfg.controller, cfg.axes, law=law, work_zone=None)
            seconds, _ = best(1, lambda planner=planner: sum(1 for _ in planner.plan(
                read_file(plain, start=(0.01, 0.01)))))
            by_law[law] = round(args.lines / seconds)
        report["read_and_plan_lines_per_s_by_law"] = by_law
        report["max_rss_mb"] = round(
            resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    if report["linuxcnc_lines_per_s"]:
        for key in ("read", "read_with_expressions", "read_and_plan"):
            report[f"{key}_ratio_to_linuxcnc"] = round(
                report[f"{key}_lines_per_s"] / report["linuxcnc_lines_per_s"], 3)
        # the expression file against LinuxCNC reading that same file
        report["read_with_expressions_ratio_to_linuxcnc_same_file"] = round(
            report["read_with_expressions_lines_per_s"]
            / report["linuxcnc_with_expressions_lines_per_s"], 3)
    print(json.dumps(report))


if __name__ == "__main__":
    main()
