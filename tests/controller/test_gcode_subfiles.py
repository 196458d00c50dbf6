"""Called subroutine files (issue 33): looked up only in the program's folder and the
configured subroutine folders, never outside them (``..``, absolute names, symlinks), with
one message whether an outside file exists or not, and streamed like the main program."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from twin.config import load_machine
from twin.controller.gcode import Limits, ReaderOptions, parse, read_file
from twin.errors import GCodeError
from twin.session.setup import reader_options

SUB = "o<{name}> sub\nG1 X{x} Y[#1] F100\no<{name}> endsub\n"


def _tree(tmp_path: Path) -> dict[str, Path]:
    """A program folder ``c/sub`` with secrets around it, and a subroutine folder."""
    paths = {"prog": tmp_path / "c" / "sub", "lib": tmp_path / "lib",
             "outside": tmp_path / "outside"}
    for folder in paths.values():
        folder.mkdir(parents=True)
    (tmp_path / "secret.ngc").write_text(SUB.format(name="../../secret", x=1))
    (tmp_path / "c" / "secret2.ngc").write_text(SUB.format(name="../secret2", x=2))
    (paths["outside"] / "secret3.ngc").write_text(SUB.format(name="secret3", x=3))
    (paths["lib"] / "libsub.ngc").write_text(SUB.format(name="libsub", x=7))
    (paths["prog"] / "here.ngc").write_text(SUB.format(name="here", x=4))
    return paths


def _call(name: str, paths: dict[str, Path], subroutine_path: tuple[str, ...] = ()):
    text = f"G21 G90\no<{name}> call [3]\nM2\n"
    return parse(text, folder=str(paths["prog"]),
                 options=ReaderOptions(limits=Limits(subroutine_path=subroutine_path)))


def _refusal(name: str, paths: dict[str, Path], subroutine_path=()) -> GCodeError:
    with pytest.raises(GCodeError) as info:
        _call(name, paths, subroutine_path)
    error = info.value
    assert (error.line, error.column, error.code) == (2, 1, "unknown-sub")
    return error


@pytest.mark.parametrize("name", ["../../secret", "../secret2", "..", "a..b", "sub/here",
                                  "{outside}/secret3", "{outside}/../c/secret2", "a\\b",
                                  "c:secret", "\\..\\secret"])
def test_a_name_that_is_not_a_plain_file_name_is_refused_before_any_lookup(name, tmp_path):
    paths = _tree(tmp_path)
    name = name.format(outside=paths["outside"])
    error = _refusal(name, paths, (str(paths["lib"]),))
    assert "a subroutine name is a file name in the subroutine folders" in error.message
    # nothing about the file system: no folder, no path, no "does not define"
    assert str(tmp_path) not in error.message or name.startswith(str(tmp_path))
    assert "does not define" not in error.message


def test_a_symlink_out_of_the_folders_is_the_same_as_no_file(tmp_path):
    paths = _tree(tmp_path)
    prog = paths["prog"]
    os.symlink(tmp_path / "c" / "secret2.ngc", prog / "up.ngc")          # exists, outside
    os.symlink(tmp_path / "nothing.ngc", prog / "dangling.ngc")           # missing, outside
    os.symlink(paths["outside"], prog / "dir")                            # a folder outside
    os.symlink(tmp_path / "secret.ngc", paths["lib"] / "deep.ngc")        # via the lib
    messages = {}
    for name in ("up", "dangling", "missing", "deep"):
        error = _refusal(name, paths, (str(paths["lib"]),))
        messages[name] = error.message.replace(name, "NAME")
    # one message, whether the file behind the name exists or not
    assert len(set(messages.values())) == 1, messages
    assert "no subroutine <NAME> in the program and no NAME.ngc in" in messages["up"]


def test_a_symlink_inside_the_folders_is_followed(tmp_path):
    paths = _tree(tmp_path)
    os.symlink(paths["lib"] / "libsub.ngc", paths["prog"] / "libsub.ngc")
    program = _call("libsub", paths, (str(paths["lib"]),))
    assert [m.end for m in program.moves] == [pytest.approx((7e-3, 3e-3))]


def test_the_program_folder_comes_first_then_the_configured_ones(tmp_path):
    paths = _tree(tmp_path)
    assert _call("here", paths).moves[0].end == pytest.approx((4e-3, 3e-3))
    assert _call("libsub", paths, (str(paths["lib"]),)).moves[0].end == \
        pytest.approx((7e-3, 3e-3))
    (paths["prog"] / "libsub.ngc").write_text(SUB.format(name="libsub", x=9))
    assert _call("libsub", paths, (str(paths["lib"]),)).moves[0].end == \
        pytest.approx((9e-3, 3e-3))
    error = _refusal("libsub2", paths, (str(paths["lib"]), str(tmp_path / "absent")))
    assert f"in {paths['prog']}, {paths['lib']}" in error.message     # absent: left out


def test_a_file_replaced_while_the_program_runs_is_refused(tmp_path):
    paths = _tree(tmp_path)
    target = paths["prog"] / "here.ngc"
    items = read_file_with_calls(paths["prog"], 2)
    next(items)                                   # first call: the file as checked
    target.unlink()
    os.symlink(tmp_path / "secret.ngc", target)   # swapped for a link out
    with pytest.raises(GCodeError) as info:
        list(items)
    assert info.value.code == "unknown-sub" and "cannot read" in info.value.message


def read_file_with_calls(folder: Path, calls: int):
    program = folder / "main.ngc"
    program.write_text("G21 G90\n" + "o<here> call [3]\nG0 X0 Y0\n" * calls + "M2\n")
    return read_file(program)


def test_the_machine_file_names_the_subroutine_folders_relative_to_itself(tmp_path):
    paths = _tree(tmp_path)
    machine = tmp_path / "m.toml"
    base = (Path(load_machine("tomsk_xy").source)).read_text()
    machine.write_text(base + '\n[controller.gcode]\nsubroutine_path = ["lib"]\n')
    options = reader_options(load_machine(machine))
    assert options.limits.subroutine_path == (str(tmp_path / "lib"),)
    program = parse("G21 G90\no<libsub> call [3]\nM2\n", folder=str(paths["prog"]),
                    options=options)
    assert program.moves[0].end == pytest.approx((7e-3, 3e-3))


MEASURE = textwrap.dedent("""
    import sys
    from twin.controller.gcode import read_file
    n = sum(1 for _ in read_file(sys.argv[1]))
    # the peak of this program's own memory: ru_maxrss would carry over the parent's
    # high-water mark through fork and exec
    with open("/proc/self/status") as f:
        peak = next(row.split()[1] for row in f if row.startswith("VmHWM:"))
    print(n, peak)   # kB
""")


def _peak(program: Path) -> tuple[int, float]:
    done = subprocess.run([sys.executable, "-c", MEASURE, str(program)], check=True,
                          capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    items, kib = done.stdout.split()
    return int(items), int(kib) / 1024


@pytest.mark.slow
@pytest.mark.timeout(900)
@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="VmHWM is Linux's")
def test_a_called_file_runs_in_the_memory_of_the_same_main_program(tmp_path):
    mib = 1 if os.environ.get("CI") else 16          # the 16 MB; CI a sixteenth
    bound = 20.0 * mib / 16                           # MiB: the 20 MB, in proportion
    rows, size, k = [], 0, 0
    while size < mib * 2**20:
        row = f"G1 X{(k * 37) % 1000 / 10:.3f} Y{(k * 91) % 1000 / 10:.3f}\n"
        rows.append(row)
        size += len(row)
        k += 1
    body = "".join(rows)
    (tmp_path / "main.ngc").write_text("G21 G90 F600\n" + body + "M2\n")
    (tmp_path / "caller.ngc").write_text("G21 G90 F600\no<big> call\nM2\n")
    (tmp_path / "big.ngc").write_text("o<big> sub\n" + body + "o<big> endsub\n")
    main_items, main_peak = _peak(tmp_path / "main.ngc")
    called_items, called_peak = _peak(tmp_path / "caller.ngc")
    assert called_items == main_items > len(rows) * 0.99
    # a called file read whole took 633 MB against 352 MB for the same main program
    assert called_peak - main_peak < bound, (called_peak, main_peak)
