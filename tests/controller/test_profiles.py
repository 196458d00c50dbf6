"""Acceleration laws: every law, every kind of move, checked on a dense time grid.

References: scipy's cumulative_trapezoid (s from v, v from a), textbook closed forms of the
trapezoid and double-S moves, the defining formula of each law, and ruckig against the
closed-form S-curve.
"""

import math

import numpy as np
import pytest
from hypothesis import assume, event, given
from hypothesis import strategies as st
from scipy.integrate import cumulative_trapezoid

from twin.config import load_machine
from twin.controller.profiles import (
    LAWS,
    Limits,
    Polynomial,
    Profile,
    max_end_speed,
    min_distance,
    plan_move,
    scurve,
)
from twin.errors import ConfigError, PlanningError

EPS = float(np.finfo(float).eps)
DT = 1e-5                               # s: the dense grid
TOMSK = Limits(0.015, 0.2, 5.0)         # every smooth change jerk-limited
LASER = Limits(0.5, 0.8, 40.0)          # long changes acceleration-limited
LIMITS = {"tomsk": TOMSK, "laser": LASER}
SMOOTH = [law for law in LAWS if law != "trapezoid"]


# ----------------------------------------------------------------------------- the checker
# Peak |φ'''(u)| of each shape: a speed change dv over T has snap (da/dt) ≤ |dv|·K/T³.
SNAP = {"trapezoid": 0.0, "parabolic": 12.0, "cosine": math.pi**3 / 2, "cubic": 60.0,
        "jerk-limited": 0.0}


def _grid(p: Profile, dt: float) -> np.ndarray:
    """Step ``dt`` (at least 64 points per segment), every segment boundary and its two
    float neighbours."""
    pieces = [seg.start + np.linspace(0.0, seg.duration, max(int(seg.duration / dt), 64) + 1)
              for seg in p.segments]
    edges = np.array([seg.start for seg in p.segments] + [p.duration])
    around = np.concatenate([edges, np.nextafter(edges, -np.inf), np.nextafter(edges, np.inf)])
    return np.unique(np.clip(np.concatenate([*pieces, around]), 0.0, p.duration))


def check_move(p: Profile, law, distance, v_start, v_end, cap, lim, dt=DT):
    """Every property a planned move must have; returns the sampled grid."""
    assert p.law == law and p.distance == distance
    T = p.duration
    vs = max(p.v_peak, v_start, v_end, 1e-300)
    # Ends: exact position, speeds to the planner's tolerance on speeds.
    s0, v0, _, _ = p.at(0.0)
    assert s0 == 0.0 and v0 == pytest.approx(v_start, rel=1e-9, abs=1e-300)
    assert p.at(T) == (distance, v_end, 0.0, 0.0)
    assert p.at(T + 1.0) == (distance, v_end, 0.0, 0.0)
    assert p.at(-1.0) == p.at(0.0)
    assert p.v_peak <= cap * (1 + 1e-9)
    if T == 0.0:
        assert distance == 0.0
        return None
    dt = min(dt, T / 2000)                  # at least 2000 points on any move
    t = _grid(p, dt)
    s, v, a, j = p.sample(t)
    # Limits on the grid; slack = rounding plus float resolution of the speeds over T.
    slack_a = 8 * EPS * vs / T
    assert v.min() >= -1e-12 * vs and v.max() <= cap * (1 + 1e-9) + 4 * EPS * vs
    assert np.abs(a).max() <= lim.max_acceleration * (1 + 3e-9) + slack_a
    if law != "trapezoid":
        assert np.abs(j).max() <= lim.max_jerk * (1 + 3e-9) + slack_a / T
    # Continuity: Lipschitz bounds across every grid interval, boundaries included. The
    # bound is the grid's maximum of the derivative plus what it can miss between points;
    # the slack is rounding of the value and of the local time (ε·T times the derivative).
    h = np.diff(t)
    top_v = np.abs(v).max() + np.abs(a).max() * h
    top_a = np.abs(a).max() + np.abs(j).max() * h
    top_j = lim.max_jerk * (1 + 3e-9) + slack_a / T
    assert np.all(np.abs(np.diff(s)) <= top_v * (h * (1 + 1e-9) + 8 * EPS * T)
                  + 16 * EPS * distance)
    assert np.all(np.abs(np.diff(v)) <= top_a * (h * (1 + 1e-9) + 8 * EPS * T) + 8 * EPS * vs)
    if law != "trapezoid":
        assert np.all(np.abs(np.diff(a)) <= top_j * (h + 8 * EPS * T)
                      + 8 * EPS * lim.max_acceleration)
    # Integration (scipy): the trapezoid rule is exact to h²·(second derivative)/12 within
    # a segment, and the grid never straddles a segment boundary by more than one ulp.
    n = t.size
    s_int = cumulative_trapezoid(v, t, initial=0.0)
    tol_s = (T * dt**2 * np.abs(j).max() / 12 * 1.5 + 4 * n * EPS * max(distance, vs * T)
             + 8 * EPS * T * vs)
    assert np.abs(s_int - s).max() <= tol_s
    snap = max((abs(getattr(seg, "dv", 0.0)) * SNAP[law] / seg.duration**3
                for seg in p.segments), default=0.0)
    v_int = v_start + cumulative_trapezoid(a, t, initial=0.0)
    assert np.abs(v_int - v).max() <= (T * dt**2 * snap / 12 * 1.5 + 4 * n * EPS * vs
                                       + 8 * EPS * T * np.abs(a).max())
    # sample() is at().
    pick = np.concatenate([t[::97], t[-3:], [-1.0, T + 1.0]])
    ref = np.array([p.at(float(x)) for x in pick])
    got = np.stack(p.sample(pick), axis=1)
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-15 * max(distance, vs, 1.0))
    return t, s, v, a, j


# ----------------------------------------------------------------------------- the case table
# name: (distance, v_start, v_end, v_max). Speeds are fractions of max_velocity. Distance is
# ("D", k): k times the rest-to-cap change of the law; ("min", k): k times the shortest path
# between the two speeds; ("m", x): x metres.
CASES = {
    "accel-cruise-decel": (("D", 5.0), 0.0, 0.0, 1.0),
    "no cruise": (("D", 0.8), 0.0, 0.0, 1.0),
    "start above end": (("D", 4.0), 0.8, 0.2, 1.0),
    "start below end": (("D", 4.0), 0.1, 0.7, 1.0),
    "peak between, no cruise": (("min", 1.3), 0.2, 0.6, 1.0),
    "v_max below the limit": (("D", 3.0), 0.0, 0.0, 0.4),
    "cruise only": (("D", 0.5), 0.6, 0.6, 0.6),
    "pure decel": (("min", 1.0), 1.0, 0.0, 1.0),
    "pure accel": (("min", 1.0), 0.0, 1.0, 1.0),
    "high v_start braking": (("min", 1.0001), 1.0, 0.0, 1.0),
    "just more than a change": (("min", 1.0 + 1e-7), 0.05, 0.9, 1.0),
    "zero-length": (("m", 0.0), 0.3, 0.3, 1.0),
    "zero-length at rest": (("m", 0.0), 0.0, 0.0, 1.0),
    "tiny at rest": (("m", 1e-9), 0.0, 0.0, 1.0),
    "tiny at speed": (("m", 1e-9), 0.5, 0.5, 1.0),
    "tiny change at speed": (("min", 1.0), 0.5, 0.5 + 1e-9, 1.0),
}


def _case(law, lim, case):
    (kind, k), fs, fe, fm = CASES[case]
    vm = lim.max_velocity
    vs, ve, vmax = fs * vm, fe * vm, fm * vm
    if kind == "D":
        d = k * min_distance(law, 0.0, vmax, lim)
    elif kind == "min":
        d = k * min_distance(law, vs, ve, lim)
    else:
        d = k
    return d, vs, ve, vmax


@pytest.mark.parametrize("lim_name", sorted(LIMITS))
@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("law", LAWS)
def test_every_law_every_case(law, case, lim_name):
    lim = LIMITS[lim_name]
    d, vs, ve, vmax = _case(law, lim, case)
    p = plan_move(law, d, v_start=vs, v_end=ve, v_max=vmax, limits=lim)
    check_move(p, law, d, vs, ve, min(vmax, lim.max_velocity), lim)
    # The move is as fast as the law allows: at the cap, or a peak a few ulp higher would
    # need more than the distance.
    if p.v_peak < vmax * (1 - 1e-9) and d > 0:
        higher = p.v_peak + 8 * math.ulp(p.v_peak)
        assert min_distance(law, vs, higher, lim) + min_distance(law, higher, ve, lim) > d


def test_trapezoid_acceleration_jumps_the_others_do_not():
    jumps = {}
    for law in LAWS:
        p = plan_move(law, 0.01, v_start=0.0, v_end=0.0, v_max=0.015, limits=TOMSK)
        t0 = p.segments[0].duration
        a_before, a_after = p.at(np.nextafter(t0, 0.0))[2], p.at(t0)[2]
        jumps[law] = abs(a_after - a_before)
    assert jumps.pop("trapezoid") == pytest.approx(TOMSK.max_acceleration)
    assert max(jumps.values()) < 1e-9


# ----------------------------------------------------------------------------- what each law is
def _single(law, lim, vs, ve):
    d = min_distance(law, vs, ve, lim)
    p = plan_move(law, d, v_start=vs, v_end=ve, v_max=lim.max_velocity, limits=lim)
    t = np.linspace(0.0, p.duration, 4001)[:-1]
    return p, t / p.duration, *p.sample(t)


# Defining velocity of each shape law, written out independently: v = vs + Δv·φ(u).
PHI = {
    "trapezoid": lambda u: u,
    "parabolic": lambda u: 6 * (u**2 / 2 - u**3 / 3),          # ∫ 6u(1 − u)
    "cosine": lambda u: (1 - np.cos(np.pi * u)) / 2,
    "cubic": lambda u: u**3 * (6 * u**2 - 15 * u + 10),        # smootherstep
}


@pytest.mark.parametrize("lim", [TOMSK, LASER], ids=["tomsk", "laser"])
@pytest.mark.parametrize("law", list(PHI))
@pytest.mark.parametrize(("fs", "fe"), [(0.0, 1.0), (0.9, 0.1)])
def test_shape_law_is_its_formula(law, fs, fe, lim):
    vs, ve = fs * lim.max_velocity, fe * lim.max_velocity
    _, u, _, v, a, j = _single(law, lim, vs, ve)
    np.testing.assert_allclose(v, vs + (ve - vs) * PHI[law](u), atol=1e-12 * lim.max_velocity)
    # The shortest change meets a limit: acceleration, or (smooth laws) jerk.
    hit = [np.abs(a).max() / lim.max_acceleration]
    if law != "trapezoid":
        hit.append(np.abs(j).max() / lim.max_jerk)
    assert max(hit) == pytest.approx(1.0, abs=2e-3)


def test_parabolic_is_seed_000_law():
    """a(τ) = a_peak·4τ(1 − τ), zero at both ends, end jerk 4·a_peak/T (SPEC §1)."""
    p, u, _, _, a, j = _single("parabolic", TOMSK, 0.0, 0.012)
    a_peak = 1.5 * 0.012 / p.duration
    np.testing.assert_allclose(a, a_peak * 4 * u * (1 - u), atol=1e-12)
    assert j[0] == pytest.approx(4 * a_peak / p.duration, rel=1e-12)


def test_cubic_has_continuous_jerk():
    p = plan_move("cubic", 0.01, v_start=0.0, v_end=0.003, v_max=0.015, limits=TOMSK)
    for seg in p.segments:
        for tb in (seg.start, seg.start + seg.duration):
            assert abs(p.at(np.nextafter(tb, 0.0))[3]) < 1e-6 * TOMSK.max_jerk
            assert abs(p.at(tb)[3]) < 1e-6 * TOMSK.max_jerk


@pytest.mark.parametrize("lim", [TOMSK, LASER], ids=["tomsk", "laser"])
def test_jerk_limited_is_bang_zero_bang(lim):
    p = plan_move("jerk-limited", 5 * min_distance("jerk-limited", 0, lim.max_velocity, lim),
                  v_start=0.0, v_end=0.0, v_max=lim.max_velocity, limits=lim)
    jerks = np.unique(np.round(np.array([seg.j for seg in p.segments]) / lim.max_jerk, 9))
    assert set(jerks) <= {-1.0, 0.0, 1.0}


# ----------------------------------------------------------------------------- textbook references
@pytest.mark.parametrize("d", [1e-4, 2e-3, 0.05, 0.4])
@pytest.mark.parametrize(("fs", "fe"), [(0.0, 0.0), (0.3, 0.1), (0.05, 0.8)])
def test_trapezoid_matches_textbook(d, fs, fe):
    lim = LASER
    vs, ve = fs * lim.max_velocity, fe * lim.max_velocity
    A = lim.max_acceleration
    if abs(ve**2 - vs**2) / (2 * A) > d:
        with pytest.raises(PlanningError):
            plan_move("trapezoid", d, v_start=vs, v_end=ve, v_max=0.5, limits=lim)
        return
    peak = min(lim.max_velocity, math.sqrt(A * d + (vs**2 + ve**2) / 2))
    cruise = d - (2 * peak**2 - vs**2 - ve**2) / (2 * A)
    T = (2 * peak - vs - ve) / A + cruise / peak
    p = plan_move("trapezoid", d, v_start=vs, v_end=ve, v_max=0.5, limits=lim)
    assert p.v_peak == pytest.approx(peak, rel=1e-12)
    assert p.duration == pytest.approx(T, rel=1e-12)


@pytest.mark.parametrize(("d", "vmax"), [(1.0, 0.5), (0.2, 0.2), (0.05, 0.5), (1e-3, 0.5)])
def test_jerk_limited_matches_double_s(d, vmax):
    """Rest-to-rest double S (Biagiotti & Melchiorri, Trajectory Planning, §3.4)."""
    A, J = LASER.max_acceleration, LASER.max_jerk

    def length(v):                        # rest → v → rest without cruise
        return v * (v / A + A / J) if v >= A * A / J else 2 * v * math.sqrt(v / J)

    if length(vmax) <= d:
        peak = vmax
    else:                                 # bisection on the monotone length
        lo, hi = 0.0, vmax
        for _ in range(200):
            lo, hi = ((lo + hi) / 2, hi) if length((lo + hi) / 2) <= d else (lo, (lo + hi) / 2)
        peak = lo
    ramp = peak / A + A / J if peak >= A * A / J else 2 * math.sqrt(peak / J)
    T = 2 * ramp + (d - length(peak)) / peak
    p = plan_move("jerk-limited", d, v_start=0.0, v_end=0.0, v_max=vmax, limits=LASER)
    assert p.v_peak == pytest.approx(peak, rel=1e-9)
    assert p.duration == pytest.approx(T, rel=1e-9)


def test_ruckig_agrees_with_closed_form():
    rng = np.random.default_rng(7)
    for _ in range(300):
        lim = Limits(10 ** rng.uniform(-3, 0), 10 ** rng.uniform(-1.3, 1), 10 ** rng.uniform(0, 3))
        vs, ve = rng.uniform(0, lim.max_velocity, 2)
        d = min_distance("jerk-limited", vs, ve, lim) * (1 + 10 ** rng.uniform(-4, 1))
        by_ruckig = scurve.ruckig_phases(d, vs, ve, lim.max_velocity, lim)
        if by_ruckig is None:
            continue
        segs = [scurve.integrate_phases(ph, vs, distance=d, cruise=scurve.CRUISE_PHASE)
                for ph in (by_ruckig, scurve.closed_form_phases(d, vs, ve, lim.max_velocity,
                                                                lim))]
        ends = [seg[-1].start + seg[-1].duration for seg in segs]
        assert ends[0] == pytest.approx(ends[1], rel=1e-6)
        peaks = [max(s.speed_range()[1] for s in seg) for seg in segs]
        assert peaks[0] == pytest.approx(peaks[1], rel=1e-6)


@pytest.mark.parametrize("failure", [None, [(1.0, 0.0)] * 7])
def test_jerk_limited_falls_back_when_ruckig_fails(monkeypatch, failure):
    """Ruckig errors (None) or a wrong answer: the closed-form S-curve takes over."""
    args = dict(v_start=0.003, v_end=0.001, v_max=0.015, limits=TOMSK)
    reference = plan_move("jerk-limited", 0.01, **args)
    monkeypatch.setattr(scurve, "ruckig_phases", lambda *a: failure)
    p = plan_move("jerk-limited", 0.01, **args)
    check_move(p, "jerk-limited", 0.01, 0.003, 0.001, 0.015, TOMSK)
    assert p.duration == pytest.approx(reference.duration, rel=1e-9)


def test_ruckig_edge_case_is_planned():
    """A move a hair longer than its single speed change, starting at the cap: ruckig 0.19
    reports an error here; the plan must not."""
    lim = Limits(0.16244066100477977, 1.6485848296592742, 3.3133188876119712)
    vs, ve = lim.max_velocity, 0.012708103861913853
    d = min_distance("jerk-limited", vs, ve, lim) * (1 + 1.07e-8)
    p = plan_move("jerk-limited", d, v_start=vs, v_end=ve, v_max=vs, limits=lim)
    check_move(p, "jerk-limited", d, vs, ve, vs, lim, dt=1e-4)


# ----------------------------------------------------------------------------- closed forms
SPEED_PAIRS = [(0.0, 0.3), (0.0, 1.0), (0.2, 0.25), (0.5, 0.5 + 1e-6), (0.1, 0.9), (0.999, 1.0)]


@pytest.mark.parametrize("lim", [TOMSK, LASER], ids=["tomsk", "laser"])
@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize(("f0", "f1"), SPEED_PAIRS)
def test_max_end_speed_inverts_min_distance(law, lim, f0, f1):
    v0, v1 = f0 * lim.max_velocity, f1 * lim.max_velocity
    d = min_distance(law, v0, v1, lim)
    assert d == min_distance(law, v1, v0, lim)                 # symmetric
    assert max_end_speed(law, v0, d, lim) == pytest.approx(v1, rel=1e-12)
    # The planner's two uses: accelerate to it, or brake from it, over exactly d.
    cap = lim.max_velocity
    for vs, ve in ((v0, max_end_speed(law, v0, d, lim)), (max_end_speed(law, v0, d, lim), v0)):
        p = plan_move(law, d, v_start=vs, v_end=ve, v_max=cap, limits=lim)
        assert p.v_peak == pytest.approx(max(vs, ve), rel=1e-9)
    if f1 < 1.0:
        with pytest.raises(PlanningError, match="cannot change speed"):
            plan_move(law, d, v_start=v0, v_end=v1 * (1 + 1e-6), v_max=cap, limits=lim)
        with pytest.raises(PlanningError, match="cannot change speed"):
            plan_move(law, d, v_start=v1 * (1 + 1e-6), v_end=v0, v_max=cap, limits=lim)


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("v0", [0.0, 1e-4, 0.01])
def test_max_end_speed_is_monotone_and_continuous(law, v0):
    """Across 3000 distances over nine decades, through every regime boundary."""
    lim = Limits(10.0, 0.2, 5.0)
    d = np.geomspace(1e-10, 10.0, 3000)
    v = np.array([max_end_speed(law, v0, x, lim) for x in d])
    assert np.all(np.diff(v) >= 0.0)
    ok = v - v0 > 1e-6 * v                                  # well conditioned: not Δv ≪ v
    gain = np.diff(v)[ok[1:]] / (v[1:] - v0)[ok[1:]]        # relative growth per step
    assert gain.max() < 0.02                                # no jumps between neighbours
    back = np.array([min_distance(law, v0, x, lim) for x in v])
    np.testing.assert_allclose(back[ok], d[ok], rtol=1e-9)


@pytest.mark.parametrize("law", LAWS)
def test_max_end_speed_caps_at_max_velocity(law):
    assert max_end_speed(law, 0.0, 1.0, TOMSK) == TOMSK.max_velocity
    assert max_end_speed(law, 0.003, 0.0, TOMSK) == 0.003
    assert min_distance(law, 0.004, 0.004, TOMSK) == 0.0


def test_closed_forms_are_cheap_and_allocation_free():
    """They use floats only: a float in, a float out, no ndarray anywhere."""
    for law in LAWS:
        assert type(max_end_speed(law, 0.001, 1e-4, TOMSK)) is float
        assert type(min_distance(law, 0.001, 0.01, TOMSK)) is float


# ----------------------------------------------------------------------------- errors
BAD = [
    (dict(law="s-curve"), ConfigError, "unknown acceleration law"),
    (dict(distance=-1e-3), PlanningError, "distance must be finite and >= 0, got -0.001"),
    (dict(distance=math.nan), PlanningError, "distance must be finite"),
    (dict(v_start=-0.001), PlanningError, "v_start must be finite and >= 0"),
    (dict(v_end=0.02), PlanningError, "v_end=0.02 m/s is above the speed cap 0.015"),
    (dict(v_start=0.006, v_max=0.005), PlanningError, "above the speed cap 0.005"),
    (dict(v_start=0.015, distance=1e-5), PlanningError, "cannot change speed from 0.015 to 0.0"),
    (dict(v_end=0.015, distance=1e-5), PlanningError, "needs"),
    (dict(v_max=0.0), PlanningError, "speed cap of 0.0"),
]


@pytest.mark.parametrize(("change", "error", "text"), BAD)
def test_bad_moves_raise_typed_errors_naming_the_numbers(change, error, text):
    args = dict(law="parabolic", distance=0.01, v_start=0.0, v_end=0.0, v_max=0.015,
                limits=TOMSK) | change
    with pytest.raises(error, match=text.replace("(", r"\(").replace(".", r"\.")):
        plan_move(args.pop("law"), args.pop("distance"), **args)


@pytest.mark.parametrize("field", ["max_velocity", "max_acceleration", "max_jerk"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.inf, math.nan, "1"])
def test_limits_name_the_bad_field(field, value):
    args = dict(max_velocity=0.015, max_acceleration=0.2, max_jerk=5.0) | {field: value}
    with pytest.raises(ConfigError) as err:
        Limits(**args)
    assert err.value.field == field


def test_limits_from_machine_config():
    cfg = load_machine("tomsk_xy").controller.limits
    assert Limits.from_config(cfg) == TOMSK


def test_closed_forms_reject_nonsense():
    with pytest.raises(PlanningError):
        min_distance("cosine", -1.0, 0.0, TOMSK)
    with pytest.raises(PlanningError):
        max_end_speed("cosine", 0.0, math.nan, TOMSK)
    with pytest.raises(ConfigError):
        max_end_speed("quintic", 0.0, 1.0, TOMSK)


# ----------------------------------------------------------------------------- property test
@given(
    law=st.sampled_from(LAWS),
    a=st.floats(0.01, 10.0), j=st.floats(0.1, 1000.0), vm=st.floats(1e-3, 1.0),
    fs=st.one_of(st.just(0.0), st.floats(1e-9, 1.0)),
    fe=st.one_of(st.just(0.0), st.floats(1e-9, 1.0)),
    fm=st.floats(0.05, 1.0),
    d=st.one_of(st.just(0.0), st.floats(1e-12, 1.0), st.floats(1e-12, 1e-6)),
    stretch=st.one_of(st.none(), st.just(0.0), st.floats(0.0, 3.0)),
)
def test_property_any_move(law, a, j, vm, fs, fe, fm, d, stretch):
    """Any move; with ``stretch``, (1 + stretch) times the shortest path between the speeds.

    Speeds and distances stay out of the subnormal range (below 1e-300 a product underflows
    and nothing physical is left to check): speeds are 0 or ≥ 1e-9 of the cap, distances 0
    or ≥ 1e-12 m.
    """
    lim = Limits(vm, a, j)
    cap = fm * vm
    vs, ve = fs * cap, fe * cap
    if stretch is not None:
        d = min_distance(law, vs, ve, lim) * (1 + stretch)
    reachable = max_end_speed(law, min(vs, ve), d, lim)
    if max(vs, ve) > reachable * (1 + 1e-9):
        event("v_end unreachable")
        with pytest.raises(PlanningError, match="cannot change speed"):
            plan_move(law, d, v_start=vs, v_end=ve, v_max=cap, limits=lim)
        return
    p = plan_move(law, d, v_start=vs, v_end=ve, v_max=cap, limits=lim)
    assume(p.duration < 50.0)
    event("planned")
    check_move(p, law, d, vs, ve, cap, lim, dt=max(p.duration / 3000, 1e-9))


@pytest.mark.parametrize(("a0", "j"), [(1.0, -2.0), (-1.0, 2.0), (0.5, 1.0), (0.0, 0.0)])
def test_polynomial_speed_range_matches_sampling(a0, j):
    seg = Polynomial(0.0, 1.0, 0.0, 1.0, a0, j)
    _, v, _, _ = seg.sample(np.linspace(0.0, 1.0, 100_001))
    assert seg.speed_range() == pytest.approx((v.min(), v.max()), rel=1e-9)
