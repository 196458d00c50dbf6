"""Look-ahead planner, segment limits and corner model: limits, feasibility, streaming."""

import itertools
import math
import tracemalloc

import numpy as np
import pytest

from twin.config import load_machine
from twin.controller.gcode import parse
from twin.controller.gcode.items import Dwell, Event, Move, ProgramEnd
from twin.controller.geometry import Arc, Line
from twin.controller.planner import MotionBlock, PlannedBlock, Planner
from twin.controller.profiles import LAWS, Limits, max_end_speed
from twin.controller.reach import monotone_end_speed, reach_floor
from twin.controller.segment_limits import CENTRIPETAL, CRUISE_JERK, SegmentLimits
from twin.controller.spline_path import SplinePath
from twin.controller.workzone import WorkZone
from twin.errors import ConfigError, PlanningError

CFG = load_machine("tomsk_xy")
CONTOUR = Limits(0.05, 1.0, 50.0)
AXIS_LIMITS = (Limits(0.02, 0.5, 20.0), Limits(0.03, 0.8, 30.0))


def tomsk_planner(**options) -> Planner:
    """The reference rig's planner; soft limits off unless a test asks for them."""
    options.setdefault("work_zone", None)
    return Planner.from_settings(CFG.controller, CFG.axes, **options)


def free_planner(**options) -> Planner:
    """Per-axis limits tighter than the contour ones, so that the projections bind."""
    options.setdefault("rapid_velocity", 0.04)
    options.setdefault("tolerance", 20e-6)
    return Planner(CONTOUR, AXIS_LIMITS, **options)


def polyline(n, *, seed, step=(1e-3, 4e-3), turn=1.0, feed=0.01, origin=(0.1, 0.1)):
    """Moves of a random polyline: lengths uniform in ``step`` (m), turns up to ``turn``."""
    rng = np.random.default_rng(seed)
    heading, p = 0.0, np.array(origin)
    moves = []
    for i in range(n):
        heading += rng.uniform(-turn, turn)
        q = p + rng.uniform(*step) * np.array([math.cos(heading), math.sin(heading)])
        moves.append(Move("line", tuple(p), tuple(q), feed, line=i + 1))
        p = q
    return moves


def mixed_program(seed):
    """Lines, tangent and non-tangent arcs, a rapid, a dwell and an event."""
    rng = np.random.default_rng(seed)
    text = ["G21 G90 G0 X100 Y100", "G1 X120 Y100 F900", "G3 X130 Y110 I0 J10",
            "G1 X130 Y125", "G2 X125 Y130 I-5 J0", "G1 X110 Y131 F300", "G4 P0.2",
            "M3 S1000", "G1 X100 Y140 F1200", "G0 X90 Y90", "G1 X95 Y90 F500"]
    x, y = 95.0, 90.0
    for _ in range(40):
        x, y = x + rng.uniform(0.5, 3.0), y + rng.uniform(-2.0, 2.0)
        text.append(f"G1 X{x:.4f} Y{y:.4f} F{rng.uniform(200, 1000):.0f}")
    text.append(f"G3 X{x + 4:.4f} Y{y:.4f} I2 J0")
    text.append("M2")
    return parse("\n".join(text), start=(0.1, 0.1))


def blocks_of(items):
    return [b for b in items if isinstance(b, PlannedBlock)]


def node_angle(a, b):
    t0, t1 = a.segment.end_tangent, b.segment.start_tangent
    return math.acos(min(1.0, max(-1.0, float(np.dot(t0, t1)))))


def step_speed(a, b, planner):
    """The node's velocity-step limit: v·|Δt̂_k| ≤ A_k·T per axis and on the contour."""
    if planner.period is None:
        return math.inf
    dt = np.asarray(b.segment.start_tangent) - np.asarray(a.segment.end_tangent)
    limits = [*(lim.max_acceleration for lim in planner.axis_limits),
              planner.limits.max_acceleration]
    steps = [*np.abs(dt), float(np.hypot(*dt))]
    return min((lim * planner.period / d for lim, d in zip(limits, steps, strict=True)
                if d > 0.0), default=math.inf)


def reference_entries(blocks, planner):
    """Full-program two-pass optimum (no window): min(forward, backward) envelopes of the
    monotone reach of each block (`twin.controller.reach`)."""
    n, law = len(blocks), planner.law

    def reach(v, b):
        return monotone_end_speed(law, v, b.segment.length, b.limits,
                                  reach_floor(law, b.segment.length, b.limits))

    jerk = min(planner.limits.max_jerk, *(lim.max_jerk for lim in planner.axis_limits))
    emax = [0.0] * n
    for i in range(1, n):
        a, b = blocks[i - 1], blocks[i]
        if not (a.rapid or b.rapid):
            angle = node_angle(a, b)
            emax[i] = min(a.v_nominal, b.v_nominal)
            if angle > 1e-12:
                emax[i] = min(emax[i], planner.corner_model.max_node_speed(
                    angle, planner.tolerance), step_speed(a, b, planner))
            dk = abs(b.segment.curvature(0.0) - a.segment.curvature(a.segment.length))
            if dk > 0.0 and law != "trapezoid" and planner.period is not None:
                emax[i] = min(emax[i], math.sqrt(jerk * planner.period / dk))
    fw = [0.0] * n
    for i in range(1, n):
        fw[i] = min(emax[i], reach(fw[i - 1], blocks[i - 1]))
    entry = [0.0] * (n + 1)
    for i in range(n - 1, -1, -1):
        entry[i] = min(fw[i], reach(entry[i + 1], blocks[i]))
    return entry


# ------------------------------------------------------------------------ speed limits
@pytest.mark.parametrize("law", LAWS)
def test_planned_profiles_are_feasible_and_continuous(law):
    planner = tomsk_planner(law=law)
    blocks = blocks_of(planner.plan(mixed_program(1)))
    assert blocks[0].v_start == 0.0 and blocks[-1].v_end == 0.0
    for prev, nxt in itertools.pairwise(blocks):
        assert prev.v_end == nxt.v_start
    for b in blocks:
        prof = b.profile()                               # raises if not feasible
        t = np.linspace(0.0, prof.duration, 400)
        s, v, a, j = prof.sample(t)
        assert s[-1] == pytest.approx(b.segment.length, rel=1e-12)
        assert v[0] == pytest.approx(b.v_start, abs=1e-15)
        assert v[-1] == pytest.approx(b.v_end, abs=1e-15)
        assert v.max() <= b.v_nominal * (1 + 1e-9)
        assert np.abs(a).max() <= b.limits.max_acceleration * (1 + 1e-9)
        if law != "trapezoid":
            assert np.abs(j).max() <= b.limits.max_jerk * (1 + 1e-9)


def test_node_speeds_respect_technology_accuracy_and_length():
    planner = tomsk_planner()
    items = list(planner.plan(mixed_program(2)))
    blocks = blocks_of(items)
    for a, b in itertools.pairwise(blocks):
        v = a.v_end
        assert v <= min(a.v_nominal, b.v_nominal)                   # technological
        if v > 0.0:
            corner = planner.corner_model.max_node_speed(node_angle(a, b), planner.tolerance)
            assert v <= corner * (1 + 1e-9)                          # accuracy
        if a.rapid or b.rapid:
            assert v == 0.0                                          # G0 brakes at its end
    for b in blocks:
        assert b.v_start <= max_end_speed(planner.law, b.v_end, b.segment.length, b.limits)
        assert b.v_end <= max_end_speed(planner.law, b.v_start, b.segment.length, b.limits)
        cap = planner.rapid_velocity if b.rapid else min(b.feed, planner.limits.max_velocity)
        assert b.v_nominal <= cap


def test_segment_caps_respect_projected_axis_limits_and_curvature():
    planner = free_planner(mode="stop")
    rng = np.random.default_rng(3)
    segments = [Line((0, 0), tuple(rng.uniform(-1, 1, 2))) for _ in range(30)]
    for _ in range(30):
        c, r = rng.uniform(-1, 1, 2), rng.uniform(1e-4, 0.05)
        a0, a1 = rng.uniform(-4, 4, 2)
        segments.append(Arc(c + r * np.array([math.cos(a0), math.sin(a0)]),
                            c + r * np.array([math.cos(a1), math.sin(a1)]), c,
                            ccw=bool(rng.integers(2)), turns=int(rng.integers(2))))
    segments.append(SplinePath([(0, 0), (0.01, 0.004), (0.02, -0.003), (0.03, 0.0)]))
    blocks = blocks_of(planner.plan(MotionBlock(s, 0.05) for s in segments))
    a_tot = min(CONTOUR.max_acceleration, *(x.max_acceleration for x in AXIS_LIMITS))
    j_tot = min(CONTOUR.max_jerk, *(x.max_jerk for x in AXIS_LIMITS))
    for b in blocks:
        seg, v = b.segment, b.v_nominal
        tang = np.abs(seg.tangent(np.linspace(0.0, seg.length, 2001)))
        for k, lim in enumerate(AXIS_LIMITS):
            assert v * tang[:, k].max() <= lim.max_velocity * (1 + 1e-12)
        kappa = np.abs(seg.curvature(np.linspace(0.0, seg.length, 2001))).max()
        if isinstance(seg, Line):
            for k, lim in enumerate(AXIS_LIMITS):
                assert b.limits.max_acceleration * tang[0, k] <= lim.max_acceleration * (1 + 1e-12)
                assert b.limits.max_jerk * tang[0, k] <= lim.max_jerk * (1 + 1e-12)
            # the tightest of the projections (or the feed) is attained exactly
            bound = min([0.05] + [lim.max_velocity / t for lim, t in zip(
                AXIS_LIMITS, tang[0], strict=True) if t > 0])
            assert v == pytest.approx(bound, rel=1e-12)
        else:
            a_n = v * v * kappa
            assert a_n <= CENTRIPETAL * a_tot * (1 + 1e-6)
            assert math.hypot(a_n, b.limits.max_acceleration) <= a_tot * (1 + 1e-9)
            # the jerk vector (s⃛ − v³κ², 3·v·s̈·κ + v³κ') within J at the cap and the
            # block's tangential limits (issue 30's split), κ' by dense differences
            s_dense = np.linspace(0.0, seg.length, 2001)
            dk = np.abs(np.diff(seg.curvature(s_dense)) / np.diff(s_dense)).max()
            a_t, j_t = b.limits.max_acceleration, b.limits.max_jerk
            tangential = j_t + v**3 * kappa**2
            normal = 3.0 * v * a_t * kappa + v**3 * dk
            assert math.hypot(tangential, normal) <= j_tot * (1 + 1e-3)


@pytest.mark.parametrize("seed", range(20))
def test_arc_tangent_extent_matches_dense_sampling(seed):
    rng = np.random.default_rng(seed)
    c, r = rng.uniform(-1, 1, 2), rng.uniform(0.01, 1)
    a0, a1 = rng.uniform(-7, 7, 2)
    arc = Arc(c + r * np.array([math.cos(a0), math.sin(a0)]),
              c + r * np.array([math.cos(a1), math.sin(a1)]), c, ccw=bool(seed % 2))
    caps = SegmentLimits(Limits(10.0, 1.0, 1.0), (Limits(1.0, 1e9, 1e9), Limits(2.0, 1e9, 1e9)))
    v, _, _ = caps.curve_caps(arc, 10.0)
    tang = np.abs(arc.tangent(np.linspace(0.0, arc.length, 200001))).max(axis=0)
    expected = min(1.0 / tang[0], 2.0 / tang[1], math.sqrt(CENTRIPETAL * r),
                   (CRUISE_JERK * r * r) ** (1 / 3))
    assert v == pytest.approx(expected, rel=1e-6)


# ------------------------------------------------------------------------ look-ahead
def test_tangent_junctions_get_no_corner_limit():
    prog = parse("G21 G90 G1 X120 Y100 F600\nG3 X140 Y120 I0 J20\nG1 X140 Y150", start=(0.1, 0.1))
    blocks = blocks_of(tomsk_planner().plan(prog))
    assert blocks[0].v_end == pytest.approx(0.01, rel=1e-12)
    assert blocks[1].v_end == pytest.approx(0.01, rel=1e-12)


@pytest.mark.parametrize("law", ["trapezoid", "parabolic"])
def test_window_results_match_the_full_program_optimum(law):
    """Any window gives the same plan; with the trapezoid (one block, one move) it is the
    two-pass optimum of the whole program (a smooth law may plan runs of blocks as one
    move: its optimum is checked on runs below)."""
    moves = polyline(300, seed=4)
    ref = None
    for window in (6, 16, 1000):
        planner = tomsk_planner(lookahead=window, law=law)
        blocks = blocks_of(planner.plan(moves))
        speeds = np.array([(b.v_start, b.v_nominal, b.v_end) for b in blocks])
        if ref is None:
            ref = speeds
            if law == "trapezoid":
                expected = reference_entries(blocks, planner)
                # the reference computes the corner angle its own way: equal to rounding
                np.testing.assert_allclose(speeds[:, 0], expected[:-1], rtol=1e-13, atol=0)
                np.testing.assert_allclose(speeds[:, 2], expected[1:], rtol=1e-13, atol=0)
        else:
            np.testing.assert_array_equal(speeds, ref)
        for b in blocks:
            b.profile()                                  # every part of a run is feasible
    assert ref[:, 0].mean() > 0.3 * ref[:, 1].mean()        # the nodes are not stops


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("window", [2, 3, 7])
def test_short_window_is_conservative_but_feasible(law, window):
    """Tiny segments: the window does not cover the braking distance."""
    moves = polyline(150, seed=window, step=(0.02e-3, 0.3e-3), turn=0.1)
    full = blocks_of(tomsk_planner(law=law, lookahead=1000).plan(moves))
    short = blocks_of(tomsk_planner(law=law, lookahead=window).plan(moves))
    # the committed speeds: at block ends, and at the end of a run planned as one move
    # (inside a run the speeds are its move's, shaped by both ends)
    committed = [k for k, b in enumerate(full) if b.piece is None
                 or b.piece[2] == b.piece[0].duration]
    assert committed == [k for k, b in enumerate(short) if b.piece is None
                         or b.piece[2] == b.piece[0].duration]
    a = np.array([short[k].v_end for k in committed])
    b = np.array([full[k].v_end for k in committed])
    assert np.all(a <= b)
    if window == 2:
        assert a.sum() < 0.95 * b.sum()
    for blk in short + full:
        blk.profile()                                    # plan_move raises if infeasible


@pytest.mark.parametrize("law", ["trapezoid", "parabolic"])
def test_lookahead_beats_stop_mode_in_cycle_time(law):
    moves = polyline(150, seed=6, turn=0.3)

    def cycle(mode):
        return sum(b.profile().duration for b in blocks_of(tomsk_planner(law=law, mode=mode)
                                                            .plan(moves)))

    look, stop = cycle("lookahead"), cycle("stop")
    assert look < 0.9 * stop


def test_stop_mode_and_lookahead_one_stop_at_every_node():
    moves = polyline(50, seed=7)
    for planner in (tomsk_planner(mode="stop"), tomsk_planner(lookahead=1)):
        for b in blocks_of(planner.plan(moves)):
            assert b.v_start == 0.0 and b.v_end == 0.0


def test_pass_through_items_keep_order_and_force_stops():
    prog = mixed_program(8)
    items = list(tomsk_planner().plan(prog))
    assert [type(i).__name__ for i in items if not isinstance(i, PlannedBlock)] == [
        "Dwell", "Event", "Event", "ProgramEnd"]
    lines = [i.line for i in items]
    assert lines == sorted(lines)
    for i, item in enumerate(items):
        if isinstance(item, Dwell | Event):
            before = [b for b in items[:i] if isinstance(b, PlannedBlock)][-1]
            after = next(b for b in items[i + 1:] if isinstance(b, PlannedBlock))
            assert before.v_end == 0.0 and after.v_start == 0.0
    assert isinstance(items[-1], ProgramEnd)


@pytest.mark.parametrize("seed", [8, 9])
def test_a_stop_dwell_waits_before_events_and_where_a_rapid_meets_a_move(seed):
    """``stop_dwell``: a Dwell of that length right before each Event (after motion) and
    between a rapid and the next move; none in stop mode, none without it, and the
    blocks themselves are the planner's without it."""
    prog = list(mixed_program(seed))
    plain = list(tomsk_planner().plan(prog))
    items = list(tomsk_planner(stop_dwell=0.07).plan(prog))
    def key(bs):
        return [(tuple(b.segment.start), tuple(b.segment.end), b.v_start, b.v_nominal,
                 b.v_end, b.line) for b in blocks_of(bs)]

    assert key(items) == key(plain)
    added = {i for i, item in enumerate(items)
             if isinstance(item, Dwell) and item.duration == 0.07}
    wanted, last = set(), None        # last: the previous block's rapid flag since a stop
    for i, item in enumerate(items):
        if isinstance(item, PlannedBlock):
            rapid = item.feed is None
            if last is not None and (last or rapid) and item.v_start == 0.0:
                wanted.add(i - 1)
            last = rapid
        elif isinstance(item, Event) and last is not None:
            wanted.add(i - 1)
            last = None
        elif not (isinstance(item, Dwell) and i in added):
            last = None
    assert added == wanted and added
    stop = list(tomsk_planner(mode="stop", stop_dwell=0.07).plan(prog))
    assert not [i for i in stop if isinstance(i, Dwell) and i.duration == 0.07]
    with pytest.raises(ConfigError, match="stop_dwell"):
        tomsk_planner(stop_dwell=-1.0)


@pytest.mark.parametrize("radius", [2e-3, 5e-3, 20e-3])
def test_the_quartic_curve_cap_is_the_analytic_speed(radius):
    """``curve_quartic`` q caps an arc of curvature κ at v⁴κ³·q ≤ 1, and a blend also by
    ``curve_acceleration`` (v²κ ≤ A_c); an unblended arc is not capped by A_c then."""
    q, a_c = 2e-3, 0.05
    caps = SegmentLimits(CONTOUR, (CONTOUR, CONTOUR), curve_acceleration=a_c, curve_quartic=q)
    arc = Arc((0.0, 0.0), (2.0 * radius, 0.0), (radius, 0.0), ccw=True)
    v, _, _ = caps.curve_caps(arc, 10.0)
    k = 1.0 / radius
    expect = min(CONTOUR.max_velocity, math.sqrt(CENTRIPETAL * CONTOUR.max_acceleration / k),
                 (1.0 / (q * k**3)) ** 0.25, (CRUISE_JERK * CONTOUR.max_jerk / k**2) ** (1 / 3))
    assert v == pytest.approx(expect, rel=1e-12)
    v_blend, _, _ = caps.curve_caps(arc, 10.0, blend=True)
    assert v_blend == pytest.approx(min(expect, math.sqrt(a_c / k)), rel=1e-12)


def test_nothing_after_program_end_is_read():
    consumed = []

    def source():
        for item in (Move("line", (0.1, 0.1), (0.11, 0.1), 0.01, line=1), ProgramEnd("M2", 2),
                     Move("line", (0.11, 0.1), (0.12, 0.1), 0.01, line=3)):
            consumed.append(item.line)
            yield item

    items = list(tomsk_planner().plan(source()))
    assert [i.line for i in items] == [1, 2] and consumed == [1, 2]


# ------------------------------------------------------------------------ soft limits
def test_leaving_the_work_zone_is_refused_naming_the_line():
    moves = polyline(30, seed=9, origin=(0.15, 0.1))
    bad = Move("line", moves[-1].end, (0.5, 0.1), 0.01, line=31)
    planner = tomsk_planner(work_zone=WorkZone.from_axes(CFG.axes))
    with pytest.raises(PlanningError, match="line 31"):
        planner.check([*moves, bad])
    got = []
    with pytest.raises(PlanningError, match="line 31"):
        for b in planner.plan([*moves, bad]):
            got.append(b)
    programmed = [b for b in got if not b.blend]
    assert [b.line for b in programmed] == list(range(1, 31))   # all valid blocks ran...
    assert got[-1].v_end == 0.0                                  # ...out to rest
    arc = Arc((0.1, 0.19), (0.1, 0.19), (0.1, 0.195), ccw=True)     # reaches y = 0.2
    with pytest.raises(PlanningError, match="line 7"):
        planner.check([MotionBlock(arc, 0.01, 7)])


def test_work_zone_is_inside_the_limit_switches_unless_soft_limits_are_off():
    zone = WorkZone.from_axes(CFG.axes)
    assert zone.lower == (0.002, 0.002) and zone.upper == (0.298, 0.198)
    assert Planner.from_settings(CFG.controller, CFG.axes).work_zone == zone
    off = CFG.with_overrides({"controller.soft_limits": False})
    assert Planner.from_settings(off.controller, off.axes).work_zone is None


@pytest.mark.parametrize(("options", "field"), [
    ({"mode": "fast"}, "mode"), ({"lookahead": 0}, "lookahead"), ({"law": "sine"}, "law"),
    ({"tolerance": 0.0}, "tolerance"),
])
def test_invalid_options_name_the_field(options, field):
    with pytest.raises(ConfigError) as err:
        free_planner(**options)
    assert err.value.field == field


# ------------------------------------------------------------------------ streaming
def _generated(n):
    rng = np.random.default_rng(10)
    p = np.array([0.1, 0.1])
    for i in range(n):
        q = np.clip(p + rng.uniform(-5e-4, 5e-4, 2), 0.01, 0.19)
        yield Move("line", (float(p[0]), float(p[1])), (float(q[0]), float(q[1])), 0.01,
                   line=i + 1)
        p = q


def _peak_while_planning(n):
    tracemalloc.start()
    count, line = 0, 0
    for b in tomsk_planner().plan(_generated(n)):   # every programmed line, blended or not
        count += b.line != line
        line = b.line
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return count, peak


def test_streaming_plans_in_bounded_memory():
    small_n, small_peak = _peak_while_planning(1_000)
    large_n, large_peak = _peak_while_planning(10_000)
    assert large_n == 10_000 and small_n == 1_000
    assert large_peak < 1.3 * small_peak + 50_000
    assert large_peak < 2_000_000


def _counted(items, taken: list[int]):
    """``items``, counting in ``taken[0]`` how many the consumer has taken."""
    for item in items:
        taken[0] += 1
        yield item


def test_the_planner_reads_no_further_than_a_barrier_before_passing_it():
    """The planner reads the program in batches, but never past a dwell (or any item that
    is not a motion block) before it has yielded it: a live source is not asked early."""
    moves = [Move("line", (0.01 * k, 0.0), (0.01 * (k + 1), 0.0), 0.01, line=k + 1)
             for k in range(10)]
    program = [*moves[:5], Dwell(0.5, line=6), *moves[5:], ProgramEnd("M2", line=20)]
    taken = [0]
    for item in tomsk_planner().plan(_counted(program, taken)):
        if type(item) is Dwell:
            assert taken[0] == 6                 # five moves and the dwell, nothing after
    assert taken[0] == len(program)


def test_a_source_error_comes_after_the_blocks_read_before_it():
    """An error of the program (a bad line) comes after every block before it is planned,
    in order, ending at rest, whatever the batch the planner was reading."""
    def source():
        for k in range(150):
            yield Move("line", (0.001 * k, 0.0), (0.001 * (k + 1), 0.0), 0.01, line=k + 1)
        raise PlanningError("line 151: bad")

    planned = []
    with pytest.raises(PlanningError, match="line 151"):
        for item in tomsk_planner().plan(source()):
            planned.append(item)
    assert [b.line for b in planned] == list(range(1, 151))
    assert planned[-1].v_end == 0.0
