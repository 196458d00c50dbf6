"""Test-wide settings: no analytics, no display, deterministic hypothesis profile in CI."""

import os

os.environ.setdefault("RERUN_ANALYTICS", "0")
os.environ.setdefault("RERUN_DISABLE_ANALYTICS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

from hypothesis import settings

settings.register_profile("ci", max_examples=200, deadline=None, derandomize=True)
settings.register_profile("dev", max_examples=100, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")
