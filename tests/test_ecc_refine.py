"""The ECC corner refinement (``refine="ecc"``, arshadow.tracking.ecc) against the generating pose.

The truth is the pose each synthetic photo is rendered from (its projected corners), never the code under
test. Blur is applied in code values (as arshadow.synth does) and in linear light (as a lens blurs light
before the camera's tone curve: the case the edge refinement is biased in).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import TOL
from marker_views import VIEWS

import arshadow.tracking.tracker as tracker_module
from arshadow.camera.model import Intrinsics
from arshadow.synth.markers import camera_effects, look_at_pose, render_marker_photo, render_print_scene
from arshadow.tracking.board import load_board
from arshadow.tracking.dictionary import marker_bits, marker_object_points
from arshadow.tracking.ecc import refine_corners_ecc
from arshadow.tracking.tracker import MarkerTracker
from arshadow.transforms import rotation_error_deg

ROOT = Path(__file__).resolve().parents[1]
CAM = Intrinsics.from_file(ROOT / "calib" / "synth_1280x720.yml")
L = 0.05


def _photo(k: int, linear_blur: bool) -> tuple[np.ndarray, np.ndarray, int]:
    """Photo ``k`` (BGR uint8), its true corners (4, 2) and its marker id."""
    pose = look_at_pose(*VIEWS[k])
    mid = k + 3
    if linear_blur:
        img = render_print_scene(CAM, pose, marker_id=mid, marker_length=L)["image"]
        image = camera_effects(img, blur_sigma=1.0, blur_linear=True, noise_sigma=2.0, seed=k, jpeg_quality=90)
    else:
        image = render_marker_photo(
            CAM, pose, marker_length=L, marker_id=mid, blur_sigma=0.8, noise_sigma=2.0, jpeg_quality=90, seed=k
        ).image
    return image, CAM.project(marker_object_points(L), pose), mid


@pytest.mark.parametrize("linear_blur", [False, True], ids=["code-blur", "linear-blur"])
def test_ecc_corners_match_the_generating_pose(linear_blur):
    """Every ECC corner within TOL.ecc_corner_px of the projected true corner, no systematic offset (a
    half-pixel convention error would show as 0.5 px), and the alignment used (no fallback)."""
    for k in range(len(VIEWS)):
        image, truth, mid = _photo(k, linear_blur)
        pose = MarkerTracker(CAM, marker_length=L, refine="ecc").estimate(image)
        assert pose.marker_ids == [mid] and pose.refine == "ecc" and pose.refine_note is None
        err = pose.corners[:4] - truth
        assert np.linalg.norm(err, axis=1).max() < TOL.ecc_corner_px, (k, err)
        assert np.linalg.norm(err.mean(axis=0)) < TOL.ecc_corner_centroid_px, (k, err)


def test_ecc_with_a_distorted_lens():
    """Behind a strong lens (k1 -0.3) the alignment is made in pinhole pixels: the corners match the truth
    to TOL.ecc_distorted_corner_px (aligning in the distorted image errs 0.24-0.33 px here)."""
    lens = Intrinsics(700.0, 700.0, 639.5, 359.5, 1280, 720, np.array([-0.3, 0.09, 0.0, 0.0, 0.0]))
    for k, (eye, target) in enumerate(
        [
            ([0.35, 0.2, 0.35], [0.18, 0.1, 0]),
            ([-0.3, -0.25, 0.3], [-0.18, -0.1, 0]),
            ([0.3, -0.22, 0.32], [0.18, -0.1, 0]),
        ]
    ):
        ph = render_marker_photo(lens, look_at_pose(eye, target), marker_length=L, marker_id=5, blur_sigma=0.6,
                                 noise_sigma=1.0, seed=k)  # fmt: skip
        pose = MarkerTracker(lens, marker_length=L, refine="ecc").estimate(ph.image)
        assert pose.refine_note is None
        assert np.linalg.norm(pose.corners[:4] - ph.corners_px[5], axis=1).max() < TOL.ecc_distorted_corner_px, k


def test_failed_alignment_keeps_the_edge_corners():
    """A marker that ECC cannot align keeps its starting corners exactly, and says why: the wrong marker's
    bitmap (low correlation or a large move), a blank image (ECC fails), a start too close to the border."""
    image, truth, mid = _photo(0, False)
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    start = truth[None] + 0.3
    res = refine_corners_ecc(gray, start, marker_bits("DICT_6X6_250", mid + 1), CAM)
    assert res.fallback[0] is not None and np.array_equal(res.corners, start)
    res = refine_corners_ecc(np.full_like(gray, 128), start, marker_bits("DICT_6X6_250", mid), CAM)
    assert res.fallback[0] is not None and np.array_equal(res.corners, start)
    res = refine_corners_ecc(gray, start - start[0, 0] + 1.0, marker_bits("DICT_6X6_250", mid), None)
    assert res.fallback[0] == "too close to the image border"
    ok = refine_corners_ecc(gray, start, marker_bits("DICT_6X6_250", mid), CAM)  # the right bitmap: used
    assert ok.fallback == (None,) and np.linalg.norm(ok.corners[0] - truth, axis=1).max() < TOL.ecc_corner_px


def test_tracker_reports_the_fallback(monkeypatch):
    """When the alignment is refused (here: any move at all), the tracker's corners are the edge
    refinement's, bit for bit, and the pose carries a note (a report field, not a flag)."""
    image, _, mid = _photo(1, False)
    edge = MarkerTracker(CAM, marker_length=L, refine="edge").estimate(image)

    def refuse(gray, corners, bits, intrinsics=None, **kw):
        return refine_corners_ecc(gray, corners, bits, intrinsics, max_move_px=0.0)

    monkeypatch.setattr(tracker_module, "refine_corners_ecc", refuse)
    pose = MarkerTracker(CAM, marker_length=L, refine="ecc").estimate(image)
    assert np.array_equal(pose.corners, edge.corners)
    assert pose.refine_note is not None and f"marker {mid}" in pose.refine_note
    assert any(n.startswith("refinement:") for n in pose.notes)
    assert not any(r.startswith("refinement:") for r in pose.flag_reasons)


def test_ecc_inverted_marker():
    """A marker printed white on black (the photo's negative) is aligned on its negative."""
    image, truth, mid = _photo(2, False)
    gray = 255 - cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    res = refine_corners_ecc(gray, truth[None] + [0.3, -0.3], marker_bits("DICT_6X6_250", mid), CAM)
    assert res.fallback == (None,) and np.linalg.norm(res.corners[0] - truth, axis=1).max() < TOL.ecc_corner_px


def test_ecc_grid_board_keeps_the_edge_corners():
    """A grid board keeps the edge corners under ``ecc`` (its many corners average their errors out: ECC on a
    5 x 7 board measured no rotation gain for twice the time, docs/tracking.md): the same pose bit for bit."""
    board = load_board(ROOT / "calib" / "gridboard_5x7.yml")
    ph = render_marker_photo(CAM, look_at_pose([0.25, -0.45, 0.6], [0.12, -0.18, 0]), board=board, blur_sigma=0.8,
                             noise_sigma=2.0, seed=4)  # fmt: skip
    pose = MarkerTracker(CAM, board=board, refine="ecc").estimate(ph.image)
    edge = MarkerTracker(CAM, board=board, refine="edge").estimate(ph.image)
    assert len(pose.marker_ids) >= 30 and np.array_equal(pose.cam_from_world, edge.cam_from_world)
    assert rotation_error_deg(pose.cam_from_world[:3, :3], ph.cam_from_world[:3, :3]) < TOL.charuco_rot_median_deg


def test_videos_keep_the_edge_refinement_photos_take_ecc():
    """The default refinement is ``ecc`` for photos and ``edge`` for videos (a scene tracked in a window round
    the last detection, ``track_roi``, as the video API and ``arshadow video`` set it): docs/tracking.md
    measured ecc's per-frame cost in the video pipeline. An explicit refinement is kept for both."""
    import dataclasses

    from arshadow.frame.session import Session
    from arshadow.scene.spec import scene_from_dict
    from arshadow.tracking.detect import DEFAULT_REFINE, VIDEO_REFINE

    assert (DEFAULT_REFINE, VIDEO_REFINE) == ("ecc", "edge")
    d = {"calib": CAM, "marker_length": 0.05, "model": "box:0.02,0.02,0.02", "lights": ["directional:0,0,1"]}
    for extra, photo_refine, video_refine in (({}, "ecc", "edge"), ({"refine": "ecc"}, "ecc", "ecc")):
        spec = scene_from_dict({**d, **extra})
        video = dataclasses.replace(spec, options=dataclasses.replace(spec.options, track_roi=True))
        with Session(spec) as s_photo, Session(video) as s_video:
            assert s_photo.hooks.calibration(CAM.width, CAM.height).trackers()[1].refine == photo_refine
            assert s_video.hooks.calibration(CAM.width, CAM.height).trackers()[1].refine == video_refine
