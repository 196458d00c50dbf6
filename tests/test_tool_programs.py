"""A pen plotter's and a laser's programs run as written (``controller.gcode.z = "tool"``):
their tool switches are events on the recording, read back with rerun's own reader, and
counted in the summary."""

from __future__ import annotations

from pathlib import Path

import pytest
import rerun.chunk as rc

from twin.controller.gcode import Event, ReaderOptions, parse
from twin.errors import GCodeError
from twin.session.run import RunSpec, run

PROGRAMS = Path(__file__).resolve().parents[1] / "twin" / "programs"
TOOL = {"controller.gcode.z": "tool"}


def _events(path) -> list[str]:
    texts = []
    for chunk in rc.RrdReader(path).stream().to_chunks():
        if chunk.entity_path != "/events":
            continue
        rb = chunk.to_record_batch()
        column = next(name for name in rb.schema.names if name.endswith(":text"))
        texts.extend(row[0] for row in rb.column(column).to_pylist())
    return texts


def _tool_events(name: str) -> list[tuple[str, int]]:
    text = (PROGRAMS / name).read_text()
    return [(item.kind, item.line) for item in parse(text, options=ReaderOptions(z="tool"))
            if isinstance(item, Event) and item.kind.startswith("tool_")]


def test_a_pen_plotter_program_is_refused_by_default_with_a_hint():
    with pytest.raises(GCodeError) as info:
        parse((PROGRAMS / "plotter_pen.ngc").read_text())
    assert info.value.code == "no-axis"
    assert "controller.gcode.z" in info.value.message


def test_the_readers_tool_switches_follow_the_pen_and_the_beam():
    # the pen goes down 3 times (two boxes, a circle) and up after each
    assert [k for k, _ in _tool_events("plotter_pen.ngc")] == ["tool_on", "tool_off"] * 3
    # the beam: on at M4 S800, off at S0, on at S1000, off at M5
    assert _tool_events("laser_power.ngc") == [("tool_on", 7), ("tool_off", 11),
                                               ("tool_on", 12), ("tool_off", 14)]


@pytest.mark.parametrize(("name", "switches"), [("plotter_pen.ngc", 3),
                                                ("laser_power.ngc", 2)])
def test_tool_programs_run_and_their_events_are_recorded(name, switches, tmp_path):
    result = run(RunSpec(machine="laser_belt", program=str(PROGRAMS / name), overrides=TOOL),
                 out_dir=tmp_path, run_id=name.split(".")[0])
    summary = result.summary
    assert summary["status"] == "FINISHED"
    assert summary["events"]["tool_on"] == switches
    assert summary["events"]["tool_off"] == switches
    texts = _events(summary["recording"])
    assert sum(t.endswith("tool on") for t in texts) == switches
    assert sum(t.endswith("tool off") for t in texts) == switches
