"""Command line: ``arshadow pose``, ``calibrate``, ``marker``, ``board`` -- output, exit codes, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import TOL

from arshadow.camera.model import Intrinsics
from arshadow.cli import main
from arshadow.cli.marker import read_png_dpi
from arshadow.synth.markers import look_at_pose, render_marker_photo
from arshadow.transforms import rotation_error_deg

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_1280x720.yml"
CAM = Intrinsics.from_file(CALIB)
REPORT_KEYS = {
    "input",
    "output",
    "mask",
    "status",
    "error",
    "marker_ids",
    "rvec",
    "tvec",
    "reprojection_error_px",
    "pose_ambiguity",
    "mode",
    "silhouette_edges",
    "timings_ms",
}


@pytest.fixture(scope="module")
def photos(tmp_path_factory):
    d = tmp_path_factory.mktemp("photos")
    pose = look_at_pose([0.12, -0.25, 0.4], [0, 0, 0])
    ph = render_marker_photo(CAM, pose, marker_id=7, marker_length=0.05, noise_sigma=1, seed=1)
    cv2.imwrite(str(d / "good.png"), ph.image)
    cv2.imwrite(str(d / "half.png"), cv2.resize(ph.image, (640, 360), interpolation=cv2.INTER_AREA))
    cv2.imwrite(str(d / "blank.png"), np.full((720, 1280, 3), 120, np.uint8))
    cv2.imwrite(str(d / "square.png"), ph.image[:, :720])
    (d / "corrupt.jpg").write_bytes(b"\xff\xd8\xff garbage")
    return d, ph


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# ---------------------------------------------------------------------------------------------------
# pose
# ---------------------------------------------------------------------------------------------------
def test_pose_json_report(capsys, photos):
    d, ph = photos
    code, out, err = run(capsys, "pose", d / "good.png", "--calib", CALIB, "--marker-length", 0.05, "--json")
    assert code == 0 and err == ""
    rep = json.loads(out)
    assert rep["arshadow"] and len(rep["images"]) == 1
    item = rep["images"][0]
    assert REPORT_KEYS <= set(item)
    assert item["status"] == "ok" and item["marker_ids"] == [7] and item["error"] is None
    assert rotation_error_deg(np.array(item["rvec"]), ph.cam_from_world[:3, :3]) < TOL.cli_pose_rot_deg
    assert np.linalg.norm(np.array(item["tvec"]) - ph.cam_from_world[:3, 3]) < TOL.cli_pose_trans_m
    assert 0 < item["pose_ambiguity"] <= 1 and item["reprojection_error_px"] < 1
    assert "total" in item["timings_ms"]


def test_pose_text_and_overlay_and_report(capsys, photos, tmp_path):
    d, _ = photos
    code, out, err = run(
        capsys,
        "pose",
        d / "good.png",
        d / "half.png",
        "--calib",
        CALIB,
        "--marker-length",
        0.05,
        "--overlay",
        tmp_path / "ov",
        "--report",
        tmp_path / "r.json",
        "--refine",
        "contour",
    )
    assert code == 0
    assert "good.png: ids [7] rvec [" in out and "reprojection" in out and "ambiguity" in out
    assert "calibration scaled to 640x360" in out
    assert (tmp_path / "ov" / "good.png").is_file() and cv2.imread(str(tmp_path / "ov" / "half.png")).shape == (
        360,
        640,
        3,
    )
    rep = json.loads((tmp_path / "r.json").read_text())
    assert [i["status"] for i in rep["images"]] == ["ok", "ok"]
    assert rep["images"][1]["calibration_scaled"] is True


def test_pose_bad_inputs_continue(capsys, photos):
    """Each failing input: one line naming it, status in the report; the others still processed; exit 1."""
    d, _ = photos
    inputs = [d / "corrupt.jpg", d / "blank.png", d / "good.png", d / "missing.png", d / "square.png"]
    code, out, err = run(capsys, "pose", *inputs, "--calib", CALIB, "--marker-length", 0.05, "--json")
    assert code == 1
    items = json.loads(out)["images"]
    assert [i["status"] for i in items] == ["error", "no_marker", "ok", "error", "error"]
    assert "cannot decode" in items[0]["error"] and "no marker of DICT_6X6_250 found" in items[1]["error"]
    assert "no such image" in items[3]["error"] and "720x720" in items[4]["error"]
    lines = err.strip().splitlines()
    assert len(lines) == 4 and all(line.startswith("arshadow pose: error: ") for line in lines)
    assert "Traceback" not in err


def test_pose_requested_id_absent(capsys, photos):
    d, _ = photos
    code, out, err = run(capsys, "pose", d / "good.png", "--calib", CALIB, "--marker-length", 0.05, "--marker-id", 3)
    assert code == 1 and "marker id 3 not found (found 7)" in err and err.count("\n") == 1


@pytest.mark.parametrize(
    "calib_text, word",
    [
        ("%YAML:1.0\n---\nimage_width: 1280\nimage_height: 720\n", "missing key 'camera_matrix'"),
        (
            "%YAML:1.0\n---\nimage_width: 1280\nimage_height: 720\n"
            "camera_matrix: {rows: 3, cols: 3, data: [.nan, 0, 640, 0, 1000, 360, 0, 0, 1]}\n",
            "NaN",
        ),
        (
            "%YAML:1.0\n---\nimage_width: 1280\nimage_height: 720\n"
            "camera_matrix: {rows: 3, cols: 3, data: [0, 0, 640, 0, 1000, 360, 0, 0, 1]}\n",
            "focal lengths must be positive",
        ),
        (
            "%YAML:1.0\n---\ncamera_matrix: {rows: 3, cols: 3, data: [1000, 0, 640, 0, 1000, 360, 0, 0, 1]}\n",
            "image_width",
        ),
    ],
)
def test_pose_bad_calibration(capsys, photos, tmp_path, calib_text, word):
    d, _ = photos
    c = tmp_path / "cal.yml"
    c.write_text(calib_text)
    code, out, err = run(capsys, "pose", d / "good.png", "--calib", c, "--marker-length", 0.05)
    assert code == 2 and word in err and "cal.yml" in err and err.count("\n") == 1 and out == ""


@pytest.mark.parametrize(
    "extra, word",
    [
        (["--marker-length", "0.05", "--dictionary", "DICT_NOPE"], "unknown dictionary 'DICT_NOPE'"),
        ([], "--marker-length"),
        (["--marker-length", "-0.05"], "positive"),
        (["--board", "nope.yml"], "no such board file"),
        (["--marker-length", "0.05", "--detector-params", "nope.yml"], "no such detector parameter file"),
    ],
)
def test_pose_bad_usage(capsys, photos, extra, word):
    d, _ = photos
    code, out, err = run(capsys, "pose", d / "good.png", "--calib", CALIB, *extra)
    assert code == 2 and word in err and "Traceback" not in err


def test_pose_missing_calibration(capsys, photos):
    d, _ = photos
    code, _, err = run(capsys, "pose", d / "good.png", "--calib", d / "none.yml", "--marker-length", 0.05)
    assert code == 2 and "no such calibration file" in err


@pytest.mark.realdata
def test_pose_board_and_detector_params(capsys, realdata):
    a = realdata / "aruco_tutorial"
    code, out, _ = run(
        capsys,
        "pose",
        a / "choriginal.jpg",
        a / "chocclusion_original.jpg",
        "--calib",
        a / "tutorial_camera_charuco.yml",
        "--board",
        ROOT / "calib" / "charuco_5x7.yml",
        "--json",
    )
    items = json.loads(out)["images"]
    assert code == 0 and [len(i["marker_ids"]) for i in items] == [17, 13]
    # the report also gives OpenCV's own board-frame pose: compare with OpenCV's ChArUco pipeline run here
    intr = Intrinsics.from_file(a / "tutorial_camera_charuco.yml")
    board = cv2.aruco.CharucoBoard((5, 7), 0.04, 0.02, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250))
    ch_corners, ch_ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(cv2.imread(str(a / "choriginal.jpg")))
    obj, img = board.matchImagePoints(ch_corners, ch_ids)
    ok, rvec, tvec = cv2.solvePnP(obj, img, intr.K, intr.dist)
    assert ok
    got_r, got_t = np.array(items[0]["opencv_board_rvec"]), np.array(items[0]["opencv_board_tvec"])
    assert rotation_error_deg(got_r, rvec.ravel()) < TOL.opencv_board_rot_deg
    assert np.linalg.norm(got_t - tvec.ravel()) < TOL.opencv_board_trans_rel * np.linalg.norm(tvec)
    code, out, _ = run(
        capsys,
        "pose",
        a / "singlemarkersoriginal.jpg",
        "--calib",
        a / "tutorial_camera_charuco.yml",
        "--marker-length",
        0.05,
        "--detector-params",
        a / "detector_params.yml",
        "--json",
    )
    assert code == 0 and json.loads(out)["images"][0]["marker_ids"] == [23, 40, 62, 98, 124, 203]


# ---------------------------------------------------------------------------------------------------
# calibrate
# ---------------------------------------------------------------------------------------------------
@pytest.mark.realdata
def test_calibrate_command_reproduces_reference(capsys, realdata, tmp_path, tol):
    src = realdata / "chessboard_left"
    imgs = [f for f in sorted(src.glob("left*.jpg")) if f.name != "left10.jpg"]
    out = tmp_path / "left.yml"
    code, stdout, err = run(capsys, "calibrate", *imgs, "--pattern", "chessboard:9,6,0.025", "-o", out, "--fix-aspect")
    assert code == 0, err
    assert "RMS" in stdout and "wrote" in stdout
    ref = Intrinsics.from_file(src / "left_intrinsics.yml")
    k = Intrinsics.from_file(out)
    assert abs(k.fx / ref.fx - 1) <= tol.calib_focal_rel and abs(k.fy / ref.fy - 1) <= tol.calib_focal_rel
    assert abs(k.cx - ref.cx) <= tol.calib_center_px and abs(k.cy - ref.cy) <= tol.calib_center_px
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    assert fs.getNode("avg_reprojection_error").real() <= tol.calib_rms_px
    assert fs.getNode("per_view_reprojection_errors").mat().size == 13
    fs.release()


@pytest.mark.realdata
def test_calibrate_rejects_and_too_few(capsys, realdata, tmp_path):
    src = realdata / "chessboard_left"
    bad = tmp_path / "bad.jpg"
    bad.write_bytes(b"junk")
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((480, 640, 3), 255, np.uint8))
    out = tmp_path / "c.yml"
    few = sorted(src.glob("left0[1-3].jpg"))
    code, stdout, err = run(capsys, "calibrate", *few, bad, "--pattern", "chessboard:9,6,0.025", "-o", out)
    assert code == 2 and "only 3 usable view(s), need at least 5" in err and not out.exists()
    assert "bad.jpg: rejected:" in err
    views = sorted(src.glob("left0[1-6].jpg"))
    code, stdout, err = run(capsys, "calibrate", *views, bad, blank, "--pattern", "chessboard:9,6,0.025", "-o", out)
    assert code == 1 and out.exists()
    assert "blank.png: rejected: no 9x6 chessboard found" in err
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    assert fs.getNode("rejected_views").size() == 2 and fs.getNode("nframes").real() == 6
    fs.release()
    code, _, err = run(capsys, "calibrate", *views, "--pattern", "chessboard:9,6", "-o", out)
    assert code == 2 and "bad pattern" in err


# ---------------------------------------------------------------------------------------------------
# marker / board
# ---------------------------------------------------------------------------------------------------
def test_marker_png_true_size(capsys, tmp_path):
    code, out, _ = run(capsys, "marker", "--id", 42, "--length-mm", 60, "--dpi", 200, "-o", tmp_path / "m.png", "--svg")
    assert code == 0
    data = (tmp_path / "m.png").read_bytes()
    dpi = read_png_dpi(data)
    assert dpi is not None and abs(dpi - 200) < 10
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250))
    corners, ids, _ = det.detectMarkers(img)
    assert ids.ravel().tolist() == [42]
    side_px = np.linalg.norm(corners[0][0][1] - corners[0][0][0]) + 1  # contour corners sit on the inner pixels
    assert side_px / dpi * 25.4 == pytest.approx(60.0, abs=25.4 / dpi * 1.5)
    svg = (tmp_path / "m.svg").read_text()
    assert 'width="80.0000mm"' in svg and svg.count("<rect") > 10


def test_board_png_and_board_file(capsys, tmp_path):
    code, _, _ = run(
        capsys,
        "board",
        "--type",
        "charuco",
        "--size",
        "5,7",
        "--square-mm",
        30,
        "--marker-mm",
        22,
        "-o",
        tmp_path / "b.png",
        "--save-board",
        tmp_path / "b.yml",
        "--svg",
    )
    assert code == 0 and (tmp_path / "b.svg").is_file()
    from arshadow.tracking.board import load_board

    board = load_board(tmp_path / "b.yml")
    img = cv2.imread(str(tmp_path / "b.png"))
    cc, cid, _, mid = cv2.aruco.CharucoDetector(board.cv_board).detectBoard(img)
    assert len(mid) == 17 and len(cid) == 24
    assert read_png_dpi((tmp_path / "b.png").read_bytes()) == pytest.approx(300, abs=0.1)


@pytest.mark.parametrize(
    "argv, word",
    [
        (["marker", "--id", "999", "--length-mm", "50"], "not in the dictionary"),
        (["marker", "--id", "1", "--length-mm", "0"], "--length-mm"),
        (["marker", "--id", "1", "--length-mm", "50", "--dictionary", "DICT_NOPE"], "unknown dictionary"),
        (["board", "--type", "charuco", "--size", "5,7", "--marker-mm", "20"], "--square-mm"),
        (["board", "--board", "missing.yml"], "no such board file"),
    ],
)
def test_marker_board_bad_input(capsys, tmp_path, argv, word):
    code, _, err = run(capsys, *argv, "-o", tmp_path / "x.png")
    assert code == 2 and word in err and not (tmp_path / "x.png").exists()
