"""xy-twin: a digital twin of a two-axis CNC cross table.

Packages (``docs/ARCHITECTURE.md`` draws who imports whom):
``twin.config`` (machine files, overrides), ``twin.drive`` (thyristor/PWM DC drives,
numerics only), ``twin.plant`` (MuJoCo mechanics + drives: the only MuJoCo user),
``twin.controller`` (the CNC stack, hardware independent), ``twin.hardware`` (drivers
implementing ``MachineIO``), ``twin.telemetry`` (rerun), ``twin.identify`` (fitting a machine
file to a machine's I/O), ``twin.session`` (a run from request to record), ``twin.analysis``
(comparisons and the seeds' studies), ``twin.system`` (atomic files, process groups) and
``twin.cli`` (the ``twin`` command). ``units`` and ``errors`` are the leaves.

Importing the package points numba's on-disk cache at a folder named by a hash of the
compiled modules' sources. Numba checks only the timestamp of the file that holds a cached
function, not of the files it calls into, so a kernel compiled before an edit of a function
in another module would otherwise be loaded stale.

It also keeps OpenBLAS to one thread unless ``OPENBLAS_NUM_THREADS`` says otherwise (it
takes effect when nothing has loaded numpy yet, as in the ``twin`` command and the worker
processes it spawns). The twin's matrices are small (a drive's state, a regulator's design)
and its parallelism is by processes (tuning and identification workers): a BLAS thread pool
per process only competes for the same cores, and a 8×8 ``expm`` took 50× longer with it
on a loaded two-core machine.
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

__version__ = "0.1.0"

_COMPILED = ("drive", "plant", "controller/cyclic.py", "controller/regulator.py",
             "controller/_spline_curve.py", "controller/window.py", "controller/reach.py",
             "controller/profiles/closed_forms.py", "controller/geometry.py")
"""Parts of the package that hold numba-compiled code, or constants a kernel compiles in
(folders or files)."""


def _source_stamp() -> str:
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for part in _COMPILED:
        path = root / part
        files = sorted(path.glob("*.py")) if path.is_dir() else [path]
        for f in files:
            digest.update(f.name.encode())
            digest.update(f.read_bytes())
    return digest.hexdigest()[:16]


def _keyed_numba_cache() -> None:
    base = os.environ.get("NUMBA_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"),
        "xy-twin", "numba")
    stamp = _source_stamp()
    if Path(base).name == stamp:
        return
    keyed = os.path.join(base, stamp)
    os.environ["NUMBA_CACHE_DIR"] = keyed
    if "numba" in sys.modules:  # already imported: its config was read from the old value
        sys.modules["numba"].config.CACHE_DIR = keyed


_keyed_numba_cache()
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
