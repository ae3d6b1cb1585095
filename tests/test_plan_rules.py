"""The planner's pure decisions (arshadow/plan/rules.py), each taken when it should be and never when it
must not be. Ground truth is independent: hand-built meshes whose convexity is known, cameras placed inside
or outside a volume by construction, footprints far off screen by construction."""

from __future__ import annotations

import numpy as np
import pytest

from arshadow.errors import MarkerNotFoundError
from arshadow.geometry.mesh import ShadowCaster, load_occluder
from arshadow.plan.rules import (
    light_shadow_in_view,
    planar_applies,
    reuse_light_geometry,
    same_silhouette,
    zpass_safe,
)
from arshadow.tracking.roi_track import tracking_roi


def _l_shape():
    """A closed L-shaped prism (non-convex: the inner corner), built by hand."""
    p = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float) * 0.02
    n = len(p)
    v = np.r_[np.c_[p, np.zeros(n)], np.c_[p, np.full(n, 0.03)]]
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]
    # caps (fan triangulation of the L is fine from vertex 0? no: use an explicit split into two rectangles)
    bottom = [[0, 3, 1], [1, 3, 2], [0, 5, 3], [3, 5, 4]]
    faces += bottom + [[n + a, n + c, n + b] for a, b, c in bottom]
    return ShadowCaster(v, faces)


def test_convexity_of_known_meshes():
    assert _l_shape().is_closed
    for spec in ("box:0.06,0.05,0.09", "sphere:0.04", "cylinder:0.03,0.1"):
        assert load_occluder(spec).is_convex, spec
    assert not load_occluder("torus:0.06,0.02").is_convex
    assert not _l_shape().is_convex
    # an open mesh (one triangle) is never called convex
    assert not ShadowCaster([[0, 0, 0.01], [1, 0, 0.01], [0, 1, 0.01]], [[0, 1, 2]]).is_convex


def test_planar_taken_only_where_exact():
    box = load_occluder("box:0.06,0.05,0.09")
    L = [0.2, 0.1, 0.5, 1.0]
    ok, why = planar_applies(box, L, convex=True, draw_occluder=True)
    assert ok and "convex" in why
    # non-convex occluder drawn (self-shadowing): never planar, whatever the light
    lsh = _l_shape()
    for light in (L, [0.0, 0.0, 1.0, 0.0], [0.3, -0.4, 2.0, 1.0]):
        assert not planar_applies(lsh, light, convex=lsh.is_convex, draw_occluder=True)[0]
    # ... but it is when the occluder is not drawn (only the ground receives)
    assert planar_applies(lsh, L, convex=False, draw_occluder=False)[0]
    # a point light at or below the top of the mesh, a sun at / below the horizon: never
    assert not planar_applies(box, [0.2, 0.1, 0.09, 1.0], convex=True, draw_occluder=False)[0]
    assert not planar_applies(box, [0.2, 0.1, 0.05, 1.0], convex=True, draw_occluder=False)[0]
    assert not planar_applies(box, [1.0, 0.0, 0.0, 0.0], convex=True, draw_occluder=False)[0]
    assert not planar_applies(box, [1.0, 0.0, -0.1, 0.0], convex=True, draw_occluder=False)[0]
    # a mesh reaching below the ground: never
    sunk = load_occluder("box:0.06,0.05,0.09", place=(0, 0, -0.01))
    assert not planar_applies(sunk, L, convex=True, draw_occluder=False)[0]


def test_zpass_never_with_the_camera_inside_the_volume():
    box = load_occluder("box:0.06,0.05,0.09")
    L = np.array([0.0, 0.0, 0.5, 1.0])
    # below the box, on the light's axis: inside the volume by construction
    assert not zpass_safe(box, L, [0.0, 0.0, 0.01], 0.001)[0]
    # between the box and the ground, off the axis but still under the box's shadow
    assert not zpass_safe(box, L, [0.01, -0.01, 0.02], 0.001)[0]
    # far to the side and above: outside
    assert zpass_safe(box, L, [0.5, -0.4, 0.3], 0.001)[0]
    # just outside the volume but within the near radius of it: not provably safe -> z-fail
    assert not zpass_safe(box, L, [0.031 + 0.0005, 0.0, 0.02], 0.002)[0]


def test_light_culling_only_when_footprint_off_canvas_and_no_self_shadow():
    canvas = (100, 50, 400, 300)
    inside = (150.0, 60.0, 300.0, 200.0)
    left = (-500.0, 60.0, 90.0, 200.0)
    assert light_shadow_in_view(inside, canvas, occluder_matters=False)[0]
    assert not light_shadow_in_view(left, canvas, occluder_matters=False)[0]
    # touching the canvas' edge pixel: kept
    assert light_shadow_in_view((-500.0, 60.0, 99.5, 200.0), canvas, occluder_matters=False)[0]
    # self-shadowing may be visible, or unbounded footprint: never culled
    assert light_shadow_in_view(left, canvas, occluder_matters=True)[0]
    assert light_shadow_in_view(None, canvas, occluder_matters=False)[0]


def test_geometry_reuse_follows_the_facing_and_the_float32_volume():
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume

    knot = load_occluder("torus:0.06,0.02", rotate=(30, 10, 0), place=(0, 0, 0.05))
    L = np.array([0.2, 0.1, 0.5, 1.0])
    sil = silhouette(knot, L)
    vols = {True: shadow_volume(knot, L, sil, caps=True, truncate_z=-1e-4)}
    # the same light: everything reused, the very same volume object (the renderer skips the upload)
    s2, v2, why = reuse_light_geometry(knot, L.copy(), sil, vols, truncate_z=-1e-4)
    assert s2 is not None and v2[True] is vols[True] and "reused" in why
    # moved by far less than float32 resolution of the vertices: still the same object
    s3, v3, _ = reuse_light_geometry(knot, L + [1e-13, 0, 0, 0], sil, vols, truncate_z=-1e-4)
    assert v3[True] is vols[True]
    # moved a little: same facing -> silhouette kept, volume re-extruded, equal to a fresh one
    Lm = L + [2e-6, 0.0, 0.0, 0.0]
    assert same_silhouette(knot.face_planes, sil.facing, Lm)
    s4, v4, why = reuse_light_geometry(knot, Lm, sil, vols, truncate_z=-1e-4)
    fresh = shadow_volume(knot, Lm, silhouette(knot, Lm), caps=True, truncate_z=-1e-4)
    assert v4[True] is not vols[True] and "re-extruded" in why
    np.testing.assert_array_equal(v4[True].vertices, fresh.vertices)
    np.testing.assert_array_equal(v4[True].triangles, fresh.triangles)
    # moved a lot: a face flips -> recompute
    s5, v5, why = reuse_light_geometry(knot, [-0.3, 0.2, 0.3, 1.0], sil, vols, truncate_z=-1e-4)
    assert s5 is None and v5 == {} and "recomputed" in why


def test_tracking_roi_window():
    c = np.array([[600, 300], [680, 300], [680, 380], [600, 380]], float)
    x0, y0, w, h = tracking_roi(c, 1280, 720)
    assert x0 <= 600 - 40 and y0 <= 300 - 40 and x0 + w >= 680 + 40 and y0 + h >= 380 + 40
    assert tracking_roi(np.array([[5, 5], [1270, 710]], float), 1280, 720) is None  # most of the frame
    assert tracking_roi(np.zeros((0, 2)), 1280, 720) is None


def test_tracking_detector_window_then_fallback(tol):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo
    from arshadow.tracking.roi_track import TrackingDetector
    from arshadow.tracking.tracker import MarkerTracker

    intr = Intrinsics(900.0, 900.0, 639.5, 359.5, 1280, 720, np.zeros(5))
    trk = MarkerTracker(intr, marker_length=0.05)
    full = MarkerTracker(intr, marker_length=0.05)
    trk._detector = td = TrackingDetector(trk._detector)
    poses = [
        look_at_pose([0.05, -0.3, 0.35], [0.0, 0.0, 0.0]),
        look_at_pose([0.06, -0.3, 0.35], [0.0, 0.0, 0.0]),
        look_at_pose([0.05, -0.3, 0.35], [0.12, 0.08, 0.0]),
    ]  # last: a jump (outside the window)
    kinds = []
    for pose in poses:
        img = render_marker_photo(intr, pose, marker_length=0.05, seed=1).image
        a = trk.estimate(img)
        b = full.estimate(img)
        kinds.append(td.last)
        np.testing.assert_allclose(a.cam_from_world, b.cam_from_world, atol=tol.tracking_window_pose_atol)
    assert kinds[0] == "full" and kinds[1] == "window"
    # a frame with no marker at all: full-frame fallback, then the window is forgotten
    blank = np.full((720, 1280, 3), 128, np.uint8)
    with pytest.raises(MarkerNotFoundError):
        trk.estimate(blank)
    assert td.last == "full" and td.window is None


def test_outside_view_only_when_one_plane_excludes_everything():
    from arshadow.plan.rules import outside_view

    ext = (-0.5, -0.5, 639.5, 479.5)
    k = dict(fx=500.0, fy=500.0, cx=319.5, cy=239.5, extent=ext, znear=0.01)
    behind = np.array([[0.0, 0.0, -1.0], [0.3, 0.2, -0.5]])
    assert outside_view(behind, **k)
    # straddling the eye (one point in front, in view): visible
    assert not outside_view(np.r_[behind, [[0.0, 0.0, 1.0]]], **k)
    # all far to the left of the view (u < -0.5), some of them behind the camera: outside
    left = np.array([[-5.0, 0.0, 1.0], [-3.0, 0.0, 0.5], [-2.0, 0.0, -0.2]])
    assert outside_view(left, **k)
    # a segment crossing the view from far left to far right at z = 1: its hull is visible
    assert not outside_view(np.array([[-5.0, 0.0, 1.0], [5.0, 0.0, 1.0]]), **k)
