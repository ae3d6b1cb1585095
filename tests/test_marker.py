"""Dictionaries, board files, detector parameters, detection on real photos, tracker errors and hooks."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import TOL

from arshadow.camera.model import Intrinsics
from arshadow.errors import CalibrationError, MarkerNotFoundError, UsageError
from arshadow.frame.report import ReportItem
from arshadow.synth.markers import look_at_pose, random_pose, render_marker_photo
from arshadow.tracking.board import Board, load_board
from arshadow.tracking.detect import (
    DEFAULT_REFINE,
    REFINE_METHODS,
    detect_markers,
    load_detector_params,
    make_detector_params,
)
from arshadow.tracking.dictionary import get_dictionary, marker_object_points
from arshadow.tracking.quality import AMBIGUITY_FLAG
from arshadow.tracking.tracker import MarkerTracker
from arshadow.transforms import rotation_error_deg

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib"
CAM = Intrinsics.from_file(CALIB / "synth_1280x720.yml")


# ---------------------------------------------------------------------------------------------------
# dictionaries, boards, parameters
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["DICT_6X6_250", "dict_6x6_250", "6X6_250", "DICT_APRILTAG_36h11", "ARUCO_ORIGINAL"])
def test_predefined_dictionaries(name):
    d = get_dictionary(name)
    assert d.markerSize in (5, 6) and len(d.bytesList) > 0


def test_unknown_dictionary():
    with pytest.raises(UsageError, match="unknown dictionary 'DICT_9X9_1'"):
        get_dictionary("DICT_9X9_1")


def test_custom_dictionary_file(tmp_path):
    d = cv2.aruco.extendDictionary(12, 5, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_5X5_50), 1)
    fs = cv2.FileStorage(str(tmp_path / "mine.yml"), cv2.FILE_STORAGE_WRITE)
    d.writeDictionary(fs)
    fs.release()
    got = get_dictionary(str(tmp_path / "mine.yml"))
    assert got.markerSize == 5 and np.array_equal(got.bytesList, d.bytesList)
    with pytest.raises(UsageError, match="no such dictionary file"):
        get_dictionary(str(tmp_path / "other.yml"))
    (tmp_path / "bad.yml").write_text("%YAML:1.0\n---\nfoo: 1\n")
    with pytest.raises(UsageError, match="not a dictionary file"):
        get_dictionary(str(tmp_path / "bad.yml"))


def test_shipped_board_files():
    ch = load_board(CALIB / "charuco_5x7.yml")
    assert ch.kind == "charuco" and ch.size == (5, 7) and ch.n_markers == 17
    assert ch.extent == pytest.approx((0.2, 0.28))
    assert ch.charuco_corners_world.shape == (24, 3)
    gb = load_board(CALIB / "gridboard_5x7.yml")
    assert gb.kind == "gridboard" and gb.n_markers == 35 and gb.marker_ids[-1] == 34
    # world frame: y up (towards the printed top edge), z out of the print; OpenCV's board origin
    c0 = gb.marker_corners_world[0]
    assert np.allclose(c0[0], [0, 0, 0]) and np.allclose(c0[2], [0.04, -0.04, 0])
    opencv = np.asarray(gb.cv_board.getObjPoints()[0]).reshape(4, 3)
    assert np.allclose(c0, opencv * [1, -1, -1], atol=1e-6)


@pytest.mark.parametrize("ext", [".yml", ".json"])
def test_board_file_round_trip(tmp_path, ext):
    b = Board("gridboard", (3, 2), 0.05, marker_separation=0.01, dictionary="DICT_4X4_50", ids=(5, 9, 3, 1, 7, 8))
    p = b.to_file(tmp_path / f"b{ext}")
    back = load_board(p)
    assert (back.kind, back.size, back.marker_ids, back.marker_length, back.marker_separation) == (
        "gridboard",
        (3, 2),
        (5, 9, 3, 1, 7, 8),
        0.05,
        0.01,
    )


def test_board_with_relative_custom_dictionary(tmp_path, realdata):
    shutil.copy(realdata / "aruco_tutorial" / "tutorial_dict.yml", tmp_path / "tutorial_dict.yml")
    (tmp_path / "gb.yml").write_text(
        "%YAML:1.0\n---\ntype: gridboard\nsize: [5, 7]\nmarker_length: 0.04\nmarker_separation: 0.01\n"
        "dictionary: tutorial_dict.yml\n"
    )
    b = load_board(tmp_path / "gb.yml")
    assert len(b.cv_dictionary.bytesList) == 35


@pytest.mark.parametrize(
    "text, word",
    [
        ("type: hexboard\nsize: [5, 7]\nmarker_length: 0.04\n", "gridboard"),
        ("type: gridboard\nmarker_length: 0.04\nmarker_separation: 0.01\n", "size"),
        ("type: gridboard\nsize: [5, 7]\nmarker_separation: 0.01\n", "marker_length"),
        ("type: gridboard\nsize: [5, 7]\nmarker_length: 0.04\n", "marker_separation"),
        ("type: charuco\nsize: [5, 7]\nmarker_length: 0.04\nsquare_length: 0.03\n", "square_length"),
        ("type: charuco\nsize: [5, 7]\nmarker_length: 0.02\nsquare_length: 0.04\ndictionary: NOPE\n", "NOPE"),
        ("type: gridboard\nsize: [50, 70]\nmarker_length: 0.04\nmarker_separation: 0.01\n", "exceed"),
        ("type: gridboard\nsize: [5, 7]\nmarker_length: -1\nmarker_separation: 0.01\n", "positive"),
    ],
)
def test_bad_board_files(tmp_path, text, word):
    p = tmp_path / "board.yml"
    p.write_text("%YAML:1.0\n---\n" + text)
    with pytest.raises(UsageError, match=word) as ei:
        load_board(p)
    assert "board.yml" in str(ei.value) or word == "NOPE"


def test_missing_board_file(tmp_path):
    with pytest.raises(UsageError, match="no such board file"):
        load_board(tmp_path / "none.yml")


@pytest.mark.parametrize(
    "reader, what",
    [
        (load_board, "board file"),
        (get_dictionary, "dictionary file"),
        (load_detector_params, "detector parameter file"),
    ],
)
def test_unparsable_files_quote_the_parser(tmp_path, reader, what):
    """Board, dictionary and detector parameter files fail like calibration files: one UsageError naming
    the file, what it should be, and OpenCV's parser message (file and line), not the binding's SystemError."""
    p = tmp_path / "broken.yml"
    p.write_text("%YAML:1.0\n---\ntype: [gridboard\n")
    with pytest.raises(UsageError, match=f"cannot parse {what}") as ei:
        reader(str(p))
    assert "broken.yml(3)" in str(ei.value) and "SystemError" not in str(ei.value)


def test_detector_params_file(realdata, tmp_path):
    p = load_detector_params(realdata / "aruco_tutorial" / "detector_params.yml")
    assert p.minMarkerDistanceRate == pytest.approx(0.05) and p.adaptiveThreshWinSizeMax == 23
    q = make_detector_params("apriltag", p)
    assert q.cornerRefinementMethod == cv2.aruco.CORNER_REFINE_APRILTAG
    assert q.minMarkerDistanceRate == pytest.approx(0.05) and p.cornerRefinementMethod == 0  # base untouched
    with pytest.raises(UsageError, match="no such"):
        load_detector_params(tmp_path / "x.yml")
    with pytest.raises(UsageError, match="refinement"):
        make_detector_params("fancy")


# ---------------------------------------------------------------------------------------------------
# real photos: OpenCV's own test expectations
# ---------------------------------------------------------------------------------------------------
def _expected(realdata):
    return json.loads((realdata / "expected.json").read_text())


MARKER_FILES = [
    "aruco_tutorial/singlemarkersoriginal.jpg",
    "aruco_tutorial/gboriginal.jpg",
    "aruco_tutorial/choriginal.jpg",
    "aruco_tutorial/chocclusion_original.jpg",
]


def _dict_for(realdata, entry):
    return (
        str(realdata / "aruco_tutorial" / "tutorial_dict.yml")
        if "custom" in entry["dictionary"]
        else entry["dictionary"]
    )


@pytest.mark.realdata
@pytest.mark.parametrize("name", MARKER_FILES)
def test_realdata_corners(realdata, tol, name):
    """Every id and corner OpenCV's test expects, within 1 px, with OpenCV's test detector settings
    (default DetectorParameters = no corner refinement)."""
    e = _expected(realdata)[name]
    img = cv2.imread(str(realdata / name))
    det = detect_markers(img, _dict_for(realdata, e), refine="none")
    assert len(det) == e["n_markers"]
    by_id = det.by_id
    assert sorted(by_id) == sorted(int(k) for k in e["corners"])
    for k, corners in e["corners"].items():
        err = np.abs(by_id[int(k)] - np.asarray(corners, float)).max()
        assert err <= tol.corner_px, f"marker {k}: corner off by {err:.2f} px"


@pytest.mark.realdata
@pytest.mark.parametrize("name", MARKER_FILES)
@pytest.mark.parametrize("refine", [m for m in REFINE_METHODS if m != "none"])
def test_realdata_ids_with_refinement(realdata, name, refine):
    """Refinement moves corners (to sub-pixel positions) but never loses or invents a marker."""
    e = _expected(realdata)[name]
    det = detect_markers(cv2.imread(str(realdata / name)), _dict_for(realdata, e), refine=refine)
    assert sorted(det.ids.tolist()) == sorted(int(k) for k in e["corners"])
    by_id = det.by_id
    worst = max(np.abs(by_id[int(k)] - np.asarray(c, float)).max() for k, c in e["corners"].items())
    assert worst < TOL.unrefined_corner_px  # the unrefined expectation is integer contour points


@pytest.mark.realdata
def test_realdata_diamond_markers(realdata):
    name = "aruco_tutorial/diamondmarkers.png"
    e = _expected(realdata)[name]
    params = realdata / "aruco_tutorial" / "detector_params.yml"
    det = detect_markers(
        cv2.imread(str(realdata / name)),
        realdata / "aruco_tutorial" / "tutorial_dict.yml",
        params=params,
        refine="apriltag",
    )
    assert len(det) == e["n_markers"]
    got = {}
    for i in det.ids.tolist():
        got[str(i)] = got.get(str(i), 0) + 1
    assert got == e["marker_id_multiset"]


@pytest.mark.realdata
@pytest.mark.parametrize("name, n", [("choriginal.jpg", 17), ("chocclusion_original.jpg", 13)])
def test_realdata_charuco_pose(realdata, name, n):
    cam = Intrinsics.from_file(realdata / "aruco_tutorial" / "tutorial_camera_charuco.yml")
    tracker = MarkerTracker(cam, board=CALIB / "charuco_5x7.yml")
    pose = tracker.estimate(cv2.imread(str(realdata / "aruco_tutorial" / name)))
    assert len(pose.marker_ids) == n and pose.kind == "charuco"
    assert pose.n_points >= 12 and pose.reprojection_error_px < 1.0
    # the board lies in front of the camera, printed face towards it
    assert pose.tvec[2] > 0.1 and pose.cam_from_world[2, 2] < 0


@pytest.mark.realdata
def test_realdata_charuco_occlusion_consistent(realdata):
    """The occluded photo and the clean one of the same board, same camera: both poses are sane and the
    occluded one still uses the corners around the visible markers only."""
    cam = Intrinsics.from_file(realdata / "aruco_tutorial" / "tutorial_camera_charuco.yml")
    tracker = MarkerTracker(cam, board=CALIB / "charuco_5x7.yml")
    occ = tracker.estimate(cv2.imread(str(realdata / "aruco_tutorial" / "chocclusion_original.jpg")))
    full = tracker.estimate(cv2.imread(str(realdata / "aruco_tutorial" / "choriginal.jpg")))
    assert occ.n_points < full.n_points == 24


@pytest.mark.realdata
def test_realdata_custom_gridboard_pose(realdata, tmp_path):
    shutil.copy(realdata / "aruco_tutorial" / "tutorial_dict.yml", tmp_path / "tutorial_dict.yml")
    (tmp_path / "gb.yml").write_text(
        "%YAML:1.0\n---\ntype: gridboard\nsize: [5, 7]\nmarker_length: 0.04\nmarker_separation: 0.01\n"
        "dictionary: tutorial_dict.yml\n"
    )
    # camera and printed lengths unknown: a plausible camera; this checks detection through the board
    # path (detect + refineDetectedMarkers + matchImagePoints), not the pose's accuracy
    cam = Intrinsics(560.0, 560.0, 319.5, 239.5, 640, 480)
    img = cv2.imread(str(realdata / "aruco_tutorial" / "gboriginal.jpg"))
    pose = MarkerTracker(cam, board=tmp_path / "gb.yml").estimate(img)
    assert pose.marker_ids == list(range(35)) and pose.n_points == 140 and pose.kind == "gridboard"
    assert pose.tvec[2] > 0


# ---------------------------------------------------------------------------------------------------
# tracker behaviour on synthetic photos
# ---------------------------------------------------------------------------------------------------
def test_tracker_errors():
    pose = look_at_pose([0.1, -0.2, 0.4], [0, 0, 0])
    photo = render_marker_photo(CAM, pose, marker_id=3, marker_length=0.05)
    with pytest.raises(MarkerNotFoundError, match=r"marker id 7 not found \(found 3\)"):
        MarkerTracker(CAM, marker_length=0.05, marker_id=7).estimate(photo.image)
    with pytest.raises(MarkerNotFoundError, match="no marker of DICT_4X4_50 found"):
        MarkerTracker(CAM, dictionary="DICT_4X4_50", marker_length=0.05).estimate(photo.image)
    blank = np.full((720, 1280, 3), 128, np.uint8)
    with pytest.raises(MarkerNotFoundError, match="no marker of DICT_6X6_250"):
        MarkerTracker(CAM, marker_length=0.05).estimate(blank)
    with pytest.raises(CalibrationError, match="640x480"):
        MarkerTracker(CAM, marker_length=0.05).estimate(np.zeros((480, 640, 3), np.uint8))
    with pytest.raises(UsageError, match="marker side length"):
        MarkerTracker(CAM)
    with pytest.raises(UsageError, match="positive"):
        MarkerTracker(CAM, marker_length=float("nan"))
    with pytest.raises(UsageError, match="not in DICT_6X6_250"):
        MarkerTracker(CAM, marker_length=0.05, marker_id=250)
    with pytest.raises(UsageError, match="refinement"):
        MarkerTracker(CAM, marker_length=0.05, refine="magic")


def test_tracker_scaled_image():
    """A half-size photo of the same view: the calibration is scaled and the pose stays put."""
    pose = look_at_pose([0.1, -0.2, 0.35], [0, 0, 0])
    photo = render_marker_photo(CAM, pose, marker_id=3, marker_length=0.06)
    half = cv2.resize(photo.image, (640, 360), interpolation=cv2.INTER_AREA)
    p = MarkerTracker(CAM, marker_length=0.06).estimate(half)
    assert p.scaled and p.intrinsics.size == (640, 360)
    assert rotation_error_deg(p.cam_from_world[:3, :3], pose[:3, :3]) < 1.0
    assert np.linalg.norm(p.tvec - pose[:3, 3]) < 0.01 * np.linalg.norm(pose[:3, 3])


def test_tracker_reports_all_ids_reference_first():
    pose = look_at_pose([0.0, -0.25, 0.45], [0, 0, 0])
    board = Board("gridboard", (2, 1), 0.05, marker_separation=0.05, ids=(12, 4))
    photo = render_marker_photo(CAM, pose, board=board)
    p = MarkerTracker(CAM, marker_length=0.05).estimate(photo.image)
    assert p.marker_ids == [4, 12]  # lowest id is the reference by default
    p12 = MarkerTracker(CAM, marker_length=0.05, marker_id=12).estimate(photo.image)
    assert p12.marker_ids == [12, 4] and set(p12.all_corners) == {4, 12}
    assert np.allclose(p12.corners, p12.all_corners[12])


def test_pose_fields_and_alternative(rng):
    pose = look_at_pose([0.15, -0.3, 0.45], [0, 0, 0])
    photo = render_marker_photo(CAM, pose, marker_length=0.05, noise_sigma=2, blur_sigma=0.6, seed=1)
    p = MarkerTracker(CAM, marker_length=0.05).estimate(photo.image)
    assert p.rvec.shape == (3,) and p.tvec.shape == (3,) and p.cam_from_world.shape == (4, 4)
    assert p.corners.shape == (4, 2) and p.object_points.shape == (4, 3) and p.n_points == 4
    assert np.allclose(p.object_points, marker_object_points(0.05))
    assert 0 < p.pose_ambiguity <= 1 and p.alternative is not None
    assert p.reprojection_error_px <= p.alternative.reprojection_error_px
    assert rotation_error_deg(p.alternative.cam_from_world[:3, :3], p.cam_from_world[:3, :3]) > 1.0
    s = p.swapped()
    assert np.array_equal(s.rvec, p.alternative.rvec) and np.array_equal(s.alternative.rvec, p.rvec)
    item = ReportItem(input="x")
    item.set_pose(p)  # the one place a pose becomes report keys
    fields = item.to_dict()
    assert {"marker_ids", "rvec", "tvec", "reprojection_error_px", "pose_ambiguity"} <= set(fields)
    assert fields["marker_ids"] == [0] and fields["rvec"] == p.rvec.tolist()
    json.dumps(fields)


def test_previous_pose_hook():
    """A nearly frontal, small, noisy marker is ambiguous; the previous frame's pose picks the solution."""
    found_ambiguous = 0
    rng = np.random.default_rng(5)
    for i in range(40):
        pose = random_pose(rng, CAM, distance=(0.7, 0.8), tilt_deg=(0, 12), keep_in_view=marker_object_points(0.05))
        photo = render_marker_photo(CAM, pose, marker_length=0.035, noise_sigma=4, blur_sigma=0.8, seed=i)
        tracker = MarkerTracker(CAM, marker_length=0.035)
        try:
            p = tracker.estimate(photo.image)
        except MarkerNotFoundError:
            continue
        if not p.ambiguous:
            continue
        found_ambiguous += 1
        q = tracker.estimate(photo.image, previous=pose)  # the truth as "previous frame"
        e_prev = rotation_error_deg(q.cam_from_world[:3, :3], pose[:3, :3])
        e_alt = rotation_error_deg(
            (q.alternative.cam_from_world if q.alternative else q.cam_from_world)[:3, :3], pose[:3, :3]
        )
        assert e_prev <= e_alt + 1e-9
        assert q.chosen_by in ("error", "previous")
    assert found_ambiguous >= 1  # the scenario really produces ambiguous poses


def test_default_refinement_is_a_known_method():
    assert DEFAULT_REFINE in REFINE_METHODS and 0 < AMBIGUITY_FLAG < 1


def test_inputs_not_modified():
    pose = look_at_pose([0.1, -0.2, 0.4], [0, 0, 0])
    photo = render_marker_photo(CAM, pose, marker_length=0.05)
    img = photo.image.copy()
    img.setflags(write=False)
    MarkerTracker(CAM, marker_length=0.05).estimate(img)
    assert np.array_equal(img, photo.image)
