"""The whole command line, as a user meets it: every command's ``--help`` works and every
option has help; every bad input ends in exit 2 and ONE line ``error: ...`` naming the place,
with no traceback and no usage box. Real subprocesses of ``twin``, run a few at a time."""

from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import pytest
import typer.main

from twin.cli import app

ENV = {**os.environ, "RERUN_ANALYTICS": "0", "COLUMNS": "200"}
COMMANDS = ("run", "demo", "view", "machines", "experiment", "home", "jog", "hil-server",
            "compare", "tune", "identify", "measure", "runs", "shaper")

BAD = [
    # (arguments, what the one line must contain); more are in test_cli_bad_input.py,
    # test_units_edge.py, test_compare.py and test_output_paths.py
    (("bogus",), "No such command 'bogus'"),
    (("--nope",), "No such option: --nope"),
    (("run", "--builtin", "nope"), "Invalid value for '--builtin'"),
    (("run", "--profile", "sinus"), "--profile: unknown law 'sinus'"),
    (("run", "--profile", "trapezoid+foo"), "--profile: unknown shaper 'foo'"),
    (("compare", "--profiles", "trapezoid,parabolic+foo"), "--profiles: unknown shaper 'foo'"),
    (("compare", "--profiles", "trapezoid,trapezoid+mzv"),          # tomsk_xy's y: 161 Hz
     "--profiles: trapezoid+mzv: controller.shaper.y.frequency: unset, and the model's mode"),
    (("shaper", "--shapers", "zv,foo"), "--shapers: unknown shaper 'foo'"),
    (("shaper", "--driver", "bogus://x"), "driver: unknown driver 'bogus://x'"),
    (("shaper", "--frequency-spread", "1.5"), "--frequency-spread: must lie in [0, 1)"),
    (("run", "--planner", "maybe"), "Invalid value for '--planner'"),
    (("run", "--dcu-order", "7"), "--dcu-order: must be at most 3, got 7"),
    (("run", "--rerun", "foo"), "--rerun: must be file, none, spawn, serve"),
    (("run", "--set", "max_velocity=900kg"), "is not in m/s"),
    (("run", "no_such_program.ngc"), "no_such_program.ngc"),
    (("run", "--period", "abc"), "--period: must be a number, got abc"),
    (("run", "--driver", "bogus://x"), "driver"),
    (("demo", "--machine", "no_such_machine"), "no_such_machine"),
    (("view", "no_such.rrd"), "does not exist"),
    (("view", "--port", "0", "x.rrd"), "--port: must be at least 1, got 0"),
    (("machines", "--diff", "tomsk_xy"), "requires 2 arguments"),
    (("machines", "--fields", "no_such_machine"), "no_such_machine"),
    (("experiment", "wiggle", "--amplitude", "1"), "Invalid value for 'kind"),
    (("experiment", "step", "--axis", "z", "--amplitude", "1"), "Invalid value for '--axis'"),
    (("experiment", "step"), "Missing option '--amplitude'"),
    (("experiment", "step", "--amplitude", "1", "--rerun", "foo"), "--rerun: must be"),
    (("home", "--axes", "z"), "Invalid value for '--axes'"),
    (("home", "--from", "abc"), "--from: expected X,Y in mm"),
    (("jog", "--distance", "1"), "Missing option '--axis'"),
    (("jog", "--axis", "z", "--distance", "1"), "Invalid value for '--axis'"),
    (("jog", "--axis", "x", "--distance", "abc"), "--distance: must be a number"),
    (("hil-server", "--port", "70000"), "--port: must be at most 65535"),
    (("hil-server", "--from", "1,2,3"), "--from: expected X,Y in mm"),
    (("hil-server", "--map", "no_such_map.toml"), "no_such_map"),
    (("compare", "--builtin", "nope"), "Invalid value for '--builtin'"),
    (("compare", "--rerun", "foo"), "--rerun: must be file, none"),
    (("compare", "--sweep", "max_jerk"), "--sweep: expected key=v1,v2"),
    (("tune",), "--method: is required"),
    (("tune", "--method", "grid"), "Invalid value for '--method'"),
    (("tune", "--method", "cma", "--program", "nope"), "Invalid value for '--program'"),
    (("tune", "--method", "cma", "--budget-s", "-1"), "budget_s"),
    (("tune", "--method", "cma", "--shaper", "foo"), "--shaper: unknown shaper 'foo'"),
    (("measure", "--excitation", "hammer", "--driver", "modbus://127.0.0.1:5020"),
     "--excitation: hammer: a modal hammer is a physical instrument"),
    (("measure", "--excitation", "hammer", "--hammer-force", "0"),
     "--hammer-force: must lie in (0, 100000] N"),
    (("measure", "--excitation", "hammer", "--hammer-duration", "-1"),
     "--hammer-duration: must lie in [0.05, 50] ms"),
    (("measure", "--excitation", "hammer", "--loop", "speed"),
     "--loop: the hammer measures the mechanics"),
    (("identify",), "Missing option '--output'"),
    (("identify", "-o", "x.toml", "--axes", "z"), "Invalid value for '--axes'"),
    (("measure", "--axis", "z"), "Invalid value for '--axis'"),
    (("measure", "--f-max", "5000"), "--f-max: must lie in (0, 1600] Hz, the Nyquist "
                                     "frequency of the accelerometer"),
    (("measure", "--sensor", "motor", "--f-max", "150"), "--f-max: must lie in (0, 100] "
                                                          "Hz"),
    (("measure", "--f-min", "0.05"), "--amplitude: axis x: the measurement travels"),
    (("measure", "--excitation", "prbs", "--periods", "2"),
     "--periods: is a setting of the multisine"),
    (("measure", "--periods", "0"), "--periods: must be a whole number 1 … 100, got 0"),
    (("measure", "--amplitude", "500"), "--amplitude: must lie in (0, 15] mm/s"),
]


def _twin(args, cwd) -> subprocess.CompletedProcess:
    # niced, as the suite's other background subprocesses: four of them at once on a 2-core
    # CI machine left a paced Modbus measurement beside them half its ticks late
    return subprocess.run([sys.executable, "-m", "twin.cli", *args], capture_output=True,
                          text=True, env=ENV, timeout=300, cwd=cwd,
                          preexec_fn=lambda: os.nice(10))


def test_the_choices_are_the_libraries_own():
    from tuning.jobs import METHODS
    from twin.cli.common import LAW_NAMES, PROGRAM_NAMES
    from twin.cli.tune import Method
    from twin.controller.library import PROGRAMS
    from twin.controller.profiles.laws import LAWS

    assert PROGRAM_NAMES == tuple(PROGRAMS) and LAW_NAMES == tuple(LAWS)
    assert tuple(m.value for m in Method) == METHODS


def test_every_option_of_every_command_has_help():
    group = typer.main.get_command(app)
    assert set(group.commands) == set(COMMANDS)
    missing = [f"{name} {p.name}" for name, cmd in group.commands.items()
               for p in cmd.params if not getattr(p, "help", None)]
    assert missing == []


def test_every_command_has_help_and_version(tmp_path):
    runs = [(c, "--help") for c in COMMANDS] + [("--help",), ("--version",)]
    with ThreadPoolExecutor(4) as pool:
        done = list(pool.map(lambda a: _twin(a, tmp_path), runs))
    for args, d in zip(runs, done, strict=True):
        assert d.returncode == 0 and "Traceback" not in d.stderr, (args, d.stderr)
        assert d.stdout.strip(), args


def test_every_bad_input_is_exit_2_and_one_line(tmp_path):
    with ThreadPoolExecutor(4) as pool:
        done = list(pool.map(lambda case: _twin(case[0], tmp_path), BAD))
    wrong = []
    for (args, words), d in zip(BAD, done, strict=True):
        lines = [ln for ln in d.stderr.splitlines() if ln.strip()]
        ok = (d.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: ")
              and words in lines[0] and "Traceback" not in d.stderr)
        if not ok:
            wrong.append((" ".join(args), d.returncode, d.stderr[-500:]))
    assert wrong == []
    assert not list(tmp_path.iterdir()) or all(p.name == "runs" for p in tmp_path.iterdir())


@pytest.mark.parametrize("name", ["compact", "tiny"])
def test_the_tuning_programs_run_with_twin_run(name, tmp_path):
    d = _twin(("run", "--builtin", name, "--rerun", "none", "--out", str(tmp_path), "--json"),
              tmp_path)
    assert d.returncode == 0, d.stderr
    assert '"status": "FINISHED"' in d.stdout
