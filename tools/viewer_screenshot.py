"""Screenshot of a recording in rerun's web viewer, taken headless: ``twin view --web`` on
loopback, headless Chromium (Debian's ``chromium``) driven by Playwright, and a real wait
until the viewer has loaded the recording and laid it out.

    .venv/bin/pip install -e '.[screenshot]'   # playwright (uses the system chromium)
    .venv/bin/python tools/viewer_screenshot.py runs/<id>.rrd shot.png --wait 25

Prints one JSON object: the URL, the wait and the file written.
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import subprocess
import sys
import time


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recording")
    ap.add_argument("out")
    ap.add_argument("--wait", type=float, default=25.0, help="seconds to wait after load")
    ap.add_argument("--size", default="1800x1100", help="window WIDTHxHEIGHT")
    ap.add_argument("--port", type=int, default=9190)
    ap.add_argument("--grpc-port", type=int, default=9977)
    a = ap.parse_args()
    from playwright.sync_api import sync_playwright

    browser_exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser_exe is None:
        print("no chromium on the PATH (apt-get install chromium)", file=sys.stderr)
        return 2
    view = subprocess.Popen([sys.executable, "-m", "twin.cli", "view", "--web", "--port",
                             str(a.port), "--grpc-port", str(a.grpc_port), a.recording],
                            stderr=subprocess.PIPE, text=True)
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
            browser = pw.chromium.launch(
                executable_path=browser_exe, headless=True,
                args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                      "--ignore-gpu-blocklist"])
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(url, wait_until="load")
            t0 = time.monotonic()
            page.wait_for_timeout(a.wait * 1000.0)      # the wasm app loads, then the data
            page.screenshot(path=a.out)
            waited = time.monotonic() - t0
            browser.close()
    finally:
        view.send_signal(signal.SIGTERM)
        view.wait(timeout=30)
    print(json.dumps({"url": url, "waited_s": round(waited, 1), "screenshot": a.out}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
