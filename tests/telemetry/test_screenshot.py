"""The viewer as an engineer sees it: a run's recording in rerun's web viewer, shot headless
by ``tools/viewer_screenshot.py`` (Chromium driven by Playwright, the README's screenshot),
and the picture checked for the layout's traces, path and grid.

It runs where Chromium and Playwright are installed. ``make test-screenshot`` (or
``XY_TWIN_SCREENSHOT=1``) requests it: then a missing browser is a failure that says what
to install, never a skip. Under CI, where a browser and the wasm viewer cost about a minute
on two cores, it runs only when requested.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from twin.session.run import RunSpec, run

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "viewer_screenshot.py"
REQUESTED = os.environ.get("XY_TWIN_SCREENSHOT") == "1"
CI = os.environ.get("CI") == "true"


def _missing() -> str | None:
    sys.path.insert(0, str(TOOL.parent))
    try:
        import viewer_screenshot
    finally:
        sys.path.pop(0)
    return viewer_screenshot.missing()


@pytest.fixture(scope="module")
def browser_ready():
    why = _missing()
    if why is not None and REQUESTED:
        pytest.fail(f"the screenshot check was requested (XY_TWIN_SCREENSHOT=1) but {why}")
    if why is not None:
        pytest.skip(f"{why}: the viewer screenshot check needs them (make test-screenshot "
                    "requests it and fails without them)")
    if CI and not REQUESTED:
        pytest.skip("under CI the screenshot check (a minute of browser) runs when "
                    "requested: make test-screenshot")


def _pixels(png: Path) -> np.ndarray:
    import matplotlib.image as mpimg

    return (mpimg.imread(png)[:, :, :3] * 255).round().astype(int)


def _has(img: np.ndarray, rgb: tuple[int, int, int], *, tol: int = 12, least: int = 30) -> bool:
    return int(np.sum(np.all(np.abs(img - np.array(rgb)) <= tol, axis=2))) >= least


def test_the_viewer_shows_the_run_tab_a_drive_tab_and_the_spectra(browser_ready, tmp_path):
    from twin.telemetry.channels import COLOURS
    from twin.telemetry.rerun_sink import GRID_COLOUR

    s = run(RunSpec(machine="tomsk_xy", builtin="tiny"), out_dir=tmp_path,
            run_id="shot").summary
    shot, drive, spectra = (tmp_path / f"{n}.png" for n in ("run", "x_drive", "spectra"))
    size = "1200x800" if CI else "1800x1100"
    r = subprocess.run([sys.executable, str(TOOL), s["recording"], str(shot), "--tab",
                        f"X drive={drive}", "--tab", f"Spectra={spectra}", "--size", size,
                        "--port", "9391",
                        "--grpc-port", "9392", "--wait", "300"],
                       capture_output=True, text=True, timeout=900, cwd=ROOT,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr[-2000:]
    report = json.loads(r.stdout.strip().splitlines()[-1])
    assert [Path(x["file"]) for x in report["screenshots"]] == [shot, drive, spectra]
    img = _pixels(shot)
    assert img.shape[:2] == tuple(int(v) for v in reversed(size.split("x")))
    # the Run tab: the actual path (green at this error), its grid, the feeds, the terms
    assert _has(img, (40, 180, 60)), "the actual path is drawn"
    assert _has(img, GRID_COLOUR[:3], least=500), "the path view's grid is drawn"
    for colour in ("blue", "orange"):                     # commanded and actual feed, ...
        assert _has(img, COLOURS[colour]), colour
    tab = _pixels(drive)
    assert _has(tab, COLOURS["purple"]) and _has(tab, COLOURS["red"])   # converter, current
    assert not np.array_equal(img, tab), "the tab was switched"
    # the spectra, on their timeline: x's curves in orange (the Spectra tab on sim_time
    # draws no curve: only the viewer's own orange warning)
    assert _has(_pixels(spectra), COLOURS["orange"], least=500), "the spectra are drawn"
