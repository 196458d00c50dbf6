"""``twin compare``: the figures that tell laws apart, against references, and the command as
a user runs it (a subprocess: one JSON object, a PNG, one .rrd with one subtree per law)."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rerun.chunk as rc

from twin.analysis.compare import elastic_oscillation, junction_speed_jump, junctions, mode_periods
from twin.config import load_machine

TWIN = [sys.executable, "-m", "twin.cli"]
ENV = {**os.environ, "RERUN_ANALYTICS": "0", "MPLBACKEND": "Agg", "COLUMNS": "200"}
PROGRAM = """G21 G90 G17 G94
G1 X40 Y10 F600
G1 X40 Y30
G0 X10 Y10
M30
"""


# ------------------------------------------------------------------ metrics, synthetic
@pytest.mark.parametrize("freq, amp", [(93.0, 0.4e-6), (161.0, 1e-6), (15.9, 50e-6)])
def test_elastic_oscillation_recovers_a_sine_on_a_quasi_static_ramp(freq, amp):
    dt = 1e-4
    t = np.arange(0.0, 1.0, dt)
    slow = 2e-6 * t + 1e-6 * np.sin(2 * np.pi * 0.5 * t)      # m·a/k and friction: slow
    d = np.column_stack([slow + amp * np.sin(2 * np.pi * freq * t), np.zeros_like(t)])
    got = elastic_oscillation(t, d, (1.0 / freq, 1.0 / freq))
    assert got == pytest.approx(amp, rel=0.03)


def test_elastic_oscillation_of_a_quasi_static_signal_is_tiny():
    t = np.arange(0.0, 1.0, 1e-3)
    d = np.column_stack([3e-6 * t**2, 1e-6 * t])
    assert elastic_oscillation(t, d, (0.0107, 0.0062)) < 1e-10


def test_mode_periods_match_the_locked_rotor_modes_of_the_model_readme():
    # twin/models/README.md: tomsk X 92.7 Hz, Y 158.3 Hz (the three-mass chain with the nut
    # at the far end, where the mode is lowest); laser_belt ω_L = 100 rad/s
    px, py = mode_periods(load_machine("tomsk_xy"))
    assert 1.0 / px == pytest.approx(92.7, rel=0.01)
    assert 1.0 / py == pytest.approx(158.3, rel=0.01)
    lx, ly = mode_periods(load_machine("laser_belt"))
    assert lx == pytest.approx(2 * math.pi / 100.0, rel=1e-3)
    assert ly == pytest.approx(2 * math.pi / 100.0, rel=1e-3)


def _trapezoid_record(period=0.01, accel=1.0, v=0.5, cruise=0.5, lag=0.0):
    """A 1-D trapezoid along x: accelerate, cruise, brake; the table at ``ref − lag·a``."""
    t_acc = v / accel
    t = np.arange(0.0, 2 * t_acc + cruise + 0.3, period)
    a = np.where(t < t_acc, accel, np.where(t < t_acc + cruise, 0.0,
                                            np.where(t < 2 * t_acc + cruise, -accel, 0.0)))
    vel = np.concatenate([[0.0], np.cumsum(a[:-1]) * period])
    z = np.zeros_like(t)
    return {"t": t, "ref_velocity": np.column_stack([vel, z]),
            "ref_acceleration": np.column_stack([a, z]),
            "table_velocity": np.column_stack([vel - lag * a, z]),
            "block": np.zeros(t.size, dtype=np.int64)}


def test_junctions_are_the_four_ends_of_the_speed_changes():
    rec = _trapezoid_record()
    j = junctions(rec)
    t_acc = 0.5
    expected = [0.0, t_acc, t_acc + 0.5, 2 * t_acc + 0.5]
    got = rec["t"][j]
    assert len(got) == 3          # the start at t = 0 is no change of state (tick 0)
    np.testing.assert_allclose(got, expected[1:], atol=0.011)


def test_junction_speed_jump_is_the_speed_lag_a_over_kv():
    # a table lagging the reference speed by a/K_v (K_v = 20 1/s) during each change
    rec = _trapezoid_record(lag=1.0 / 20.0)
    assert junction_speed_jump(rec, 0.01) == pytest.approx(1.0 / 20.0, rel=1e-9)
    assert junction_speed_jump(_trapezoid_record(), 0.01) == 0.0


# ------------------------------------------------------------------ the command
def _twin(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*TWIN, *args], capture_output=True, text=True, env=ENV,
                          timeout=300)


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("compare")
    prog = tmp / "two_lines.ngc"
    prog.write_text(PROGRAM)
    r = _twin("compare", str(prog), "--profiles", "trapezoid,parabolic", "--out",
              str(tmp / "out"), "--json")
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stdout
    return json.loads(lines[0])


def test_compare_json_has_one_summary_per_law_and_the_report(compared):
    assert set(compared["profiles"]) == {"trapezoid", "parabolic"}
    for s in compared["profiles"].values():
        assert s["status"] == "FINISHED"
        for key in ("cycle_time_s", "max_contour_error_um", "rms_contour_error_um",
                    "max_coordinate_error_um", "max_velocity_error_um_s",
                    "peak_reference_jerk_m_per_s3", "junction_speed_jump_mm_per_s",
                    "elastic_oscillation_um", "settling_travel_um"):
            assert key in s, key
    png = compared["report"]
    with open(png, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    # the trapezoid's acceleration steps: braking along x (−A) ends, and accelerating along
    # y begins, from one tick to the next around the 90° corner's blend arc: |Δa|/T of
    # at least A/T and at most 2·A/T, A = 0.2 m/s²
    trap = compared["profiles"]["trapezoid"]["peak_reference_jerk_m_per_s3"]
    para = compared["profiles"]["parabolic"]["peak_reference_jerk_m_per_s3"]
    assert 0.2 / 0.005 <= trap <= 2.0 * 0.2 / 0.005
    # tomsk_xy's max_jerk J = 5 m/s³ along the path; entering the corner's blend arc the
    # normal acceleration steps by at most J·T in one period (the planner's node rule), at
    # right angles to the tangential jerk of at most J: each within J, the vector within √2·J
    assert 5.0 * 0.9 <= para <= math.sqrt(2.0) * 5.0 * 1.01


def test_the_verdict_names_the_winner_of_every_figure_and_its_margin(compared):
    from twin.analysis.compare import FIGURES, figure_value

    verdict = {e["label"]: e for e in compared["verdict"]}
    assert set(verdict) == {label for label, _, _ in FIGURES}
    for label, key, _ in FIGURES:
        e = verdict[label]
        values = {law: figure_value(s, key) for law, s in compared["profiles"].items()}
        assert e["values"] == values
        best, second = sorted(values, key=values.__getitem__)
        if e["winner"] is None:                      # a tie: within 0.1 %
            assert values[second] - values[best] <= 1e-3 * values[second]
        else:
            assert e["winner"] == best and e["runner_up"] == second
            assert e["margin"] == pytest.approx(values[second] - values[best], rel=1e-12)
    # the trapezoid is the fastest; the parabolic law asks for less jerk
    assert verdict["cycle time"]["winner"] in ("trapezoid", None)
    assert verdict["peak reference jerk |Δa|/T"]["winner"] == "parabolic"
    # every output in the call's own folder
    folder = Path(compared["folder"])
    assert Path(compared["report"]).parent == folder == Path(compared["recording"]).parent
    assert {p.name for p in folder.glob("*.json")} == {
        "verdict.json", *(f"compare-{law}.json" for law in compared["profiles"])}
    assert json.loads((folder / "verdict.json").read_text()) == compared["verdict"]


def test_verdict_ties_and_margins():
    from twin.analysis.compare import verdict

    rows = [("a", "a_s", "s"), ("b", ("b_um", "x"), "µm")]
    out = verdict({"fast": {"a_s": 1.0, "b_um": {"x": 5.0}},
                   "slow": {"a_s": 1.0005, "b_um": {"x": 4.0}}}, rows)
    assert out[0]["winner"] is None and out[0]["runner_up"] == "slow"          # 0.05 %: tie
    assert out[1]["winner"] == "slow" and out[1]["margin"] == pytest.approx(1.0)
    assert out[1]["margin_ratio"] == pytest.approx(1.25)
    assert verdict({"only": {"a_s": 2.0}}, rows[:1])[0]["winner"] == "only"
    assert verdict({"x": {}}, rows) == []                    # a figure a law lacks: left out


def test_every_call_writes_into_a_folder_of_its_own(compared, tmp_path):
    r = _twin("compare", "--builtin", "tiny", "--profiles", "parabolic", "--rerun", "none",
              "--out", str(Path(compared["folder"]).parent), "--json")
    assert r.returncode == 0, r.stderr
    second = Path(json.loads(r.stdout)["folder"])
    assert second != Path(compared["folder"]) and second.parent == Path(compared["folder"]).parent
    assert (second / "compare.png").exists() and (Path(compared["folder"]) / "compare.png").exists()


def test_rrd_holds_one_subtree_per_law_with_every_tick(compared):
    reader = rc.RrdReader(compared["recording"])
    assert len(reader.recordings()) == 1
    assert reader.blueprints(), "the overlay blueprint is in the file"
    counts: dict[str, int] = {}
    for chunk in reader.stream().to_chunks():
        path = chunk.entity_path.lstrip("/")
        if path.endswith("errors/contour_um") and not chunk.is_static:
            counts[path] = counts.get(path, 0) + chunk.num_rows
    for law, s in compared["profiles"].items():
        assert counts[f"laws/{law}/errors/contour_um"] == s["ticks"]["due"]
    # the overlaid paths are drawn as in a run's layout: mm, Y up
    (frame,) = [rb for rb in (c.to_record_batch() for c in reader.stream().to_chunks()
                              if c.entity_path == "/laws")
                if "Transform3D:mat3x3" in rb.schema.names]
    mat = np.asarray(frame.column("Transform3D:mat3x3").to_pylist()[0][0]).reshape(3, 3)
    np.testing.assert_array_equal(mat, np.diag([1.0, -1.0, 1.0]))


def test_overlay_is_framed_on_the_whole_path_and_the_data_time_span(compared):
    """compare.rrd's layout: the path view holds every law's whole path (programmed and
    actual), the plots the data's time span and value range with at least two labelled
    ticks, and their titles name each law's colour (no legend over the traces)."""
    from tests.rrd import labelled, layout_views
    from tests.test_run import _rrd_points, _rrd_scalars

    path = compared["recording"]
    views = layout_views(path)
    scalars = _rrd_scalars(path)
    (paths,) = [v for v in views if v["kind"] == "2D"]
    pts = np.vstack([_rrd_points(path, f"laws/{law}/path/table")
                     for law in compared["profiles"]])
    assert not _rrd_points(path, "laws/trapezoid/path/actual").size   # the table's, only
    assert "the table, " in paths["name"]
    (x0, x1), (y0, y1) = paths["bounds"]["x_range"], paths["bounds"]["y_range"]
    assert x0 < pts[:, 0].min() and pts[:, 0].max() < x1
    assert y0 < -pts[:, 1].max() and -pts[:, 1].min() < y1
    assert max(x1 - x0, y1 - y0) <= 1.2 * max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]))
    assert "trapezoid red" in paths["name"] and "parabolic blue" in paths["name"]
    # the view's origin lies above /laws, which flips Y: a view at /laws itself would show
    # its data untransformed (upside down, and outside these bounds)
    assert paths["origin"] == "/"
    t_all = np.concatenate([t for t, _ in scalars.values()])
    plots = [v for v in views if v["kind"] == "TimeSeries"
             and "/spectra/" not in v["contents"][0]]
    assert len(plots) == 5
    for view in plots:
        values = np.concatenate([scalars[e.lstrip("/")][1] for e in view["contents"]])
        lo, hi = view["y_range"]
        assert lo <= values.min() and values.max() <= hi and labelled(lo, hi) >= 2
        assert view["legend"] is False
        assert "trapezoid red, parabolic blue" in view["name"], view["name"]
        np.testing.assert_allclose(view["time"], (t_all.min(), t_all.max()), atol=1e-9)


def test_overlay_has_each_laws_spectra_per_quantity_and_axis(compared):
    """compare.rrd's Spectra tab: one plot per quantity and axis, one series per law (in its
    colour, named in the title), each law's spectra recorded under its subtree."""
    from tests.rrd import layout_views, rrd_spectra

    path = compared["recording"]
    got = rrd_spectra(path)
    laws = list(compared["profiles"])
    plots = sorted((v for v in layout_views(path) if v["kind"] == "TimeSeries"
                    and "/spectra/" in v["contents"][0]), key=lambda v: v["contents"])
    expected = sorted([f"/laws/{law}/spectra/{q}/{a}" for law in laws]
                      for q in ("following_error", "screw_deflection") for a in ("x", "y"))
    assert [v["contents"][:len(laws)] for v in plots] == expected
    for view in plots:
        assert "trapezoid red, parabolic blue" in view["name"], view["name"]
        assert "(dB re 1 µm/√Hz vs Hz)" in view["name"]
        for entity in view["contents"][:len(laws)]:
            hz, level = got[entity.lstrip("/")]
            assert hz[0] == 0 and np.isnan(level[0]) and np.isfinite(level[1:]).all()


def test_sweep_plots_a_figure_against_the_parameter(tmp_path):
    prog = tmp_path / "two_lines.ngc"
    prog.write_text(PROGRAM)
    r = _twin("compare", str(prog), "--profiles", "parabolic", "--sweep",
              "max_jerk=1.0,5.0", "--figure", "peak_reference_jerk_m_per_s3", "--out",
              str(tmp_path / "out"), "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["sweep"]["key"] == "controller.limits.max_jerk"
    low, high = d["sweep"]["table"]["parabolic"]
    # the law keeps its jerk limit on each axis (the vector: within √2·J, see above)
    assert low <= math.sqrt(2.0) * 1.0 * 1.01 and 1.0 < high <= math.sqrt(2.0) * 5.0 * 1.01
    assert os.path.getsize(d["report"]) > 1000
    # the cycle time each law pays for the figure, beside it
    assert [len(v) for v in d["sweep"]["cycle_time_s"].values()] == [2]
    assert Path(d["report"]).parent == Path(d["folder"])


def test_unknown_law_exits_2_naming_it(tmp_path):
    r = _twin("compare", "--profiles", "trapezoid,sinusoid", "--out", str(tmp_path))
    assert r.returncode == 2
    assert "sinusoid" in r.stderr


def test_compare_on_the_default_program_names_the_winner_of_every_figure(tmp_path):
    r = _twin("compare", "--profiles", "trapezoid,jerk-limited", "--rerun", "none", "--out",
              str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "winner" in r.stdout and "margin" in r.stdout              # the terminal table
    from twin.analysis.compare import FIGURES

    assert re.search(rf"(trapezoid|jerk-limited) wins \d+ of {len(FIGURES)} figures", r.stdout)
    (folder,) = tmp_path.iterdir()
    verdict = json.loads((folder / "verdict.json").read_text())
    assert len(verdict) == len(FIGURES)
    for e in verdict:
        values = e["values"]
        if e["winner"] is not None:
            assert values[e["winner"]] == min(values.values()), e["label"]
            assert f"{e['winner']} " in r.stdout
        else:
            assert max(values.values()) - min(values.values()) <= 1e-3 * max(values.values())
    named = {e["label"]: e["winner"] for e in verdict}
    assert named["cycle time"] == "trapezoid"
    assert named["peak reference jerk |Δa|/T"] == "jerk-limited"
