"""Child processes the twin starts (rerun viewers, HIL servers): stopped one way."""

from __future__ import annotations

import os
import signal
import subprocess
import time

__all__ = ["stop_process"]


def _leads_group(proc: subprocess.Popen) -> bool:
    """``proc`` leads its own process group (started with ``start_new_session``)."""
    try:
        return os.getpgid(proc.pid) == proc.pid
    except (ProcessLookupError, PermissionError):
        return False


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _group_gone(pgid: int, until: float) -> bool:
    """Wait until the process group ``pgid`` has no member left, or ``until`` (monotonic);
    whether it is gone."""
    while _group_alive(pgid):
        if time.monotonic() >= until:
            return False
        time.sleep(0.01)
    return True


def stop_process(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    """SIGTERM ``proc`` if it still runs, wait up to ``timeout`` s, then SIGKILL; always
    reap it (no zombie is left behind).

    A process that leads its own group (started with ``start_new_session``) is stopped with
    its whole group: a launcher such as the ``rerun`` entry point runs the real server as
    its child, which would otherwise outlive it, orphaned, still listening.
    """
    group = proc.pid if proc.poll() is None and _leads_group(proc) else None
    if group is not None:
        deadline = time.monotonic() + timeout
        os.killpg(group, signal.SIGTERM)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            pass
        if not _group_gone(group, deadline):
            os.killpg(group, signal.SIGKILL)
            _group_gone(group, time.monotonic() + 5.0)   # SIGKILL is only delivered late
    elif proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
    proc.wait()
