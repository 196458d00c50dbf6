"""End to end: the default program through the full controller on the twin, recorded to a
real .rrd that is read back with rerun's own reader."""

from __future__ import annotations

import json

import numpy as np
import pytest
import rerun.chunk as rc

from twin.session.run import RunSpec, run


def _rrd_scalars(path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every scalar entity of a recording: {entity: (sim_time (s), values)}."""
    out: dict[str, list] = {}
    for chunk in rc.RrdReader(path).stream().to_chunks():
        rb = chunk.to_record_batch()
        if "Scalars:scalars" not in rb.schema.names or "sim_time" not in rb.schema.names:
            continue
        t = rb.column("sim_time").cast("int64").to_numpy() * 1e-9
        v = np.array([row[0] for row in rb.column("Scalars:scalars").to_pylist()])
        out.setdefault(chunk.entity_path.lstrip("/"), []).append((t, v))
    return {k: (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))
            for k, parts in out.items()}


def _rrd_points(path, entity: str) -> np.ndarray:
    pts = []
    for chunk in rc.RrdReader(path).stream().to_chunks():
        if chunk.entity_path.lstrip("/") != entity:
            continue
        rb = chunk.to_record_batch()
        pts.extend(row[0] for row in rb.column("Points2D:positions").to_pylist())
    return np.array(pts)


@pytest.fixture(scope="module", params=["tomsk_xy", "laser_belt"])
def default_run(request, tmp_path_factory):
    out = tmp_path_factory.mktemp(request.param)
    return run(RunSpec(machine=request.param), out_dir=out, run_id="default", keep_fine=True)


def test_default_program_finishes_and_writes_both_records(default_run):
    s = default_run.summary
    assert s["status"] == "FINISHED" and s["aborted"] is None
    for key in ("cycle_time_s", "path_length_mm", "max_contour_error_um", "rms_contour_error_um",
                "settling_travel_um", "sim_time_s", "wall_time_s", "real_time_factor"):
        assert np.isfinite(s[key]), key
    assert set(s["max_coordinate_error_um"]) == {"x", "y"}
    assert set(s["ticks"]) >= {"due", "on_time", "late", "jitter_p99_us"}
    saved = json.loads(open(s["recording"].replace(".rrd", ".json")).read())
    assert saved["max_contour_error_um"] == pytest.approx(s["max_contour_error_um"])
    assert saved["spec"]["machine"] == s["machine"]
    assert "axes" in saved["config"]          # the full configuration, to repeat the run


def test_the_streamed_summary_is_the_whole_record_summary(default_run):
    """The summary is computed while the run goes, from the rows the telemetry sends; it is
    what the metrics give on the whole kept record."""
    from twin.session.record import run_summary

    want = run_summary(default_run.record, default_run.path)
    got = default_run.summary
    for key, value in want.items():
        if isinstance(value, dict):
            assert got[key] == pytest.approx(value, rel=1e-12, abs=0.0), key
        else:
            assert got[key] == pytest.approx(value, rel=1e-12, abs=0.0), key


def test_a_run_that_does_not_keep_its_record_releases_it_and_says_the_same(
        default_run, tmp_path):
    """``twin run``'s way: the record is released as it is consumed, so memory does not
    grow with the run; the summary is the same as the kept run's."""
    from twin.session.setup import RECORD_CHUNK

    machine = default_run.summary["machine"]
    lean = run(RunSpec(machine=machine), out_dir=tmp_path, run_id="lean", keep_record=False)
    n = default_run.summary["ticks"]["due"]
    assert n > 2 * RECORD_CHUNK                      # long enough to release something
    assert len(lean.record["t"]) <= 2 * RECORD_CHUNK
    np.testing.assert_array_equal(lean.record["position"],
                                  default_run.record["position"][-len(lean.record["t"]):])
    for key, value in default_run.summary.items():
        if key.endswith("_um") or key in ("cycle_time_s", "productivity_mm_per_min"):
            assert lean.summary[key] == pytest.approx(value, rel=1e-12, abs=0.0), key


def test_rrd_matches_the_simulation_record_sample_for_sample(default_run):
    rec = default_run.record
    scalars = _rrd_scalars(default_run.summary["recording"])
    for k, axis in enumerate("xy"):
        t, v = scalars[f"axes/{axis}/position/actual"]
        order = np.argsort(t, kind="stable")
        assert len(t) == len(rec["t"])
        np.testing.assert_allclose(t[order], rec["t"], rtol=0, atol=1e-9)
        # float64, in mm: the record's metres times 1000, nothing lost
        np.testing.assert_array_equal(v[order], rec["position"][:, k] * 1e3)
        # the converter's channels at the drive rate, every sample
        fine = default_run.fine
        t, v = scalars[f"axes/{axis}/drive/armature_current"]
        order = np.argsort(t, kind="stable")
        np.testing.assert_allclose(t[order], fine["t"], rtol=0, atol=1e-9)
        np.testing.assert_array_equal(v[order], fine["armature_current"][:, k])
    pts = _rrd_points(default_run.summary["recording"], "path/actual")
    np.testing.assert_allclose(pts, rec["position"] * 1e3, rtol=1e-6, atol=1e-4)  # float32
    assert "errors/contour_um" in scalars


def test_the_summary_has_the_elastic_oscillation_of_the_drive_rate_deflection(default_run):
    from twin.analysis.compare import elastic_oscillation, mode_periods

    fine, s = default_run.fine, default_run.summary
    batch = elastic_oscillation(fine["t"], fine["screw_deflection"],
                                mode_periods(default_run.config))
    assert s["elastic_oscillation_um"] == pytest.approx(batch * 1e6, rel=1e-6)
    assert s["elastic_oscillation_um"] > 0.0


def test_the_recording_shows_discontinuous_conduction_at_table_2s_feed(tmp_path):
    """Seed 000's Table-2 move (0.44 mm/s): the armature current in the .rrd, logged at the
    drive rate, flows in pulses with gaps (conduction < 1 of most intervals)."""
    result = run(RunSpec(machine="tomsk_xy", builtin="spline_line", dcu_order=3),
                 out_dir=tmp_path, run_id="table2")
    assert result.summary["status"] == "FINISHED"
    scalars = _rrd_scalars(result.summary["recording"])
    t, i = scalars["axes/x/drive/armature_current"]
    _, conduction = scalars["axes/x/drive/conduction"]
    order = np.argsort(t, kind="stable")
    t, i, conduction = t[order], i[order], conduction[order][:len(order)]
    cruise = (t > 1.0) & (t < 2.4)
    dt = np.median(np.diff(t))
    assert dt == pytest.approx(1e-3, rel=1e-6)               # the drive rate, not 200 Hz
    assert np.count_nonzero(i[cruise] == 0.0) > 0.3 * np.count_nonzero(cruise)
    assert i[cruise].max() > 0.0
    assert np.mean(conduction[cruise]) < 0.5


def test_rrd_has_the_paths_blueprint_and_events(default_run):
    reader = rc.RrdReader(default_run.summary["recording"])
    assert reader.blueprints(), "the default blueprint is in the file"
    entities = {c.entity_path for c in reader.stream().to_chunks()}
    assert {"/path/programmed", "/path/actual", "/events"} <= entities


@pytest.fixture(scope="module")
def dcu_runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("dcu")
    return {order: run(RunSpec(machine="tomsk_xy", dcu_order=order), out_dir=out,
                       rerun="none").summary for order in (0, 1, 3)}


def _max_coord(summary):
    return max(summary["max_coordinate_error_um"].values())


def test_dcu_order_3_halves_the_coordinate_error(dcu_runs):
    assert _max_coord(dcu_runs[3]) <= 0.5 * _max_coord(dcu_runs[0])


def test_velocity_feed_forward_alone_already_helps(dcu_runs):
    # Seed 000, Table 2: the first-order DCU (velocity feed-forward) removes most of it.
    assert _max_coord(dcu_runs[1]) < 0.5 * _max_coord(dcu_runs[0])
    for s in dcu_runs.values():
        assert s["status"] == "FINISHED"


def test_drives_off_does_not_move_the_machine(tmp_path):
    r = run(RunSpec(machine="tomsk_xy", drives_off=True, overrides={
        "controller.regulator.following_error_limit": 1.0}), out_dir=tmp_path, rerun="none")
    moved = np.ptp(r.record["table_position"], axis=0)
    assert np.all(moved < 1e-6)
    assert np.ptp(r.record["ref_position"], axis=0).max() > 0.05
