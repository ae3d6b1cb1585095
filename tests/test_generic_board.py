"""Generic boards (markers at known 3D corners), ArUco layout files, inverted markers, and the detector
fixes of the real-footage work (luma range, AprilTag losses, the second search), on synthetic photos with known truth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from arshadow.camera.model import Intrinsics
from arshadow.errors import MarkerNotFoundError, UsageError
from arshadow.synth.markers import look_at_pose, render_marker_photo
from arshadow.tracking.board import OPENCV_BOARD_TO_WORLD, Board, load_board, read_aruco_layout
from arshadow.tracking.detect import AprilTagDetector, RescueDetector, luma_to_gray, make_detector_params
from arshadow.tracking.tracker import MarkerTracker
from arshadow.transforms import rotation_error_deg

CAM = Intrinsics(900.0, 900.0, 639.5, 359.5, 1280, 720)
GRID = Board("gridboard", (3, 2), 0.04, marker_separation=0.01, dictionary="DICT_4X4_50")
POSE = look_at_pose([0.05, -0.25, 0.35], [0.07, -0.04, 0.0])


def generic_from_grid(board: Board, **kw) -> Board:
    """The same markers as a generic board (independent of OpenCV's GridBoard layout code)."""
    step = board.marker_length + board.marker_separation
    ml = board.marker_length
    markers = {}
    for k, mid in enumerate(board.marker_ids):
        col, row = k % board.size[0], k // board.size[0]
        x0, y0 = col * step, -row * step  # top-left corner, world frame (y up)
        markers[mid] = [[x0, y0, 0], [x0 + ml, y0, 0], [x0 + ml, y0 - ml, 0], [x0, y0 - ml, 0]]
    return Board("markers", (0, 0), 1.0, dictionary=board.dictionary, markers=markers, **kw)


def test_generic_board_pose_matches_truth():
    photo = render_marker_photo(CAM, POSE, board=GRID, noise_sigma=1.0, seed=3)
    board = generic_from_grid(GRID)
    assert board.n_markers == 6 and board.marker_length == pytest.approx(0.04) and board.planar
    pose = MarkerTracker(CAM, board=board).estimate(photo.image)
    assert pose.kind == "markers" and sorted(pose.marker_ids) == list(GRID.marker_ids)
    assert rotation_error_deg(pose.cam_from_world[:3, :3], POSE[:3, :3]) < 0.3
    assert np.linalg.norm(pose.tvec - POSE[:3, 3]) < 1e-3
    assert pose.reprojection_error_px < 0.5


class _Projected:
    """A detector that reports the exact projections of given 3D corners (OpenCV's corner order)."""

    def __init__(self, markers, cam_from_world):
        self.corners, self.ids = [], []
        rvec = cv2.Rodrigues(cam_from_world[:3, :3])[0]
        for mid, c in markers.items():
            px = cv2.projectPoints(np.asarray(c, np.float64), rvec, cam_from_world[:3, 3], CAM.K, CAM.dist_cv)[0]
            self.corners.append(px.reshape(1, 4, 2).astype(np.float32))
            self.ids.append(mid)

    def detectMarkers(self, gray):  # noqa: N802
        return tuple(self.corners), np.array(self.ids, np.int32).reshape(-1, 1), ()


def test_generic_board_not_coplanar():
    """Markers on two planes (a box corner): SQPNP + LM recovers the true pose from exact projections."""
    board = generic_from_grid(GRID)
    lifted = {k: np.array(v) + ([0.0, 0.0, 0.03] if k % 2 else 0.0) for k, v in board.markers.items()}
    b3 = Board("markers", (0, 0), 1.0, dictionary=board.dictionary, markers=lifted)
    assert not b3.planar
    tr = MarkerTracker(CAM, board=b3, detector=_Projected(lifted, POSE))
    pose = tr.estimate(np.zeros((720, 1280), np.uint8))
    assert rotation_error_deg(pose.cam_from_world[:3, :3], POSE[:3, :3]) < 1e-4
    assert np.linalg.norm(pose.tvec - POSE[:3, 3]) < 1e-6 and pose.pose_ambiguity is None


def test_markers_board_file_round_trip_and_errors(tmp_path):
    b = generic_from_grid(GRID, inverted=True)
    p = b.to_file(tmp_path / "b.yml")
    b2 = load_board(p)
    assert b2.kind == "markers" and b2.inverted and b2.dictionary == "DICT_4X4_50"
    for mid in b.marker_ids:
        np.testing.assert_allclose(b2.marker_corners_world[mid], b.marker_corners_world[mid])
    bad = tmp_path / "bad.yml"
    bad.write_text("%YAML:1.0\ntype: markers\nmarkers:\n  - { id: 3, corners: [[0, 0, 0], [1, 0, 0]] }\n")
    with pytest.raises(UsageError, match="4 \\[x, y, z\\]"):
        load_board(bad)
    bad.write_text("%YAML:1.0\ntype: markers\nmarkers:\n  - { corners: [[0,0,0],[1,0,0],[1,1,0],[0,1,0]] }\n")
    with pytest.raises(UsageError, match="integer 'id'"):
        load_board(bad)
    with pytest.raises(UsageError, match="non-empty"):
        Board("markers", (0, 0), 1.0, markers={})


def test_aruco_layout_file(tmp_path):
    """The ArUco library's layout (OpenCV's board convention: y down, z into the board) -> world frame."""
    p = tmp_path / "layout.yml"
    p.write_text(
        "%YAML:1.0\naruco_bc_nmarkers: 1\naruco_bc_mInfoType: 1\naruco_bc_markers:\n"
        "   - { id:7, corners:[ [ -0.02, -0.02, 0. ], [ 0.02, -0.02, 0. ], [ 0.02, 0.02, 0. ],"
        " [ -0.02, 0.02, 0. ] ] }\n"
    )
    b = load_board(p)
    assert b.kind == "markers" and b.dictionary == "DICT_ARUCO_ORIGINAL" and b.marker_ids == (7,)
    expected = (
        np.array([[-0.02, -0.02, 0], [0.02, -0.02, 0], [0.02, 0.02, 0], [-0.02, 0.02, 0]]) @ OPENCV_BOARD_TO_WORLD.T
    )
    np.testing.assert_allclose(b.marker_corners_world[7], expected)
    # TL is top-left in the world frame (y up): the single-marker frame's corner order
    assert b.marker_corners_world[7][0].tolist()[:2] == [-0.02, 0.02]
    assert read_aruco_layout(p, dictionary="DICT_4X4_50").dictionary == "DICT_4X4_50"
    p.write_text(p.read_text().replace("aruco_bc_mInfoType: 1", "aruco_bc_mInfoType: 0"))
    with pytest.raises(UsageError, match="pixels"):
        load_board(p)


def test_inverted_marker_found_when_asked_and_hinted_otherwise():
    pose = look_at_pose([0.05, -0.1, 0.3], [0, 0, 0])
    photo = render_marker_photo(CAM, pose, marker_length=0.05, dictionary="DICT_4X4_50", marker_id=5)
    neg = 255 - photo.image
    with pytest.raises(MarkerNotFoundError, match="inverted .*ids 5.*--inverted"):
        MarkerTracker(CAM, marker_length=0.05, dictionary="DICT_4X4_50").estimate(neg)
    p = MarkerTracker(CAM, marker_length=0.05, dictionary="DICT_4X4_50", inverted=True).estimate(neg)
    assert p.marker_ids[0] == 5 and rotation_error_deg(p.cam_from_world[:3, :3], pose[:3, :3]) < 0.5
    assert not p.ambiguous  # the white ring of an inverted marker is not an occlusion


def test_luma_to_gray_matches_bt601_gray():
    """A limited-range luma plane (Y = 16 + 219 * gray / 255) maps back onto the gray within rounding."""
    g = np.arange(256, dtype=np.float64)
    y = np.round(16 + 219 * g / 255).astype(np.uint8).reshape(16, 16)
    assert np.abs(luma_to_gray(y).astype(int) - g.reshape(16, 16)).max() <= 1


def test_apriltag_detector_keeps_what_the_ordinary_search_finds():
    photo = render_marker_photo(CAM, POSE, board=GRID, seed=5)
    gray = cv2.cvtColor(photo.image, cv2.COLOR_BGR2GRAY)
    p = make_detector_params("apriltag")
    c, ids, _ = AprilTagDetector(GRID.cv_dictionary, p).detectMarkers(gray)
    found = set(np.asarray(ids).ravel().tolist())
    assert found == set(GRID.marker_ids)
    for cc, i in zip(c, np.asarray(ids).ravel(), strict=True):  # pixel-centre corners, at the true corners
        assert np.abs(np.asarray(cc).reshape(4, 2) - photo.corners_px[int(i)]).max() < 0.5


class _Blind:
    """A first search that finds nothing (the second one must then run)."""

    def detectMarkers(self, gray):  # noqa: N802
        return (), None, ()


def test_rescue_detector_runs_a_second_search_only_on_a_miss():
    photo = render_marker_photo(CAM, POSE, board=GRID, seed=6)
    gray = cv2.cvtColor(photo.image, cv2.COLOR_BGR2GRAY)
    p = make_detector_params("subpix")
    r = RescueDetector(_Blind(), GRID.cv_dictionary, p, marker_id=3)
    _, ids, _ = r.detectMarkers(gray)
    assert r.rescued and 3 in np.asarray(ids).ravel().tolist()
    r2 = RescueDetector(cv2.aruco.ArucoDetector(GRID.cv_dictionary, p), GRID.cv_dictionary, p, marker_id=3)
    r2.detectMarkers(gray)
    assert not r2.rescued


# ---------------------------------------------------------------------------------------------------
# the sanity gates ('s)'s tracking messages: other dictionaries named, flag reasons with numbers, board units
# ---------------------------------------------------------------------------------------------------
def test_no_marker_names_the_dictionaries_in_the_photo():
    photo = render_marker_photo(
        CAM, look_at_pose([0.05, -0.1, 0.3], [0, 0, 0]), marker_length=0.05, dictionary="DICT_5X5_1000", marker_id=403
    )
    with pytest.raises(MarkerNotFoundError, match="DICT_5X5_1000 ids 403"):
        MarkerTracker(CAM, marker_length=0.05, dictionary="DICT_6X6_250").estimate(photo.image)
    # a video tracker (track_roi) does not spend the scan on every missed frame
    with pytest.raises(MarkerNotFoundError) as exc:
        MarkerTracker(CAM, marker_length=0.05, track_roi=True).estimate(photo.image)
    assert "DICT_5X5" not in str(exc.value)


def test_small_marker_flag_reason_names_its_size():
    """A marker 24 px across (true pose: 0.05 m at ~1.9 m with f = 900): flagged, the reason says so."""
    pose = look_at_pose([0.0, -0.3, 1.85], [0, 0, 0])
    photo = render_marker_photo(CAM, pose, marker_length=0.05)
    p = MarkerTracker(CAM, marker_length=0.05, refine="subpix").estimate(photo.image)  # edge: a report note
    q = photo.corners_px[0]
    side = float(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).min())
    assert side < 32 and p.ambiguous and p.flagged
    (small,) = [r for r in p.flag_reasons if r.startswith("small marker: ")]
    assert abs(float(small.split()[2]) - side) < 0.5  # the detected size, against the true corners


def test_mismatched_board_flagged_by_reprojection():
    """A board file whose spacing does not match the print: the pose reprojects tens of pixels off and
    is flagged with the number; the true board is not flagged."""
    photo = render_marker_photo(CAM, POSE, board=GRID, seed=7)
    good = MarkerTracker(CAM, board=GRID).estimate(photo.image)
    assert not good.flagged and good.flag_reasons == []
    wrong = Board("gridboard", (3, 2), 0.04, marker_separation=0.03, dictionary="DICT_4X4_50")
    bad = MarkerTracker(CAM, board=wrong).estimate(photo.image)
    assert bad.reprojection_error_px > 10 and bad.flagged
    assert any(f"{bad.reprojection_error_px:.1f} px" in r for r in bad.flag_reasons)


def test_board_in_millimetres_warns():
    assert GRID.unit_warnings() == []
    mm = Board("gridboard", (3, 2), 40.0, marker_separation=10.0, dictionary="DICT_4X4_50")
    (w,) = mm.unit_warnings()
    assert "millimetres" in w and "0.04" in w
