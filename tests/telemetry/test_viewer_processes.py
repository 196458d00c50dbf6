"""Rerun processes that cannot leak: a headless ``spawn`` falls back to the file, a port
already in use is refused, a viewer lost mid-run costs only the live view, and ``serve`` and
``twin view --web`` stop their whole process group on SIGTERM, bound to 127.0.0.1 only."""

import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import numpy as np
import pytest
import rerun.chunk as rc

from tests.telemetry.test_rerun_sink import _free_port, _listening_addresses
from twin.errors import ViewerError
from twin.telemetry.rerun_sink import RerunSink
from twin.telemetry.viewer import ViewerUnavailable, running_rerun, stop_rerun

TWIN = [sys.executable, "-m", "twin.cli"]


def _rows(path, entity: str) -> int:
    chunks = rc.RrdReader(path).stream().to_chunks()
    return sum(c.num_rows for c in chunks if c.entity_path == entity)


def _processes_with(text: str) -> list[int]:
    """pids whose command line contains ``text``."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/cmdline", "rb") as f:
                    cmd = f.read().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if text in cmd:
                found.append(int(entry))
    return found


@pytest.fixture
def headless(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)


def test_headless_spawn_records_the_file_with_one_notice(tmp_path, headless):
    notes: list[str] = []
    sink = RerunSink(tmp_path / "r.rrd", live="spawn", port=_free_port(),
                     notice=notes.append)
    assert sink.url is None and not running_rerun()
    t = np.arange(100) * 0.005
    sink.scalars(t, {"a": t})
    sink.close()
    assert len(notes) == 1 and notes[0].startswith("no display") and "\n" not in notes[0]
    assert sink.notices == notes
    assert _rows(tmp_path / "r.rrd", "/a") == 100


def test_headless_spawn_without_a_file_is_an_error(headless):
    with pytest.raises(ViewerUnavailable, match="no display"):
        RerunSink(None, live="spawn", port=_free_port())


@pytest.mark.parametrize("live", ["serve", "spawn"])
def test_a_port_in_use_is_refused_not_streamed_into(tmp_path, live):
    with socket.socket() as stale:        # a server left from an earlier run
        stale.bind(("127.0.0.1", 0))
        stale.listen()
        port = stale.getsockname()[1]
        with pytest.raises(ViewerError, match=f"port {port} on 127.0.0.1 is already in use"):
            RerunSink(tmp_path / "r.rrd", live=live, port=port)
    assert not running_rerun()
    assert list(tmp_path.iterdir()) == []                 # no .rrd, no .partial


def test_a_viewer_lost_mid_run_costs_the_live_view_only(tmp_path):
    notes: list[str] = []
    sink = RerunSink(tmp_path / "r.rrd", live="serve", port=_free_port(), notice=notes.append)
    try:
        t = np.arange(1000) * 0.005
        sink.scalars(t, {"a": t})
        for proc in running_rerun():                  # the server dies
            os.killpg(proc.pid, signal.SIGKILL)
        for k in range(1, 25):
            sink.scalars(t + 5.0 * k, {"a": t})
            time.sleep(0.1)                           # reach the sink's flush checkpoints
        sink.close()
    finally:
        stop_rerun()
    assert sink.failed is None
    assert len(notes) == 1 and "went away" in notes[0]
    assert _rows(tmp_path / "r.rrd", "/a") == 25_000


def _read_until(proc: subprocess.Popen, text: str, timeout: float = 120.0) -> str:
    """stderr lines of ``proc`` until one contains ``text`` (that line)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if text in line:
            return line
        if not line and proc.poll() is not None:
            break
    proc.kill()
    pytest.fail(f"{text!r} never appeared (exit {proc.poll()})")


def test_served_run_stops_its_server_on_sigterm(tmp_path):
    port = _free_port()
    proc = subprocess.Popen([*TWIN, "run", "--builtin", "tiny", "--rerun", "serve",
                             "--rerun-port", str(port), "--out", str(tmp_path), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = _read_until(proc, f"serving it at rerun+http://127.0.0.1:{port}/proxy")
        # the run is reported when it ends, not when the server is stopped
        summary = json.loads(proc.stdout.readline())
        assert line.startswith(f"run {summary['run_id']} finished after ")
        assert "--connect" in line
        assert _listening_addresses(port) == {"0100007F"}
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "Traceback" not in err and not out.strip()
    assert _listening_addresses(port) == set()
    assert _processes_with(f"--port {port}") == []        # no rerun left in its group
    assert summary["status"] == "FINISHED"
    assert (tmp_path / f"{summary['run_id']}.rrd").exists()


def test_headless_spawn_run_is_complete_with_a_one_line_warning(tmp_path, headless):
    done = subprocess.run([*TWIN, "run", "--builtin", "tiny", "--rerun", "spawn",
                           "--rerun-port", str(_free_port()), "--out", str(tmp_path),
                           "--json"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    warnings = [line for line in done.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and "no display" in warnings[0]
    summary = json.loads(done.stdout)
    assert summary["status"] == "FINISHED"
    assert summary["warnings"] and "no display" in summary["warnings"][0]
    assert (tmp_path / f"{summary['run_id']}.rrd").exists()
    assert (tmp_path / f"{summary['run_id']}.json").exists()
    assert not list(tmp_path.glob("*.partial"))


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("view") / "r.rrd"
    with RerunSink(path) as sink:
        t = np.arange(200) * 0.005
        sink.scalars(t, {"errors/contour_um": np.sin(t)})
    return path


def test_view_web_prints_the_address_that_opens_the_recording(recording):
    web, grpc = _free_port(), _free_port()
    proc = subprocess.Popen([*TWIN, "view", "--web", "--port", str(web), "--grpc-port",
                             str(grpc), str(recording)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = _read_until(proc, "web viewer:", timeout=60)
        url = line.split("web viewer:", 1)[1].split()[0]
        assert url == (f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}"
                       "%2Fproxy")
        with urllib.request.urlopen(url, timeout=10) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        assert _listening_addresses(web) == {"0100007F"}
        assert _listening_addresses(grpc) == {"0100007F"}
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and "Traceback" not in err
    assert _listening_addresses(web) == set() and _listening_addresses(grpc) == set()


def test_native_view_without_a_display_says_so(recording, headless):
    done = subprocess.run([*TWIN, "view", str(recording)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "error: no display for the native viewer (DISPLAY and WAYLAND_DISPLAY are unset); "
        "serve it to a browser with --web"]
