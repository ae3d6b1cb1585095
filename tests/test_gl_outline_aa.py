"""The object's anti-aliased outline on the renderer's layers and through a session (GL).

The truth is computed here: the box's silhouette is the convex hull of its corners projected by the pinhole
camera (OpenCV's convex hull, the shoelace formula for its area), a pixel's exact coverage the area of its
square clipped by that hull (:func:`tests.test_outline_aa.clip_area`).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.conftest import TOL
from tests.test_outline_aa import clip_area, pixel_square, shoelace

pytestmark = pytest.mark.gl

W, H = 320, 240
ROOT = Path(__file__).resolve().parent.parent


def _K():
    from arshadow.camera.model import Intrinsics

    return Intrinsics(fx=400.0, fy=400.0, cx=(W - 1) / 2, cy=(H - 1) / 2, width=W, height=H, dist=np.zeros(0))


def _box_render(ctx):
    from arshadow.geometry.mesh import load_occluder
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import ShadowRenderer
    from arshadow.renderer.request import LightPass, RenderRequest
    from arshadow.synth.markers import look_at_pose
    from arshadow.transforms import CV_TO_GL

    box = load_occluder("box:0.045,0.065,0.07")
    pose = look_at_pose((0.07, -0.21, 0.17), (0.004, 0.003, 0.03))
    lh = np.array([0.3, -0.2, 1.0, 0.0])
    vol = shadow_volume(box, lh, silhouette(box, lh), caps=True)
    req = RenderRequest(
        projection=_K().gl_projection(0.01, None),
        view=CV_TO_GL @ pose,
        width=W,
        height=H,
        caster=box,
        passes=[LightPass(lh, 1.0, vol, "zfail")],
    )
    r = ShadowRenderer(ctx, max_width=W, max_height=H)
    try:
        return box, pose, req, r.render(req)
    finally:
        r.release()


def test_a_box_outlines_coverage_is_its_projected_silhouettes(ctx):
    from arshadow.compose.outline import antialias_outline
    from arshadow.geometry.contour import outline_segments

    box, pose, req, res = _box_render(ctx)
    before = res.alpha.copy()  # top-down
    assert res.layers is not None
    antialias_outline(res.layers.rgba, res.layers.mask_ground, outline_segments(box, req.projection, req.view, W, H))
    after = res.alpha  # a view of the layers
    # the truth: the corners by the pinhole camera (OpenCV pixel centres at integers, rows down)
    corners = _K().project(np.asarray(box.vertices, np.float64), pose)
    hull = cv2.convexHull(corners.astype(np.float32)).reshape(-1, 2).astype(np.float64)
    x, y = hull[:, 0], hull[:, 1]
    if np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)) < 0:  # clip_area's order: positive signed area
        hull = hull[::-1]
    area = shoelace(hull)
    assert abs(float(after.sum()) - area) < TOL.outline_area_px2
    x0, y0 = np.floor(hull.min(axis=0)).astype(int) - 1
    x1, y1 = np.ceil(hull.max(axis=0)).astype(int) + 2
    exact = np.zeros((H, W))
    exact[y0:y1, x0:x1] = [[clip_area(pixel_square(j, i), hull) for j in range(x0, x1)] for i in range(y0, y1)]
    edge = (exact > 0) & (exact < 1)
    err_aa, err_0 = np.abs(after - exact)[edge], np.abs(before - exact)[edge]
    assert err_aa.mean() < TOL.outline_edge_mean < 10 * TOL.outline_edge_mean < err_0.mean()
    # pixels one straight edge crosses, away from the corners: the half-plane's coverage
    yy, xx = np.mgrid[0:H, 0:W]
    far = np.min(np.hypot(xx[..., None] - hull[:, 0], yy[..., None] - hull[:, 1]), axis=-1) > 1.5
    single = edge & far
    assert single.sum() > 100
    assert np.abs(after - exact)[single].max() < 0.01  # the contour's float32 projection against float64


def _session_result(photo, layers=False, **keys):
    from arshadow.frame.session import Session
    from arshadow.scene.spec import scene_from_dict

    d = {
        "calib": str(ROOT / "calib" / "synth_1280x720.yml"),
        "marker_length": 0.05,
        "dictionary": "DICT_6X6_250",
        "model": "box:0.045,0.065,0.07",
        "place": (-0.02, 0.1, 0.0),
        "lights": ["directional:-0.6,-0.35,0.65"],
        **keys,
    }
    with Session(scene_from_dict(d)) as s:
        return s.process(photo, layers=layers)


def test_outline_aa_is_a_planner_decision_that_changes_only_the_outline(gl_ctx):
    from arshadow.frame.execute import OUTLINE_WHY
    from arshadow.io import read_image

    photo = read_image(str(ROOT / "samples" / "probe_shadow.jpg"))
    on = _session_result(photo, compose="gpu")  # forced shader path: the outline takes the numpy path
    assert on.item.plan["outline_aa"].startswith("on")
    assert on.item.compose == "cpu" and on.item.plan["compose"] == OUTLINE_WHY
    off = _session_result(photo, outline_aa="off", layers=True)
    assert off.item.plan["outline_aa"] == "off (--outline-aa off)"
    msaa = _session_result(photo, aa=4)
    assert msaa.item.plan["outline_aa"].startswith("off: MSAA")
    # the option changes the outline's pixels only: those beside a pixel of the other side (the lens warp's
    # bilinear taps reach one pixel further)
    alpha = off.layers.full()[0][:, :, 3]
    obj = (alpha > 0.5).astype(np.uint8)
    k = np.ones((3, 3), np.uint8)
    outline = cv2.dilate((cv2.dilate(obj, k) != cv2.erode(obj, k)).view(np.uint8), k) > 0
    changed = np.any(on.composite != off.composite, axis=2)
    assert changed.sum() > 100
    assert not np.any(changed & ~outline)


def test_auto_outline_aa_in_a_video_follows_the_sky_occlusion(gl_ctx):
    """``auto``: a video frame (``track_roi``) without sky occlusion keeps pixel-centre samples (its speed);
    with sky occlusion on, or ``on`` given, its outline is anti-aliased like a photo's."""
    from arshadow.io import read_image

    photo = read_image(str(ROOT / "samples" / "probe_shadow.jpg"))
    plain = _session_result(photo, track_roi=True)
    assert plain.item.plan["outline_aa"].startswith("off: a video without sky occlusion")
    sky = _session_result(photo, track_roi=True, ambient_occlusion="on")
    assert sky.item.plan["outline_aa"].startswith("on")
    forced = _session_result(photo, track_roi=True, outline_aa="on")
    assert forced.item.plan["outline_aa"].startswith("on")
    assert np.any(forced.composite != plain.composite)
