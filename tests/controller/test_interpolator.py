"""Equal-time interpolator: feed stability, exact end point, channels against references."""

import math

import numpy as np
import pytest

from twin.config import load_machine
from twin.controller.gcode import parse
from twin.controller.gcode.items import Dwell, Event, Move, ProgramEnd
from twin.controller.interpolator import Interpolator, InterpolatorStatus
from twin.controller.planner import MotionBlock, PlannedBlock, Planner
from twin.controller.profiles import Limits, Polynomial
from twin.controller.spline_path import SplinePath
from twin.errors import ConfigError, PlanningError

CFG = load_machine("tomsk_xy")
CPM = CFG.axes["x"].counts_per_metre


def planner(**options):
    options.setdefault("work_zone", None)
    return Planner.from_settings(CFG.controller, CFG.axes, **options)


def run(items, **options):
    """Tick to the end; arrays of time, position, velocity, acceleration, jerk, status."""
    interp = Interpolator(items, **options)
    rows = []
    while True:
        status = interp.update()
        r = interp.reference
        rows.append((r.time, *r.position, *r.velocity, *r.acceleration, *r.jerk, status,
                     r.block))
        if status >= InterpolatorStatus.FINISHED:
            break
    a = np.array(rows)
    return interp, {"t": a[:, 0], "p": a[:, 1:3], "v": a[:, 3:5], "a": a[:, 5:7],
                    "j": a[:, 7:9], "status": a[:, 9].astype(int), "block": a[:, 10]}


def cruise_window(block: PlannedBlock):
    """(start, end) time of the constant-speed piece of the block's profile (s)."""
    prof = block.profile()
    pieces = [s for s in prof.segments if isinstance(s, Polynomial) and s.a0 == 0 and s.j == 0]
    assert len(pieces) == 1
    return pieces[0].start, pieces[0].start + pieces[0].duration


# ------------------------------------------------------------------------ feed stability
@pytest.mark.parametrize(("text", "end"), [
    ("G21 G90 G1 X80 Y70 F600", (0.08, 0.07)),
    ("G21 G90 G2 X50 Y50 I-10 J0 F600", (0.05, 0.05)),       # full circle, R = 10 mm
    ("G21 G90 G3 X50 Y50 I0 J7.5 F450", (0.05, 0.05)),       # full circle, R = 7.5 mm
])
def test_feed_is_constant_in_cruise_and_the_end_point_exact(text, end):
    prog = parse(text, start=(0.05, 0.05))
    blocks = list(planner().plan(prog))
    feed = prog.moves[0].feed
    assert blocks[0].v_nominal == feed
    t0, t1 = cruise_window(blocks[0])
    _, out = run(planner().plan(prog), period=5e-3)
    speed = np.hypot(*out["v"].T)
    cruise = (out["t"] > t0) & (out["t"] < t1)
    assert cruise.sum() > 100
    assert np.abs(speed[cruise] / feed - 1.0).max() <= 1e-6
    assert out["p"][-1, 0] == end[0] and out["p"][-1, 1] == end[1]      # exactly
    np.testing.assert_array_equal(out["v"][-1], 0.0)
    move = prog.moves[0]
    if move.kind == "arc":                   # uniform circular motion in cruise
        r = move.radius
        acc = out["a"][cruise]
        np.testing.assert_allclose(np.hypot(*acc.T), feed**2 / r, rtol=1e-9)
        np.testing.assert_allclose(np.hypot(*out["j"][cruise].T), feed**3 / r**2, rtol=1e-9)
        inward = np.asarray(move.center) - out["p"][cruise]
        cos = np.sum(acc * inward, axis=1) / (np.hypot(*acc.T) * np.hypot(*inward.T))
        np.testing.assert_allclose(cos, 1.0, atol=1e-9)


# ------------------------------------------------------------------------ references
def _global_reference(blocks, t):
    """Path state at global times ``t`` from the block profiles and vectorised geometry."""
    p, v, a, j = (np.full((t.size, 2), np.nan) for _ in range(4))
    start = 0.0
    for b in blocks:
        prof, seg = b.profile(), b.segment
        mask = (t >= start) & (t < start + prof.duration)
        if mask.any():
            s, sd, sdd, sddd = prof.sample(t[mask] - start)
            tan = seg.tangent(s)
            nrm = np.column_stack([-tan[:, 1], tan[:, 0]])
            k = np.asarray(seg.curvature(s), dtype=float)[:, None]
            p[mask] = seg.point(s)
            v[mask] = sd[:, None] * tan
            a[mask] = sdd[:, None] * tan + (sd**2)[:, None] * k * nrm
            j[mask] = (sddd - sd**3 * k[:, 0] ** 2)[:, None] * tan + \
                (3 * sd * sdd)[:, None] * k * nrm
        start += prof.duration
    return p, v, a, j, start


@pytest.mark.parametrize("law", ["trapezoid", "parabolic", "jerk-limited"])
@pytest.mark.parametrize("period", [5e-3, 1e-3])
def test_channels_follow_the_planned_path_in_global_time(law, period):
    """Leftover time is carried across block ends: tick n is the path at time n·T."""
    text = ("G21 G90 G1 X60 Y50 F900\nG1 X60.3 Y50.2\nG1 X60.35 Y50.21\n"
            "G3 X70.14 Y60 I0 J9.79\nG1 X70.14 Y61\nG2 X72.14 Y63 I2 J0\nG1 X60 Y63 F300")
    prog = parse(text, start=(0.05, 0.05))
    blocks = list(planner(law=law).plan(prog))
    _, out = run(planner(law=law).plan(prog), period=period)
    p, v, a, j, total = _global_reference(blocks, out["t"])
    moving = ~np.isnan(p[:, 0])
    assert math.ceil(total / period - 1e-9) == len(out["t"])
    # local block times come from carried leftovers, the reference's from t − start: the
    # two agree to ~1e-13 s, which bounds the differences below
    np.testing.assert_allclose(out["p"][moving], p[moving], rtol=0, atol=1e-14)
    np.testing.assert_allclose(out["v"][moving], v[moving], rtol=0, atol=1e-13)
    np.testing.assert_allclose(out["a"][moving], a[moving], rtol=0, atol=1e-11)
    np.testing.assert_allclose(out["j"][moving], j[moving], rtol=0, atol=1e-9)


def test_spline_jerk_includes_the_curvature_derivative():
    """In cruise j = ṡ³(κ'·n̂ − κ²·t̂); here the κ' part is as large as the κ² part, and the
    jerk channel must match the finite difference of the acceleration channel."""
    spline = SplinePath([(0.05, 0.05), (0.06, 0.055), (0.07, 0.048), (0.08, 0.05)])
    blocks = list(planner(law="trapezoid").plan([MotionBlock(spline, 0.005)]))
    t0, t1 = cruise_window(blocks[0])
    _, out = run(iter(blocks), period=2e-4)
    fd_j = np.gradient(out["a"], out["t"], axis=0)
    cruise = (out["t"] > t0 + 1e-3) & (out["t"] < t1 - 1e-3)
    # κ' (so the true jerk) jumps at the knots: leave out the ticks next to one
    s_tick = spline.closest(out["p"])[0]
    near_knot = np.abs(s_tick[:, None] - spline.knot_s[None, :]).min(axis=1) < 2.0 * 0.005 * 2e-4
    cruise &= ~near_knot
    j = out["j"][cruise]
    scale = np.abs(j).max()
    assert scale > 0.005                                    # m/s³
    np.testing.assert_allclose(fd_j[cruise], j, rtol=0, atol=2e-3 * scale)
    tangent = out["v"][cruise] / 0.005
    normal_part = np.abs(tangent[:, 0] * j[:, 1] - tangent[:, 1] * j[:, 0])
    assert normal_part.max() > 0.5 * scale                  # the κ' term is exercised
    assert out["p"][-1].tolist() == [0.08, 0.05]


# ------------------------------------------------------------------------ dwell, events
def test_dwell_holds_the_end_point_and_events_arrive_in_order():
    prog = parse("G21 G90 G1 X60 Y50 F600\nG4 P0.25\nM3 S100\nG1 X60 Y55\nM2",
                 start=(0.05, 0.05))
    seen = []
    interp, out = run(planner().plan(prog), period=5e-3,
                      on_event=lambda t, item: seen.append((t, item)))
    dwell = out["status"] == InterpolatorStatus.DWELLING
    assert abs(dwell.sum() - 0.25 / 5e-3) <= 1
    assert np.all(out["p"][dwell] == [0.06, 0.05])
    assert [type(i).__name__ for _, i in seen] == ["Event", "Event", "ProgramEnd"]
    assert [i.kind for _, i in seen[:2]] == ["spindle_speed", "spindle_cw"]
    assert seen[-1][0] == pytest.approx(out["t"][-1])
    assert list(interp.events) == seen


def test_block_source_error_stops_at_rest_and_reports():
    good = list(planner().plan(parse("G21 G90 G1 X60 Y50 F600\nG1 X60 Y60", start=(0.05, 0.05))))

    def failing():
        yield from good
        raise PlanningError("line 3: the move leaves the work zone")

    interp, out = run(failing(), period=5e-3)
    assert out["status"][-1] == InterpolatorStatus.ERROR
    assert isinstance(interp.error, PlanningError)
    assert out["p"][-1].tolist() == [0.06, 0.06]
    assert interp.update() == InterpolatorStatus.ERROR


def test_reference_starts_at_the_first_block_even_after_leading_events():
    prog = parse("G21 G90 M3 S100\nG4 P0.01\nG1 X60 Y50 F600\nM2", start=(0.05, 0.05))
    interp = Interpolator(planner().plan(prog), period=5e-3)
    assert interp.reference.position.tolist() == [0.05, 0.05]
    interp.update()
    assert interp.status == InterpolatorStatus.DWELLING
    assert [i.kind for _, i in interp.events] == ["spindle_speed", "spindle_cw"]


def test_zero_dwell_and_bare_events_cost_no_time():
    items = [Dwell(0.0, 1), Event("spindle_stop", None, 2), ProgramEnd("M2", 3)]
    interp, out = run(items, period=5e-3, start=(0.1, 0.2))
    assert len(out["t"]) == 1 and out["p"][0].tolist() == [0.1, 0.2]
    assert [i.line for _, i in interp.events] == [2, 3]


# ------------------------------------------------------------------------ stop
def test_stop_brakes_smoothly_to_rest_along_the_block():
    prog = [Move("line", (0.05, 0.05), (0.15, 0.05), 0.01, line=1),
            Move("line", (0.15, 0.05), (0.15, 0.1), 0.01, line=2)]
    interp = Interpolator(planner().plan(prog), period=5e-3)
    for _ in range(300):
        interp.update()
    v_before = interp.reference.velocity.copy()
    interp.stop()
    speeds = []
    while interp.update() < InterpolatorStatus.FINISHED:
        speeds.append(interp.reference.velocity[0])
    a_max = CFG.controller.limits.max_acceleration
    assert abs(speeds[0] - v_before[0]) <= a_max * 5e-3
    assert np.all(np.diff(speeds) <= 1e-15) and speeds[-1] < 1e-3
    assert interp.reference.position[1] == 0.05 and interp.reference.position[0] < 0.15
    np.testing.assert_array_equal(interp.reference.velocity, 0.0)


# ------------------------------------------------------------------------ traditional
@pytest.mark.parametrize(("feed_mm_per_min", "errors"), [
    (10.0, {1.0, -5.0}),       # F_T = 1/6 count per tick: V is 0 or 1 count (+100 %/−500 %)
    (5000.0, None),            # F_T = 83.3 counts per tick: V is 83 or 84 (about ±1 %)
])
def test_traditional_mode_reproduces_the_integer_feed_ripple_of_seed_004(feed_mm_per_min,
                                                                        errors):
    """1 kHz, 1000 counts/mm, as in seed 004's table; the extended channel is exact."""
    cpm, period = 1e6, 1e-3
    feed = feed_mm_per_min / 60e3
    length = feed * 3.0
    move = Move("line", (0.01, 0.01), (0.01 + length, 0.01), feed, line=1)
    lim = Limits(0.1, 1.0, 100.0)                  # a machine fast enough for 5 m/min
    fast = Planner(lim, (lim, lim), rapid_velocity=0.1, tolerance=20e-6, law="trapezoid")
    block = next(iter(fast.plan([move])))
    t0, t1 = cruise_window(block)
    _, trad = run(fast.plan([move]), period=period, mode="traditional",
                  counts_per_metre=(cpm, cpm))
    _, ext = run(fast.plan([move]), period=period)
    cruise = (trad["t"] > t0 + 0.05) & (trad["t"] < t1)
    counts = trad["p"][:, 0] * cpm
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    np.testing.assert_allclose(trad["v"][1:, 0], np.diff(trad["p"][:, 0]) / period, rtol=1e-12)
    rel = (feed - trad["v"][cruise, 0]) / feed
    if errors is not None:
        assert set(np.round(rel, 9)) == errors
    else:
        assert 0.003 < np.abs(rel).max() < 0.012
    assert np.abs(ext["v"][cruise, 0] / feed - 1.0).max() < 1e-12


@pytest.mark.parametrize(("options", "field"), [
    ({"period": 0.0}, "period"), ({"mode": "integer"}, "mode"),
    ({"mode": "traditional"}, "counts_per_metre"),
    ({"mode": "traditional", "counts_per_metre": (1.0, -1.0)}, "counts_per_metre"),
])
def test_invalid_options_name_the_field(options, field):
    with pytest.raises(ConfigError) as err:
        Interpolator([], **options)
    assert err.value.field == field


def test_counts_per_metre_of_the_rig_is_used_in_traditional_mode():
    prog = parse("G21 G90 G1 X50.0013 Y50 F60", start=(0.05, 0.05))
    _, out = run(planner().plan(prog), period=5e-3, mode="traditional",
                 counts_per_metre=(CPM, CPM))
    assert out["p"][-1, 0] * CPM == pytest.approx(round(0.0500013 * CPM), abs=1e-6)
