"""Test-wide settings: no analytics, no display, deterministic hypothesis profile in CI, and
the check that the suite leaves no process of its own behind.

Every process the suite starts (xdist workers, ``twin`` subprocesses, rerun viewers and
servers, HIL servers, PostgreSQL) inherits ``XY_TWIN_TEST_SESSION`` from the process that
started the session. When the session ends, any process still carrying this session's tag
(other than the session's own) was leaked by a test: it is named, killed, and the session
fails. Orphans re-parented to init are found as well, since the tag is in the environment,
not the process tree.
"""

import os
import signal
import time
import uuid

os.environ.setdefault("RERUN_ANALYTICS", "0")
os.environ.setdefault("RERUN_DISABLE_ANALYTICS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
# the identification fit's replays in one process (twin.identify.parallel): the suite's two
# workers already use both cores
os.environ.setdefault("XY_TWIN_FIT_PROCESSES", "1")
os.environ.pop("DISPLAY", None)           # CI has none; a viewer must never open on a desk
os.environ.pop("WAYLAND_DISPLAY", None)

# xdist starts its workers with SIGINT ignored, and an ignored signal stays ignored across
# exec: every `twin` the tests start would ignore a Ctrl-C until its run installs handlers,
# and the tests of stop signals at random instants would see a SIGINT at start-up vanish.
# The tests' processes get Python's own handler, as a command started from a terminal has.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

from hypothesis import settings

settings.register_profile("ci", max_examples=200, deadline=None, derandomize=True)
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

TAG = "XY_TWIN_TEST_SESSION"
_OWNER = TAG not in os.environ   # the process that started the session (not an xdist worker)
if _OWNER:
    os.environ[TAG] = uuid.uuid4().hex


def tagged_processes(tag: str) -> dict[int, str]:
    """pid -> command line of every process whose environment carries ``TAG=tag``."""
    found = {}
    needle = f"{TAG}={tag}".encode()
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as f:
                if needle not in f.read().split(b"\0"):
                    continue
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmd = f.read().replace(b"\0", b" ").decode(errors="replace").strip()
            with open(f"/proc/{entry}/stat") as f:
                if f.read().rsplit(")", 1)[1].split()[0] == "Z":
                    continue                 # a zombie holds nothing
        except OSError:                      # gone meanwhile, or not ours to read
            continue
        found[int(entry)] = cmd
    return found


def pytest_sessionfinish(session, exitstatus):
    if not _OWNER or not os.path.isdir("/proc"):
        return
    tag = os.environ[TAG]
    deadline = time.monotonic() + 10.0       # xdist workers take a moment to exit
    left = tagged_processes(tag)
    while left and time.monotonic() < deadline:
        time.sleep(0.2)
        left = tagged_processes(tag)
    if not left:
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    lines = [f"  pid {pid}: {cmd}" for pid, cmd in sorted(left.items())]
    text = "processes started by the suite are still alive (killed now):\n" + "\n".join(lines)
    if reporter is not None:
        reporter.write_line(text, red=True)
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    session.exitstatus = 1

