"""The streaming reader: same items as ``parse``, lazily, in bounded memory."""

from __future__ import annotations

import itertools
import tracemalloc

import pytest

from twin.controller.gcode import Move, ProgramEnd, iter_items, parse, read_file
from twin.errors import GCodeError

CYCLE = (
    "N{n} G1 X10 Y0 F1200 (one cycle returns to the origin)",
    "G3 X0 Y10 I-10 J0",
    "G2 X-10 Y0 R10",
    "S{s} M3 ; spindle",
    "G4 P0.01",
    "G91 G1 X5 Y-5",
    "G90 G0 X0 Y0",
)
"""Seven lines that exercise every item kind and end where they started."""


def write_program(path, cycles: int) -> int:
    """Write ``cycles`` repetitions of ``CYCLE`` plus a header and M30; return the lines."""
    with open(path, "w", encoding="utf-8") as out:
        out.write("%\nG21 G90 G17 G94\n")
        for n in range(cycles):
            for template in CYCLE:
                out.write(template.format(n=n, s=1000 + n % 7) + "\n")
        out.write("M30\n%\n")
    return 2 + cycles * len(CYCLE) + 2


def test_read_file_equals_parse(tmp_path):
    path = tmp_path / "program.ngc"
    write_program(path, 30)
    text = path.read_text(encoding="utf-8")
    streamed = list(read_file(path))
    assert streamed == list(parse(text).items)
    assert isinstance(streamed[-1], ProgramEnd)
    assert sum(isinstance(item, Move) for item in streamed) == 30 * 5


def test_read_file_handles_crlf_and_cr_like_parse(tmp_path):
    text = "G0 X1\r\nG1 X2 F100\rG1 Y2\nM2\r\n"
    path = tmp_path / "crlf.ngc"
    path.write_bytes(text.encode())
    assert list(read_file(path)) == list(parse(text).items)
    assert [item.line for item in read_file(path)] == [1, 2, 3, 4]


def test_read_file_is_lazy_and_reports_the_error_in_place(tmp_path):
    path = tmp_path / "bad.ngc"
    path.write_text("G0 X1\nG0 X2\nG0 Z3\nG0 X4\n", encoding="utf-8")
    items = read_file(path)
    assert next(items).end == pytest.approx((1e-3, 0.0))
    assert next(items).end == pytest.approx((2e-3, 0.0))
    with pytest.raises(GCodeError) as info:
        next(items)
    assert (info.value.line, info.value.column, info.value.code) == (3, 4, "no-axis")


def test_undecodable_bytes_are_harmless_in_comments_and_an_error_in_code(tmp_path):
    path = tmp_path / "latin1.ngc"
    path.write_bytes(b"(\xd8 6 mm end mill)\nG0 X1\nG0 X\xb52\n")
    items = read_file(path)
    assert next(items).end == pytest.approx((1e-3, 0.0))
    with pytest.raises(GCodeError) as info:
        next(items)
    assert (info.value.line, info.value.column, info.value.code) == (3, 5, "syntax")


def test_iter_items_takes_any_iterable_of_lines():
    lines = iter(["G0 X1\n", "G0 Y1\r\n", "M2\n", "not read\n"])
    assert [type(item) for item in iter_items(lines)] == [Move, Move, ProgramEnd]
    assert next(lines) == "not read\n"  # M2 stops reading: the rest is left untouched


def traced_peak(items, count: int) -> int:
    """Peak of the allocations made while taking ``count`` items from ``items`` (bytes)."""
    tracemalloc.start()
    try:
        taken = sum(1 for _ in itertools.islice(items, count))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert taken == count
    return peak


def test_streaming_memory_does_not_grow_with_the_file(tmp_path):
    path = tmp_path / "large.ngc"
    assert write_program(path, 30_000) > 200_000     # 210 004 lines, 240 001 items
    items = read_file(path)
    # Tracing slows Python several times, so trace a window at the start (file opened,
    # reader built) and one near the end; stream the rest untraced.
    first = traced_peak(items, 20_000)
    assert sum(1 for _ in itertools.islice(items, 190_000)) == 190_000
    last = traced_peak(items, 20_000)
    assert sum(1 for _ in items) == 10_001
    # A reader that kept its items would grow by ~150 bytes per item: 3 MB per window.
    assert first < 512 * 1024
    assert last < 128 * 1024
