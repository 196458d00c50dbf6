"""The HIL server as a subprocess: ``twin hil-server`` started on a free port, waited for
until it listens, and always stopped and reaped, for the tests, the benches and anyone
scripting a hardware-in-the-loop run (``spawn_hil_server``)."""

from __future__ import annotations

import contextlib
import json
import os
import selectors
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from typing import IO, Any

from twin.system.processes import stop_process

__all__ = ["HilProcess", "spawn_hil_server"]


@dataclass(frozen=True)
class HilProcess:
    """A running ``twin hil-server`` subprocess (see ``spawn_hil_server``).

    Attributes
    ----------
    process : subprocess.Popen
    info : dict
        Its ready line: host, port, machine, realtime, watchdog_ms, drive_interval_s, ...
    """

    process: subprocess.Popen
    info: dict[str, Any]
    _log: IO[str]

    @property
    def url(self) -> str:
        """The driver URL of the server (``modbus://HOST:PORT``)."""
        return f"modbus://{self.info['host']}:{self.info['port']}"

    def log(self) -> str:
        """What the server wrote on stderr so far (with an unread stderr pipe: everything,
        once it has stopped)."""
        pipe = self.process.stderr
        if pipe is not None:
            return pipe.read() if self.process.poll() is not None and not pipe.closed else ""
        self._log.seek(0)
        return self._log.read()

    def stop(self) -> dict[str, Any] | None:
        """Stop the server (SIGTERM) and return its statistics (``HilStats`` as a dict;
        None if it died without reporting them)."""
        stop_process(self.process)
        for line in reversed(self.log().splitlines()):
            with contextlib.suppress(ValueError):
                return json.loads(line)["hil_stats"]
        return None


def _ready(line: str) -> dict[str, Any] | None:
    """The server's ready object, or None (nothing, or a refusal: no port)."""
    try:
        info = json.loads(line) if line else None
    except ValueError:
        return None
    return info if isinstance(info, dict) and "port" in info else None


@contextlib.contextmanager
def spawn_hil_server(*args: str, ready_timeout: float = 60.0,
                     unread_stderr: bool = False) -> Iterator[HilProcess]:
    """Start ``twin hil-server --port 0 --json ARGS`` as a subprocess, yield it once it
    listens, and always stop it (SIGTERM, then SIGKILL) and reap it. ``unread_stderr``:
    its stderr is a pipe that nobody reads (as under a careless supervisor), instead of a
    file.

    Raises
    ------
    RuntimeError
        If the server exits or does not listen within ``ready_timeout`` (s); the message
        carries its stderr.
    """
    with tempfile.TemporaryFile("w+", encoding="utf-8") as log:
        proc = subprocess.Popen([sys.executable, "-m", "twin.cli", "hil-server", "--port", "0",
                                 "--json", *args], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE if unread_stderr else log,
                                text=True, env={**os.environ, "RERUN_ANALYTICS": "0"})
        try:
            with selectors.DefaultSelector() as sel:
                sel.register(proc.stdout, selectors.EVENT_READ)  # type: ignore[arg-type]
                line = proc.stdout.readline() if sel.select(ready_timeout) else ""  # type: ignore[union-attr]
            info = _ready(line)
            if info is None:        # no line, or the refusal object --json prints instead
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=10.0)
                proc.kill()
                proc.wait()
                log.seek(0)
                said = log.read().strip() if proc.stderr is None else ""
                raise RuntimeError(f"twin hil-server did not start (exit {proc.returncode})"
                                   f": {said or line.strip()}")
            yield HilProcess(proc, info, log)
        finally:
            stop_process(proc)
            proc.stdout.close()  # type: ignore[union-attr]
            if proc.stderr is not None:
                proc.stderr.close()
