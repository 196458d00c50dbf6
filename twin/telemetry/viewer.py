"""The rerun processes the twin starts: a live viewer or gRPC server for a run
(``start_rerun``), a viewer for a recording (``open_recording``, ``twin view``).

Every one is bound to loopback, runs in a process group of its own and is stopped with the
whole group (``twin.system.processes.stop_process``): the ``rerun`` entry point runs the real
server as its child, which would otherwise outlive it, still listening. A port something
already listens on is refused, never streamed into.
"""

from __future__ import annotations

import atexit
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import quote

from twin.errors import ViewerError
from twin.system.processes import stop_process

__all__ = ["ViewerUnavailable", "has_display", "listening", "open_recording", "rerun_command",
           "running_rerun", "start_rerun", "stop_rerun", "web_viewer_url"]

_PROCESSES: list[subprocess.Popen] = []


class ViewerUnavailable(ViewerError):
    """A live viewer cannot be shown here (no display, or the viewer exited at start)."""


def has_display() -> bool:
    """A native window can open: a display on X11/Wayland; assumed on macOS and Windows."""
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def listening(host: str, port: int) -> bool:
    """Something accepts TCP connections on ``host:port``."""
    try:
        with socket.create_connection((host, port), timeout=0.2):
            return True
    except OSError:
        return False


def rerun_command() -> str:
    """The ``rerun`` command as a user can type it: ``rerun`` when it is on the PATH, else
    the full path of the one beside this Python (a venv not activated)."""
    return "rerun" if shutil.which("rerun") else str(Path(sys.executable).with_name("rerun"))


def _rerun_exe() -> str:
    """The ``rerun`` executable: on the PATH, or beside this Python (a venv not activated)."""
    return shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))


def start_rerun(kind: str, *, host: str = "127.0.0.1", port: int = 9876,
                timeout: float = 20.0) -> str:
    """Start ``rerun`` as a viewer (``kind="spawn"``) or a headless gRPC server
    (``"serve"``) listening on ``host:port`` only, in a process group of its own; return its
    ``rerun+http`` URL once it accepts connections.

    Refused (``ViewerError``) when something already listens on the port: a server left by
    an earlier run would take the stream with no window and no message. A viewer without a
    display, or one that exits before it listens, raises ``ViewerUnavailable``."""
    if listening(host, port):
        raise ViewerError(f"rerun: port {port} on {host} is already in use (a rerun server or "
                          "viewer left from an earlier run?); close it and run again")
    if kind == "spawn" and not has_display():
        raise ViewerUnavailable("no display for a rerun viewer (DISPLAY and WAYLAND_DISPLAY "
                                "are unset)")
    exe = _rerun_exe()
    args = [exe, "--bind", host, "--port", str(port)]
    if kind == "serve":
        args.append("--serve-grpc")
    proc = subprocess.Popen(args, env={**os.environ, "RERUN_ANALYTICS": "0"},
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    if kind == "serve":  # a spawned viewer is the user's window: it stays open
        _PROCESSES.append(proc)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise ViewerUnavailable(f"the rerun {'viewer' if kind == 'spawn' else 'server'} "
                                    f"exited with code {proc.returncode} before it listened "
                                    f"on {host}:{port}")
        if listening(host, port):
            return f"rerun+http://{host}:{port}/proxy"
        time.sleep(0.05)
    stop_process(proc, timeout=5.0)
    raise ViewerUnavailable(f"rerun did not listen on {host}:{port} within {timeout} s")


def running_rerun() -> list[subprocess.Popen]:
    """The rerun servers this process started that are still running."""
    return [p for p in _PROCESSES if p.poll() is None]


@atexit.register
def stop_rerun() -> None:
    """Stop the rerun servers this process started."""
    for proc in _PROCESSES:
        stop_process(proc, timeout=5.0)
    _PROCESSES.clear()


def web_viewer_url(web_port: int, grpc_url: str, host: str = "127.0.0.1") -> str:
    """The address that opens the web viewer on ``grpc_url``'s data (the bare
    ``http://host:port`` opens an empty viewer)."""
    return f"http://{host}:{web_port}/?url={quote(grpc_url, safe='')}"


def open_recording(recording: str | Path, *, web: bool = False, web_port: int = 9090,
                   grpc_port: int = 9876, host: str = "127.0.0.1",
                   announce=lambda text: print(text, file=sys.stderr),
                   timeout: float = 20.0) -> int:
    """Show a recording in the native viewer, or (``web``) serve it to the web viewer, until
    the viewer closes or a KeyboardInterrupt arrives (the caller raises one for SIGTERM and
    SIGHUP too: ``twin.session.run_end.stop_signals``); then stop the viewer's whole process group.
    Every listener binds ``host``; ports already in use are refused. Returns the viewer's
    exit code (0 after a stop signal).

    ``announce`` is told the web viewer's working address once both servers listen."""
    ports = (grpc_port, web_port) if web else (grpc_port,)
    for port in ports:
        if listening(host, port):
            raise ViewerError(f"port {port} on {host} is already in use (a rerun server or "
                              "viewer left from an earlier run?); close it or choose another "
                              "port")
    if not web and not has_display():
        raise ViewerUnavailable("no display for the native viewer (DISPLAY and "
                                "WAYLAND_DISPLAY are unset); serve it to a browser with "
                                "--web")
    exe = _rerun_exe()
    args = [exe, str(recording), "--bind", host, "--port", str(grpc_port)]
    if web:
        args += ["--web-viewer", "--web-viewer-port", str(web_port)]
    # rerun's own INFO log names a different address (localhost): warnings only
    proc = subprocess.Popen(args, env={**os.environ, "RERUN_ANALYTICS": "0", "RUST_LOG": "warn"},
                            stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        if web:
            deadline = time.monotonic() + timeout
            while not all(listening(host, p) for p in ports):
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise ViewerUnavailable(
                        f"the rerun web viewer did not start (exit code {proc.poll()})")
                time.sleep(0.05)
            grpc = f"rerun+http://{host}:{grpc_port}/proxy"
            announce(f"web viewer: {web_viewer_url(web_port, grpc, host)} (Ctrl-C to stop)")
        return proc.wait()
    except KeyboardInterrupt:
        return 0
    finally:
        stop_process(proc, timeout=5.0)
