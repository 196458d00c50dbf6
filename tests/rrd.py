"""Recordings as rerun itself reads them: ``rerun rrd verify`` (footers included) and the
chunks back through ``rerun.chunk.RrdReader``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import rerun.chunk as rc

RERUN = Path(sys.executable).with_name("rerun")


def assert_verified(rrd: Path, where: str = "") -> None:
    """The recording passes ``rerun rrd verify`` (with footers) and has chunks."""
    done = subprocess.run([str(RERUN), "rrd", "verify", str(rrd)], capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 0, f"{where}: {rrd.name}: {done.stderr[-2000:]}"
    assert list(rc.RrdReader(rrd).stream().to_chunks()), f"{where}: {rrd.name} is empty"
