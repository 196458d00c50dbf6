"""A disk that fills during a run (issue 19): the recording ends, the run goes on to its
safe stop, the summary is still written (or, if even that does not fit, printed), saying
the recording failed; no traceback, no ``.partial`` left, earlier files intact.

The full disk is a 300 KiB tmpfs where the test may mount one (root in the CI container),
else a file-size limit (RLIMIT_FSIZE, with SIGXFSZ ignored so writes fail with EFBIG)."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ENV = {**os.environ, "RERUN_ANALYTICS": "0"}


def _limit(size: int) -> Callable[[], None]:
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))
    return apply


@pytest.fixture
def small_disk(tmp_path) -> Iterator[tuple[Path, Callable[[], None] | None]]:
    """A folder on a 300 KiB file system, and the preexec function that stands in for one
    when mounting is not allowed."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    mounted = os.geteuid() == 0 and subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=300k", "tmpfs", str(mnt)],
        capture_output=True).returncode == 0
    try:
        yield mnt, (None if mounted else _limit(300 * 1024))
    finally:
        if mounted:
            subprocess.run(["umount", str(mnt)], check=False)


def _run(out: Path, preexec: Callable[[], None] | None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "twin.cli", "run", "--out", str(out),
                           "--json"], env=ENV, capture_output=True, text=True, timeout=300,
                          preexec_fn=preexec)


def test_a_disk_that_fills_during_a_run_keeps_the_run_and_its_summary(small_disk):
    mnt, preexec = small_disk
    earlier = mnt / "earlier.txt"
    earlier.write_bytes(b"x" * 10_000)
    done = _run(mnt / "runs", preexec)
    assert done.returncode == 1, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    printed = json.loads(done.stdout)
    assert printed["status"] == "FAULT" and printed["fault"] == "RECORDING"
    assert printed["controller_status"] == "FINISHED"      # the run went on to its end
    assert printed["recording"] is None and printed["recording_error"]
    assert "could not be written" in printed["error"]
    files = sorted(p.name for p in (mnt / "runs").iterdir())
    assert files == [f"{printed['run_id']}.json"]            # no .rrd, no .partial
    saved = json.loads((mnt / "runs" / files[0]).read_text())
    assert saved["status"] == "FAULT" and saved["recording_error"] == printed["recording_error"]
    assert earlier.read_bytes() == b"x" * 10_000


def test_a_summary_that_does_not_fit_is_printed_and_nothing_is_left(tmp_path):
    out = tmp_path / "runs"
    done = _run(out, _limit(4096))                          # not even the summary fits
    assert done.returncode == 1 and "Traceback" not in done.stderr
    printed = json.loads(done.stdout)
    assert printed["fault"] == "RECORDING" and "summary could not be written" in \
        printed["summary_error"]
    assert "the summary could not be written" in " ".join(done.stderr.split())
    assert [p for p in out.iterdir() if p.stat().st_size == 0 or ".partial" in p.name] == []


@pytest.fixture
def read_only(tmp_path) -> Iterator[Path]:
    """A read-only folder holding an earlier run's files: a tmpfs remounted read-only (root,
    where chmod would not stop a write), else a folder without write permission."""
    mnt = tmp_path / "ro"
    mnt.mkdir()
    mounted = os.geteuid() == 0 and subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)],
        capture_output=True).returncode == 0
    if os.geteuid() == 0 and not mounted:
        pytest.fail("running as root but cannot mount a tmpfs to make a read-only folder")
    (mnt / "runs").mkdir()
    (mnt / "runs" / "earlier.json").write_text('{"status": "FINISHED"}')
    try:
        if mounted:
            subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True)
        else:
            (mnt / "runs").chmod(0o555)
        yield mnt / "runs"
    finally:
        if mounted:
            subprocess.run(["umount", str(mnt)], check=False)
        else:
            (mnt / "runs").chmod(0o755)


def test_a_read_only_folder_is_refused_before_anything_runs(read_only):
    done = _run(read_only, None)
    assert done.returncode == 2, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    assert "cannot write in" in done.stderr and ("Read-only" in done.stderr
                                                 or "Permission denied" in done.stderr)
    assert sorted(p.name for p in read_only.iterdir()) == ["earlier.json"]
    assert json.loads((read_only / "earlier.json").read_text()) == {"status": "FINISHED"}
