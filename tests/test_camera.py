"""Camera model: files, validation, scaling, projection, exact undistortion, the OpenGL matrix."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from arshadow.camera.model import Intrinsics, distort_normalized, undistort_normalized
from arshadow.errors import CalibrationError
from arshadow.transforms import CV_TO_GL, matrix_from_rvec_tvec

ROOT = Path(__file__).resolve().parents[1]
SYNTH = ROOT / "calib" / "synth_1280x720.yml"
SYNTH_K1 = ROOT / "calib" / "synth_1280x720_k1.yml"

DISTS = {
    "none": np.zeros(0),
    "k5": np.array([-0.12, 0.05, 0.001, -0.0007, -0.01]),
    "k1": np.array([-0.25, 0.0, 0.0, 0.0, 0.0]),
    "rational8": np.array([0.3, -0.1, 0.001, 0.002, 0.01, 0.35, -0.05, 0.02]),
    "prism12": np.array([-0.1, 0.03, 0.001, -0.001, 0.0, 0.0, 0.0, 0.0, 0.002, -0.001, 0.001, 0.0005]),
    "tilt14": np.array([-0.1, 0.03, 0.001, -0.001, 0.0, 0.0, 0.0, 0.0, 0.002, -0.001, 0.001, 0.0005, 0.01, -0.02]),
}


def cam_with(dist) -> Intrinsics:
    return Intrinsics(1010.0, 995.0, 641.3, 358.2, 1280, 720, dist)


def random_cam_points(rng, n, cam: Intrinsics, margin=0.0):
    """Camera-frame points whose pinhole projections fall inside the image (+- margin px)."""
    u = rng.uniform(-margin, cam.width - 1 + margin, n)
    v = rng.uniform(-margin, cam.height - 1 + margin, n)
    z = rng.uniform(0.2, 20.0, n)
    return np.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z], axis=1)


# ---------------------------------------------------------------------------------------------------
# validation and files
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(fx=0.0), "focal"),
        (dict(fy=-5.0), "focal"),
        (dict(fx=float("nan")), "fx"),
        (dict(cx=float("inf")), "cx"),
        (dict(width=0), "width"),
        (dict(height=-3), "height"),
        (dict(dist=np.zeros(3)), "coefficients"),
        (dict(dist=np.array([0.1, np.nan, 0, 0])), "NaN"),
    ],
)
def test_validation(kwargs, word):
    args = dict(fx=1000.0, fy=1000.0, cx=640.0, cy=360.0, width=1280, height=720, dist=np.zeros(5))
    args.update(kwargs)
    with pytest.raises(CalibrationError, match=word):
        Intrinsics(**args)


def test_dist_is_read_only_copy():
    d = np.array([-0.1, 0.01, 0.0, 0.0])
    cam = cam_with(d)
    d[0] = 5.0
    assert cam.dist[0] == -0.1
    with pytest.raises(ValueError):
        cam.dist[0] = 1.0
    assert cam == cam_with(np.array([-0.1, 0.01, 0.0, 0.0]))
    assert hash(cam) == hash(cam_with(np.array([-0.1, 0.01, 0.0, 0.0])))


@pytest.mark.parametrize("ext", [".yml", ".xml", ".json"])
def test_file_round_trip(tmp_path, ext):
    cam = cam_with(DISTS["rational8"])
    p = cam.to_file(tmp_path / f"c{ext}", rms=0.25, per_view_errors=np.array([0.2, 0.3]), note="x")
    back = Intrinsics.from_file(p)
    assert back == cam
    fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    assert fs.getNode("rms").real() == 0.25
    assert fs.getNode("note").string() == "x"
    fs.release()
    assert not [f for f in tmp_path.iterdir() if f.name.startswith(".")]  # no temp file left


def test_shipped_calibrations():
    a = Intrinsics.from_file(SYNTH)
    assert (a.width, a.height) == (1280, 720)
    assert abs(a.fx - 1000) < 50 and abs(a.fy - 1000) < 50 and a.has_distortion
    assert np.max(np.abs(a.dist)) < 0.1
    b = Intrinsics.from_file(SYNTH_K1)
    assert b.dist[0] == -0.25 and (b.width, b.height) == (1280, 720)


def test_realdata_calibration_files(realdata):
    # left_intrinsics.yml uses plain {rows, cols, data} maps (no !!opencv-matrix tag)
    cam = Intrinsics.from_file(realdata / "chessboard_left" / "left_intrinsics.yml")
    assert cam.fx == pytest.approx(535.915733961632) and cam.cy == pytest.approx(235.57082909788173)
    assert cam.dist.size == 5 and cam.dist[0] == pytest.approx(-0.26637260909660682)
    cam2 = Intrinsics.from_file(realdata / "aruco_tutorial" / "tutorial_camera_charuco.yml")
    assert cam2.fy == pytest.approx(456.76707935146891) and cam2.size == (640, 480)


ROS_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [500.0, 0.0, 320.5, 0.0, 501.0, 240.5, 0.0, 0.0, 1.0]
distortion_model: {model}
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.1, 0.01, 0.001, 0.0, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
"""


def test_ros_camera_info(tmp_path):
    p = tmp_path / "ros.yaml"
    p.write_text(ROS_YAML.format(model="plumb_bob"))
    cam = Intrinsics.from_file(p)
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (500.0, 501.0, 320.5, 240.5, 640, 480)
    assert cam.dist.tolist() == [-0.1, 0.01, 0.001, 0.0, 0.0]
    p.write_text(ROS_YAML.format(model="equidistant"))
    with pytest.raises(CalibrationError, match="equidistant"):
        Intrinsics.from_file(p)


@pytest.mark.parametrize(
    "text, word",
    [
        ("%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n", "camera_matrix"),
        (
            "%YAML:1.0\n---\ncamera_matrix: {rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}\n"
            "image_height: 480\n",
            "image_width",
        ),
        (
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
            "camera_matrix: {rows: 3, cols: 3, data: [.nan, 0, 320, 0, 500, 240, 0, 0, 1]}\n",
            "NaN",
        ),
        (
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
            "camera_matrix: {rows: 3, cols: 3, data: [0, 0, 320, 0, 500, 240, 0, 0, 1]}\n",
            "positive",
        ),
        (
            "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
            "camera_matrix: {rows: 2, cols: 2, data: [1, 0, 0, 1]}\n",
            "3x3",
        ),
        (
            "%YAML:1.0\n---\nimage_width: -640\nimage_height: 480\n"
            "camera_matrix: {rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}\n",
            "image_width",
        ),
        ("this is: [not: valid yaml\n", "calib"),
    ],
)
def test_bad_calibration_files(tmp_path, text, word):
    p = tmp_path / "bad.yml"
    p.write_text(text)
    with pytest.raises(CalibrationError, match=word) as ei:
        Intrinsics.from_file(p)
    assert "bad.yml" in str(ei.value)


def test_missing_calibration_file(tmp_path):
    with pytest.raises(CalibrationError, match="no such"):
        Intrinsics.from_file(tmp_path / "nope.yml")


# ---------------------------------------------------------------------------------------------------
# scaling
# ---------------------------------------------------------------------------------------------------
def test_scaled_is_pixel_centre_exact(rng):
    cam = cam_with(DISTS["k5"])
    half = cam.scaled(640, 360)
    pts = random_cam_points(rng, 200, cam)
    uv = cam.project(pts)
    uv_half = half.project(pts)
    # a ray through full-res pixel u hits the half-res image at (u + 0.5) / 2 - 0.5
    assert np.allclose(uv_half, (uv + 0.5) / 2.0 - 0.5, atol=1e-9)


def test_for_image():
    cam = cam_with(DISTS["k5"])
    same, scaled = cam.for_image(1280, 720)
    assert same is cam and not scaled
    big, scaled = cam.for_image(1920, 1080)
    assert scaled and big.size == (1920, 1080) and big.fx == pytest.approx(1.5 * cam.fx)
    with pytest.raises(CalibrationError, match="640x480"):
        cam.for_image(640, 480)


# ---------------------------------------------------------------------------------------------------
# projection and distortion
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(DISTS))
def test_project_matches_opencv(rng, tol, name):
    cam = cam_with(DISTS[name])
    rvec, tvec = rng.normal(size=3) * 0.3, np.array([0.05, -0.02, 1.5])
    pose = matrix_from_rvec_tvec(rvec, tvec)
    pts = rng.uniform(-0.4, 0.4, (300, 3))
    ours = cam.project(pts, pose)
    ref = cv2.projectPoints(pts, rvec, tvec, cam.K, cam.dist_cv)[0].reshape(-1, 2)
    assert np.max(np.abs(ours - ref)) < tol.project_vs_opencv_px
    pin = cam.project(pts, pose, distort=False)
    ref0 = cv2.projectPoints(pts, rvec, tvec, cam.K, None)[0].reshape(-1, 2)
    assert np.max(np.abs(pin - ref0)) < tol.project_vs_opencv_px


def test_project_behind_camera_is_nan():
    cam = cam_with(DISTS["k5"])
    uv = cam.project([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0], [0.1, 0.0, 1.0]])
    assert np.isnan(uv[:2]).all() and np.isfinite(uv[2]).all()


@pytest.mark.parametrize("name", list(DISTS))
def test_undistort_pixels_round_trip(rng, tol, name):
    cam = cam_with(DISTS[name])
    # every pixel of the image plus a margin, and a random set
    grid = cam.pixel_grid()[::37]
    uv = np.concatenate([grid, rng.uniform([-0.5, -0.5], [cam.width - 0.5, cam.height - 0.5], (2000, 2))])
    pin = cam.undistort_pixels(uv)
    assert np.isfinite(pin).all()
    assert np.max(np.abs(cam.distort_pixels(pin) - uv)) < tol.undistort_px
    # and from the other side: project(distort=True) of a 3D point, undistorted, is project(distort=False)
    pts = random_cam_points(rng, 500, cam)
    d = cam.project(pts)
    inside = (d[:, 0] > -0.5) & (d[:, 0] < cam.width) & (d[:, 1] > -0.5) & (d[:, 1] < cam.height)
    assert np.max(np.abs(cam.undistort_pixels(d[inside]) - cam.project(pts[inside], distort=False))) < tol.undistort_px


def test_undistort_beats_opencv_default(tol):
    """OpenCV's undistortPoints stops after 5 iterations; ours is exact where theirs is not."""
    cam = Intrinsics.from_file(SYNTH_K1)
    corners = np.array([[0.0, 0.0], [1279.0, 0.0], [1279.0, 719.0], [0.0, 719.0]])
    ours = cam.undistort_pixels(corners)
    cv5 = cv2.undistortPoints(corners.reshape(-1, 1, 2), cam.K, cam.dist_cv, P=cam.K).reshape(-1, 2)
    assert np.max(np.abs(cam.distort_pixels(ours) - corners)) < tol.undistort_px
    assert np.max(np.abs(cam.distort_pixels(cv5) - corners)) > 1e-3


def test_undistort_full_map_k1(tol):
    cam = Intrinsics.from_file(SYNTH_K1)
    grid = cam.pixel_grid()
    pin = cam.undistort_pixels(grid)
    assert pin.shape == grid.shape and np.isfinite(pin).all()
    assert np.max(np.abs(cam.distort_pixels(pin) - grid)) < tol.undistort_px
    # barrel distortion: the image corners come from far outside the pinhole image
    assert pin[0, 0] < -100 and pin[-1, 0] > cam.width + 100


def test_undistort_beyond_fold_is_nan():
    # k1 = -0.5: x_d = x (1 - 0.5 r^2) peaks at x = sqrt(2/3) (x_d = 0.544); beyond it there is no inverse
    out = undistort_normalized([[0.7, 0.0], [0.3, 0.0]], [-0.5, 0.0, 0.0, 0.0])
    assert np.isnan(out[0]).all()
    assert distort_normalized(out[1:], [-0.5, 0, 0, 0])[0, 0] == pytest.approx(0.3, abs=1e-12)


def test_inputs_not_modified():
    cam = cam_with(DISTS["k5"])
    uv = np.array([[10.0, 20.0], [30.0, 40.0]])
    keep = uv.copy()
    cam.undistort_pixels(uv)
    cam.distort_pixels(uv)
    assert np.array_equal(uv, keep)


# ---------------------------------------------------------------------------------------------------
# OpenGL projection
# ---------------------------------------------------------------------------------------------------
def gl_pixels(P, pts_cam, w, h):
    """Clip -> NDC -> window (pixel-centre) coordinates, the way the GL rasteriser does it."""
    eye = np.c_[pts_cam, np.ones(len(pts_cam))] @ CV_TO_GL.T
    clip = eye @ P.T
    ndc = clip[:, :3] / clip[:, 3:4]
    # glViewport(0, 0, w, h): x_win = (x_ndc + 1) w / 2 with the bottom-left *corner* at 0
    x_win = (ndc[:, 0] + 1.0) * w / 2.0
    y_win = (ndc[:, 1] + 1.0) * h / 2.0
    u = x_win - 0.5
    v = (h - y_win) - 0.5
    return np.stack([u, v], axis=1), ndc[:, 2], clip[:, 3]


@pytest.mark.parametrize(
    "canvas", [None, (0, 0, 1280, 720), (-150, -90, 1580, 900), (400, 200, 128, 64), (1300, 800, 50, 30)]
)
@pytest.mark.parametrize("zfar", [50.0, None])
def test_gl_projection_pixel_exact(rng, tol, canvas, zfar):
    cam = cam_with(DISTS["k5"])
    P = cam.gl_projection(0.05, zfar, canvas=canvas)
    u0, v0, w, h = canvas if canvas is not None else (0, 0, cam.width, cam.height)
    pts = random_cam_points(rng, 500, cam, margin=300)
    pts[:, 2] = np.clip(pts[:, 2], 0.06, 49.0)
    uv, depth, wclip = gl_pixels(P, pts, w, h)
    ref = cam.project(pts, distort=False) - np.array([u0, v0])
    assert np.max(np.abs(uv - ref)) < tol.gl_projection_px
    assert (wclip > 0).all() and (depth > -1).all() and (depth < 1).all()
    # the stated formula literally
    x_ndc = 2 * (ref[:, 0] + 0.5) / w - 1
    y_ndc = 1 - 2 * (ref[:, 1] + 0.5) / h
    eye = np.c_[pts, np.ones(len(pts))] @ CV_TO_GL.T @ P.T
    assert np.allclose(eye[:, 0] / eye[:, 3], x_ndc, atol=1e-10)
    assert np.allclose(eye[:, 1] / eye[:, 3], y_ndc, atol=1e-10)


def test_gl_projection_depth_range():
    cam = cam_with(DISTS["none"])
    n, f = 0.1, 20.0
    P = cam.gl_projection(n, f)
    _, depth, _ = gl_pixels(P, np.array([[0.0, 0.0, n], [0.0, 0.0, f], [0.3, 0.1, 5.0]]), 1280, 720)
    assert depth[0] == pytest.approx(-1.0) and depth[1] == pytest.approx(1.0) and -1 < depth[2] < 1
    Pinf = cam.gl_projection(n, None)
    far = np.array([[0.0, 0.0, n], [1.0, -2.0, 1e3], [5.0, 3.0, 1e9], [0.0, 0.0, 1e15]])
    _, d, w = gl_pixels(Pinf, far, 1280, 720)
    assert d[0] == pytest.approx(-1.0)
    assert (w > 0).all() and (d >= -1).all() and (d <= 1).all()
    assert np.all(np.diff(d) > 0) or np.all(np.diff(d[:3]) > 0)  # monotone in distance
    # a direction (w = 0 in the world) goes exactly to the far plane
    clip = Pinf @ np.array([0.1, -0.2, -1.0, 0.0])
    assert clip[2] / clip[3] == pytest.approx(1.0) and clip[3] > 0


@pytest.mark.parametrize(
    "bad", [dict(znear=0.0), dict(znear=-1.0), dict(znear=1.0, zfar=0.5), dict(znear=0.1, canvas=(0, 0, 0, 10))]
)
def test_gl_projection_bad_args(bad):
    with pytest.raises(CalibrationError):
        cam_with(DISTS["none"]).gl_projection(**bad)


def test_gl_fov_sanity():
    """fx = 1000 at 1280 px: horizontal field of view 2 atan(640 / 1000) = 65.2 deg."""
    cam = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    P = cam.gl_projection(0.1)
    assert math.degrees(2 * math.atan(1 / P[0, 0])) == pytest.approx(math.degrees(2 * math.atan(0.64)))
    assert P[0, 2] == pytest.approx(0.0) and P[1, 2] == pytest.approx(0.0)
