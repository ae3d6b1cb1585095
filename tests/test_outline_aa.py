"""The object's anti-aliased outline without MSAA (:mod:`arshadow.compose.outline`), without GL.

The truth is computed here, independently: a pixel's exact coverage is the area of its square clipped by the
polygon (Sutherland-Hodgman, then the shoelace formula); the composite's blend is written out with the sRGB
formulas.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import TOL


def clip_area(square: np.ndarray, polygon: np.ndarray) -> float:
    """Area of the convex ``square`` (k, 2) clipped by the counter-clockwise convex ``polygon`` (m, 2)."""
    pts = [tuple(p) for p in square]
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        side = [(b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) for p in pts]
        out = []
        for i, p in enumerate(pts):
            q, sp, sq = pts[i - 1], side[i], side[i - 1]
            if (sp >= 0) != (sq >= 0):
                f = sq / (sq - sp)
                out.append((q[0] + f * (p[0] - q[0]), q[1] + f * (p[1] - q[1])))
            if sp >= 0:
                out.append(p)
        pts = out
        if not pts:
            return 0.0
    return shoelace(np.array(pts))


def shoelace(p: np.ndarray) -> float:
    """The area of the polygon ``p`` (k, 2)."""
    x, y = p[:, 0], p[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def pixel_square(x: float, y: float) -> np.ndarray:
    """The unit square centred on ``(x, y)``, counter-clockwise."""
    return np.array([(x - 0.5, y - 0.5), (x + 0.5, y - 0.5), (x + 0.5, y + 0.5), (x - 0.5, y + 0.5)])


def test_box_coverage_is_the_clipped_squares_area():
    from arshadow.compose.outline import box_coverage

    rng = np.random.default_rng(3)
    theta, t = rng.uniform(0, 2 * np.pi, 400), rng.uniform(-0.9, 0.9, 400)
    theta[:8] = np.arange(8) * np.pi / 4  # axis-aligned and diagonal normals
    nx, ny = np.cos(theta), np.sin(theta)
    got = box_coverage(t, nx, ny)
    for i in range(len(t)):  # the half-plane n.u <= t as a huge counter-clockwise polygon
        p0 = np.array([nx[i], ny[i]]) * t[i]
        d = np.array([-ny[i], nx[i]]) * 10.0  # along the line: the half-plane (towards -n) on its left
        far = -np.array([nx[i], ny[i]]) * 10.0
        half = np.array([p0 - d, p0 + d, p0 + d + far, p0 - d + far])  # counter-clockwise
        assert got[i] == pytest.approx(clip_area(pixel_square(0.0, 0.0), half), abs=TOL.outline_exact)


def _pentagon() -> np.ndarray:
    a = np.deg2rad(np.arange(5) * 72.0 + 13.0)
    return np.c_[20.3 + 12.7 * np.cos(a), 19.6 + 11.9 * np.sin(a)]  # counter-clockwise


def _centre_sampled(poly: np.ndarray, n: int = 40) -> np.ndarray:
    """(n, n) bool: the pixel centres ``(j + 0.5, i + 0.5)`` inside the convex counter-clockwise ``poly``."""
    y, x = np.mgrid[0:n, 0:n] + 0.5
    inside = np.ones((n, n), bool)
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        inside &= (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]) >= 0
    return inside


def _layers(on: np.ndarray, colour=(0.6, 0.3, 0.1), ground=(0.5, 1.0, 0.25)):
    rgba = np.zeros(on.shape + (4,), np.float32)
    rgba[on] = (*colour, 1.0)
    g = np.zeros(on.shape + (3,), np.float32)
    g[~on] = ground
    return rgba, g


def test_a_polygons_outline_gets_its_exact_coverage_and_the_layers_the_blend():
    from arshadow.compose.outline import antialias_outline

    poly = _pentagon()
    on = _centre_sampled(poly)
    rgba, ground = _layers(on)
    seg = np.stack([poly, np.roll(poly, -1, axis=0)], axis=1)
    assert antialias_outline(rgba, ground, seg) > 0
    area = shoelace(poly)
    alpha = rgba[:, :, 3]
    assert abs(float(alpha.sum()) - area) < TOL.outline_area_px2
    assert abs(float(on.sum()) - area) > abs(float(alpha.sum()) - area)  # pixel centres alias
    exact = np.array([[clip_area(pixel_square(j + 0.5, i + 0.5), poly) for j in range(40)] for i in range(40)])
    edge = (exact > 0) & (exact < 1)
    assert float(np.abs(alpha - exact)[edge].mean()) < TOL.outline_edge_mean
    assert float(np.abs(on - exact)[edge].mean()) > 10 * TOL.outline_edge_mean
    # a pixel one edge crosses, away from the corners: the half-plane's exact coverage
    corner_d = np.min(np.hypot(*(np.mgrid[0:40, 0:40][::-1, :, :, None] + 0.5 - poly.T[:, None, None, :])), axis=-1)
    single = edge & (corner_d > 1.5)
    assert single.sum() > 40
    np.testing.assert_allclose(alpha[single], exact[single], atol=TOL.outline_exact)
    # the layers there: coverage x the object's colour, (1 - coverage) x the ground's values
    np.testing.assert_allclose(rgba[edge, :3], alpha[edge, None] * np.float32([0.6, 0.3, 0.1]), atol=1e-6)
    np.testing.assert_allclose(ground[edge], (1 - alpha[edge, None]) * np.float32([0.5, 1.0, 0.25]), atol=1e-6)
    assert np.array_equal(alpha[~edge], exact[~edge])  # the rest as the pixel centres had it


def _srgb_to_linear(c):
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _linear_to_srgb8(x):
    x = np.clip(x, 0.0, 1.0)
    return np.round(255.0 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055))


def test_the_composite_at_the_outline_is_the_coverage_blend_written_out():
    from arshadow.compose.composite import Overlay, composite
    from arshadow.compose.look import Look
    from arshadow.compose.outline import antialias_outline

    poly = _pentagon()
    on = _centre_sampled(poly)
    rgba, ground = _layers(on, colour=(0.6, 0.3, 0.1), ground=(0.5, 1.0, 0.0))
    seg = np.stack([poly, np.roll(poly, -1, axis=0)], axis=1)
    antialias_outline(rgba, ground, seg)
    photo = np.full((40, 40, 3), 128, np.uint8)
    out = composite(
        photo,
        Overlay(ground[:, :, 0].copy(), rgba[:, :, :3].copy(), rgba[:, :, 3].copy()),
        (0, 0, 40, 40),
        look=Look(opacity=0.7, shadow_color=(0.0, 0.0, 0.0)),
    )
    exact = np.array([[clip_area(pixel_square(j + 0.5, i + 0.5), poly) for j in range(40)] for i in range(40)])
    edge = (exact > 0.02) & (exact < 0.98)
    cov = rgba[:, :, 3][edge].astype(np.float64)[:, None]
    plate = _srgb_to_linear(128.0)
    shadowed = plate * (1 - 0.7 * 0.5)  # the ground beside the object: half its light blocked
    want = _linear_to_srgb8(cov * np.array([0.6, 0.3, 0.1]) + (1 - cov) * shadowed)  # the object's colour is RGB
    got = out[edge][:, ::-1].astype(np.float64)  # BGR -> RGB
    assert np.abs(got - want).max() <= 1


def test_a_camera_inside_the_object_sees_no_outline():
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.contour import outline_segments
    from arshadow.geometry.mesh import load_occluder
    from arshadow.transforms import CV_TO_GL

    K = Intrinsics(100.0, 100.0, 31.5, 31.5, 64, 64)
    cam = np.eye(4)
    cam[2, 3] = -0.1  # the camera at z = 0.1, inside the 0.2 m box
    seg = outline_segments(load_occluder("box:0.2,0.2,0.2"), K.gl_projection(0.01, None), CV_TO_GL @ cam, 64, 64)
    assert seg.shape == (0, 2, 2)


def test_an_object_a_pixel_across_or_a_point_contour_changes_nothing_and_does_not_fail():
    """A user report's 50 m marker put the object a pixel or two across: no contour segment crosses a band
    pixel (and a contour of points only has no segment at all); the layers stay as rendered."""
    from arshadow.compose.outline import antialias_outline

    rgba = np.zeros((8, 8, 4), np.float32)
    rgba[4, 4] = (0.5, 0.5, 0.5, 1.0)  # one pixel's centre on the object
    ground = np.ones((8, 8, 1), np.float32)
    ground[4, 4] = 0.0
    before = rgba.copy(), ground.copy()
    far = np.array([[[0.2, 0.2], [0.3, 0.2]]])  # a segment nowhere near it
    points = np.array([[[4.5, 4.5], [4.5, 4.5]]])  # zero length
    for seg in (far, points):
        assert antialias_outline(rgba, ground, seg) == 0
        assert np.array_equal(rgba, before[0]) and np.array_equal(ground, before[1])
