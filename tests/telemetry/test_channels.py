"""The live contour error agrees with the exact metric within its stated sagitta."""

import numpy as np
import pytest

from twin.config import load_machine
from twin.controller.geometry import Arc, Line
from twin.controller.library import default_program, program_path
from twin.controller.metrics import contour_error
from twin.controller.spline_path import SplinePath
from twin.telemetry.channels import PathDistance


@pytest.mark.parametrize("machine", ["tomsk_xy", "laser_belt"])
def test_path_distance_matches_the_exact_contour_error(machine):
    cfg = load_machine(machine)
    path = program_path(default_program(cfg, (0.01, 0.01)))
    rng = np.random.default_rng(7)
    # points near the path (up to 300 µm off it), as a lagging table would be
    s = [rng.uniform(0, seg.length, 400) for seg in path]
    near = np.concatenate([seg.point(si) for seg, si in zip(path, s, strict=True)])
    pts = near + rng.normal(0.0, 1e-4, near.shape)
    exact = contour_error(path, pts)
    distance = PathDistance(path)
    assert distance.sagitta <= 1e-8
    np.testing.assert_allclose(distance(pts), exact, rtol=0, atol=distance.sagitta + 1e-12)


def test_path_distance_on_simple_shapes():
    line = Line((0.0, 0.0), (0.1, 0.0))
    arc = Arc((0.1, 0.0), (0.1, 0.0), (0.1, 0.02), ccw=True)
    spline = SplinePath(np.array([[0.1, 0.0], [0.15, 0.01], [0.2, 0.0]]))
    path = [line, arc, spline]
    d = PathDistance(path)
    assert d(np.array([[0.05, 0.003]]))[0] == pytest.approx(0.003, abs=1e-12)
    far = np.array([[0.1, 0.02], [0.15, -0.03], [0.3, 0.2]])    # also far from the path
    np.testing.assert_allclose(d(far), contour_error(path, far), rtol=0, atol=d.sagitta)
