"""Child processes the twin starts (rerun viewers, HIL servers): stopped one way."""

from __future__ import annotations

import subprocess

__all__ = ["stop_process"]


def stop_process(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    """SIGTERM ``proc`` if it still runs, wait up to ``timeout`` s, then SIGKILL; always
    reap it (no zombie is left behind)."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            proc.kill()
    proc.wait()
