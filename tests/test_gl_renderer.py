"""Accuracy of the stencil shadow renderer against the independent per-pixel oracle (tests/image_oracle.py).

Scenes at 1280x720 (pinhole; lens distortion is the compositor's, on top): a box under a point light, a
non-convex mesh of > 8000 faces, a torus under a directional light, a camera INSIDE a wall's shadow volume
under a low sun (z-fail needed; z-pass is shown to be wrong), two lights (fractional mask).

Metrics (thresholds in conftest.TOL):
- IoU of the renderer's mask >= t and the oracle's mask >= t at pixel centres, t = half of one light's
  share of the total weight;
- boundary error: for every mismatched pixel, the distance from its centre to the boundary of the oracle's
  thresholded mask, measured on a 1/32 px grid of oracle samples around it (see
  image_oracle.boundary_distance); the mean over mismatched pixels (0 when there are none).
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from image_oracle import ShadowOracle, boundary_distance, iou
from render_scenes import ZNEAR, H, Scene, W, intrinsics, scenes

from arshadow.renderer.request import RenderRequest, Shading

pytestmark = pytest.mark.gl


def _render(ctx_or_renderer, scene: Scene, mode: str | None = None, **kw):
    """Render a scene; ``mode=None`` picks z-pass/z-fail with the conservative test."""
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import camera_may_be_in_shadow, near_plane_radius, shadow_volume
    from arshadow.gl.stencil import LightPass
    from arshadow.transforms import CV_TO_GL, invert_rigid

    K = intrinsics(scene.fx)
    eye = invert_rigid(scene.cam_from_world)[:3, 3]
    near = near_plane_radius(ZNEAR, W, H, K.fx, K.fy, K.cx, K.cy)
    passes, modes = [], []
    total = sum(w for _, w in scene.lights)
    for lh, w in scene.lights:
        m = mode or ("zfail" if camera_may_be_in_shadow(scene.caster, lh, eye, near) else "zpass")
        sil = silhouette(scene.caster, lh)
        vol = shadow_volume(scene.caster, lh, sil, caps=(m == "zfail"))
        passes.append(LightPass(lh, w / total, vol, m))
        modes.append(m)
    r = ctx_or_renderer
    res = r.render(
        RenderRequest(
            projection=K.gl_projection(ZNEAR, None),
            view=CV_TO_GL @ scene.cam_from_world,
            width=W,
            height=H,
            caster=scene.caster,
            passes=passes,
            ground_size=scene.ground_size,
            **kw,
        )
    )
    return res, modes


def _oracle(scene: Scene):
    K = intrinsics(scene.fx)
    return ShadowOracle(
        K.K,
        scene.cam_from_world,
        scene.caster.vertices,
        scene.caster.faces,
        scene.lights,
        ground_size=scene.ground_size,
    )


def _threshold(scene):
    total = sum(w for _, w in scene.lights)
    return 0.5 * min(w for _, w in scene.lights) / total


@pytest.fixture(scope="module")
def renderer(gl_ctx):
    from arshadow.gl.stencil import ShadowRenderer

    r = ShadowRenderer(gl_ctx, max_width=W, max_height=H)
    yield r
    r.release()


@pytest.fixture(scope="module")
def scene_results(gl_ctx, renderer):
    """Render every scene once with the automatically chosen mode; compare with the oracle."""
    out = {}
    for sc in scenes():
        res, modes = _render(renderer, sc)
        orc = _oracle(sc)
        om, og, oo = orc.image(W, H)
        t = _threshold(sc)
        rm, ob = res.mask >= t, om >= t
        mism = np.argwhere(rm != ob)
        dist = boundary_distance(orc, mism[:, ::-1].astype(np.float64), t) if len(mism) else np.zeros(0)
        out[sc.name] = dict(
            scene=sc,
            res=res,
            modes=modes,
            oracle=(om, og, oo),
            iou=iou(rm, ob),
            n_shadow=int(ob.sum()),
            n_mismatch=len(mism),
            boundary_mean=float(dist.mean()) if len(dist) else 0.0,
            boundary_max=float(dist.max()) if len(dist) else 0.0,
        )
    if os.environ.get("ARSHADOW_ACCURACY_JSON"):
        with open(os.environ["ARSHADOW_ACCURACY_JSON"], "w") as fh:
            json.dump(
                {
                    k: {
                        kk: vv
                        for kk, vv in v.items()
                        if kk in ("modes", "iou", "n_shadow", "n_mismatch", "boundary_mean", "boundary_max")
                    }
                    for k, v in out.items()
                },
                fh,
                indent=1,
            )
    return out


def test_modes_chosen_by_conservative_test(scene_results):
    for name, r in scene_results.items():
        want = "zfail" if name.startswith("wall") else "zpass"
        assert set(r["modes"]) == {want}, (name, r["modes"])


@pytest.mark.parametrize(
    "name", ["box_point", "nonconvex_point", "torus_directional", "wall_camera_in_shadow", "box_two_lights"]
)
def test_scene_accuracy(scene_results, tol, name):
    r = scene_results[name]
    assert r["n_shadow"] >= tol.shadow_min_pixels, f"{name}: scene too small to judge ({r['n_shadow']} px)"
    assert r["iou"] >= tol.shadow_iou_worst, (name, r["iou"], r["n_mismatch"])
    assert r["boundary_mean"] <= tol.shadow_boundary_px, (name, r["boundary_mean"], r["boundary_max"])


def test_accuracy_over_scenes(scene_results, tol):
    ious = [r["iou"] for r in scene_results.values() if r["n_shadow"] >= tol.shadow_min_pixels]
    assert len(ious) == 5
    assert np.median(ious) >= tol.shadow_iou_median
    assert min(ious) >= tol.shadow_iou_worst


def test_mask_semantics(scene_results, tol):
    """mask is 0 on the occluder and off the ground; alpha/ground agree with the oracle's coverage."""
    for name, r in scene_results.items():
        res = r["res"]
        om, og, oo = r["oracle"]
        assert res.mask.shape == (H, W) and res.mask.dtype == np.float32
        assert res.color.shape == (H, W, 3) and res.alpha.shape == (H, W) and res.ground.dtype == bool
        assert np.all(res.mask[~res.ground] == 0), name
        assert np.all(res.mask[res.alpha > 0] == 0), name
        assert np.all((res.mask >= 0) & (res.mask <= 1))
        n = H * W
        assert np.count_nonzero((res.alpha > 0.5) != oo) <= tol.coverage_mismatch_frac * n, name
        assert np.count_nonzero(res.ground != og) <= tol.coverage_mismatch_frac * n, name


def test_two_lights_fraction_levels(scene_results, tol):
    """Both levels of the fractional mask (one light blocked / both blocked) match the oracle."""
    r = scene_results["box_two_lights"]
    om = r["oracle"][0]
    res = r["res"]
    vals = np.unique(np.round(res.mask, 3))
    assert set(vals.tolist()) <= {0.0, 0.5, 1.0}
    both = iou(res.mask >= 0.75, om >= 0.75)
    assert (om >= 0.75).sum() > 500 and both >= tol.shadow_iou_worst


def test_zpass_equals_zfail_outside(gl_ctx, renderer, scene_results):
    """Camera outside every volume: z-pass and z-fail masks are pixel-identical."""
    for name, r in scene_results.items():
        if "zfail" in r["modes"]:
            continue
        res_fail, _ = _render(renderer, r["scene"], mode="zfail")
        assert np.array_equal(res_fail.mask, r["res"].mask), name
        assert np.array_equal(res_fail.ground, r["res"].ground), name


def test_zpass_wrong_inside_volume(renderer, scene_results, tol):
    """The wall scene really needs z-fail: z-pass gives a visibly wrong mask there."""
    r = scene_results["wall_camera_in_shadow"]
    res_pass, _ = _render(renderer, r["scene"], mode="zpass")
    om = r["oracle"][0]
    assert iou(res_pass.mask >= 0.5, om >= 0.5) < 0.9
    assert r["iou"] >= tol.shadow_iou_worst


def test_ground_size_limits_mask(gl_ctx, renderer, tol):
    sc = scenes()[0]
    sc.ground_size = 0.3
    res, _ = _render(renderer, sc)
    orc = _oracle(sc)
    om, og, oo = orc.image(W, H)
    assert np.count_nonzero(res.ground != og) <= 2e-4 * W * H
    assert np.all(res.mask[~og] == 0) or np.count_nonzero(res.mask[~og]) <= 2e-4 * W * H
    assert iou(res.mask >= 0.5, om >= 0.5) >= tol.shadow_iou_worst
    assert np.any(og) and np.any(~og & ~oo)


def test_stencil_bits_and_state(gl_ctx, renderer, scene_results):
    from arshadow.gl import glraw as G

    assert renderer.stencil_bits == 8
    assert renderer.depth_bits == 24
    gl = G.load()
    # raw state restored: no stencil test / depth clamp left enabled behind moderngl's back
    assert not gl.glIsEnabled(G.GL_STENCIL_TEST)
    assert not gl.glIsEnabled(G.GL_DEPTH_CLAMP)
    assert gl_ctx.error == "GL_NO_ERROR"


def test_self_shadowing(ctx, tol):
    """A low box's top face (facing the light) inside a tall box's shadow gets only ambient light."""
    from arshadow.compose.composite import srgb_to_linear
    from arshadow.geometry.mesh import ShadowCaster, load_occluder
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import LightPass, ShadowRenderer
    from arshadow.synth.markers import look_at_pose
    from arshadow.transforms import CV_TO_GL

    tall = load_occluder("box:0.04,0.2,0.3", place=(-0.06, 0, 0))
    low = load_occluder("box:0.2,0.2,0.05", place=(0.08, 0, 0))
    caster = ShadowCaster(
        np.concatenate([tall.vertices, low.vertices]),
        np.concatenate([tall.faces, low.faces + len(tall.vertices)]),
        name="two boxes",
    )
    L = np.array([-1.0, 0.0, 1.0, 0.0]) / np.sqrt(2)  # sun at 45 deg from -x: tall box shades x in [-0.02, 0.25]
    T = look_at_pose([0.25, -0.35, 0.5], [0.08, 0.0, 0.05])
    K = intrinsics(1000.0)
    sil = silhouette(caster, L)
    vol = shadow_volume(caster, L, sil, caps=True)
    with ShadowRenderer(ctx, max_width=W, max_height=H) as r:
        res = r.render(
            RenderRequest(
                projection=K.gl_projection(ZNEAR, None),
                view=CV_TO_GL @ T,
                width=W,
                height=H,
                caster=caster,
                passes=[LightPass(L, 1.0, vol, "zfail")],
                shading=Shading(ambient=0.25, diffuse=1.0, specular=0.0, color=(0.8, 0.8, 0.8)),
            )
        )
    # classify pixels on the low box's top face (z = 0.05) by its analytic shadow line:
    # a top-face point (x, y, 0.05) is shaded iff x <= -0.02 + (0.3 - 0.05) = 0.23 (light at 45 deg)
    vv, uu = np.mgrid[0:H, 0:W]
    Kinv = np.linalg.inv(K.K)
    d = np.stack([uu, vv, np.ones_like(uu)], -1).reshape(-1, 3).astype(np.float64) @ Kinv.T
    R, t = T[:3, :3], T[:3, 3]
    C = -R.T @ t
    dw = d @ R
    s = (0.05 - C[2]) / dw[:, 2]
    P = C + s[:, None] * dw
    on_top = (s > 0) & (np.abs(P[:, 1]) < 0.095) & (P[:, 0] > -0.015) & (P[:, 0] < 0.175)
    shaded = on_top & (P[:, 0] < 0.22)
    lit = on_top & (P[:, 0] > 0.24)
    assert shaded.sum() > 1000
    col = res.color.reshape(-1, 3)
    albedo = float(srgb_to_linear(0.8))
    # in shadow: ambient only; lit: ambient + diffuse * cos(45 deg)
    assert np.allclose(col[shaded], 0.25 * albedo, atol=tol.phong_shadow_atol)
    lit_px = col[lit & (res.alpha.reshape(-1) > 0.5)]
    assert lit_px.size == 0 or np.allclose(lit_px, (0.25 + np.sqrt(0.5)) * albedo, atol=tol.phong_lit_atol)


def test_render_sub_canvas_matches_full(renderer, scene_results, tol):
    """A canvas sub-rectangle (ROI) renders exactly the same pixels as the full image."""
    r = scene_results["box_point"]
    sc = r["scene"]
    from arshadow.transforms import CV_TO_GL

    K = intrinsics(sc.fx)
    u0, v0, w, h = 500, 200, 400, 300
    res_full = r["res"]
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import LightPass

    lh = sc.lights[0][0]
    vol = shadow_volume(sc.caster, lh, silhouette(sc.caster, lh), caps=False)
    roi = renderer.render(
        RenderRequest(
            projection=K.gl_projection(ZNEAR, None, canvas=(u0, v0, w, h)),
            view=CV_TO_GL @ sc.cam_from_world,
            width=w,
            height=h,
            caster=sc.caster,
            passes=[LightPass(lh, 1.0, vol, "zpass")],
        )
    )
    sub = res_full.mask[v0 : v0 + h, u0 : u0 + w]
    assert roi.mask.shape == (h, w)
    assert np.count_nonzero((roi.mask >= 0.5) != (sub >= 0.5)) <= tol.roi_vs_full_px
    assert np.count_nonzero((roi.alpha > 0.5) != (res_full.alpha[v0 : v0 + h, u0 : u0 + w] > 0.5)) <= tol.roi_vs_full_px


def test_bad_input(renderer):
    from arshadow.errors import ShapeError, UsageError
    from arshadow.gl.stencil import LightPass

    sc = scenes()[0]
    K = intrinsics(1000.0)
    P = K.gl_projection(ZNEAR, None)
    V = np.eye(4)
    with pytest.raises(UsageError):
        renderer.render(RenderRequest(projection=P, view=V, width=W + 1, height=H, caster=sc.caster, passes=[]))
    with pytest.raises(ShapeError):
        renderer.render(RenderRequest(projection=P[:3], view=V, width=W, height=H, caster=sc.caster, passes=[]))
    with pytest.raises(ShapeError):
        renderer.render(RenderRequest(projection=P * np.nan, view=V, width=W, height=H, caster=sc.caster, passes=[]))
    with pytest.raises(UsageError):
        renderer.render(
            RenderRequest(
                projection=P,
                view=V,
                width=W,
                height=H,
                caster=sc.caster,
                passes=[LightPass(np.array([0, 0, 1, 0.0]), 1.0, None, "bogus")],
            )
        )


def test_contact_depth_stability(renderer, tol):
    """Where the object stands on the ground the volume and the ground share depth at z = 0: the mask must
    not flicker there. Jittered poses (two of them grazing, camera 6-8 cm above the ground), z-pass, z-fail
    and a z-fail volume truncated just below the ground: every render matches the oracle up to a few
    boundary pixels. (Measured in docs/rendering.md: a polygon offset on the ground makes this worse.)"""
    from arshadow.geometry.mesh import load_occluder
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import LightPass
    from arshadow.synth.markers import look_at_pose
    from arshadow.transforms import CV_TO_GL

    rng = np.random.default_rng(7)
    box = load_occluder("box:0.1,0.1,0.12")
    K = intrinsics(1000.0)
    for trial in range(4):
        eye = np.array([0.4, -0.5, 0.25]) + rng.normal(0, 0.02, 3)
        if trial % 2:
            eye[2] = 0.06 + 0.02 * rng.random()
        T = look_at_pose(eye, rng.normal(0, 0.005, 3))
        L = np.array([-0.3 + rng.normal(0, 0.05), 0.2, 0.5, 1.0])
        orc = ShadowOracle(K.K, T, box.vertices, box.faces, [(L, 1.0)])
        ob = orc.image(W, H)[0] >= 0.5
        for mode, trunc in (("zpass", None), ("zfail", None), ("zfail", -1e-3 * 0.12)):
            vol = shadow_volume(box, L, silhouette(box, L), caps=(mode == "zfail"), truncate_z=trunc)
            res = renderer.render(
                RenderRequest(
                    projection=K.gl_projection(ZNEAR, None),
                    view=CV_TO_GL @ T,
                    width=W,
                    height=H,
                    caster=box,
                    passes=[LightPass(L, 1.0, vol, mode)],
                )
            )
            mism = np.argwhere((res.mask >= 0.5) != ob)
            assert len(mism) <= 10, (trial, mode, trunc, len(mism))
            if len(mism):
                d = boundary_distance(orc, mism[:, ::-1].astype(np.float64), 0.5)
                assert d.mean() <= tol.shadow_boundary_px, (trial, mode, trunc, d)


@pytest.mark.parametrize("samples,supersample", [(4, 1), (0, 2)])
def test_antialiased_mask(ctx, tol, samples, supersample):
    """MSAA / supersampling give fractional edge values; thresholded at 0.5 the mask still matches the
    pixel-centre oracle, and the fractional values approach the true area coverage."""
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import LightPass, ShadowRenderer
    from arshadow.transforms import CV_TO_GL

    if samples > ctx.max_samples:
        pytest.skip(f"GL has at most {ctx.max_samples} samples")
    sc = scenes()[0]
    K = intrinsics(sc.fx)
    canvas = (400, 250, 480, 360)
    lh = sc.lights[0][0]
    vol = shadow_volume(sc.caster, lh, silhouette(sc.caster, lh), caps=False)
    passes = [LightPass(lh, 1.0, vol, "zpass")]
    kw = dict(
        projection=K.gl_projection(ZNEAR, None, canvas=canvas),
        view=CV_TO_GL @ sc.cam_from_world,
        width=canvas[2],
        height=canvas[3],
        caster=sc.caster,
        passes=passes,
    )
    with ShadowRenderer(ctx, max_width=640, max_height=480, samples=samples, supersample=supersample) as r:
        res = r.render(RenderRequest(**kw))
        if samples:
            assert r.actual_samples >= samples
    with ShadowRenderer(ctx, max_width=640, max_height=480) as r0:
        hard = r0.render(RenderRequest(**kw))
    orc = _oracle(sc)
    om = orc.image(W, H, canvas=canvas)[0]
    assert len(np.unique(res.mask)) > 3  # fractional edge values
    assert np.count_nonzero(om >= 0.5) >= tol.shadow_min_pixels
    assert iou(res.mask >= 0.5, om >= 0.5) >= tol.shadow_iou_worst
    # against the true area coverage on the edge band (8x8 oracle samples per pixel)
    edge = np.argwhere((res.mask > 0) & (res.mask < 1) | ((hard.mask > 0) != (res.mask > 0)))
    sub = (np.arange(8) + 0.5) / 8 - 0.5
    su, sv = np.meshgrid(sub, sub)
    uu = (edge[:, 1][:, None] + canvas[0] + su.ravel()).ravel()
    vv = (edge[:, 0][:, None] + canvas[1] + sv.ravel()).ravel()
    m_all, g_all, _ = orc.classify(uu, vv)
    cov = (m_all * g_all).reshape(len(edge), 64).mean(axis=1)
    err_aa = np.abs(res.mask[edge[:, 0], edge[:, 1]] - cov).mean()
    err_hard = np.abs(hard.mask[edge[:, 0], edge[:, 1]] - cov).mean()
    assert err_aa < tol.aa_error_ratio * err_hard, (err_aa, err_hard)
    # coverage-weighted colour / alpha: alpha fractional at the occluder outline too
    assert np.any((res.alpha > 0.05) & (res.alpha < 0.95))


def test_planar_mode_and_empty_pass(renderer, tol):
    """[Kolivand-Stencil]'s projection shadow (mode "planar") gives the same ground mask as the volumes; a pass with
    no volume casts nothing but still lights the occluder."""
    from arshadow.gl.stencil import LightPass
    from arshadow.transforms import CV_TO_GL

    sc = scenes()[0]
    K = intrinsics(sc.fx)
    lh = sc.lights[0][0]
    kw = dict(
        projection=K.gl_projection(ZNEAR, None), view=CV_TO_GL @ sc.cam_from_world, width=W, height=H, caster=sc.caster
    )
    res = renderer.render(RenderRequest(passes=[LightPass(lh, 1.0, None, "planar")], **kw))
    om = _oracle(sc).image(W, H)[0]
    assert iou(res.mask >= 0.5, om >= 0.5) >= tol.shadow_iou_median
    none = renderer.render(RenderRequest(passes=[LightPass(lh, 1.0, None, "zpass")], **kw))
    assert not np.any(none.mask)
    assert np.allclose(none.alpha, res.alpha)
    assert none.color.max() > 0.3  # lit, not just ambient


def test_buffers_grow_and_caster_cache(ctx):
    """A canvas larger than any before reallocates (and still renders exactly); the caster cache is
    bounded and keyed by the caster object; released casters' buffers are freed."""
    import gc

    from arshadow.geometry.mesh import load_occluder
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import LightPass, ShadowRenderer
    from arshadow.transforms import CV_TO_GL

    sc = scenes()[0]
    K = intrinsics(sc.fx)
    lh = sc.lights[0][0]

    def render(r, caster, canvas):
        vol = shadow_volume(caster, lh, silhouette(caster, lh), caps=False)
        return r.render(
            RenderRequest(
                projection=K.gl_projection(ZNEAR, None, canvas=canvas),
                view=CV_TO_GL @ sc.cam_from_world,
                width=canvas[2],
                height=canvas[3],
                caster=caster,
                passes=[LightPass(lh, 1.0, vol, "zpass")],
            )
        )

    small, big = (560, 300, 200, 150), (400, 200, 600, 400)
    with (
        ShadowRenderer(ctx, max_width=W, max_height=H, max_cached_casters=3) as r,
        ShadowRenderer(ctx, max_width=W, max_height=H) as fresh,
    ):
        a = render(r, sc.caster, small)
        b = render(r, sc.caster, big)  # grows
        c = render(r, sc.caster, small)  # reuses the big buffers
        assert r._main.width >= 600 and r._main.height >= 400
        assert np.array_equal(a.mask, c.mask) and np.array_equal(a.color, c.color)
        ref = render(fresh, sc.caster, big)
        assert np.array_equal(b.mask, ref.mask) and np.array_equal(b.alpha, ref.alpha)
        casters = [load_occluder(f"box:0.0{k + 2},0.05,0.1") for k in range(5)]
        for cs in casters:
            render(r, cs, small)
        assert len(r._casters) <= 3
        del casters, cs
        gc.collect()
        render(r, sc.caster, small)
        assert len(r._casters) == 1  # dead casters purged, their buffers released
    assert ctx.error == "GL_NO_ERROR"


def test_upload_reuse_follows_the_volumes(ctx):
    """Volumes and light-facing subsets are re-uploaded only when the passes change: a renderer that saw
    other volumes/lights in between renders exactly what a fresh renderer does; a volume with writeable
    arrays edited in place is uploaded again."""
    from dataclasses import replace

    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import LightPass, ShadowRenderer
    from arshadow.transforms import CV_TO_GL

    sc = scenes()[0]
    K = intrinsics(sc.fx)
    canvas = (400, 250, 480, 360)
    kw = dict(
        projection=K.gl_projection(ZNEAR, None, canvas=canvas),
        view=CV_TO_GL @ sc.cam_from_world,
        width=canvas[2],
        height=canvas[3],
        caster=sc.caster,
    )
    la, lb = sc.lights[0][0], np.array([0.25, 0.2, 0.6, 1.0])
    va = shadow_volume(sc.caster, la, silhouette(sc.caster, la), caps=False)
    vb = shadow_volume(sc.caster, lb, silhouette(sc.caster, lb), caps=False)
    pa, pb = [LightPass(la, 1.0, va, "zpass")], [LightPass(lb, 1.0, vb, "zpass")]
    with (
        ShadowRenderer(ctx, max_width=640, max_height=480) as r,
        ShadowRenderer(ctx, max_width=640, max_height=480) as fresh,
    ):
        a1 = r.render(RenderRequest(passes=pa, **kw))
        a2 = r.render(RenderRequest(passes=pa, **kw))  # reused upload
        b = r.render(RenderRequest(passes=pb, **kw))
        a3 = r.render(RenderRequest(passes=pa, **kw))
        b_ref = fresh.render(RenderRequest(passes=pb, **kw))
        assert np.any(a1.mask != b.mask)  # the two lights really differ
        for x in (a2, a3):
            assert np.array_equal(x.mask, a1.mask) and np.array_equal(x.color, a1.color)
        assert np.array_equal(b.mask, b_ref.mask) and np.array_equal(b.color, b_ref.color)
        # same object, writeable arrays changed in place: must not be served from the previous upload
        vw = replace(va, vertices=np.array(va.vertices), triangles=np.array(va.triangles))
        w1 = r.render(RenderRequest(passes=[LightPass(la, 1.0, vw, "zpass")], **kw))
        np.copyto(vw.triangles, np.zeros_like(vw.triangles))  # every triangle degenerate: no shadow
        w2 = r.render(RenderRequest(passes=[LightPass(la, 1.0, vw, "zpass")], **kw))
        assert np.array_equal(w1.mask, a1.mask)
        assert not np.any(w2.mask)
    assert ctx.error == "GL_NO_ERROR"
