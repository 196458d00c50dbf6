"""Bytes that are not UTF-8: a program's are read as U+FFFD and reported with their place;
a TOML file (machine, set-file, register map) is refused naming the file and the byte."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from twin.config import load_machine, read_toml
from twin.config.overrides import set_file_overrides
from twin.controller.gcode import decode_program, parse
from twin.errors import ConfigError, GCodeError
from twin.hardware.register_map import load_register_map


def test_a_latin1_comment_is_read_and_its_place_reported():
    data = "G21 G90\nG1 X1 F100 (r\xe9glage de la vitesse)\nM30\n".encode("latin-1")
    text, notes = decode_program(data)
    assert notes == ["line 2, column 14 (byte 21): 1 byte not UTF-8 (0xe9), read as U+FFFD"]
    assert "\ufffd" in text
    assert len(list(parse(text).items)) >= 1      # the comment is harmless


def test_a_bad_byte_outside_a_comment_is_a_syntax_error_with_its_place():
    text, notes = decode_program(b"G21 G90\nG1 X1\xff F100\n")
    assert notes and notes[0].startswith("line 2, column 6")
    with pytest.raises(GCodeError) as caught:
        parse(text)
    assert caught.value.line == 2 and caught.value.column == 6


def test_many_bad_bytes_are_noted_up_to_a_bound():
    _, notes = decode_program(b"(\xff)\n" * 50)
    assert len(notes) == 21 and notes[-1] == "… and 30 more such places"


def test_twin_run_reports_the_bytes_it_mapped(tmp_path):
    program = tmp_path / "latin1.ngc"
    program.write_bytes("G91 G1 X1 F600 (avance \xe0 vide)\nM30\n".encode("latin-1"))
    proc = subprocess.run([sys.executable, "-m", "twin.cli", "run", str(program), "--rerun",
                           "none", "--out", str(tmp_path), "--json"], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["input_warnings"] == [
        "latin1.ngc: line 1, column 24 (byte 23): 1 byte not UTF-8 (0xe0), read as U+FFFD"]
    assert "warning:" in proc.stderr and "byte 23" in proc.stderr


@pytest.mark.parametrize("reader", ["machine", "set_file", "register_map"])
def test_a_toml_file_that_is_not_utf8_is_refused_naming_the_byte(reader, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_bytes(b"# caf\xe9\n[machine]\nname = 'x'\n")
    read = {"machine": load_machine, "set_file": set_file_overrides,
            "register_map": load_register_map}[reader]
    with pytest.raises(ConfigError, match=r"not UTF-8 text: byte 5 \(line 1, column 6\) "
                                          r"is 0xe9") as caught:
        read(str(path))
    assert "bad.toml" in str(caught.value)


def test_invalid_toml_is_still_named():
    with pytest.raises(ConfigError, match="invalid TOML"):
        read_toml(__file__)
