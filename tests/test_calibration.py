"""Calibration: reproduce OpenCV's own calibration of its chessboard set; patterns; view rejection."""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest
from conftest import TOL

from arshadow.camera.model import Intrinsics
from arshadow.errors import CalibrationError, UsageError
from arshadow.synth.markers import random_pose, render_marker_photo
from arshadow.tracking.board import Board
from arshadow.tracking.calibration import MIN_VIEWS, calibrate, find_view, parse_pattern


@pytest.mark.parametrize(
    "spec, kind", [("chessboard:9,6,0.025", "chessboard"), ("charuco:5,7,0.04,0.02,DICT_6X6_250", "charuco")]
)
def test_parse_pattern(spec, kind):
    p = parse_pattern(spec)
    assert p.kind == kind and p.spec == spec


@pytest.mark.parametrize(
    "spec, word",
    [
        ("chessboard:9,6", "bad pattern"),
        ("circles:4,11,0.02", "bad pattern"),
        ("chessboard:9,6,-1", "positive"),
        ("charuco:5,7,0.04,0.05,DICT_6X6_250", "smaller"),
        ("charuco:5,7,0.04,0.02,DICT_NOPE", "unknown dictionary"),
        ("chessboard:1,6,0.02", "2x2"),
    ],
)
def test_bad_patterns(spec, word):
    with pytest.raises(UsageError, match=word):
        parse_pattern(spec)


@pytest.mark.realdata
def test_reproduces_opencv_left_calibration(realdata, tol):
    """Same views (left10 excluded) and flags (CALIB_FIX_ASPECT_RATIO) as left_intrinsics.yml."""
    ref = Intrinsics.from_file(realdata / "chessboard_left" / "left_intrinsics.yml")
    files = sorted(f for f in (realdata / "chessboard_left").glob("left*.jpg") if f.name != "left10.jpg")
    p = parse_pattern("chessboard:9,6,0.025")
    res = calibrate([find_view(f, p) for f in files], flags=cv2.CALIB_FIX_ASPECT_RATIO, pattern=p)
    k = res.intrinsics
    assert len(res.views) == 13 and not res.rejected
    assert abs(k.fx / ref.fx - 1) <= tol.calib_focal_rel and abs(k.fy / ref.fy - 1) <= tol.calib_focal_rel
    assert abs(k.cx - ref.cx) <= tol.calib_center_px and abs(k.cy - ref.cy) <= tol.calib_center_px
    assert res.rms <= tol.calib_rms_px
    assert res.per_view_errors.shape == (13,)


@pytest.mark.realdata
def test_per_view_poses_match_reference(realdata, tol):
    """The board pose of every view agrees with OpenCV's reference calibration (expected.json)."""
    import json

    from arshadow.transforms import rotation_error_deg

    exp = json.loads((realdata / "expected.json").read_text())
    files = sorted(f for f in (realdata / "chessboard_left").glob("left*.jpg") if f.name != "left10.jpg")
    p = parse_pattern("chessboard:9,6,0.025")
    res = calibrate([find_view(f, p) for f in files], flags=cv2.CALIB_FIX_ASPECT_RATIO, pattern=p)
    for v, r, t in zip(res.views, res.rvecs, res.tvecs, strict=True):
        truth = exp[f"chessboard_left/{v.path.rsplit('/', 1)[-1]}"]["pose_ground_truth"]
        assert rotation_error_deg(r, np.array(truth["board_in_camera_rvec"])) < tol.calib_extrinsic_rot_deg
        assert 1000 * np.linalg.norm(t - np.array(truth["board_in_camera_tvec_m"])) < tol.calib_extrinsic_mm


@pytest.mark.realdata
def test_calibration_file_written(realdata, tmp_path):
    files = sorted((realdata / "chessboard_left").glob("left*.jpg"))[:6]
    p = parse_pattern("chessboard:9,6,0.025")
    res = calibrate([find_view(f, p) for f in files], pattern=p)
    out = res.to_file(tmp_path / "c.yml")
    back = Intrinsics.from_file(out)
    assert back == res.intrinsics
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    assert fs.getNode("avg_reprojection_error").real() == pytest.approx(res.rms)
    assert fs.getNode("per_view_reprojection_errors").mat().shape == (6, 1)
    assert fs.getNode("views").size() == 6
    fs.release()


@pytest.mark.realdata
def test_rejects_views_and_needs_enough(tmp_path, realdata):
    p = parse_pattern("chessboard:9,6,0.025")
    bad = tmp_path / "corrupt.jpg"
    bad.write_bytes(b"not a jpeg")
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640, 3), 200, np.uint8))
    small = tmp_path / "small.png"
    shutil.copy(realdata / "chessboard_left" / "left01.jpg", tmp_path / "l1.jpg")
    cv2.imwrite(str(small), cv2.resize(cv2.imread(str(tmp_path / "l1.jpg")), (320, 240)))
    views = [find_view(f, p) for f in (bad, blank, tmp_path / "nope.jpg")]
    assert not any(v.ok for v in views)
    assert "cannot decode" in views[0].reason and "no 9x6 chessboard" in views[1].reason
    assert "no such image" in views[2].reason
    good = [find_view(f, p) for f in sorted((realdata / "chessboard_left").glob("left0[1-4].jpg"))]
    with pytest.raises(CalibrationError, match=f"only 4 usable view\\(s\\), need at least {MIN_VIEWS}"):
        calibrate(views + good, pattern=p)
    more = good + [find_view(f, p) for f in sorted((realdata / "chessboard_left").glob("left0[5-6].jpg"))]
    res = calibrate(views + more + [find_view(small, p)], pattern=p)
    assert len(res.views) == 6 and len(res.rejected) == 4
    assert any("differs from the first view" in v.reason for v in res.rejected)


@pytest.mark.realdata
def test_max_view_error_rejects_outliers(realdata):
    p = parse_pattern("chessboard:9,6,0.025")
    views = [find_view(f, p) for f in sorted((realdata / "chessboard_left").glob("left*.jpg"))]
    res = calibrate(views, pattern=p, max_view_error=0.8)
    assert any("left02" in v.path and "reprojection error" in v.reason for v in res.rejected)
    assert res.per_view_errors.max() <= 0.8


def test_charuco_calibration_synthetic():
    """ChArUco calibration on synthetic photos recovers the generating camera."""
    cam = Intrinsics(900.0, 905.0, 645.0, 355.0, 1280, 720, np.array([-0.12, 0.05, 0.0, 0.0, 0.0]))
    board = Board("charuco", (5, 7), 0.02, square_length=0.04)
    p = parse_pattern("charuco:5,7,0.04,0.02,DICT_6X6_250")
    rng = np.random.default_rng(3)
    bw, bh = board.extent
    centre = np.array([bw / 2, -bh / 2, 0.0])
    paper = np.array([[0, 0, 0], [bw, 0, 0], [bw, -bh, 0], [0, -bh, 0.0]])
    views = []
    for i in range(10):
        pose = random_pose(rng, cam, distance=(0.35, 0.6), tilt_deg=(15, 50), keep_in_view=paper, target=centre)
        photo = render_marker_photo(cam, pose, board=board, noise_sigma=1.0, blur_sigma=0.5, seed=i)
        views.append(find_view(f"synth{i}", p, image=photo.image))
    res = calibrate(views, pattern=p)
    k = res.intrinsics
    assert len(res.views) >= 8 and res.rms < TOL.synth_calib_rms_px
    assert abs(k.fx / cam.fx - 1) < TOL.synth_calib_focal_rel and abs(k.fy / cam.fy - 1) < TOL.synth_calib_focal_rel
    assert abs(k.cx - cam.cx) < TOL.synth_calib_center_px and abs(k.cy - cam.cy) < TOL.synth_calib_center_px


@pytest.mark.realdata
def test_find_view_takes_any_image_layout(realdata):
    """``image=`` may be 16-bit or BGRA, like the photos `arshadow render` accepts."""
    p = parse_pattern("chessboard:9,6,0.025")
    bgr = cv2.imread(str(realdata / "chessboard_left" / "left01.jpg"))
    ref = find_view("left01", p, image=bgr)
    gray16 = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.uint16) * 257
    bgra = cv2.cvtColor(bgr, cv2.COLOR_BGR2BGRA)
    for img in (gray16, bgra):
        v = find_view("left01", p, image=img)
        assert v.ok, v.reason
        assert np.abs(v.image_points - ref.image_points).max() < TOL.corner_px
