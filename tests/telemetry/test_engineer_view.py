"""What the default layout shows, read back from a real run's ``.rrd``: the feed against the
programmed F, the motor speed, the actual path coloured by its contour error, and the path
view's transform to machine orientation (mm, Y up)."""

import numpy as np
import pytest
import rerun.chunk as rc

from tests.rrd import labelled, layout_views
from tests.test_run import _rrd_points, _rrd_scalars
from twin.session.run import RunSpec, run
from twin.session.setup import shipped_program
from twin.telemetry.channels import error_colors
from twin.units import MM_PER_MIN


def test_error_colors_run_green_yellow_red():
    rgb = error_colors(np.array([-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 9.0]))
    assert rgb.dtype == np.uint8
    np.testing.assert_array_equal(rgb, [[40, 180, 60], [40, 180, 60], [140, 190, 45],
                                        [240, 200, 30], [230, 120, 35], [220, 40, 40],
                                        [220, 40, 40]])


@pytest.fixture(scope="module")
def square(tmp_path_factory):
    out = tmp_path_factory.mktemp("view")
    return run(RunSpec(machine="tomsk_xy", program=str(shipped_program("square_circle.ngc")),
                       overrides={"controller.contour_tolerance": 2e-6}),
               out_dir=out, run_id="square", keep_fine=True)


def _chunks(path, entity):
    return [c.to_record_batch() for c in rc.RrdReader(path).stream().to_chunks()
            if c.entity_path == entity]


def test_feed_is_shown_in_mm_per_min_against_the_programmed_f(square):
    rec = square.record
    scalars = _rrd_scalars(square.summary["recording"])
    t, commanded = scalars["feed/commanded"]
    order = np.argsort(t, kind="stable")
    np.testing.assert_allclose(commanded[order], np.hypot(*rec["ref_velocity"].T) / MM_PER_MIN,
                               rtol=1e-12)
    _, programmed = scalars["feed/programmed"]
    programmed = programmed[order]
    text = shipped_program("square_circle.ngc").read_text().splitlines()
    line_of = {row.split()[0]: k + 1 for k, row in enumerate(text) if row.startswith("N")}
    line = rec["line"].ravel()
    for n, f in (("N30", 600.0), ("N40", 600.0), ("N70", 450.0)):   # F600 ... F450
        ticks = line == line_of[n]
        assert ticks.sum() > 50, n
        np.testing.assert_allclose(programmed[ticks], f, rtol=1e-12, err_msg=n)
    g0 = line == line_of["N20"]
    assert g0.sum() > 50 and np.all(np.isnan(programmed[g0]))        # G0: no programmed F
    _, actual = scalars["feed/actual"]
    on_n30 = actual[order][line == line_of["N30"]]
    assert np.median(np.abs(on_n30 - 600.0)) < 6.0                      # within 1 %


def test_motor_speed_is_the_table_speed_through_the_transmission(square):
    from twin.config import load_machine

    scalars = _rrd_scalars(square.summary["recording"])
    ratio = load_machine("tomsk_xy").axes["x"].transmission.ratio
    _, table = scalars["axes/x/velocity/actual"]                  # mm/min
    _, motor = scalars["axes/x/drive/motor_speed"]                # rpm
    np.testing.assert_allclose(motor, table / 60e3 / ratio * 60.0 / (2.0 * np.pi), rtol=1e-12)
    assert np.abs(motor).max() > 100.0                         # rpm, not rad/s


def test_actual_path_is_coloured_by_its_contour_error(square):
    path = square.summary["recording"]
    scalars = _rrd_scalars(path)
    t, contour_um = scalars["errors/contour_um"]
    colors, times = [], []
    for rb in _chunks(path, "/path/actual"):
        if "Points2D:colors" not in rb.schema.names:        # the static draw order
            continue
        colors.extend(row[0] for row in rb.column("Points2D:colors").to_pylist())
        times.append(rb.column("sim_time").cast("int64").to_numpy())
    packed = np.asarray(colors, dtype=np.uint32)            # rerun packs RGBA as 0xRRGGBBAA
    rgb = np.stack([(packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255], axis=1)
    order_c = np.argsort(np.concatenate(times), kind="stable")
    order_e = np.argsort(t, kind="stable")
    expected = error_colors(contour_um[order_e] * 1e-6 / 2e-6)
    np.testing.assert_array_equal(rgb[order_c], expected)
    # a 2 µm tolerance on this machine: green, yellow and red all appear
    assert {(40, 180, 60), (220, 40, 40)} <= {tuple(c) for c in expected}


def test_path_view_is_in_millimetres_with_y_up(square):
    reader = rc.RrdReader(square.summary["recording"])
    assert reader.blueprints()
    (rb,) = _chunks(square.summary["recording"], "/path")
    mat = np.asarray(rb.column("Transform3D:mat3x3").to_pylist()[0][0]).reshape(3, 3)
    # column-major in rerun: the same matrix either way, it is diagonal
    np.testing.assert_array_equal(mat, np.diag([1.0, -1.0, 1.0]))     # the data are in mm
    pts = _rrd_points(square.summary["recording"], "path/actual")
    np.testing.assert_allclose(pts, square.record["position"] * 1e3, rtol=1e-6, atol=1e-4)


def test_path_view_is_framed_on_the_whole_path_with_a_grid_and_a_scale(square):
    """rerun fits a 2-D view to the first frames it sees, which cut off the path's later
    parts; the layout carries the whole path's extent (mm, Y negated), with a margin, and
    the view holds a labelled grid and a scale bar."""
    from twin.telemetry.channels import programmed_polyline

    path = square.summary["recording"]
    (view,) = [v for v in layout_views(path) if v["kind"] == "2D"]
    mm = np.vstack([programmed_polyline(square.path) * 1e3,
                    square.record["position"] * 1e3])
    (x0, x1), (y0, y1) = view["bounds"]["x_range"], view["bounds"]["y_range"]
    assert x0 < mm[:, 0].min() and mm[:, 0].max() < x1
    assert y0 < -mm[:, 1].max() and -mm[:, 1].min() < y1
    span = max(np.ptp(mm[:, 0]), np.ptp(mm[:, 1]))
    assert max(x1 - x0, y1 - y0) <= 1.15 * span           # a margin, not a zoomed-out view
    assert "/path/grid/**" in view["contents"] and "(mm, Y up" in view["name"]
    assert view["origin"] == "/"               # above /path, whose transform flips Y
    labels = _chunks(path, "/path/grid/labels")[-1]       # static: the last one stands
    values = [float(t) for t in labels.column("Points2D:labels").to_pylist()[0]]
    positions = labels.column("Points2D:positions").to_pylist()[0]
    xs = [v for v, p in zip(values, positions, strict=True) if np.isclose(p[0], v)]
    ys = [v for v, p in zip(values, positions, strict=True) if np.isclose(p[1], v)]
    assert len(xs) >= 2 and len(ys) >= 2                   # coordinates along both edges
    scale = _chunks(path, "/path/grid/scale")[-1]
    (bar,) = scale.column("LineStrips2D:strips").to_pylist()[0]
    (text,) = scale.column("LineStrips2D:labels").to_pylist()[0]
    assert text == f"{bar[1][0] - bar[0][0]:g} mm"          # the bar is as long as it says
    step = np.diff(sorted(set(xs)))
    assert np.allclose(step, bar[1][0] - bar[0][0])         # one grid step


def test_every_plot_is_framed_on_its_data_with_labelled_ticks(square):
    """Each time series of the layout: a y range holding all its data with at least two
    labelled values (as egui_plot labels them), the data's time span, its unit in the
    title and no legend box over the traces; every recorded series is in a plot."""
    from twin.telemetry.channels import series_for

    path = square.summary["recording"]
    scalars = _rrd_scalars(path)
    plots = [v for v in layout_views(path) if v["kind"] == "TimeSeries"
             and not v["contents"][0].startswith("/spectra/")]   # against frequency
    assert len(plots) == 6 + 10 + 6                   # Run, drive and motion tabs
    t_all = np.concatenate([t for t, _ in scalars.values()])
    shown = set()
    for view in plots:
        entities = [e.lstrip("/") for e in view["contents"]]
        data = [scalars[e][1] for e in entities if e in scalars]
        assert data, view["name"]
        shown |= set(entities)
        values = np.concatenate([np.ravel(d) for d in data])
        values = values[np.isfinite(values)]
        lo, hi = view["y_range"]
        assert lo <= values.min() and values.max() <= hi, view["name"]
        assert (values.max() - values.min()) >= 0.1 * (hi - lo) or np.ptp(values) == 0.0
        assert labelled(lo, hi) >= 2, (view["name"], lo, hi)
        units = {series_for(e)[0] for e in entities}
        assert len(units) == 1, view["name"]
        unit = units.pop()
        assert f"({unit})" in view["name"] if unit != "1" else "(share" in view["name"]
        assert view["legend"] is False
        np.testing.assert_allclose(view["time"], (t_all.min(), t_all.max()), atol=1e-9)
    assert set(scalars) <= shown


def test_positions_are_recorded_in_mm_and_velocities_in_mm_per_min(square):
    scalars = _rrd_scalars(square.summary["recording"])
    rec = square.record
    t, pos = scalars["axes/y/position/actual"]
    order = np.argsort(t, kind="stable")
    np.testing.assert_allclose(pos[order], rec["position"][:, 1] * 1e3, rtol=1e-14)
    _, vel = scalars["axes/y/velocity/reference"]
    np.testing.assert_allclose(vel[order], rec["ref_velocity"][:, 1] * 60e3, rtol=1e-14)


def test_a_simulated_run_shows_the_table_s_true_path_and_its_contour_error(square):
    """The table's true path (the twin's truth, in mm) is drawn beside the encoder's and
    named in the path view's title, and its contour error is plotted with the encoder's:
    its largest value within the recorded distance's sagitta of the summary's (the exact
    metric)."""
    path = square.summary["recording"]
    pts = _rrd_points(path, "path/table")
    np.testing.assert_allclose(pts, square.record["table_position"] * 1e3, rtol=1e-6,
                               atol=1e-4)
    _, table_um = _rrd_scalars(path)["errors/table_contour_um"]
    assert table_um.max() == pytest.approx(square.summary["table_max_contour_error_um"],
                                           abs=0.05)
    (view,) = [v for v in layout_views(path) if v["kind"] == "2D"]
    assert "/path/table" in view["contents"] and "table: teal halo" in view["name"]
    (plot,) = [v for v in layout_views(path) if v["name"].startswith("Contour error")]
    assert "/errors/table_contour_um" in plot["contents"] and "table teal" in plot["name"]
