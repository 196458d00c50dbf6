"""The examples in the controller's docstrings run, and give what they say (as
python-control's docstrings do): every ``>>>`` of every module of ``twin.controller``, and
of the few other public entry points that carry one."""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import twin.controller

OTHERS = ("twin.hardware.timing", "twin.drive.drives")
MODULES = sorted({m.name for m in pkgutil.walk_packages(twin.controller.__path__,
                                                        "twin.controller.")} | set(OTHERS))
PUBLIC_API = ("twin.controller.encoder", "twin.controller.gcode", "twin.controller.interpolator",
              "twin.controller.metrics", "twin.controller.profiles", "twin.controller.record")
"""Modules whose "Typical use" is an executed example (at least one ``>>>`` each)."""


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    result = doctest.testmod(module, optionflags=flags, verbose=False, report=True)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name}"
    if name in PUBLIC_API:
        assert result.attempted > 0, f"{name}: its Typical use is not an executed example"
