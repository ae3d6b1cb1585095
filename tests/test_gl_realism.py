"""GL side of the realism work: the ground occlusion map projected per frame (sky occlusion channel), the object's
sky shading, and base-colour textures, against independent computations."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.conftest import TOL

pytestmark = pytest.mark.gl

W, H = 640, 480
ZNEAR = 0.01
DATA = Path(__file__).parent / "data" / "textured"


def _K(fx=700.0):
    from arshadow.camera.model import Intrinsics

    return Intrinsics(fx=fx, fy=fx, cx=(W - 1) / 2, cy=(H - 1) / 2, width=W, height=H, dist=np.zeros(0))


def _renderer(ctx):
    from arshadow.gl.stencil import ShadowRenderer

    return ShadowRenderer(ctx, max_width=W, max_height=H)


def _render(r, caster, pose, *, sky=None, light=(0.3, -0.2, 1.0, 0.0), **shading):
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.renderer.request import LightPass, RenderRequest, Shading
    from arshadow.transforms import CV_TO_GL

    lh = np.asarray(light, np.float64)
    vol = shadow_volume(caster, lh, silhouette(caster, lh), caps=True)
    K = _K()
    return r.render(
        RenderRequest(
            projection=K.gl_projection(ZNEAR, None),
            view=CV_TO_GL @ pose,
            width=W,
            height=H,
            caster=caster,
            passes=[LightPass(lh, 1.0, vol, "zfail")],
            shading=Shading(sky=sky, **shading),
        )
    )


def _pixel(pose, xyz):
    K = _K()
    p = pose[:3, :3] @ np.asarray(xyz, float) + pose[:3, 3]
    return int(round(K.fx * p[0] / p[2] + K.cx)), int(round(K.fy * p[1] / p[2] + K.cy))


def test_contact_darker_than_open_ground_with_ao_and_equal_without(ctx):
    from arshadow.geometry.mesh import load_occluder
    from arshadow.shading.sky import SkyShading, ground_sky_visibility
    from arshadow.synth.markers import look_at_pose

    box = load_occluder("box:0.045,0.065,0.07")
    pose = look_at_pose([0.0, -0.35, 0.3], [0.0, 0.0, 0.02])
    g = ground_sky_visibility(box)
    r = _renderer(ctx)
    try:
        # light from the camera side (-y): the shadow falls behind the box, the ground in front is lit
        on = _render(r, box, pose, sky=SkyShading(ground=g), light=(0.0, -0.5, 1.0, 0.0))
        off = _render(r, box, pose, sky=None, light=(0.0, -0.5, 1.0, 0.0))
    finally:
        r.release()
    near = _pixel(pose, [0.0, -0.0325 - 0.003, 0.0])  # 3 mm in front of the front face
    far = _pixel(pose, [0.0, -0.0325 - 0.05, 0.0])  # 5 cm in front
    assert on.sky_occlusion is not None and off.sky_occlusion is None
    s_near, s_far = on.sky_occlusion[near[1], near[0]], on.sky_occlusion[far[1], far[0]]
    # the map's own values there (independent check of the projection: same ground points)
    v_near, v_far = g.sample(np.array([[0.0, -0.0355], [0.0, -0.0825]]))
    assert abs(s_near - (1 - v_near)) <= TOL.sky_projection_abs and abs(s_far - (1 - v_far)) <= TOL.sky_projection_abs
    assert s_near > s_far + 0.2  # darker at the contact
    # the direct shadow mask is the same with and without
    assert np.array_equal(on.mask, off.mask)
    # AO off: the composite of the two ground points is the same (no sky channel, equal direct mask 0)
    assert off.mask[near[1], near[0]] == off.mask[far[1], far[0]] == 0.0
    # the occluder covers no sky-occluded pixel (coverage-weighted: 0 where the box is)
    assert np.all(on.sky_occlusion[on.alpha >= 1.0] == 0.0)


def test_object_sky_shading_vertical_face_half_of_top(ctx):
    # convex box, sky shading with no direct light reaching the faces (weight 0): each face's colour is
    # ambient x sky visibility x albedo: top (V = 1) vs side (V = 1/2 under a uniform sky)
    from arshadow.geometry.mesh import load_occluder
    from arshadow.shading.sky import SkyShading
    from arshadow.synth.markers import look_at_pose

    box = load_occluder("box:0.06,0.06,0.06")
    pose = look_at_pose([0.0, -0.3, 0.25], [0.0, 0.0, 0.03])
    r = _renderer(ctx)
    try:
        res = _render(
            r, box, pose, sky=SkyShading(ground=None, object_sky="uniform"), ambient=0.5, diffuse=0.0, specular=0.0
        )
        plain = _render(r, box, pose, sky=None, ambient=0.5, diffuse=0.0, specular=0.0)
    finally:
        r.release()
    top = _pixel(pose, [0.0, 0.0, 0.06])
    side = _pixel(pose, [0.0, -0.03, 0.03])
    alb = (0.8 / 1.055 + 0.055 / 1.055) ** 2.4  # DEFAULT_COLOR 0.8 decoded (sRGB)
    assert res.color[top[1], top[0], 0] == pytest.approx(0.5 * alb, rel=2e-3)
    assert res.color[side[1], side[0], 0] == pytest.approx(0.25 * alb, rel=2e-3)
    assert plain.color[side[1], side[0], 0] == pytest.approx(0.5 * alb, rel=2e-3)


def test_textured_quad_matches_the_projected_texture(ctx):
    # the textured glTF square lying 1 mm above the ground, seen from above at an angle, unlit except by an
    # ambient of 1: its colour is the texture. Expected: the texture warped into the image by the analytic
    # homography of the square's plane (cv2.warpPerspective), in linear light.
    pytest.importorskip("PIL")
    from arshadow.geometry.mesh import load_occluder
    from arshadow.synth.markers import look_at_pose

    quad = load_occluder(DATA / "quad.glb", place=(0.0, 0.0, 0.001))
    pose = look_at_pose([0.05, -0.2, 0.25], [0.0, 0.0, 0.0])
    r = _renderer(ctx)
    try:
        res = _render(r, quad, pose, ambient=1.0, diffuse=0.0, specular=0.0, light=(0.0, 0.0, 1.0, 0.0))
    finally:
        r.release()
    tex = quad.material.texture  # (64, 64, 3) linear RGB, row 0 = top = +y edge of the square
    th, tw = tex.shape[:2]
    # texture pixel (col, row) -> world (x, y, 0.001): x = -0.05 + 0.1 (col + 0.5) / tw, y = 0.05 - 0.1 (row + 0.5) / th
    A = np.array([[0.1 / tw, 0.0, -0.05 + 0.05 / tw], [0.0, -0.1 / th, 0.05 - 0.05 / th], [0.0, 0.0, 1.0]])
    K = _K().K
    R, t = pose[:3, :3], pose[:3, 3]
    Hm = K @ np.c_[R[:, 0], R[:, 1], R[:, 2] * 0.001 + t] @ A  # texture pixel -> image pixel
    expect = cv2.warpPerspective(tex, Hm, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    inside = cv2.warpPerspective(np.ones((th, tw), np.float32), Hm, (W, H), flags=cv2.INTER_NEAREST)
    # compare away from the square's edges and the texture's colour edges (bilinear vs mipmapped sampling)
    interior = cv2.erode(inside, np.ones((5, 5), np.uint8)) > 0
    edges = (
        cv2.dilate((cv2.Canny((expect * 255).astype(np.uint8), 10, 30) > 0).astype(np.uint8), np.ones((5, 5), np.uint8))
        > 0
    )
    sel = interior & ~edges
    assert sel.sum() > 2000
    err = np.abs(res.color[sel] - expect[sel])
    assert np.median(err) <= TOL.texture_median_abs and np.percentile(err, 99) <= TOL.texture_p99_abs, (
        np.median(err),
        np.percentile(err, 99),
    )
    # and the untextured render (colour override) is flat: the texture did it
    assert res.color[sel].std(axis=0).max() > 0.1


def test_gpu_item_buffer_equals_the_numpy_one(ctx):
    from arshadow.geometry.mesh import load_occluder
    from arshadow.gl.sky import GLItemBuffer
    from arshadow.shading.raster import item_buffer

    c = load_occluder("torus:0.05,0.015", rotate=(30, 0, 0))
    w = np.array([0.3, 0.2, 0.9]) / np.linalg.norm([0.3, 0.2, 0.9])
    e1 = np.cross([1.0, 0, 0], w)
    e1 /= np.linalg.norm(e1)
    fr = np.stack([e1, np.cross(w, e1), w])
    pv = c.vertices @ fr.T
    lo, hi = pv[:, :2].min(0), pv[:, :2].max(0)
    xy = (pv[:, :2] - lo) * (254 / (hi - lo).max()) + 1
    f = c.faces[c.face_planes[:, :3] @ w > 0]
    ib = GLItemBuffer(ctx, 256)
    a = ib(xy, pv[:, 2], f, 256)
    b = item_buffer(xy, pv[:, 2], f, 256)
    assert (a >= 0).sum() > 5000 and (a != b).mean() < 1e-3  # ties on shared edges only


def test_session_rasterises_its_ground_map_once_on_the_gpu(ctx, monkeypatch):
    """A Session with sky occlusion builds one ground map per scene, with its renderer's GL rasteriser, for
    the planner's region and the executor alike (the planner asked numpy for it first: 7 s for the knot)."""
    import arshadow.shading.sky as sky
    from arshadow.frame.session import Session
    from arshadow.scene.spec import scene_from_dict
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    calls = []
    real = sky.ground_sky_visibility

    def counted(*a, **k):
        calls.append(type(k.get("raster")).__name__)
        return real(*a, **k)

    def refuse(*a, **k):
        raise AssertionError("the numpy rasteriser ran in a GL session")

    monkeypatch.setattr(sky, "ground_sky_visibility", counted)
    monkeypatch.setattr(sky, "ground_raster_cpu", refuse)
    K = _K()
    photo = render_marker_photo(K, look_at_pose([0.0, -0.35, 0.3], [0.0, 0.0, 0.0]), marker_length=0.05).image
    spec = scene_from_dict(
        {
            "calib": K,
            "marker_length": 0.05,
            "model": "box:0.03,0.03,0.04",
            "lights": ["directional:0.3,-0.2,1"],
            "ambient_occlusion": "on",
        }  # fmt: skip
    )
    with Session(spec, context=ctx) as s:
        for _ in range(2):
            res = s.process(photo, want_mask=False)
    assert res.item.plan["ambient_occlusion"].startswith("on")
    assert calls == ["GLGroundRaster"]


def test_point_light_falls_off_with_distance(ctx):
    """With ``Shading.point_falloff`` a point light's term is ``albedo * cos * |L|^2 / |L - p|^2`` (normalised at
    the world origin, where a measured light's exposure is matched); without it, ``albedo * cos``. Checked on
    a wide flat box's top face against the closed form at two points, 0 and 12 cm off the lamp's foot."""
    from arshadow.geometry.mesh import load_occluder
    from arshadow.synth.markers import look_at_pose

    plate = load_occluder("box:0.4,0.4,0.01")
    pose = look_at_pose([0.0, -0.5, 0.6], [0.0, 0.0, 0.0])
    lamp = np.array([0.0, 0.0, 0.3])
    albedo = ((0.8 + 0.055) / 1.055) ** 2.4  # the default grey, linear
    r = _renderer(ctx)
    try:
        kw = {"light": (*lamp, 1.0), "ambient": 0.0, "specular": 0.0}
        on = _render(r, plate, pose, point_falloff=True, **kw)
        off = _render(r, plate, pose, point_falloff=False, **kw)
    finally:
        r.release()
    for p in ([0.0, 0.0, 0.01], [0.12, 0.05, 0.01]):
        x, y = _pixel(pose, p)
        d = lamp - np.array(p)
        cos = d[2] / np.linalg.norm(d)
        want_on = albedo * cos * float(lamp @ lamp) / float(d @ d)
        want_off = albedo * cos
        got_on, got_off = float(on.color[y, x, 1]), float(off.color[y, x, 1])
        assert on.alpha[y, x] == 1.0
        assert abs(got_on - want_on) <= TOL.falloff_rel * want_on, (p, got_on, want_on)
        assert abs(got_off - want_off) <= TOL.falloff_rel * want_off, (p, got_off, want_off)


def test_measured_light_shades_a_vertical_face_with_half_the_sky_and_half_the_ground(gl_ctx):
    # A light measured from a photo (straight down, shadow ratio r, paper recorded as P) and a uniform ground
    # recorded as g: a white box's vertical face sees half the sky and half the ground, so a camera records
    # it as paper-albedo x (r P / 2 + g / 2 x ground-albedo / paper-albedo x ...), i.e. in the photo's linear
    # units ``0.5 (r_c P_c + rho_p g_c)`` (sky irradiance r P / rho_p, ground radiance g); its top face as
    # the paper, ``P_c``. Physics of the generating values; nothing of the renderer.
    from arshadow.camera.model import Intrinsics
    from arshadow.compose.composite import srgb_to_linear
    from arshadow.estimate.exposure import Exposure
    from arshadow.estimate.record import LightEstimate
    from arshadow.frame.session import Session
    from arshadow.scene.spec import scene_from_dict
    from arshadow.shading.decide import PAPER_ALBEDO
    from arshadow.synth.markers import look_at_pose

    r, P, g8 = np.array([0.3, 0.4, 0.5]), np.array([0.6, 0.62, 0.58]), (120, 140, 160)  # g8: B, G, R
    est = LightEstimate(
        "directional", "directional:0,0,1", direction=(0.0, 0.0, 1.0), shadow_ratio=tuple(r),
        exposure=Exposure(tuple(P), (0.02, 0.02, 0.02), 20),
    )  # fmt: skip
    K = Intrinsics(fx=700.0, fy=700.0, cx=(W - 1) / 2, cy=(H - 1) / 2, width=W, height=H, dist=np.zeros(0))
    spec = scene_from_dict(
        {"calib": K, "marker_length": 0.05, "model": "box:0.06,0.06,0.06", "color": "255,255,255",
         "light_from": est, "ambient_occlusion": "on"}
    )  # fmt: skip
    pose = look_at_pose([0.0, -0.3, 0.2], [0.0, 0.0, 0.03])
    photo = np.empty((H, W, 3), np.uint8)
    photo[:] = g8
    with Session(spec) as s:
        out = s.render(photo, pose, want_mask=False).composite
    g = srgb_to_linear(np.array(g8[::-1], np.float64) / 255.0)
    side, top = _pixel(pose, [0.0, -0.03, 0.02]), _pixel(pose, [0.0, 0.0, 0.06])
    got_side = srgb_to_linear(out[side[1], side[0], ::-1] / 255.0)
    got_top = srgb_to_linear(out[top[1], top[0], ::-1] / 255.0)
    np.testing.assert_allclose(got_top, P, rtol=TOL.object_shade_rel)
    np.testing.assert_allclose(got_side, 0.5 * (r * P + PAPER_ALBEDO * g), rtol=TOL.object_shade_rel)


def test_colour_bleeding_sky_channel_per_colour_channel(ctx):
    # an orange box lit from -x: in front of its lit face the ground gets its reflected light, stronger in
    # red than in blue. The rendered sky channel is per colour channel, 1 - V - reflected * (1 + bleed_c) with
    # V + reflected the map's visibility and reflected its bounce part at that ground point (the map sampled
    # independently of the renderer's projection), bleed the colour over its mean minus 1
    from dataclasses import replace

    from arshadow.geometry.mesh import load_occluder
    from arshadow.shading.sky import SkyShading, ground_sky_visibility
    from arshadow.synth.markers import look_at_pose

    box = load_occluder("box:0.045,0.065,0.07")
    g = ground_sky_visibility(box, bounce=(np.array([-1.0, 0.0, 1.0]), 0.4, 0.5))
    assert g.bounce is not None
    bleed = (0.8, -0.1, -0.7)
    pose = look_at_pose([-0.3, -0.2, 0.25], [0.0, 0.0, 0.02])
    r = _renderer(ctx)
    try:
        res = _render(r, box, pose, sky=SkyShading(ground=g, bleed=bleed), light=(-1.0, 0.0, 1.0, 0.0))
        grey = _render(r, box, pose, sky=SkyShading(ground=g), light=(-1.0, 0.0, 1.0, 0.0))
    finally:
        r.release()
    assert res.sky_occlusion is not None and res.sky_occlusion.shape == (H, W, 3)
    assert grey.sky_occlusion is not None and grey.sky_occlusion.shape == (H, W)
    pt = np.array([[-0.0225 - 0.006, 0.0]])  # 6 mm in front of the lit -x face
    vis, refl = g.sample(pt)[0], replace(g, visibility=g.bounce).sample(pt)[0]
    assert refl > 0.05  # a visible reflection
    px = _pixel(pose, [pt[0, 0], pt[0, 1], 0.0])
    expect = 1.0 - (vis - refl) - refl * (1.0 + np.array(bleed))
    got = res.sky_occlusion[px[1], px[0]]
    assert np.abs(got - expect).max() <= TOL.sky_projection_abs, (got, expect)
    assert abs(grey.sky_occlusion[px[1], px[0]] - (1.0 - vis)) <= TOL.sky_projection_abs
