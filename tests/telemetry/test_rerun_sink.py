"""The rerun sink: atomic files, and live servers that listen on loopback only."""

import socket

import numpy as np
import rerun.chunk as rc

from twin.telemetry.rerun_sink import RerunSink
from twin.telemetry.viewer import running_rerun, stop_rerun


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _listening_addresses(port: int) -> set[str]:
    """Local addresses (hex, as in /proc/net/tcp) listening on ``port``."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            rows = open(table).read().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            local, state = row.split()[1], row.split()[3]
            addr, hexport = local.split(":")
            if state == "0A" and int(hexport, 16) == port:   # 0A = LISTEN
                found.add(addr)
    return found


def test_served_recording_listens_on_loopback_only(tmp_path):
    port = _free_port()
    sink = RerunSink(tmp_path / "r.rrd", live="serve", port=port)
    try:
        assert sink.url == f"rerun+http://127.0.0.1:{port}/proxy"
        assert _listening_addresses(port) == {"0100007F"}      # 127.0.0.1, nothing else
        t = np.arange(5) * 0.005
        sink.scalars(t, {"axes/x/position/actual": t})
        sink.close()
        assert running_rerun()                                 # outlives the run
    finally:
        stop_rerun()
    assert not running_rerun()
    assert _listening_addresses(port) == set()     # the server itself, not only its launcher
    chunks = rc.RrdReader(tmp_path / "r.rrd").stream().to_chunks()
    assert "/axes/x/position/actual" in {c.entity_path for c in chunks}


def test_file_is_written_atomically(tmp_path):
    sink = RerunSink(tmp_path / "a.rrd")
    sink.scalars(np.arange(3.0), {"s": np.arange(3.0)})
    assert not (tmp_path / "a.rrd").exists() and (tmp_path / "a.rrd.partial").exists()
    sink.close()
    assert (tmp_path / "a.rrd").exists() and not (tmp_path / "a.rrd.partial").exists()
