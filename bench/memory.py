"""Benchmark: peak memory of ``twin run`` against the length of the program.

The default program's body (a square and a circle, back to the start) is repeated until the
program lasts about 1, 10 and 60 simulated minutes. Each is run by the real command line,
``twin run FILE --out DIR --json``, with its telemetry recorded to an ``.rrd`` file,
in a fresh process; the process's peak resident set (``ru_maxrss`` of that child, from
``wait4``) is its figure. A run keeps neither its per-tick record nor the recording in
memory, so the peak should not grow with the program beyond a small constant.

``--none`` also runs each with ``--rerun none``: the twin's own memory, without rerun's
index of the recording's chunks (what an ``.rrd`` footer needs, and ``rerun rrd verify``
requires; it grows with the number of chunks sent). ``--kept`` also runs each program
through the API with the whole record kept (``run(keep_record=True)``), the cost that
bounded streaming avoids.

Prints one JSON object: per length, the simulated seconds, ticks, peak RSS (MB) and wall
time, and ``growth_mb``, the peak at the longest program minus the peak at the shortest.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROGRAM = ROOT / "twin" / "programs" / "square_circle.ngc"
PASS_S = 37.7
"""Simulated seconds of one pass of the default program's body on tomsk_xy (about)."""

KEPT = """
import resource, sys
from twin.session.run import RunSpec, run
r = run(RunSpec(machine="tomsk_xy", program=sys.argv[1]), out_dir=sys.argv[2],
        keep_record=True)
print(r.summary["sim_time_s"])
"""


def program(minutes: float) -> str:
    """The default program with its body repeated to last about ``minutes``."""
    lines = PROGRAM.read_text().splitlines()
    body = [ln for ln in lines if re.match(r"N(20|30|40|50|60|70|80|90)\b", ln)]
    head = [ln for ln in lines if ln.startswith(("%", "(", "N10"))][:4]
    passes = max(1, round(minutes * 60.0 / PASS_S))
    return "\n".join([*head, *(body * passes), "M30", "%"]) + "\n"


def measure(cmd: list[str]) -> tuple[float, float, str]:
    """(peak RSS in MB, wall s, stdout) of one child process."""
    env = {**os.environ, "RERUN_ANALYTICS": "0", "NUMBA_CACHE_DIR":
           os.environ.get("NUMBA_CACHE_DIR", str(ROOT / ".cache" / "numba"))}
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.PIPE, env=env, cwd=ROOT)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
        out.seek(0)
        text = out.read().decode()
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{err[-2000:]}")
    return usage.ru_maxrss / 1024.0, wall, text   # ru_maxrss is in KiB on Linux


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", default="1,10,60",
                    help="program lengths, simulated minutes (comma-separated)")
    ap.add_argument("--none", action="store_true",
                    help="also run each without a recording (--rerun none)")
    ap.add_argument("--kept", action="store_true",
                    help="also run each with the whole record kept (the API's default)")
    args = ap.parse_args()
    python = sys.executable
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in (float(m) for m in args.minutes.split(",")):
            path = Path(tmp) / f"program_{minutes:g}min.ngc"
            path.write_text(program(minutes))
            out = Path(tmp) / f"runs_{minutes:g}"
            twin = str(Path(python).with_name("twin"))
            rss, wall, text = measure([twin, "run", str(path), "--out", str(out), "--json"])
            summary = json.loads(text)
            row = {"minutes": minutes, "sim_time_s": round(summary["sim_time_s"], 1),
                   "ticks": summary["ticks"]["due"], "status": summary["status"],
                   "peak_rss_mb": round(rss, 1), "wall_s": round(wall, 1),
                   "rrd_mb": round(Path(summary["recording"]).stat().st_size / 2**20, 1)}
            if args.none:
                none_rss, _, _ = measure([twin, "run", str(path), "--out", str(out),
                                          "--rerun", "none", "--json"])
                row["peak_rss_no_recording_mb"] = round(none_rss, 1)
            if args.kept:
                kept_rss, _, _ = measure([python, "-c", KEPT, str(path), str(out)])
                row["peak_rss_kept_record_mb"] = round(kept_rss, 1)
            rows.append(row)
            for f in out.iterdir():          # a 60 min recording is large: free the space
                f.unlink()
    growth = {"growth_mb": round(rows[-1]["peak_rss_mb"] - rows[0]["peak_rss_mb"], 1)}
    if args.none:
        growth["growth_no_recording_mb"] = round(
            rows[-1]["peak_rss_no_recording_mb"] - rows[0]["peak_rss_no_recording_mb"], 1)
    print(json.dumps({"machine": "tomsk_xy", "runs": rows, **growth}, indent=1))


if __name__ == "__main__":
    main()
