"""The layout's ranges against the data they frame, on many random recordings: every plot
holds all its data with at least two labelled ticks (as rerun's egui_plot labels them,
``tests.rrd.labelled``), the time axis spans the data, the path view holds every point."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from tests.rrd import labelled, layout_views
from twin.telemetry.channels import SERIES
from twin.telemetry.extent import MAX_STEPS, tick_range
from twin.telemetry.rerun_sink import RerunSink

CI = os.environ.get("CI") == "true"


def _steps(lo: float, hi: float) -> tuple[float, int]:
    """The labelled step of ``tick_range``'s result and how many steps it spans (brute
    force: the smallest power of ten whose multiples bound the range within MAX_STEPS)."""
    for k in range(-15, 16):
        s = 10.0 ** k
        a, b = math.floor(lo / s) * s, math.ceil(hi / s) * s
        if b - a <= MAX_STEPS * s * (1 + 1e-9):
            return s, round((b - a) / s)
    raise AssertionError


def test_tick_range_holds_the_data_with_two_labelled_ticks_on_random_ranges():
    rng = np.random.default_rng(7)
    for _ in range(300 if CI else 3000):
        scale = 10.0 ** rng.uniform(-6, 6)
        lo = rng.normal() * scale
        hi = lo + abs(rng.normal()) * scale * 10.0 ** rng.uniform(-4, 1)
        a, b = tick_range(lo, hi)
        assert a < lo <= hi < b
        assert labelled(a, b, height=150.0) >= 2, (lo, hi, a, b)
        if hi - lo > 1e-9 * max(abs(lo), abs(hi)):
            s, n = _steps(lo, hi)
            assert n <= MAX_STEPS
            assert (b - a) <= (n * s) * 1.1 + 1e-300       # no wider than the steps + margin
            assert (hi - lo) >= 0.1 * (b - a)               # the data fill the panel


@pytest.mark.parametrize("value", [0.0, 1.0, -3.0, 1e-7, 2.5e4])
def test_tick_range_of_a_constant_is_around_it_with_two_labels(value):
    a, b = tick_range(value, value)
    assert a < value < b and labelled(a, b) >= 2


def test_tick_range_of_no_finite_data_leaves_the_range_to_the_viewer():
    assert tick_range(math.nan, 1.0) is None and tick_range(0.0, math.inf) is None


def test_random_recordings_are_framed_on_their_data(tmp_path):
    rng = np.random.default_rng(11)
    entities = [k.format(a=a) for k in SERIES for a in ("x", "y")]
    entities = sorted(set(entities))
    for case in range(2 if CI else 6):
        path = tmp_path / f"r{case}.rrd"
        sink = RerunSink(path, recording_id=f"r{case}")
        sink.machine_frame("path")          # as the default layout's sink does already
        t0 = rng.uniform(0, 5)
        n = int(rng.integers(50, 400))
        t = t0 + np.cumsum(rng.uniform(1e-3, 1e-2, n))
        chosen = [e for e in entities if rng.random() < 0.7]
        data = {}
        for e in chosen:
            width = len(SERIES[next(k for k in SERIES if any(k.format(a=a) == e
                                                                 for a in "xy"))][1])
            v = rng.normal(rng.normal() * 10.0 ** rng.uniform(-3, 4),
                           10.0 ** rng.uniform(-3, 3), (n, width) if width > 1 else n)
            if rng.random() < 0.3:
                v[rng.random(v.shape) < 0.2] = np.nan      # e.g. no programmed F on a G0
            data[e] = v
        for part in np.array_split(np.arange(n), 3):
            sink.scalars(t[part], {e: v[part] for e, v in data.items()})
        shape = rng.uniform(-200, 200, (int(rng.integers(3, 30)), 2))
        sink.static_path("path/programmed", shape)
        actual = shape[rng.integers(0, len(shape), n)] + rng.normal(0, 2, (n, 2))
        sink.points(t, {"path/actual": actual})
        sink.close()
        views = layout_views(path)
        for view in views:
            if view["kind"] == "2D":
                pts = np.vstack([shape, actual])
                (x0, x1), (y0, y1) = view["bounds"]["x_range"], view["bounds"]["y_range"]
                assert x0 < pts[:, 0].min() and pts[:, 0].max() < x1
                assert y0 < -pts[:, 1].max() and -pts[:, 1].min() < y1
            if view["kind"] != "TimeSeries":
                continue
            got = [data[e.lstrip("/")] for e in view["contents"] if e.lstrip("/") in data]
            values = np.concatenate([np.ravel(g) for g in got]) if got else np.zeros(0)
            values = values[np.isfinite(values)]
            if not values.size:
                assert "y_range" not in view          # nothing to frame: the viewer's own
                continue
            lo, hi = view["y_range"]
            assert lo < values.min() and values.max() < hi, view["name"]
            assert labelled(lo, hi) >= 2
            t0, t1 = view["time"]
            assert t0 <= t.min() and t.max() <= t1 and t1 - t0 <= np.ptp(t) + 2e-9
