"""Synthetic photos with known truth, and pose accuracy measured on them.

The truth is the pose the generator is given; OpenCV's detector (independent of the generator) is used
to check the generator's geometry.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import TOL

from arshadow.camera.model import Intrinsics
from arshadow.errors import ShapeError, UsageError
from arshadow.frame.report import ReportItem
from arshadow.synth.markers import camera_path, look_at_pose, random_pose, render_marker_photo
from arshadow.tracking.board import Board
from arshadow.tracking.dictionary import marker_object_points
from arshadow.transforms import invert_rigid, rotation_error_deg

ROOT = Path(__file__).resolve().parents[1]
CAM = Intrinsics.from_file(ROOT / "calib" / "synth_1280x720.yml")
CAM_K1 = Intrinsics.from_file(ROOT / "calib" / "synth_1280x720_k1.yml")
CHARUCO = Board("charuco", (5, 7), 0.02, square_length=0.04)


def _detect(image, refine=cv2.aruco.CORNER_REFINE_SUBPIX):
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = refine
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250), params)
    corners, ids, _ = det.detectMarkers(image)
    return {} if ids is None else {int(i): c.reshape(4, 2) for i, c in zip(ids.ravel(), corners, strict=True)}


# ---------------------------------------------------------------------------------------------------
# poses
# ---------------------------------------------------------------------------------------------------
def test_look_at_pose():
    eye, target = np.array([0.3, -0.4, 0.5]), np.array([0.05, 0.02, 0.0])
    m = look_at_pose(eye, target)
    assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12) and np.linalg.det(m[:3, :3]) > 0
    assert np.allclose(invert_rigid(m)[:3, 3], eye)  # camera centre
    t_cam = m[:3, :3] @ target + m[:3, 3]
    assert np.allclose(t_cam[:2], 0, atol=1e-12) and t_cam[2] > 0  # target straight ahead
    up_cam = m[:3, :3] @ np.array([0, 0, 1.0])
    assert up_cam[1] < 0 and abs(up_cam[0]) < 1e-12  # world up points up (-y) in the image
    # straight down: the marker's top edge (+y) is up in the image
    d = look_at_pose([0, 0, 1], [0, 0, 0])
    assert (d[:3, :3] @ [0, 1.0, 0])[1] < -0.99
    with pytest.raises(UsageError):
        look_at_pose([1, 1, 1], [1, 1, 1])


def test_random_pose_ranges(rng):
    L = 0.05
    for _ in range(50):
        m = random_pose(rng, CAM, distance=(0.3, 0.8), tilt_deg=(10, 60), keep_in_view=marker_object_points(L))
        eye = invert_rigid(m)[:3, 3]
        d = np.linalg.norm(eye)
        tilt = math.degrees(math.acos(eye[2] / d))
        assert 0.3 <= d <= 0.8 and 10 - 1e-9 <= tilt <= 60 + 1e-9
        uv = CAM.project(marker_object_points(L), m)
        assert np.all(uv >= 10) and np.all(uv[:, 0] <= CAM.width - 11) and np.all(uv[:, 1] <= CAM.height - 11)


def test_camera_path_is_smooth():
    path = camera_path(60)
    assert path.shape == (60, 4, 4)
    steps = [rotation_error_deg(path[i][:3, :3], path[i + 1][:3, :3]) for i in range(59)]
    moves = [np.linalg.norm(invert_rigid(path[i])[:3, 3] - invert_rigid(path[i + 1])[:3, 3]) for i in range(59)]
    assert max(steps) < 5.0 and max(moves) < 0.05 and sum(moves) > 0.5


# ---------------------------------------------------------------------------------------------------
# the generator
# ---------------------------------------------------------------------------------------------------
def test_render_basic_and_deterministic():
    pose = look_at_pose([0.2, -0.3, 0.4], [0, 0, 0])
    a = render_marker_photo(CAM, pose, marker_id=7, marker_length=0.05, noise_sigma=2, seed=3, jpeg_quality=90)
    b = render_marker_photo(CAM, pose, marker_id=7, marker_length=0.05, noise_sigma=2, seed=3, jpeg_quality=90)
    assert a.image.shape == (720, 1280, 3) and a.image.dtype == np.uint8
    assert np.array_equal(a.image, b.image) and np.array_equal(a.cam_from_world, pose)
    assert list(a.corners_px) == [7]
    c = render_marker_photo(CAM, pose, marker_id=7, marker_length=0.05, noise_sigma=2, seed=4)
    assert not np.array_equal(a.image, c.image)


def test_render_exposure_and_floor():
    pose = look_at_pose([0.0, -0.3, 0.4], [0, 0, 0])
    a = render_marker_photo(CAM, pose, marker_length=0.05)
    dark = render_marker_photo(CAM, pose, marker_length=0.05, exposure=0.5)
    assert abs(dark.image.mean() / a.image.mean() - 0.5) < TOL.exposure_ratio_abs
    plain = render_marker_photo(CAM, pose, marker_length=0.05, floor="plain")
    assert a.image[:100].std() > 5 and plain.image[:100].std() < 1  # textured vs plain floor


@pytest.mark.parametrize("cam", [CAM, CAM_K1], ids=["small_dist", "k1"])
def test_rendered_corners_match_truth(cam, tol):
    """OpenCV finds the rendered corners where the generator says they are (distortion included)."""
    shift = []
    for eye, tgt in [([0.0, -0.25, 0.45], [0, 0, 0]), ([0.25, 0.2, 0.35], [-0.12, -0.05, 0])]:
        pose = look_at_pose(eye, tgt)
        photo = render_marker_photo(cam, pose, marker_id=3, marker_length=0.06)
        found = _detect(photo.image)
        assert list(found) == [3]
        err = np.linalg.norm(found[3] - photo.corners_px[3], axis=1)
        assert err.max() < tol.synth_corner_px, err
        pin = cam.project(marker_object_points(0.06), pose, distort=False)
        shift.append(np.linalg.norm(pin - photo.corners_px[3], axis=1).max())
    if cam is CAM_K1:  # the distortion really is in the image, not just in the truth
        assert max(shift) > 3.0


def test_rendered_charuco_matches_truth(tol):
    pose = look_at_pose([0.3, -0.4, 0.5], [0.1, -0.14, 0])
    photo = render_marker_photo(CAM_K1, pose, board=CHARUCO)
    det = cv2.aruco.CharucoDetector(CHARUCO.cv_board)
    cc, cid, _, mid = det.detectBoard(photo.image)
    assert cid is not None and len(cid) == 24 and sorted(mid.ravel().tolist()) == list(range(17))
    err = np.linalg.norm(cc.reshape(-1, 2) - photo.charuco_corners_px[cid.ravel()], axis=1)
    assert err.max() < tol.synth_charuco_corner_px, err


def test_render_bad_args():
    pose = look_at_pose([0.0, -0.3, 0.4], [0, 0, 0])
    with pytest.raises(UsageError):
        render_marker_photo(CAM, pose)  # neither marker_length nor board
    with pytest.raises(UsageError):
        render_marker_photo(CAM, pose, marker_length=0.05, jpeg_quality=0)
    with pytest.raises(UsageError):
        render_marker_photo(CAM, pose, marker_length=0.05, marker_id=250)
    with pytest.raises(ShapeError, match="cam_from_world"):
        render_marker_photo(CAM, np.full((4, 4), np.nan), marker_length=0.05)


# ---------------------------------------------------------------------------------------------------
# pose accuracy against the generating pose (the tracking acceptance tests acceptance)
# ---------------------------------------------------------------------------------------------------
N_POSES = 200


def _single_marker_run(n, seed):
    """n photos under the acceptance conditions; returns arrays of errors, ambiguity, flags, misses."""
    from arshadow.errors import MarkerNotFoundError
    from arshadow.tracking.tracker import MarkerTracker

    rng = np.random.default_rng(seed)
    rot, trans, amb, flagged, reported, misses = [], [], [], [], [], 0
    for i in range(n):
        d = rng.uniform(0.3, 0.8)
        frac = rng.uniform(0.05, 0.10)  # marker side as a fraction of the image width
        L = frac * CAM.width * d / CAM.fx
        mid = int(rng.integers(250))
        pose = random_pose(rng, CAM, distance=(d, d), tilt_deg=(0, 70), keep_in_view=marker_object_points(1.6 * L))
        photo = render_marker_photo(
            CAM,
            pose,
            marker_id=mid,
            marker_length=L,
            noise_sigma=2.0,
            blur_sigma=0.6,
            jpeg_quality=90,
            seed=seed * 10000 + i,
        )
        try:
            p = MarkerTracker(CAM, marker_length=L, marker_id=mid).estimate(photo.image)
        except MarkerNotFoundError:
            misses += 1
            continue
        rot.append(rotation_error_deg(p.cam_from_world[:3, :3], pose[:3, :3]))
        trans.append(np.linalg.norm(p.tvec - pose[:3, 3]) / np.linalg.norm(pose[:3, 3]))
        amb.append(p.pose_ambiguity)
        flagged.append(p.ambiguous)
        item = ReportItem(input=str(i))
        item.set_pose(p)
        reported.append(item.to_dict()["pose_ambiguity"])
    return np.array(rot), np.array(trans), np.array(amb), np.array(flagged), np.array(reported), misses


def test_single_marker_accuracy(tol):
    """>= 200 poses at 1280x720: marker 5-10 % of the width, 0.3-0.8 m, tilt 0-70 deg, noise 2, blur 0.6,
    JPEG 90. Errors against the pose the photo was generated from."""
    from arshadow.tracking.quality import AMBIGUITY_FLAG

    rot, trans, amb, flagged, reported, misses = _single_marker_run(N_POSES, seed=2)
    n_found = rot.size
    assert n_found >= tol.synth_detect_rate * N_POSES, f"only {n_found}/{N_POSES} markers detected"
    med_rot, p95_rot, med_trans = np.median(rot), np.percentile(rot, 95), np.median(trans)
    print(
        f"\nsingle marker, {n_found}/{N_POSES} found: rotation median {med_rot:.3f} deg, p95 {p95_rot:.3f}, "
        f"max {rot.max():.2f}; translation median {100 * med_trans:.3f} % of distance; "
        f"flagged {flagged.sum()}; > {tol.synth_rot_flag_deg} deg: {(rot > tol.synth_rot_flag_deg).sum()}"
    )
    assert med_rot <= tol.synth_rot_median_deg
    assert p95_rot <= tol.synth_rot_p95_deg
    assert med_trans <= tol.synth_trans_median_rel
    # none silently wrong: every frame off by more than 5 degrees carries the flag, in the report too
    wrong = rot > tol.synth_rot_flag_deg
    assert np.all(flagged[wrong]), (
        f"unflagged wrong poses: errors {rot[wrong & ~flagged]}, ratios {amb[wrong & ~flagged]}"
    )
    assert np.all(reported[wrong] >= AMBIGUITY_FLAG)
    assert np.all((amb > 0) & (amb <= 1))


def _small_frontal_poses(refine: str):
    """``(pose, estimate)`` where the planar flip ambiguity really bites: 60 small (35-70 px), nearly frontal
    (tilt 0-30 deg), noisy markers tracked with ``refine`` corners (the undetected ones skipped)."""
    from arshadow.errors import MarkerNotFoundError
    from arshadow.tracking.tracker import MarkerTracker

    rng = np.random.default_rng(21)
    for i in range(60):
        d = rng.uniform(0.5, 0.8)
        L = rng.uniform(35, 70) * d / CAM.fx
        pose = random_pose(rng, CAM, distance=(d, d), tilt_deg=(0, 30), keep_in_view=marker_object_points(1.6 * L))
        photo = render_marker_photo(
            CAM, pose, marker_id=5, marker_length=L, noise_sigma=3.0, blur_sigma=0.8, jpeg_quality=80, seed=i
        )
        try:
            yield pose, MarkerTracker(CAM, marker_length=L, marker_id=5, refine=refine).estimate(photo.image)
        except MarkerNotFoundError:
            continue


def test_ambiguity_flag_catches_flips():
    """Where the planar flip ambiguity really bites (small, nearly frontal, noisy markers), every frame
    whose chosen IPPE solution is the *wrong* one of the pair by more than 5 deg is flagged.
    (Non-flip failures in that regime are not all caught: see docs/tracking.md.) ``subpix`` corners: with the
    default ``edge`` corners this regime gives no flip at all (test_edge_corners_do_not_flip_there)."""
    flips = 0
    for pose, p in _small_frontal_poses("subpix"):
        e = rotation_error_deg(p.cam_from_world[:3, :3], pose[:3, :3])
        e_alt = rotation_error_deg(p.alternative.cam_from_world[:3, :3], pose[:3, :3])
        if e > 5.0 and e_alt < e:
            flips += 1
            assert p.ambiguous, (
                f"flipped pose not flagged: error {e:.1f} deg (other solution {e_alt:.1f}), ratio {p.pose_ambiguity:.2f}"
            )
    assert flips >= 1  # the regime does produce flips: the check above is not vacuous


def test_edge_corners_do_not_flip_there():
    """The same small, nearly frontal, noisy markers with the default (``edge``) corners: no pose more than 5
    deg off at all (the reason the default changed from ``subpix``; docs/tracking.md)."""
    errors = [rotation_error_deg(p.cam_from_world[:3, :3], pose[:3, :3]) for pose, p in _small_frontal_poses("edge")]
    assert len(errors) >= 50 and max(errors) <= 5.0, (len(errors), max(errors))


def test_charuco_accuracy_and_board_beats_marker(tol):
    """ChArUco board: median rotation error <= 0.1 deg; and on the same photos a single marker of the
    board (the one nearest its centre) is clearly worse: several markers of a known layout win."""
    from arshadow.errors import MarkerNotFoundError
    from arshadow.tracking.tracker import MarkerTracker

    rng = np.random.default_rng(7)
    bw, bh = CHARUCO.extent
    centre = np.array([bw / 2, -bh / 2, 0.0])
    board_rot, single_rot, board_t, single_t = [], [], [], []
    centre_id = min(
        CHARUCO.marker_corners_world,
        key=lambda i: np.linalg.norm(CHARUCO.marker_corners_world[i].mean(axis=0) - centre),
    )
    c_world = CHARUCO.marker_corners_world[centre_id].mean(axis=0)
    paper = np.array([[-0.02, 0.02, 0], [bw + 0.02, 0.02, 0], [bw + 0.02, -bh - 0.02, 0], [-0.02, -bh - 0.02, 0]])
    tb = MarkerTracker(CAM, board=CHARUCO)
    for i in range(40):
        pose = random_pose(rng, CAM, distance=(0.45, 0.8), tilt_deg=(0, 60), keep_in_view=paper, target=centre)
        photo = render_marker_photo(
            CAM, pose, board=CHARUCO, noise_sigma=2.0, blur_sigma=0.6, jpeg_quality=90, seed=100 + i
        )
        try:
            pb = tb.estimate(photo.image)
            ps = MarkerTracker(CAM, marker_length=CHARUCO.marker_length, marker_id=centre_id).estimate(photo.image)
        except MarkerNotFoundError:
            continue
        board_rot.append(rotation_error_deg(pb.cam_from_world[:3, :3], pose[:3, :3]))
        single_rot.append(rotation_error_deg(ps.cam_from_world[:3, :3], pose[:3, :3]))
        true_c = pose[:3, :3] @ c_world + pose[:3, 3]
        board_t.append(np.linalg.norm(pb.cam_from_world[:3, :3] @ c_world + pb.tvec - true_c))
        single_t.append(np.linalg.norm(ps.tvec - true_c))
    board_rot, single_rot = np.array(board_rot), np.array(single_rot)
    assert board_rot.size >= 36
    print(
        f"\nChArUco board: rotation median {np.median(board_rot):.4f} deg (p95 {np.percentile(board_rot, 95):.3f}); "
        f"single marker {centre_id} on the same photos: median {np.median(single_rot):.3f} deg; "
        f"position of that marker: board {1000 * np.median(board_t):.2f} mm, single {1000 * np.median(single_t):.2f} mm"
    )
    assert np.median(board_rot) <= tol.charuco_rot_median_deg
    assert np.median(board_rot) < tol.board_vs_marker_rot_ratio * np.median(single_rot)
    assert np.median(board_t) < np.median(single_t)


def test_gridboard_beats_single_marker(tol):
    """A 5x7 grid board of 40 mm markers against one of its own markers, same photos: the board's pose
    (140 points) is more accurate than the single marker's (4 points)."""
    from arshadow.errors import MarkerNotFoundError
    from arshadow.tracking.board import load_board
    from arshadow.tracking.tracker import MarkerTracker

    board = load_board(ROOT / "calib" / "gridboard_5x7.yml")
    rng = np.random.default_rng(8)
    bw, bh = board.extent
    centre = np.array([bw / 2, -bh / 2, 0.0])
    paper = np.array([[0, 0, 0], [bw, 0, 0], [bw, -bh, 0], [0, -bh, 0.0]])
    mid = 17  # the centre marker (row 3, column 2)
    tb = MarkerTracker(CAM, board=board)
    ts = MarkerTracker(CAM, marker_length=board.marker_length, marker_id=mid)
    b_rot, s_rot = [], []
    for i in range(24):
        pose = random_pose(rng, CAM, distance=(0.5, 0.9), tilt_deg=(0, 60), keep_in_view=paper, target=centre)
        photo = render_marker_photo(CAM, pose, board=board, noise_sigma=2.0, blur_sigma=0.6, jpeg_quality=90, seed=i)
        try:
            pb, ps = tb.estimate(photo.image), ts.estimate(photo.image)
        except MarkerNotFoundError:
            continue
        b_rot.append(rotation_error_deg(pb.cam_from_world[:3, :3], pose[:3, :3]))
        s_rot.append(rotation_error_deg(ps.cam_from_world[:3, :3], pose[:3, :3]))
    assert len(b_rot) >= 22
    print(
        f"\ngrid board: rotation median {np.median(b_rot):.4f} deg; its marker {mid} alone: {np.median(s_rot):.3f} deg"
    )
    assert np.median(b_rot) < tol.board_vs_marker_rot_ratio * np.median(s_rot)
