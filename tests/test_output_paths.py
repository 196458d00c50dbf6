"""Faults of the filesystem: an output path that is not a writable folder is refused before
anything starts (exit 2, one line, no traceback); an atomic write that fails leaves no
``.partial``; tuning writes its settings and result before any figure."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys

import pytest

from twin.errors import ConfigError
from twin.system.jsonio import folder_lock, output_dir, write_text_atomic


def _twin(*args: str, limit_file_size: bool = False) -> subprocess.CompletedProcess:
    def no_writes() -> None:   # a full disk: every write of a byte fails with EFBIG
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (0, 0))

    return subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True,
                          text=True, timeout=300, env={**os.environ, "RERUN_ANALYTICS": "0"},
                          preexec_fn=no_writes if limit_file_size else None)


def _refused(proc: subprocess.CompletedProcess, *words: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert all(w in proc.stderr for w in words), proc.stderr


@pytest.mark.parametrize("command", [
    ["run", "--builtin", "spline_line"],
    ["compare", "--profiles", "trapezoid"],
    ["tune", "--method", "analytic", "--program", "tiny"],
])
def test_an_output_path_that_is_a_file_is_refused_before_anything_runs(command, tmp_path):
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("keep me")
    _refused(_twin(*command, "--out", str(not_a_folder)), "out", "is not a folder")
    _refused(_twin(*command, "--out", str(not_a_folder / "below")), "cannot write in")
    assert not_a_folder.read_text() == "keep me"


def test_identify_checks_both_of_its_folders_before_the_machine_moves(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    _refused(_twin("identify", "-o", str(blocker / "cal.toml")), "output", "is not a folder")
    _refused(_twin("identify", "-o", str(tmp_path / "cal.toml"), "--out", str(blocker)),
             "is not a folder")
    assert not list(tmp_path.glob("identify-*")) and not (tmp_path / "cal.toml").exists()


def test_a_folder_nothing_can_be_written_in_is_refused(tmp_path):
    proc = _twin("run", "--builtin", "spline_line", "--out", str(tmp_path / "runs"),
                 limit_file_size=True)
    _refused(proc, "cannot write in", "File too large")
    assert not (tmp_path / "runs").exists()   # nothing left behind, not even the folder


def test_output_dir_creates_and_checks(tmp_path):
    assert output_dir(tmp_path / "a" / "b").is_dir()
    (tmp_path / "f").write_text("")
    with pytest.raises(ConfigError) as caught:
        output_dir(tmp_path / "f", "record")
    assert caught.value.field == "record"


def test_a_failed_atomic_write_leaves_no_partial(tmp_path):
    target = tmp_path / "summary.json"
    target.mkdir()                       # os.replace of a file onto a folder fails
    with pytest.raises(OSError):
        write_text_atomic(target, "{}")
    assert not list(tmp_path.glob("*.partial"))


def test_tuning_keeps_settings_and_result_when_the_figure_fails(tmp_path, monkeypatch):
    import tuning.jobs as jobs

    def broken(*_args, **_kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(jobs, "plot_convergence", broken)
    with pytest.raises(OSError, match="No space"):
        jobs.tune(jobs.TuneSpec(method="analytic", program="tiny", out_dir=tmp_path))
    assert (tmp_path / "best.toml").is_file() and (tmp_path / "result.json").is_file()
    assert (tmp_path / "report.md").is_file()


def test_a_second_job_into_a_busy_folder_is_refused(tmp_path):
    with folder_lock(tmp_path) as held:
        assert held == tmp_path
        proc = _twin("tune", "--method", "analytic", "--program", "tiny", "--out",
                     str(tmp_path))
        _refused(proc, "out", "in use by another job", f"pid {os.getpid()}")
        assert not (tmp_path / "best.toml").exists()
        with pytest.raises(ConfigError, match="in use"):   # also within one process
            with folder_lock(tmp_path):
                pass
    proc = _twin("tune", "--method", "analytic", "--program", "tiny", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr       # released with its holder
    assert (tmp_path / "best.toml").is_file()


def test_an_output_path_through_a_dangling_symlink_names_the_symlink(tmp_path):
    link = tmp_path / "runs"
    link.symlink_to(tmp_path / "gone" / "deeper")
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    for path, named in ((link, link), (link / "below" / "more", link), (loop, loop)):
        with pytest.raises(ConfigError) as info:
            output_dir(path)
        assert info.value.field == "out"
        assert info.value.message.startswith(f"{named} is a symlink to "), info.value.message
        assert "File exists" not in info.value.message
    assert not (tmp_path / "gone").exists()            # nothing was created behind it
    (tmp_path / "gone" / "deeper").mkdir(parents=True)
    assert output_dir(link / "below") == link / "below" and (link / "below").is_dir()


@pytest.mark.parametrize("command", [
    ["run", "nosuch.ngc"],
    ["compare", "nosuch.ngc", "--profiles", "trapezoid,parabolic"],
    ["run", "nosuch.ngc", "--dry-run"],
])
def test_a_refused_command_leaves_no_folder_behind(command, tmp_path):
    """The folders a command made for its results go when it refuses its input; a folder
    that was there before stays, and so does what it held."""
    made = tmp_path / "new" / "deeper"
    _refused(_twin(*command, "--out", str(made)), "nosuch.ngc")
    assert not (tmp_path / "new").exists()
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "earlier.txt").write_text("an earlier result")
    _refused(_twin(*command, "--out", str(kept / "sub")), "nosuch.ngc")
    assert sorted(p.name for p in kept.iterdir()) == ["earlier.txt"]


def test_drop_unused_outputs_removes_only_empty_folders_it_made(tmp_path):
    from twin.system.jsonio import drop_unused_outputs, forget_outputs

    forget_outputs()
    empty = output_dir(tmp_path / "a" / "b")
    used = output_dir(tmp_path / "c")
    (used / "result.json").write_text("{}")
    drop_unused_outputs()
    assert not (tmp_path / "a").exists() and not empty.exists()
    assert (used / "result.json").is_file()
