"""Bad input on the command line ends in exit 2 and one line naming the place, never a
traceback (issue 19: start positions of NaN, a host that does not exist, a port in use)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys

import pytest

ENV = {**os.environ, "RERUN_ANALYTICS": "0"}


def _twin(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "twin.cli", *args], env=ENV,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args", [("home", "--axes", "x", "--from", "nan,nan"),
                                  ("jog", "--axis", "x", "--distance", "1", "--from",
                                   "900,5", "--dry-run")])
def test_a_start_outside_the_travel_is_refused_naming_it(args):
    done = _twin(*args)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert "start: must be 2 positions within the travel" in " ".join(done.stderr.split())


def test_a_bracketed_value_in_a_message_is_printed_as_it_is():
    # rich took "[nan, nan]" for markup and printed "got array()"
    done = _twin("home", "--axes", "x", "--from", "nan,nan")
    assert "got nan, nan mm" in " ".join(done.stderr.split())
    done = _twin("run", "--set", "axes.x.mechanics.travel=[0, 0.3]", "--rerun", "none")
    assert "a bare [0, 0.3] would be read in m" in " ".join(done.stderr.split())


def test_a_host_that_does_not_exist_is_refused_naming_it():
    done = _twin("hil-server", "--host", "999.1.1.1", "--port", "5999")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "--host: cannot bind '999.1.1.1'" in done.stderr


def test_a_port_in_use_is_refused_naming_it():
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        done = _twin("hil-server", "--port", str(port))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert f"--port: cannot listen on 127.0.0.1:{port}" in done.stderr


def test_an_unknown_builtin_program_is_refused_naming_the_valid_ones(tmp_path):
    done = _twin("run", "--builtin", "nope", "--rerun", "none", "--out", str(tmp_path))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    text = " ".join(done.stderr.split())
    assert "Invalid value for '--builtin'" in text and "'nope' is not one of" in text
    assert "'compact', 'tiny', 'spline_line'" in text


def test_version():
    from importlib.metadata import version

    done = _twin("--version")
    assert done.returncode == 0 and done.stdout.strip() == f"xy-twin {version('xy-twin')}"


def test_a_shipped_program_runs_from_any_folder_and_a_missing_one_is_named(tmp_path):
    for name in ("twin/programs/square_circle.ngc", "square_circle.ngc"):
        done = subprocess.run([sys.executable, "-m", "twin.cli", "run", name, "--rerun",
                               "none", "--out", str(tmp_path), "--dry-run", "--json"],
                              env=ENV, capture_output=True, text=True, timeout=300,
                              cwd=tmp_path)
        assert "no such file" not in done.stderr, done.stderr
        assert "Traceback" not in done.stderr
    done = _twin("run", str(tmp_path / "nope.ngc"), "--rerun", "none", "--out", str(tmp_path))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    text = " ".join(done.stderr.split())
    assert "no such file" in text and "square_circle.ngc" in text and "plotter_pen.ngc" in text
