"""A run's spectra as its recording holds them, read back with ``rerun.chunk.RrdReader``:
``scipy.signal.welch`` of the run's own following error and screw deflection (an
independent estimate of the same records), the deflection's peak at the machine's first
elastic mode, the layout's Spectra tab framed on them, and a run stopped early.

The machines are tomsk_xy with a random nut stiffness and a light random damping, its screw
made rigid: the first elastic mode (``axis_mechanics(...).locked_rotor_frequency``) is then
the same over the travel, and rings long enough to stand out of a 2 s run.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import rerun.chunk as rc
from scipy.signal import welch

from tests.rrd import assert_verified, layout_views, rrd_spectra
from twin.config import AXES
from twin.plant.model import axis_mechanics
from twin.session.run import RunSpec, prepare, run
from twin.telemetry.blueprint import SPECTRA_TAB
from twin.telemetry.spectra import DB_SPAN, SEGMENT

CI = os.environ.get("CI") == "true"
RESOLUTION = 3.0
"""How near the mode a 2 s run's deflection spectrum peaks (Hz, 1 Hz bins): half the Hann
window's main lobe (2 bins), and a bin for the ripple of the few rings such a run holds (on
40 random machines the peak lay within 2.0 Hz of the mode; a ±30 % band is ±20 Hz and more)."""


def _spec(seed: int) -> RunSpec:
    rng = np.random.default_rng(seed)
    zeta = float(rng.uniform(0.002, 0.005))
    overrides = {}
    for a in AXES:
        overrides |= {f"axes.{a}.transmission.stiffness.screw": 1e11,
                      f"axes.{a}.transmission.stiffness.nut": float(rng.uniform(3e7, 1.5e8)),
                      f"axes.{a}.transmission.damping_ratio": zeta}
    return RunSpec(machine="tomsk_xy", builtin="tiny", overrides=overrides)


@pytest.fixture(scope="module", params=range(1 if CI else 4))
def ringing(request, tmp_path_factory):
    spec = _spec(500 + request.param)
    p = prepare(spec)
    result = run(spec, out_dir=tmp_path_factory.mktemp("spectra"), run_id="ring",
                 prepared=p, keep_fine=True)
    modes = {a: axis_mechanics(p.cfg, a).locked_rotor_frequency / (2.0 * math.pi)
             for a in AXES}
    return result, p.plant.drive_dt, modes


def _reference(x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """scipy's Welch estimate (1 s Hann windows, half overlapping) as a level in dB re 1
    µm/√Hz, none at DC (the means are removed); a record shorter than a window is one
    window, zero-padded."""
    length = round(SEGMENT / dt)
    m = min(len(x), length)
    f, p = welch(x, fs=1.0 / dt, window="hann", nperseg=m, noverlap=m // 2, nfft=length,
                 detrend="constant", axis=0)
    p = np.where(p > 0.0, p, np.nan)                  # a constant signal: no level
    p[0] = np.nan
    return f, 20.0 * np.log10(np.sqrt(p) / 1e-6)


def _signals(result, drive_dt: float) -> dict[str, tuple[np.ndarray, float]]:
    return {"following_error": (result.record["following_error"],
                                result.summary["config"]["controller"]["period"]),
            "screw_deflection": (result.fine["screw_deflection"], drive_dt)}


def _assert_spectra_are_welch(rrd, signals) -> None:
    got = rrd_spectra(rrd)
    for quantity, (x, dt) in signals.items():
        f, level = _reference(x, dt)
        for k, a in enumerate(AXES):
            hz, logged = got[f"spectra/{quantity}/{a}"]
            np.testing.assert_array_equal(hz, np.rint(f))
            assert np.all(np.abs(hz - f) <= 0.25)
            np.testing.assert_allclose(logged, level[:, k], rtol=0, atol=1e-9,
                                       err_msg=f"{quantity} {a}")


def test_recorded_spectra_are_scipy_welch_of_the_runs_own_records(ringing):
    result, drive_dt, _ = ringing
    assert result.summary["status"] == "FINISHED"
    _assert_spectra_are_welch(result.summary["recording"], _signals(result, drive_dt))


def test_the_deflection_peaks_at_the_machines_elastic_mode_which_is_marked(ringing):
    result, _, modes = ringing
    got = rrd_spectra(result.summary["recording"])
    for a, mode in modes.items():
        hz, level = got[f"spectra/screw_deflection/{a}"]
        band = (hz > 0.7 * mode) & (hz < 1.3 * mode)
        top = int(np.argmax(np.where(band, level, -np.inf)))
        assert abs(hz[top] - mode) <= RESOLUTION, (a, hz[top], mode)
        assert level[top] > np.median(level[band]) + 10.0, a    # a peak, not the band's edge
        (f_mark,), (mark,) = got[f"spectra/screw_deflection/{a}_mode"]
        assert f_mark == round(mode)            # the nearest bin of the model's mode ...
        assert mark == level[hz == f_mark][0]   # ... drawn on the curve


def test_the_spectra_tab_is_framed_on_the_spectra_and_names_the_modes(ringing):
    result, _, modes = ringing
    path = result.summary["recording"]
    got = rrd_spectra(path)
    views = sorted((v for v in layout_views(path) if v["kind"] == "TimeSeries"
                    and v["contents"][0].startswith("/spectra/")), key=lambda v: v["contents"])
    assert [v["contents"] for v in views] == [
        [f"/spectra/{q}/{a}{m}" for m in ("", "_mode") for a in AXES]
        for q in ("following_error", "screw_deflection")]
    for view in views:
        curves = [got[e.lstrip("/")] for e in view["contents"] if e.lstrip("/") in got]
        top = max(np.nanmax(v) for _, v in curves)
        bottom = min(np.nanmin(v) for _, v in curves)
        lo, hi = view["y_range"]
        assert hi - 12.0 < top < hi                       # whole 10 dB steps, a margin
        assert top - DB_SPAN - 12.0 < lo < max(bottom, top - DB_SPAN)   # 120 dB at most
        assert "(dB re 1 µm/√Hz vs Hz)" in view["name"]
        assert "x orange, y blue" in view["name"]
        band = view["contents"][0].rsplit("/", 2)[1]
        hz = got[f"spectra/{band}/x"][0]
        # the frequency axis (sequence values, read back as if nanoseconds): the band
        np.testing.assert_allclose(view["time"], (0.0, hz.max() * 1e-9))
    for a, mode in modes.items():                     # the marked modes, in whole hertz
        assert f"{a} {round(mode)} Hz" in views[1]["name"]
    assert SPECTRA_TAB in _container_names(path)


def _container_names(rrd) -> set[str]:
    """The names of the containers (tabs) of a recording's layouts."""
    reader = rc.RrdReader(rrd)
    names = set()
    for store in reader.blueprints():
        for chunk in reader.stream(store=store).to_chunks():
            rb = chunk.to_record_batch()
            if "ContainerBlueprint:display_name" in rb.schema.names:
                names |= {row[0] for row in rb.column(
                    "ContainerBlueprint:display_name").to_pylist() if row}
    return names


def test_a_run_stopped_early_records_the_spectra_of_what_was_run(tmp_path):
    """Interrupted (Ctrl-C) at the first progress report: the spectra of the ticks that
    ran; stopped after seven ticks: no following-error spectrum (too few samples), the
    deflection's (its drive interval is shorter) — either recording complete and verified."""
    def interrupt(sim_time: float, done: float) -> None:
        raise KeyboardInterrupt

    spec = RunSpec(machine="tomsk_xy")
    p = prepare(spec)
    result = run(spec, out_dir=tmp_path, run_id="stopped", prepared=p, keep_fine=True,
                 progress=interrupt)
    assert result.summary["aborted"].startswith("interrupted")
    assert 0.0 < result.summary["sim_time_s"] < 60.0
    assert_verified(result.summary["recording"], "interrupted")
    _assert_spectra_are_welch(result.summary["recording"], _signals(result, p.plant.drive_dt))
    tiny = run(RunSpec(machine="tomsk_xy", max_time=0.035), out_dir=tmp_path, run_id="short",
               keep_fine=True)
    assert_verified(tiny.summary["recording"], "short")
    got = rrd_spectra(tiny.summary["recording"])
    assert len(tiny.record["t"]) < 8 and not any(e.startswith("spectra/following_error")
                                                 for e in got)
    _assert_spectra_are_welch(tiny.summary["recording"], {
        "screw_deflection": (tiny.fine["screw_deflection"], p.plant.drive_dt)})
    assert np.isfinite(got["spectra/screw_deflection/x"][1][1:]).all()   # x has begun to move
