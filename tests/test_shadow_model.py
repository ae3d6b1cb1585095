"""The light estimate's model of the probe's shadow on its ground grid (arshadow/estimate/shadow.py): a hull's
coverage as the photo's samples see it, the blur across each edge, the ground's Jacobian.

Truth: closed forms written here (a Gaussian-blurred straight edge, a pinhole's homography), not the code
under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import TOL

from arshadow.camera.model import Intrinsics
from arshadow.estimate.shadow import (
    MIN_EDGE_CELLS,
    Evidence,
    edge_sigma,
    ground_jacobian,
    hull_coverage,
    sample_blur_px,
)
from arshadow.synth.markers import look_at_pose

STEP = 0.002  # metres per cell
N = 120


def _evidence(blur_px=None, jacobian=None) -> Evidence:
    z = np.zeros((N, N))
    return Evidence(
        0.0,
        0.0,
        STEP,
        z,
        np.zeros((N, N, 3)),
        np.ones((N, N), bool),
        np.zeros((N, N), bool),
        np.zeros((0, 3)),
        np.zeros((0, 3), int),
        True,
        blur_px=blur_px,
        jacobian=None if jacobian is None else np.asarray(jacobian, np.float64),
    )


def _profile(d: np.ndarray, sigma: float) -> np.ndarray:
    """A straight edge's coverage at signed distance ``d`` outside it, blurred by a Gaussian ``sigma``."""
    return np.array([0.5 * math.erfc(v / (sigma * math.sqrt(2.0))) for v in d])


def test_edge_profile_is_the_blurred_step():
    """Across each side of a large rectangle the coverage is the Gaussian-blurred step, with the side's own
    blur: ``blur_px |J e| / |det J|`` metres (a foreshortened ground: J = diag(800, 450) px/m)."""
    J = np.diag([800.0, 450.0])
    ev = _evidence(blur_px=1.2, jacobian=J)
    x0, x1, y0, y1 = 0.0503, 0.1707, 0.0611, 0.1809  # off the cell centres
    S = hull_coverage(ev, np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]))
    cols = STEP * np.arange(N)
    # the right side (along y, normal x): |J e| = 450, sigma = 1.2 * 450 / (800 * 450) = 1.2 / 800 m
    row = S[60, :]
    right = slice(int(x1 / STEP) - 4, int(x1 / STEP) + 5)
    assert np.allclose(row[right], _profile(cols[right] - x1, 1.2 / 800.0), atol=TOL.shadow_model_coverage)
    # the top side (along x, normal y): sigma = 1.2 / 450 m, wider: the ground is foreshortened across it
    col = S[:, 55]
    top = slice(int(y1 / STEP) - 4, int(y1 / STEP) + 5)
    assert np.allclose(col[top], _profile(cols[top] - y1, 1.2 / 450.0), atol=TOL.shadow_model_coverage)
    # inside and far outside
    assert S[60, 55] == pytest.approx(1.0, abs=1e-6) and S[5, 5] == 0.0


def test_unknown_blur_is_the_grid_floor():
    """Without a measured blur each edge gets MIN_EDGE_CELLS of a cell; a measured one under it is raised."""
    dirs = np.array([[1.0, 0.0], [0.6, 0.8]])
    assert np.allclose(edge_sigma(_evidence(), dirs), MIN_EDGE_CELLS * STEP)
    tiny = edge_sigma(_evidence(blur_px=0.01, jacobian=np.eye(2) * 500.0), dirs)
    assert np.allclose(tiny, MIN_EDGE_CELLS * STEP)
    iso = edge_sigma(_evidence(blur_px=2.0, jacobian=np.eye(2) * 500.0), dirs)
    assert np.allclose(iso, 2.0 / 500.0)


def test_coverage_moves_continuously_with_the_shadow():
    """Shifting a shadow by a hundredth of a cell changes an edge cell's coverage by the blurred step's slope
    times the shift, every time (the objective the light is fitted by has no steps: the old 4 x 4 raster
    stayed put, then jumped by a sixteenth); the summed coverage is the polygon's area in cells."""
    sigma = 0.6 / 600.0
    ev = _evidence(blur_px=0.6, jacobian=np.eye(2) * 600.0)
    rect = np.array([[0.0503, 0.06], [0.1501, 0.06], [0.1501, 0.19], [0.0503, 0.19]])
    cell = (60, 75)  # x = 0.150: 0.1 mm inside the right side
    prev = hull_coverage(ev, rect)[cell]
    for k in range(1, 11):
        dx = 0.01 * k * STEP
        now = hull_coverage(ev, rect + [dx, 0.0])[cell]
        d = STEP * cell[1] - (0.1501 + dx)
        slope = math.exp(-0.5 * (d / sigma) ** 2) / (sigma * math.sqrt(2 * math.pi))
        assert now - prev == pytest.approx(slope * 0.01 * STEP, rel=0.05), k
        prev = now
    tri = np.array([[0.05, 0.06], [0.17, 0.08], [0.09, 0.19]])
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    area = 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0]) / STEP**2
    assert float(hull_coverage(ev, tri).sum()) == pytest.approx(area, rel=TOL.shadow_model_area)


def test_ground_jacobian_is_the_homography_derivative():
    """``d(u, v) / d(x, y)`` of a pinhole (no distortion) against the derivative of its ground homography."""
    intr = Intrinsics(900.0, 880.0, 640.0, 360.0, 1280, 720)
    pose = look_at_pose([0.1, -0.4, 0.35], [0.0, 0.05, 0.0])
    K = np.array([[900.0, 0, 640.0], [0, 880.0, 360.0], [0, 0, 1]])
    H = K @ np.column_stack([pose[:3, 0], pose[:3, 1], pose[:3, 3]])
    x, y = 0.03, -0.02
    w = H @ [x, y, 1.0]
    # d(h12 / h3) = (d h12 * h3 - h12 * d h3) / h3^2
    J = np.column_stack([(H[:2, k] * w[2] - w[:2] * H[2, k]) / w[2] ** 2 for k in (0, 1)])
    assert np.allclose(ground_jacobian(intr, pose, (x, y)), J, rtol=1e-6)


def test_sample_blur_adds_the_pixel_and_the_resampling():
    assert sample_blur_px(0.0) == pytest.approx(0.5)
    assert sample_blur_px(1.0) == pytest.approx(math.sqrt(1.25))
    assert sample_blur_px(-3.0) == pytest.approx(0.5)  # a negative width is none
