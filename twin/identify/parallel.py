"""Replays side by side: the fit's independent replays (the Jacobian's columns, the mains
phase grid, the profiles of different parameters) split over two processes.

``split_map`` runs the second half of a list of independent jobs in a forked child (it
inherits the problem as it stands) while the parent runs the first half; the child's
results come back through a file. The results are exactly the serial ones, in order; only
the wall time changes. ``processes`` says how many: ``XY_TWIN_FIT_PROCESSES`` (1 or 2), by
default 2 where the machine has two cores and ``fork``. The test suite sets 1: its two
workers already use both cores.

The CPU time a fit reports includes its children's (``cpu_time``).
"""

from __future__ import annotations

import os
import pickle
import resource
import tempfile
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

__all__ = ["ENV", "cpu_time", "processes", "split_map"]

ENV = "XY_TWIN_FIT_PROCESSES"
"""Environment variable: how many processes the fit's replays use (1 or 2)."""

T = TypeVar("T")

_inside = [False]
"""True while this process runs one half of a ``split_map``: the jobs' own replays then
stay in it (two processes, never four)."""


def processes() -> int:
    """How many processes the fit's replays use: ``ENV`` if set (1 or 2), else 2 where the
    machine has at least two cores and ``os.fork``, else 1 (and 1 inside a job of a
    ``split_map``)."""
    if _inside[0]:
        return 1
    text = os.environ.get(ENV, "").strip()
    if text:
        try:
            return 2 if int(text) >= 2 and hasattr(os, "fork") else 1
        except ValueError:
            return 1
    return 2 if (os.cpu_count() or 1) >= 2 and hasattr(os, "fork") else 1


def cpu_time() -> float:
    """CPU time of this process and of its children that have ended (s)."""
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + kids.ru_utime + kids.ru_stime


def split_map(problem: Any, fn: Callable[[T], Any], items: Sequence[T]) -> list[Any]:
    """``[fn(item) for item in items]``, the second half in a forked child when
    ``processes()`` is 2. ``problem.replays`` counts the child's replays too. An exception
    in the child is raised in the parent."""
    items = list(items)
    if processes() < 2 or len(items) < 2:
        return [fn(i) for i in items]
    k = (len(items) + 1) // 2
    fd, path = tempfile.mkstemp(prefix="xy-twin-fit-", suffix=".pickle")
    os.close(fd)
    try:
        before = problem.replays
        pid = os.fork()
        _inside[0] = True
        if pid == 0:   # the child: its half, pickled to the file, and out at once
            code = 0
            try:
                try:
                    payload: Any = ("ok", [fn(i) for i in items[k:]],
                                    problem.replays - before)
                except BaseException as exc:  # handed to the parent, which raises it
                    payload = ("error", exc, 0)
                with open(path, "wb") as f:
                    pickle.dump(payload, f)
            except BaseException:
                code = 1
            finally:
                os._exit(code)
        try:
            first = [fn(i) for i in items[:k]]
        finally:
            _inside[0] = False
            _pid, status = os.waitpid(pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError("a replay process of the fit ended abnormally")
        with open(path, "rb") as f:
            kind, second, replays = pickle.load(f)
        if kind == "error":
            raise second
        problem.replays += replays
        return first + second
    finally:
        try:
            os.unlink(path)
        except OSError:
            pass
