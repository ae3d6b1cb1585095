"""A measured point light's shadow ratio across the ground (``Shading.ratio_falloff``, docs/shading.md): the
lamp's irradiance falls off over the floor while the sky's does not, so a shadow farther from the lamp keeps
more of the ground's light. Checked against the closed form of the lamp's and the sky's irradiance at each
ground point (``z / d^3`` and a constant), never against the renderer."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import TOL

W, H = 640, 480
ZNEAR = 0.01
LAMP = np.array([0.15, 0.0, 0.3])
Q0 = 0.5  # sky / lamp irradiance at the world origin


def _K():
    from arshadow.camera.model import Intrinsics

    return Intrinsics(fx=700.0, fy=700.0, cx=(W - 1) / 2, cy=(H - 1) / 2, width=W, height=H, dist=np.zeros(0))


def _pose():
    from arshadow.synth.markers import look_at_pose

    return look_at_pose([-0.05, -0.35, 0.3], [-0.04, 0.0, 0.0])


def _ground_at(pose, px):
    """The ground point (z = 0) seen through the centre of pixel ``px`` (x, y): the camera ray, closed form."""
    K = _K()
    ray = np.array([(px[0] - K.cx) / K.fx, (px[1] - K.cy) / K.fy, 1.0])
    R, t = pose[:3, :3], pose[:3, 3]
    c, d = -R.T @ t, R.T @ ray
    return c - c[2] / d[2] * d


def _pixel(pose, xyz):
    K = _K()
    p = pose[:3, :3] @ np.asarray(xyz, float) + pose[:3, 3]
    return int(round(K.fx * p[0] / p[2] + K.cx)), int(round(K.fy * p[1] / p[2] + K.cy))


def _lamp_gain(q):
    """The lamp's irradiance at ground point ``q`` over its irradiance at the origin: ``z / d^3``."""
    return (np.linalg.norm(LAMP) / np.linalg.norm(LAMP - q)) ** 3


#: ground points in the box's hard shadow (the lamp at x = 0.15 throws it towards -x, to x = -0.082)
IN_SHADOW = ([-0.035, 0.0, 0.0], [-0.06, 0.004, 0.0], [-0.075, -0.004, 0.0])


def _render(ctx, light, falloff, sky=None):
    from arshadow.geometry.mesh import load_occluder
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import ShadowRenderer
    from arshadow.renderer.request import LightPass, RenderRequest, Shading
    from arshadow.transforms import CV_TO_GL

    box = load_occluder("box:0.04,0.04,0.08")
    lh = np.asarray(light, np.float64)
    vol = shadow_volume(box, lh, silhouette(box, lh), caps=True)
    shading = Shading(sky=sky, ratio_falloff=(0.0, 0.0, Q0) if falloff else None)
    if sky is not None:
        sky = sky(box)
        shading = Shading(sky=sky, ratio_falloff=shading.ratio_falloff)
    r = ShadowRenderer(ctx, max_width=W, max_height=H)
    try:
        req = RenderRequest(
            projection=_K().gl_projection(ZNEAR, None), view=CV_TO_GL @ _pose(), width=W, height=H,
            caster=box, passes=[LightPass(lh, 1.0, vol, "zfail")], shading=shading,
        )  # fmt: skip
        return r.render(req), sky
    finally:
        r.release()


def _sky(box):
    from arshadow.shading.sky import SkyShading, ground_sky_visibility

    return SkyShading(ground=ground_sky_visibility(box))


@pytest.mark.gl
def test_point_light_mask_keeps_the_blocked_weight_and_the_sky_channel_carries_the_lamps_share(ctx):
    # in a full shadow at x the lamp's blocked share is a = g (1 + q0) / (g + q0) times the mask's (g: the
    # lamp's irradiance there over the origin's). The mask keeps the weight (the saved mask's contract) and
    # the sky channel carries (a - 1) / q0 more (the composite weighs it by r0, the mask by 1 - r0), on top
    # of the map's 1 - V scaled by (1 + q0) / (g + q0)
    pose = _pose()
    on, s = _render(ctx, (*LAMP, 1.0), True, sky=_sky)
    off, _ = _render(ctx, (*LAMP, 1.0), False, sky=_sky)
    assert on.sky_occlusion is not None
    for p in IN_SHADOW:
        x, y = _pixel(pose, p)
        q = _ground_at(pose, (x, y))
        g = _lamp_gain(q)
        v = float(s.ground.sample(q[None, :2])[0])
        want = (1.0 - v) * (1 + Q0) / (g + Q0) + (g * (1 + Q0) / (g + Q0) - 1.0) / Q0
        assert on.mask[y, x] == off.mask[y, x] == pytest.approx(1.0, abs=1e-3), p
        got = float(on.sky_occlusion[y, x])
        assert abs(got - want) <= TOL.sky_projection_abs, (p, got, want)
    far = _pixel(pose, IN_SHADOW[-1])
    assert on.sky_occlusion[far[1], far[0]] < off.sky_occlusion[far[1], far[0]] - 0.1  # visibly lighter
    # a directional light's irradiance is the same everywhere: nothing changes; nor without sky occlusion
    # (the correction rides on the sky channel)
    sun_on, _ = _render(ctx, (*LAMP, 0.0), True, sky=_sky)
    sun_off, _ = _render(ctx, (*LAMP, 0.0), False, sky=_sky)
    assert np.array_equal(sun_on.mask, sun_off.mask) and np.array_equal(sun_on.sky_occlusion, sun_off.sky_occlusion)
    plain_on, _ = _render(ctx, (*LAMP, 1.0), True)
    plain_off, _ = _render(ctx, (*LAMP, 1.0), False)
    assert plain_on.sky_occlusion is None and np.array_equal(plain_on.mask, plain_off.mask)


@pytest.mark.gl
def test_point_light_sky_channel_is_scaled_to_each_ground_points_sky_share(ctx):
    # outside the hard shadow: the sky's share at x is q0 / (g + q0) where the composite applies r0 = q0 / (1 + q0): the sky channel
    # (1 - V, V the map's visibility, checked against Lambert in test_shading_sky) is (1 - V)(1 + q0) / (g + q0)
    pose = _pose()
    on, s = _render(ctx, (*LAMP, 1.0), True, sky=_sky)
    assert on.sky_occlusion is not None
    checked = 0
    for p in ([0.0, -0.024, 0.0], [0.035, 0.0, 0.0], [0.03, -0.025, 0.0], [-0.012, -0.026, 0.0]):
        x, y = _pixel(pose, p)
        q = _ground_at(pose, (x, y))
        g = _lamp_gain(q)
        v = float(s.ground.sample(q[None, :2])[0])
        want = (1.0 - v) * (1 + Q0) / (g + Q0)
        assert abs(float(on.sky_occlusion[y, x]) - want) <= TOL.sky_projection_abs, (
            p,
            float(on.sky_occlusion[y, x]),
            want,
        )
        checked += want > 0.05
    assert checked >= 3


@pytest.mark.gl
def test_measured_point_light_composite_keeps_the_sky_share_at_each_shadow_point(gl_ctx):
    # end to end: a lamp measured with shadow ratio 0.4 at the origin (where the object stands), a uniform
    # ground photo, a black box (no reflected light), sky occlusion on: a full shadow at x keeps
    # V(x) sky / (sky + lamp(x)) of the ground's light (V the box's sky visibility there: the numpy map,
    # checked against Lambert's form factor in test_shading_sky)
    from arshadow.compose.composite import srgb_to_linear
    from arshadow.estimate.record import LightEstimate
    from arshadow.frame.session import Session
    from arshadow.geometry.mesh import load_occluder
    from arshadow.scene.spec import scene_from_dict
    from arshadow.shading.sky import ground_sky_visibility

    r0 = 0.4
    est = LightEstimate(
        "point", "point:{},{},{}".format(*LAMP), position=tuple(LAMP), shadow_ratio=(r0, r0, r0), ratio_at=(0.0, 0.0)
    )
    spec = scene_from_dict(
        {"calib": _K(), "marker_length": 0.05, "model": "box:0.04,0.04,0.08", "color": "0,0,0", "light_from": est,
         "ambient_occlusion": "on"}
    )  # fmt: skip
    pose = _pose()
    photo = np.full((H, W, 3), 180, np.uint8)
    with Session(spec) as s:
        out = s.render(photo, pose, want_mask=False).composite
    vis = ground_sky_visibility(load_occluder("box:0.04,0.04,0.08"))
    base = srgb_to_linear(np.array([180 / 255.0]))[0]
    q0 = r0 / (1 - r0)
    for p in IN_SHADOW:
        x, y = _pixel(pose, p)
        q = _ground_at(pose, (x, y))
        want = q0 / (_lamp_gain(q) + q0) * float(vis.sample(q[None, :2])[0])
        got = float(srgb_to_linear(out[y, x, 1] / 255.0)) / base
        assert got == pytest.approx(want, rel=TOL.ratio_falloff_rel), (p, got, want)
