"""Screenshots of a recording in rerun's web viewer, taken headless: ``twin view --web`` on
loopback, headless Chromium (Debian's ``chromium``) driven by Playwright, and a real wait
until the viewer has loaded the recording and laid it out (the picture stops changing).

    .venv/bin/pip install -e '.[screenshot]'   # playwright (uses the system chromium)
    .venv/bin/python tools/viewer_screenshot.py runs/<id>.rrd run.png \\
        --tab "X drive=x_drive.png" --tab "X motion=x_motion.png"

The first file shows the layout's active tab; each ``--tab NAME=FILE`` clicks the tab NAME
of a run's layout (``twin.telemetry.blueprint.default_blueprint``: Run, X drive, Y drive,
X motion, Y motion, Spectra) and shoots it, on the timeline the tab draws against (the
spectra on ``frequency_hz``, chosen in the time panel's menu, as a reader would). Prints one
JSON object: the URL, the files written and how long each took to settle. Exit 2 (and a
line saying what to install) without Chromium or Playwright.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import signal
import subprocess
import sys
import time

TABS = {"Run": 39, "X drive": 103, "Y drive": 177, "X motion": 252, "Y motion": 337,
        "Spectra": 495}
"""Where each tab of a run's layout sits on the viewer's tab bar (x, screen points; the bar
is at y = 50): the bar is left-aligned, so these hold at any window width."""

TAB_BAR_Y = 50

TAB_TIMELINE = {"Spectra": "frequency_hz"}
"""The timeline a tab draws against, where it is not ``sim_time``."""

TIMELINES = ("frequency_hz", "log_time", "sim_time")
"""A run's timelines as the time panel's menu lists them (by name, bottom up from
``sim_time``)."""

TIMELINE_MENU = (178, 14)
"""The time panel's timeline menu: x, and height above the window's bottom (screen points);
its entries lie ``TIMELINE_ROW`` apart above it, the last one ``TIMELINE_LAST`` above the
bottom."""

TIMELINE_ROW, TIMELINE_LAST, TIMELINE_ENTRY_X = 24, 42, 205


def choose_timeline(page, name: str, height: int, most: float) -> None:
    """Choose timeline ``name`` in the time panel's menu (a window ``height`` points tall):
    open the menu, wait until it is drawn, click the entry, wait until the views are."""
    page.mouse.click(TIMELINE_MENU[0], height - TIMELINE_MENU[1])
    settle(page, least=2.0, most=most)
    below = len(TIMELINES) - 1 - TIMELINES.index(name)
    page.mouse.click(TIMELINE_ENTRY_X, height - TIMELINE_LAST - TIMELINE_ROW * below)
    settle(page, least=2.0, most=most)

SETTLED = 3
"""Consecutive identical frames (one per ``POLL`` s) that count as laid out."""

POLL = 1.5

SHOT_TIMEOUT = 180_000
"""Milliseconds one screenshot may take: a software-rendered 1800×1100 frame on a busy
two-core machine takes tens of seconds while the recording loads."""


def browser() -> str | None:
    """Chromium's executable, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def missing() -> str | None:
    """What is missing for a screenshot (a sentence), or None."""
    if browser() is None:
        return "no chromium on the PATH (Debian: apt-get install chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright is not installed (pip install -e '.[screenshot]')"
    return None


def settle(page, *, least: float, most: float) -> float:
    """Wait until the picture has not changed for ``SETTLED`` polls (at least ``least``,
    at most ``most`` seconds); return the seconds waited."""
    t0 = time.monotonic()
    last, same = None, 0
    while time.monotonic() - t0 < most:
        page.wait_for_timeout(POLL * 1000.0)
        digest = hashlib.sha1(page.screenshot(timeout=SHOT_TIMEOUT)).hexdigest()
        same = same + 1 if digest == last else 0
        last = digest
        if same >= SETTLED and time.monotonic() - t0 >= least:
            break
    return time.monotonic() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recording")
    ap.add_argument("out", help="PNG of the layout as it opens")
    ap.add_argument("--tab", action="append", default=[], metavar="NAME=FILE",
                    help=f"also click tab NAME ({', '.join(TABS)}) and save it to FILE")
    ap.add_argument("--wait", type=float, default=240.0,
                    help="most seconds to wait for the viewer to settle")
    ap.add_argument("--size", default="1800x1100", help="window WIDTHxHEIGHT")
    ap.add_argument("--port", type=int, default=9190)
    ap.add_argument("--grpc-port", type=int, default=9977)
    a = ap.parse_args()
    tabs = []
    for item in a.tab:
        name, sep, path = item.partition("=")
        if not sep or name not in TABS:
            ap.error(f"--tab expects NAME=FILE with NAME one of {', '.join(TABS)}, got "
                     f"{item!r}")
        tabs.append((name, path))
    why = missing()
    if why is not None:
        print(f"viewer_screenshot: {why}", file=sys.stderr)
        return 2
    from playwright.sync_api import sync_playwright

    view = subprocess.Popen([sys.executable, "-m", "twin.cli", "view", "--web", "--port",
                             str(a.port), "--grpc-port", str(a.grpc_port), a.recording],
                            stderr=subprocess.PIPE, text=True)
    shots = []
    try:
        url = None
        while url is None:
            line = view.stderr.readline()
            if not line:
                print("twin view --web did not start", file=sys.stderr)
                return 1
            if "web viewer:" in line:
                url = line.split("web viewer:", 1)[1].split()[0]
        width, height = (int(v) for v in a.size.split("x"))
        with sync_playwright() as pw:
            chrome = pw.chromium.launch(
                executable_path=browser(), headless=True,
                args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                      "--ignore-gpu-blocklist"])
            page = chrome.new_page(viewport={"width": width, "height": height})
            page.goto(url, wait_until="load")
            waited = settle(page, least=8.0, most=a.wait)     # the wasm app, then the data
            page.screenshot(path=a.out, timeout=SHOT_TIMEOUT)
            shots.append({"file": a.out, "settled_s": round(waited, 1)})
            timeline = "sim_time"
            for name, path in tabs:
                if TAB_TIMELINE.get(name, "sim_time") != timeline:
                    timeline = TAB_TIMELINE.get(name, "sim_time")
                    choose_timeline(page, timeline, height, a.wait)
                page.mouse.click(TABS[name], TAB_BAR_Y)
                page.mouse.move(width / 2, height - 5)      # no hover tooltip on the shot
                waited = settle(page, least=2.0, most=a.wait)
                page.screenshot(path=path, timeout=SHOT_TIMEOUT)
                shots.append({"file": path, "tab": name, "settled_s": round(waited, 1)})
            chrome.close()
    finally:
        view.send_signal(signal.SIGTERM)
        view.wait(timeout=30)
    print(json.dumps({"url": url, "screenshots": shots}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
