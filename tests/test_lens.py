"""The pinhole -> distorted warp, checked against OpenCV's forward distortion model (cv2.projectPoints)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from conftest import TOL

from arshadow.camera.model import Intrinsics
from arshadow.compose.lens import LensWarp, undistort_map


def _cam(dist):
    return Intrinsics(1000.0, 1000.0, 641.3, 358.2, 1280, 720, np.asarray(dist, dtype=np.float64))


def _cv_distort(cam, uv_pinhole):
    """Independent forward model: OpenCV projects the pinhole ray through its distortion."""
    xy = np.column_stack([(uv_pinhole[:, 0] - cam.cx) / cam.fx, (uv_pinhole[:, 1] - cam.cy) / cam.fy])
    pts = np.column_stack([xy, np.ones(len(xy))]).reshape(-1, 1, 3)
    out, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, cam.dist)
    return out.reshape(-1, 2)


K1 = (-0.25, 0.0, 0.0, 0.0, 0.0)
MIXED = (-0.045, 0.021, 0.0004, -0.0003, -0.006)


@pytest.fixture(scope="module")
def warp_k1():
    return LensWarp(_cam(K1))


@pytest.mark.parametrize("dist", [K1, MIXED])
def test_map_is_the_exact_inverse_of_opencv_distortion(dist, rng):
    cam = _cam(dist)
    mx, my = undistort_map(cam)
    assert mx.shape == (720, 1280) and mx.dtype == np.float32
    v = rng.integers(0, 720, 3000)
    u = rng.integers(0, 1280, 3000)
    back = _cv_distort(cam, np.column_stack([mx[v, u], my[v, u]]).astype(np.float64))
    # float32 storage of ~1500-px coordinates: 1e-4 px resolution
    assert np.max(np.abs(back - np.column_stack([u, v]))) < TOL.lens_map_px


def test_distorted_roi_is_conservative(warp_k1, rng):
    mx, my = warp_k1.maps
    for _ in range(40):
        a = rng.uniform(-250, 1500, 2)
        b = rng.uniform(-200, 900, 2)
        rect = (min(a), min(b), max(a), max(b))
        x0, y0, w, h = warp_k1.distorted_roi(rect)
        inside = (mx >= rect[0]) & (mx <= rect[2]) & (my >= rect[1]) & (my <= rect[3])
        ys, xs = np.nonzero(inside)
        if ys.size == 0:
            continue
        assert xs.min() >= x0 and xs.max() < x0 + w and ys.min() >= y0 and ys.max() < y0 + h
        # and not grossly larger than needed (two 8-px cells and the slack on each side)
        assert (
            w <= xs.max() - xs.min() + 1 + TOL.lens_roi_slack_px
            and h <= ys.max() - ys.min() + 1 + TOL.lens_roi_slack_px
        )


def test_canvas_covers_the_roi_and_warp_reproduces_linear_functions(warp_k1):
    roi = (900, 40, 300, 250)  # near a corner, where k1 = -0.25 bends most
    canvas = warp_k1.canvas_for(roi)
    u0, v0, cw, ch = canvas
    mx, my = warp_k1.maps
    sx, sy = mx[40:290, 900:1200], my[40:290, 900:1200]
    assert sx.min() >= u0 and sx.max() <= u0 + cw - 1 and sy.min() >= v0 and sy.max() <= v0 + ch - 1
    # a linear function of the pinhole pixel is reproduced exactly by bilinear sampling
    uu, vv = np.meshgrid(np.arange(u0, u0 + cw, dtype=np.float32), np.arange(v0, v0 + ch, dtype=np.float32))
    f = (0.01 * uu - 0.02 * vv + 3.0).astype(np.float32)
    g = np.dstack([uu, vv, np.ones_like(uu)]).astype(np.float32)
    wf, wg = warp_k1.warp(roi, canvas, f, g)
    assert wf.shape == (250, 300) and wg.shape == (250, 300, 3)
    ref = 0.01 * sx - 0.02 * sy + 3.0
    # cv2.remap quantises coordinates to 1/32 px
    assert np.max(np.abs(wf - ref)) < 0.02 * TOL.remap_step_px + 1e-3
    assert np.max(np.abs(wg[..., 0] - sx)) <= TOL.remap_step_px + 1e-3
    assert np.max(np.abs(wg[..., 1] - sy)) <= TOL.remap_step_px + 1e-3


def test_warped_disk_lands_where_the_distorted_camera_sees_it(warp_k1):
    """A disk drawn in pinhole space, warped, equals the disk tested per distorted pixel via OpenCV."""
    cam = warp_k1.intrinsics
    centre, radius = np.array([1100.0, 150.0]), 60.0
    # the pinhole canvas around the disk, drawn with 8x supersampling (coverage)
    rect = (centre[0] - radius, centre[1] - radius, centre[0] + radius, centre[1] + radius)
    roi = warp_k1.distorted_roi(rect)
    canvas = warp_k1.canvas_for(roi, rect)
    u0, v0, cw, ch = canvas
    s = 8
    uu, vv = np.meshgrid(u0 + (np.arange(cw * s) + 0.5) / s - 0.5, v0 + (np.arange(ch * s) + 0.5) / s - 0.5)
    cover = (((uu - centre[0]) ** 2 + (vv - centre[1]) ** 2) <= radius**2).reshape(ch, s, cw, s).mean(axis=(1, 3))
    (warped,) = warp_k1.warp(roi, canvas, cover.astype(np.float32))
    # oracle: each distorted pixel centre undistorted by OpenCV (iterated to convergence)
    x0, y0, w, h = roi
    pu, pv = np.meshgrid(np.arange(x0, x0 + w, dtype=np.float64), np.arange(y0, y0 + h, dtype=np.float64))
    pts = np.column_stack([pu.ravel(), pv.ravel()]).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    und = cv2.undistortPoints(pts, cam.K, cam.dist, None, cam.K, criteria=crit).reshape(h, w, 2)
    inside = ((und[..., 0] - centre[0]) ** 2 + (und[..., 1] - centre[1]) ** 2) <= radius**2
    got = warped >= 0.5
    iou = np.sum(got & inside) / np.sum(got | inside)
    assert inside.sum() > 5000
    assert iou > TOL.lens_warp_disk_iou
    # and the whole disk is inside the ROI (nothing cut off)
    full_x, full_y = warp_k1.maps
    all_inside = ((full_x - centre[0]) ** 2 + (full_y - centre[1]) ** 2) <= radius**2
    assert all_inside.sum() == inside.sum()


def test_pinhole_extent_exceeds_the_image_for_barrel_distortion(warp_k1):
    u0, v0, u1, v1 = warp_k1.pinhole_extent
    assert u0 < -50 and v0 < -20 and u1 > 1330 and v1 > 740
