"""The edge corner refinement (``refine="edge"``, arshadow.tracking.refine) on photos blurred in linear light.

A lens and the sensor's pixel area blur light; the camera's tone curve (sRGB) comes after. The photos here
are made that way: the print rendered at 4 x 4 the resolution, decoded to linear light, blurred there and
averaged over each pixel's area, then encoded. Blur in code values (as :mod:`arshadow.synth` renders) is
the other case. The truth is the generating pose's projected corners, never the code under test.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import TOL
from marker_views import VIEWS

from arshadow.camera.model import Intrinsics
from arshadow.compose.composite import linear_to_srgb, srgb_to_linear
from arshadow.synth.markers import camera_effects, look_at_pose, render_marker_photo, render_print_scene
from arshadow.tracking.dictionary import marker_object_points
from arshadow.tracking.refine import refine_corners_edges, refine_edges
from arshadow.tracking.tracker import MarkerTracker

ROOT = Path(__file__).resolve().parents[1]
CAM = Intrinsics.from_file(ROOT / "calib" / "synth_1280x720.yml").scaled(640, 360)
L = 0.05


def linear_light_photo(cam, pose, marker_id, blur, *, dictionary="DICT_6X6_250", length=L, seed=0, jpeg=90):
    """A photo (BGR uint8) whose pixel area and Gaussian blur (sigma ``blur`` px) act in linear light:
    the print at 4 x 4 the resolution, decoded, blurred, area-averaged, sRGB-encoded; noise 1, JPEG."""
    s = 4
    hi = render_print_scene(
        cam.scaled(cam.width * s, cam.height * s), pose, marker_id=marker_id, marker_length=length,
        dictionary=dictionary, supersample=1,
    )["image"]  # fmt: skip
    lin = srgb_to_linear(np.clip(hi, 0, 255) / 255.0).astype(np.float32)
    if blur:
        lin = cv2.GaussianBlur(lin, (0, 0), blur * s)
    lin = cv2.resize(lin, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
    return camera_effects(
        (linear_to_srgb(lin) * 255.0).astype(np.float32), noise_sigma=1.0, seed=seed, jpeg_quality=jpeg
    )


def errors(corners, truth):
    """(worst corner error px, mean radial offset px: + outwards, the marker's scale error)."""
    d = corners - truth
    out = (truth - truth.mean(axis=0)) / np.linalg.norm(truth - truth.mean(axis=0), axis=1, keepdims=True)
    return float(np.linalg.norm(d, axis=1).max()), float(np.mean(np.sum(d * out, axis=1)))


def start_corners(cam, image, marker_id, dictionary="DICT_6X6_250"):
    """OpenCV's unrefined corners of ``marker_id`` (1, 4, 2) and the photo's grey."""
    det = MarkerTracker(cam, marker_length=L, refine="none", dictionary=dictionary).detect(image)
    i = det.ids.tolist().index(marker_id)
    return det.corners[i : i + 1], cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


@pytest.mark.parametrize("blur", [0.0, 0.8])
def test_edge_corners_in_linear_light(blur):
    """Pixel area (and a 0.8 px blur) in linear light: every edge corner within TOL.edge_linear_corner_px,
    the marker's scale within TOL.edge_linear_scale_px. The code-value crossings alone (the refinement
    before 2026-11-28) put every corner 0.21-0.82 px inwards here."""
    for k, view in enumerate(VIEWS):
        pose = look_at_pose(*view)
        image = linear_light_photo(CAM, pose, k + 3, blur, seed=k)
        truth = CAM.project(marker_object_points(L), pose)
        start, gray = start_corners(CAM, image, k + 3)
        res = refine_edges(gray, start, CAM)
        worst, scale = errors(res.corners[0], truth)
        assert worst < TOL.edge_linear_corner_px and abs(scale) < TOL.edge_linear_scale_px, (k, worst, scale)
        assert res.linear_weight[0] > 0.9, (k, res.linear_weight)  # the border says: linear light
        code = refine_corners_edges(gray, start, CAM, space="code")[0]
        assert errors(code, truth)[1] < -0.15, k  # (what the old crossings did: the photos show the bias)


def test_edge_corners_blurred_in_code_values_keep_the_code_fit():
    """Blur in code values (arshadow.synth's photos): the border shows no bias, the corners are the code-value
    fit's exactly (the refinement before 2026-11-28), within TOL.edge_linear_corner_px of the truth."""
    cam = Intrinsics.from_file(ROOT / "calib" / "synth_1280x720.yml")
    for k, view in enumerate(VIEWS):
        pose = look_at_pose(*view)
        ph = render_marker_photo(cam, pose, marker_length=L, marker_id=k + 3, blur_sigma=0.8, noise_sigma=2.0,
                                 jpeg_quality=90, seed=k)  # fmt: skip
        start, gray = start_corners(cam, ph.image, k + 3)
        res = refine_edges(gray, start, cam)
        assert res.linear_weight[0] == 0.0, (k, res.linear_weight, res.bias_code_px, res.bias_code_se_px)
        assert np.array_equal(res.corners, refine_corners_edges(gray, start, cam, space="code"))
        assert errors(res.corners[0], cam.project(marker_object_points(L), pose))[0] < TOL.edge_linear_corner_px


def test_edge_corners_blurred_partly_in_each_space():
    """A photo whose pixel area acts in code values and its 1 px blur in linear light (bench_ecc.py's and
    test_ecc_refine.py's "linear" photos) lies between the two fits: the interpolated corners keep the
    marker's scale within TOL.edge_linear_scale_px (code values alone: 0.73-0.78 px inwards)."""
    cam = Intrinsics.from_file(ROOT / "calib" / "synth_1280x720.yml")
    for k, view in enumerate(VIEWS):
        pose = look_at_pose(*view)
        img = render_print_scene(cam, pose, marker_id=k + 3, marker_length=L)["image"]
        lin = cv2.GaussianBlur(srgb_to_linear(img / 255.0).astype(np.float32), (0, 0), 1.0)
        image = camera_effects(
            (linear_to_srgb(lin) * 255.0).astype(np.float32), noise_sigma=2.0, seed=k, jpeg_quality=90
        )
        start, gray = start_corners(cam, image, k + 3)
        res = refine_edges(gray, start, cam)
        _, scale = errors(res.corners[0], cam.project(marker_object_points(L), pose))
        assert abs(scale) < TOL.edge_linear_scale_px and 0.5 < res.linear_weight[0] < 0.95, (
            k,
            scale,
            res.linear_weight,
        )


def test_edge_in_linear_light_behind_a_distorted_lens():
    """Behind a strong lens (k1 -0.3, 45-50 px markers near the image's edges) the border is measured in
    pinhole pixels too: the tracker's edge corners within TOL.edge_linear_corner_px."""
    lens = Intrinsics(350.0, 350.0, 319.5, 179.5, 640, 360, np.array([-0.3, 0.09, 0.0, 0.0, 0.0]))
    for k, (eye, target) in enumerate(
        [
            ([0.35, 0.2, 0.35], [0.18, 0.1, 0]),
            ([-0.3, -0.25, 0.3], [-0.18, -0.1, 0]),
            ([0.3, -0.22, 0.32], [0.18, -0.1, 0]),
        ]
    ):
        pose = look_at_pose(eye, target)
        image = linear_light_photo(lens, pose, 5, 0.8, length=0.08, seed=k)
        corners = MarkerTracker(lens, marker_length=0.08, refine="edge").estimate(image).corners[:4]
        worst, scale = errors(corners, lens.project(marker_object_points(0.08), pose))
        assert worst < TOL.edge_linear_corner_px and abs(scale) < TOL.edge_linear_scale_px, (k, worst, scale)


def test_the_tracker_tells_the_edge_refinement_the_markers_cells():
    """A 4 x 4 dictionary's marker is 6 cells across: the tracker says so (told 8, the border is measured in
    the wrong place and the corners stay 0.8-1.1 px inwards here)."""
    for k in range(3):
        pose = look_at_pose(*VIEWS[k])
        image = linear_light_photo(CAM, pose, k + 3, 0.8, dictionary="DICT_4X4_50", seed=k)
        tr = MarkerTracker(CAM, marker_length=L, refine="edge", dictionary="DICT_4X4_50")
        worst, scale = errors(tr.estimate(image).corners[:4], CAM.project(marker_object_points(L), pose))
        assert worst < TOL.edge_linear_corner_px and abs(scale) < TOL.edge_linear_scale_px, (k, worst, scale)


def test_edge_refinement_rejects_an_unknown_space():
    with pytest.raises(ValueError, match="space must be one of"):
        refine_edges(np.zeros((10, 10), np.uint8), np.zeros((1, 4, 2)), space="gamma")
