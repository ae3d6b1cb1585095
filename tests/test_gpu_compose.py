"""The GPU-resident compose path (arshadow/gl/gpu_compose.py) against the numpy path (lens warp + composite).

Both paths are fed the same render of the same canvas; the numpy path's result is the reference (it is
tested against hand values and analytic oracles in test_composite.py / test_lens.py / test_pipeline.py).
The shader must give the same 8-bit photo and mask within TOL.gpu_compose_levels, with and without lens
distortion, with MSAA 0 and 4, grey and tinted shadows, with and without the occluder, with and without sky
occlusion (the ground occlusion map's channel, darkening the ground beyond the shadow's mask), with the
camera effects' blur; the shader's sensor noise is checked against the measured table, as numpy's is.
The outline's anti-aliasing (the planner's ``outline_aa``) is off here: a frame with it takes the numpy path
(tests/test_gl_outline_aa.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from arshadow.renderer.request import RenderRequest

W, H = 1280, 720


def _rendered(res):
    """A :class:`arshadow.frame.session.FrameResult` as ``(composite, mask, report item)``."""
    return res.composite, res.mask, res.item


def _intrinsics(dist=()):
    from arshadow.camera.model import Intrinsics

    return Intrinsics(1000.0, 1000.0, 641.3, 358.2, W, H, np.asarray(dist, float))


def _photo(seed=3):
    # random texture: every 8-bit code of every channel is exercised (the sRGB tables both ways)
    img = np.random.default_rng(seed).integers(0, 256, (H, W, 3), dtype=np.uint8)
    img.setflags(write=False)
    return img


def _both_paths(ctx, paths, *, dist, aa, caster_spec, light, eye, target, **opts):
    """The frame rendered by each compose path of ``paths`` (None: numpy and shader) in a session of its own:
    ``(photo, {path: (composite, mask, report item)})``."""
    from arshadow.frame.session import Session
    from arshadow.geometry.mesh import load_occluder
    from arshadow.lights.spec import parse_light
    from arshadow.scene.spec import RenderOptions, Scene
    from arshadow.synth.markers import look_at_pose

    intr = _intrinsics(dist)
    caster = load_occluder(caster_spec)
    pose = look_at_pose(eye, target)
    photo = _photo()
    results = {}
    for path in paths or ("cpu", "gpu"):
        scene = Scene(
            intr,
            caster,
            [parse_light(light)],
            RenderOptions(aa=aa, compose=path, outline_aa="off", **opts),
            {"marker_length": 0.05},
        )
        comp = Session(scene, context=ctx)
        with comp:
            out, mask, info = _rendered(comp.render(photo, pose))
        assert info.compose == path
        results[path] = (out, mask, info)
    return photo, results


CASES = {
    "box_point": dict(
        caster_spec="box:0.06,0.05,0.09",
        light="point:0.25,0.15,0.45",
        eye=[0.15, -0.55, 0.42],
        target=[0.17, -0.12, 0.02],
    ),
    "torus_sun_tinted": dict(
        caster_spec="torus:0.06,0.02",
        light="directional:-0.3,0.5,1.0",
        eye=[-0.5, -0.45, 0.35],
        target=[-0.08, 0.12, 0.0],
        opacity=0.55,
        shadow_color=(0.05, 0.1, 0.3),
    ),
    "sphere_no_occluder": dict(
        caster_spec="sphere:0.04",
        light="point:0.1,-0.2,0.5",
        eye=[0.0, -0.5, 0.4],
        target=[0.0, 0.0, 0.0],
        draw_occluder=False,
        opacity=1.0,
    ),
}


@pytest.mark.parametrize("aa", [0, 4])
@pytest.mark.parametrize("dist", [(), (-0.25, 0.05, 0.001, -0.002, 0.0)], ids=["pinhole", "distorted"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_shader_compose_equals_numpy_compose(ctx, tol, case, dist, aa):
    photo, res = _both_paths(ctx, None, dist=dist, aa=aa, **CASES[case])
    (o_cpu, m_cpu, i_cpu), i_gpu = res["cpu"], res["gpu"][2]
    assert i_cpu.roi == i_gpu.roi and i_cpu.canvas == i_gpu.canvas
    # the scene really puts a shadow (and the occluder, when drawn) into the photo
    assert np.count_nonzero(m_cpu) > 2000
    assert np.count_nonzero(np.any(o_cpu != photo, axis=2)) > 2000
    _assert_paths_agree(tol, photo, res, f"{case} {dist} aa={aa}")


def _assert_paths_agree(tol, photo, res, label):
    """The two paths' photos and masks within ``tol.gpu_compose_levels``; outside the ROI both leave the photo
    as it was."""
    (o_cpu, m_cpu, i_cpu), (o_gpu, m_gpu, _) = res["cpu"], res["gpu"]
    d = np.abs(o_gpu.astype(np.int16) - o_cpu)
    dm = np.abs(m_gpu.astype(np.int16) - m_cpu)
    print(
        f"\n{label}: photo max {d.max()} ({np.count_nonzero(d)} values), mask max {dm.max()} ({np.count_nonzero(dm)})"
    )
    assert int(d.max()) <= tol.gpu_compose_levels
    assert int(dm.max()) <= tol.gpu_compose_levels
    x0, y0, w, h = i_cpu.roi
    outside = np.ones((H, W), bool)
    outside[y0 : y0 + h, x0 : x0 + w] = False
    assert np.array_equal(o_gpu[outside], photo[outside]) and not np.any(m_gpu[outside])


#: sky occlusion on ("on" whatever the light): a tinted shadow, the ground's reflected light (negative sky
#: occlusion beside the lit faces: ``exposure_gain`` turns the bounce's measurement on), no object drawn
SKY_CASES = {
    "box_point_sky_tinted": dict(
        CASES["box_point"], ambient_occlusion="on", opacity=0.8, shadow_color=(0.25, 0.3, 0.4)
    ),
    "box_point_sky_bounce": dict(CASES["box_point"], ambient_occlusion="on", exposure_gain=(1.2, 1.1, 1.0)),
    "sphere_sky_no_occluder": dict(CASES["sphere_no_occluder"], ambient_occlusion="on", opacity=0.6),
    # an orange box: its reflected light is orange (colour bleeding, the sky channel per colour channel)
    "box_point_sky_bounce_orange": dict(
        CASES["box_point"], ambient_occlusion="on", exposure_gain=(1.2, 1.1, 1.0), occluder_color=(1.0, 0.55, 0.1)
    ),
}


@pytest.mark.parametrize("aa", [0, 4])
@pytest.mark.parametrize("dist", [(), (-0.25, 0.05, 0.001, -0.002, 0.0)], ids=["pinhole", "distorted"])
@pytest.mark.parametrize("case", sorted(SKY_CASES))
def test_shader_compose_equals_numpy_compose_with_sky_occlusion(ctx, tol, case, dist, aa):
    """The shader composites the sky-occlusion channel as the numpy path does (composite._darken_sky), over
    the same region: the sky darkens (or, with the reflected light, brightens) the ground beyond the mask."""
    photo, res = _both_paths(ctx, None, dist=dist, aa=aa, **SKY_CASES[case])
    (o_cpu, m_cpu, i_cpu), i_gpu = res["cpu"], res["gpu"][2]
    assert i_cpu.plan["ambient_occlusion"].startswith("on") and i_gpu.plan["ambient_occlusion"].startswith("on")
    assert ("colour_bleeding" in i_cpu.plan) == ("orange" in case) == ("colour_bleeding" in i_gpu.plan)
    assert i_cpu.roi == i_gpu.roi and i_cpu.canvas == i_gpu.canvas
    # what the sky term changes: the numpy composite of the same frame without sky occlusion
    off = _both_paths(ctx, ("cpu",), dist=dist, aa=aa, **{**SKY_CASES[case], "ambient_occlusion": "off"})
    o_off = off[1]["cpu"][0]
    sky = np.abs(o_cpu.astype(np.int16) - o_off).max(axis=2) > tol.gpu_compose_levels
    assert np.count_nonzero(sky & (m_cpu == 0)) > 2000  # beyond the shadow's mask too
    if "bounce" in case:  # the ground's reflected light: the ground brighter than without sky occlusion somewhere
        # (the ground: where the composite without sky occlusion is the photo; until 2026-11-29 this counted the
        # object's pixels too, which the ground bounce brightened on this photo: 13 000 of them against 3-43 of
        # the ground at > 3 levels; the object now sees the photo's own ground, arshadow.shading.objground)
        ground = np.all(o_off == photo, axis=2)
        brighter = o_cpu.astype(np.int16).sum(axis=2) - o_off.astype(np.int16).sum(axis=2) > 1
        assert np.count_nonzero(brighter & ground) > 40
    _assert_paths_agree(tol, photo, res, f"{case} {dist} aa={aa}: sky changes {np.count_nonzero(sky)} px")


def _sky_session(ctx, chooser=None, renderer=None, dist=(), **opts):
    """A Session of the box_point case with sky occlusion on (compose "auto" unless ``opts`` say), its pose."""
    from arshadow.frame.session import Session
    from arshadow.geometry.mesh import load_occluder
    from arshadow.lights.spec import parse_light
    from arshadow.scene.spec import RenderOptions, Scene
    from arshadow.synth.markers import look_at_pose

    c = CASES["box_point"]
    options = RenderOptions(**{"compose": "auto", "ambient_occlusion": "on", "outline_aa": "off", **opts})
    scene = Scene(_intrinsics(dist), load_occluder(c["caster_spec"]), [parse_light(c["light"])], options, {})
    s = Session(scene, context=ctx, renderer=renderer)
    if chooser is not None:
        s.hooks.compose_chooser = chooser
    return s, look_at_pose(c["eye"], c["target"])


def test_a_frame_with_sky_occlusion_may_take_the_shader_path(ctx):
    """Sky occlusion no longer forces the numpy path: the chooser's choice for the frame's key is taken, and
    the plan records it with the measurement (a key of its own: sky occlusion is part of it)."""
    from arshadow.gl.gpu_compose import PathChooser
    from arshadow.plan.planner import MEASURED

    decisions: dict = {}
    s, pose = _sky_session(ctx, PathChooser(decisions=decisions, time_software=True))
    with s:
        key = s.hooks.compose_key(W, H, False)
        with _sky_session(ctx, ambient_occlusion="off")[0] as plain:
            assert plain.hooks.compose_key(W, H, False) != key  # measured apart from frames without the sky
        ms = {"cpu": 5.0, "gpu": 1.0}
        decisions[key] = {"choice": "gpu", "ms": ms}
        res = s.render(_photo(), pose)
        assert res.item.plan["ambient_occlusion"].startswith("on")
        assert res.item.compose == "gpu" and res.plan.compose == "gpu"
        assert res.item.plan["compose"] == MEASURED.format(ms=ms)
        assert np.count_nonzero(res.mask) > 2000
    # not measured yet: both paths are timed on this frame (on llvmpipe too, as asked), the faster kept
    decisions.clear()
    s, pose = _sky_session(ctx, PathChooser(decisions=decisions, time_software=True))
    with s:
        res = s.render(_photo(), pose)
        d = decisions[s.hooks.compose_key(W, H, False)]
    assert set(d["ms"]) == {"cpu", "gpu"} and res.item.compose == d["choice"]
    assert res.item.plan["compose"] == MEASURED.format(ms=d["ms"])
    # forced: taken as asked, with its reason
    s, pose = _sky_session(ctx, compose="gpu")
    with s:
        res = s.render(_photo(), pose)
    assert res.item.compose == "gpu" and res.item.plan["compose"] == "forced gpu"


class _NoSkyOnGpu:
    """The default renderer, but its GPU layers say they hold no sky channel (a renderer that cannot)."""

    def __init__(self, ctx, options):
        from arshadow.frame.hooks import default_renderer

        self.inner = default_renderer(ctx, options)
        self.gpu_layers, self.software, self.backend, self.ctx = True, self.inner.software, "nosky", ctx
        self.ground_raster = self.inner.ground_raster

    def render(self, request):
        return self.inner.render(request)

    def render_gpu(self, request):
        import dataclasses

        return dataclasses.replace(self.inner.render_gpu(request), sky=False)

    def release(self):
        self.inner.release()


def test_the_shader_path_refuses_layers_without_the_frame_sky(ctx):
    """GPU layers without the sky channel a frame asks for are an error, not a composite without the sky."""
    from arshadow.errors import UsageError

    s, pose = _sky_session(ctx, renderer=_NoSkyOnGpu, compose="gpu")
    with s, pytest.raises(UsageError, match="sky occlusion"):
        s.render(_photo(), pose)


def test_gpu_layers_hold_what_the_readback_holds(ctx):
    """render_gpu() keeps the same layers the default readback returns (MSAA resolved on the GPU)."""
    from arshadow.geometry.mesh import load_occluder
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import LightPass, ShadowRenderer
    from arshadow.synth.markers import look_at_pose
    from arshadow.transforms import CV_TO_GL

    intr = _intrinsics()
    caster = load_occluder("box:0.06,0.05,0.09")
    L = np.array([0.25, 0.15, 0.45, 1.0])
    vol = shadow_volume(caster, L, silhouette(caster, L), caps=True)
    pose = look_at_pose([0.15, -0.55, 0.42], [0.0, 0.0, 0.02])
    canvas = (400, 200, 500, 300)
    proj = intr.gl_projection(0.01, None, canvas=canvas)
    for samples in (0, 4):
        with ShadowRenderer(ctx, samples=samples) as r:
            kw = dict(
                projection=proj,
                view=CV_TO_GL @ pose,
                width=canvas[2],
                height=canvas[3],
                caster=caster,
                passes=[LightPass(L, 1.0, vol, "zfail")],
            )
            ref = r.render(RenderRequest(**kw))
            lay = r.render_gpu(RenderRequest(**kw))
            c = np.frombuffer(lay.color_tex.read(), np.float16).reshape(lay.color_tex.height, lay.color_tex.width, 4)
            m = np.frombuffer(lay.mask_tex.read(), np.float16).reshape(
                lay.mask_tex.height, lay.mask_tex.width, lay.mask_tex.components
            )[:, :, :2]
            c = c[: canvas[3], : canvas[2]][::-1].astype(np.float32)
            m = m[: canvas[3], : canvas[2]][::-1].astype(np.float32)
            assert ref.mask.sum() > 1000 and ref.alpha.sum() > 1000
            np.testing.assert_array_equal(np.clip(m[..., 0], 0, 1), ref.mask)
            np.testing.assert_array_equal(m[..., 1], ref.ground_coverage)
            np.testing.assert_array_equal(c[..., 3], ref.alpha)
            np.testing.assert_array_equal(c[..., :3], ref.color)


def _executed(ctx, camera, paths, *, dist=(), out=None, chooser=None, **opts):
    """The box_point frame composited by :func:`arshadow.frame.execute.execute` with the camera effects
    ``camera`` (a CameraEffects: the session measures them on a tracked photo; here they are given), by each
    compose path of ``paths`` (``"measure"``: both, timed by ``chooser``): ``{path: (composite, mask, item)}``."""
    return {path: _executed_by(ctx, camera, path, dist, out, chooser, opts) for path in paths}


def _executed_by(ctx, camera, path, dist, out, chooser, opts):
    from arshadow.compose.composite import Workspace
    from arshadow.frame.execute import FrameContext, FrameOutputs, execute
    from arshadow.gl.gpu_compose import GpuCompositor
    from arshadow.plan.planner import decide_compose

    s, pose = _sky_session(ctx, chooser, dist=dist, **{"aa": 4, "ambient_occlusion": "off", **opts})
    made = []

    def gpu():
        if not made:
            made.append(GpuCompositor(s.renderer.ctx))
        return made[0]

    with s:
        plan = s.plan(pose, W, H)
        decide_compose(plan, force=None if path == "measure" else path, shader_available=True)
        context = FrameContext(
            geometry=s.geometry,
            renderer=lambda: s.renderer,
            work=Workspace(),
            calibration=s.hooks.calibration,
            compose_key=s.hooks.compose_key,
            chooser=s.hooks.compose_chooser,
            gpu=gpu,
        )
        outputs = FrameOutputs(out=out)
        composite, mask = execute(plan, _photo() if out is None else out, context, outputs, camera=camera)
        for g in made:
            g.release()
    return composite.copy(), mask, outputs.item


@pytest.mark.parametrize("sigma", [0.8, 2.4])
@pytest.mark.parametrize("sky", ["off", "on"])
@pytest.mark.parametrize("dist", [(), (-0.25, 0.05, 0.001, -0.002, 0.0)], ids=["pinhole", "distorted"])
def test_shader_compose_blurs_the_layers_as_the_numpy_path(ctx, tol, dist, sky, sigma):
    """Camera effects' blur (the photo's point-spread width) on the shader path: the warped layers (shadow,
    sky occlusion, object) blurred by the same Gaussian over the ROI grown by its reach, equal to the numpy
    path's composite within one level; the frame takes the shader path as decided (no forced numpy)."""
    from arshadow.frame.effects import CameraEffects

    cam = CameraEffects(sigma, ())  # blur only: the noise is compared statistically (below)
    res = _executed(ctx, cam, ("cpu", "gpu"), dist=dist, ambient_occlusion=sky)
    plain = _executed(ctx, None, ("cpu",), dist=dist, ambient_occlusion=sky)["cpu"][0]
    (o_cpu, m_cpu, i_cpu), (o_gpu, m_gpu, i_gpu) = res["cpu"], res["gpu"]
    assert i_gpu.compose == "gpu" and i_gpu.plan["compose"] == "forced gpu"
    assert i_cpu.plan["camera_effects"]["blur_sigma_px"] == sigma
    # the blur really changes the photo, where nothing was composited without it too
    blurred = np.abs(o_cpu.astype(np.int16) - plain).max(axis=2) > tol.gpu_compose_levels
    untouched = np.all(plain == _photo(), axis=2)
    assert np.count_nonzero(blurred) > 2000 and np.count_nonzero(blurred & untouched) > 100
    d = np.abs(o_gpu.astype(np.int16) - o_cpu)
    dm = np.abs(m_gpu.astype(np.int16) - m_cpu)
    print(
        f"\nblur {sigma} sky {sky} {dist}: {np.count_nonzero(blurred)} px blurred; photo max {d.max()} "
        f"({np.count_nonzero(d)}), mask max {dm.max()} ({np.count_nonzero(dm)})"
    )
    assert int(d.max()) <= tol.gpu_compose_levels
    assert int(dm.max()) <= tol.gpu_compose_levels


def test_in_place_composite_with_camera_blur_while_the_chooser_times_both_paths(ctx, tol):
    """The blur writes beyond the plan's ROI: every timed run must start from the untouched photo there too
    (the grown region), not from the previous run's composite."""
    from arshadow.frame.effects import CameraEffects
    from arshadow.gl.gpu_compose import PathChooser

    cam = CameraEffects(2.4, ())
    ref = _executed(ctx, cam, ("cpu",))["cpu"][0]
    photo = np.array(_photo())
    chooser = PathChooser(decisions={}, time_software=True)
    res = _executed(ctx, cam, ("measure",), out=photo, chooser=chooser)["measure"]
    assert res[0] is not None and set(next(iter(chooser.decisions.values()))["ms"]) == {"cpu", "gpu"}
    assert res[2].compose in ("cpu", "gpu")
    lim = 0 if res[2].compose == "cpu" else tol.gpu_compose_levels
    assert int(np.abs(photo.astype(np.int16) - ref).max()) <= lim


def _noise_stats(tol, noisy, clean, table, rows, half):
    """Check the noise ``noisy - clean`` (8-bit) against ``table (1, 256, 3)``: over ``rows`` (full coverage)
    per channel and 16-level bin of the clean code, its sigma (with the rounding's 1/12) and mean; there,
    neighbours and channels uncorrelated; over ``half`` (coverage 0.5), half the sigma. Returns the worst
    relative sigma error."""
    d, c = noisy[half].astype(np.float64) - clean[half], clean[half]
    for ch in range(3):
        want = np.sqrt(np.mean(0.25 * table[0, c[:, :, ch], ch].astype(np.float64) ** 2) + 1 / 12)
        assert abs(d[:, :, ch].std() / want - 1) <= tol.noise_table_sigma_rel, (ch, d[:, :, ch].std(), want)
    d = noisy[rows].astype(np.float64) - clean[rows]
    c = clean[rows]
    worst, bins = 0.0, 0
    for ch in range(3):
        for lo in range(16, 224, 16):  # clear of the clipping at 0 and 255
            sel = (c[:, :, ch] >= lo) & (c[:, :, ch] < lo + 16)
            if np.count_nonzero(sel) < 3000:
                continue
            want = np.sqrt(np.mean(table[0, c[:, :, ch][sel], ch].astype(np.float64) ** 2) + 1 / 12)
            got = d[:, :, ch][sel]
            worst = max(worst, abs(got.std() / want - 1))
            assert abs(got.std() / want - 1) <= tol.noise_table_sigma_rel, (ch, lo, got.std(), want)
            assert abs(got.mean()) <= tol.noise_table_mean_se * got.std() / np.sqrt(got.size), (ch, lo, got.mean())
            bins += 1
    assert bins >= 36  # the ramp covers the levels in every channel
    for a, b in ((d[:, :-1, 0], d[:, 1:, 0]), (d[:-1, :, 1], d[1:, :, 1]), (d[:, :, 0], d[:, :, 2])):
        assert abs(np.corrcoef(a.ravel(), b.ravel())[0, 1]) <= tol.noise_corr_abs
    return worst


def test_shader_noise_matches_the_measured_table(ctx, tol):
    """The shader path's sensor noise where the object covers: per level and channel the sigma of the
    measured table (as numpy's add_noise, checked by the same rule), zero mean, independent between pixels
    and channels, none where nothing is drawn, the same for the same photo."""
    from arshadow.compose.composite import srgb_to_linear
    from arshadow.compose.look import Look
    from arshadow.estimate.optics import NoiseEstimate
    from arshadow.frame.effects import CameraEffects, add_noise
    from arshadow.gl.gpu_compose import GpuCompositor
    from arshadow.gl.layers import GpuLayers
    from arshadow.plan.planner import FramePlan

    w, h, top, half = 512, 256, 32, 96
    # the object covers all but the top rows with a ramp of every code (B rising, G falling, R rising), half
    # of rows top..half (premultiplied colour), all of the rows below
    lin = srgb_to_linear(np.linspace(0.0, 1.0, w))
    rgba = np.zeros((h, w, 4), np.float32)  # bottom-up rows, as the renderer's
    rgba[:, :, 0], rgba[:, :, 1], rgba[:, :, 2], rgba[:, :, 3] = lin, lin[::-1], lin, 1.0
    rgba[h - half : h - top] *= 0.5
    rgba[h - top :] = 0.0
    color = ctx.texture((w, h), 4, data=rgba.astype(np.float16).tobytes(), dtype="f2")
    mask = ctx.texture((w, h), 2, data=np.zeros((h, w, 2), np.float16).tobytes(), dtype="f2")
    layers = GpuLayers(color, mask, w, h)
    plan = FramePlan(size=(w, h), cam_from_world=np.eye(4), znear=0.1, roi=(0, 0, w, h), canvas=(0, 0, w, h))
    paper = NoiseEstimate(np.array([2.0, 3.0, 4.0]) / 255, np.full(3, 0.2), 100)
    floor = NoiseEstimate(np.array([5.0, 6.0, 9.0]) / 255, np.full(3, 0.8), 100)
    cam = CameraEffects(0.0, (paper, floor))
    photo = np.random.default_rng(1).integers(0, 256, (h, w, 3), dtype=np.uint8)
    gpu = GpuCompositor(ctx)
    try:
        clean = gpu.compose(photo, layers, plan, Look())
        noisy = gpu.compose(photo, layers, plan, Look(camera=cam))
        again = gpu.compose(photo, layers, plan, Look(camera=cam))
        other = gpu.compose(photo[::-1].copy(), layers, plan, Look(camera=cam))
    finally:
        gpu.release()
        color.release()
        mask.release()
    assert np.array_equal(noisy, again)  # reproducible per photo
    assert np.array_equal(noisy[:top], clean[:top])  # nothing drawn: the photo's own noise only
    assert not np.array_equal(other[top:] - clean[top:], noisy[top:] - clean[top:])  # seeded by the photo
    worst_gpu = _noise_stats(tol, noisy, clean, cam.noise_table, slice(half, None), slice(top, half))
    # the numpy path's noise on the same composite passes the same rule
    ref = clean.copy()
    alpha = np.ones((h, w), np.float32)
    alpha[:top], alpha[top:half] = 0.0, 0.5
    add_noise(ref, alpha, cam.noise_table, cam.noise_seed(photo))
    worst_cpu = _noise_stats(tol, ref, clean, cam.noise_table, slice(half, None), slice(top, half))
    print(f"\nworst sigma error: shader {worst_gpu:.4f}, numpy {worst_cpu:.4f}")


def test_path_chooser_times_both_and_keeps_the_faster():
    import time

    from arshadow.gl.gpu_compose import PathChooser

    calls = []

    def slow():
        calls.append("slow")
        time.sleep(0.004)
        return "s"

    def fast():
        calls.append("fast")
        return "f"

    ch = PathChooser(trials=2, decisions={}, margin=0.0)
    assert ch.run("k", {"slow": slow, "fast": fast}) == ("fast", "f")
    assert calls.count("slow") == 3 and calls.count("fast") == 4  # warm-up + 2 timed each, then the winner
    assert ch.decisions["k"]["choice"] == "fast" and ch.decisions["k"]["ms"]["slow"] >= 4.0
    calls.clear()
    assert ch.run("k", {"slow": slow, "fast": fast}) == ("fast", "f") and calls == ["fast"]
    from arshadow.gl.gpu_compose import SHARED_DECISIONS

    assert PathChooser(decisions=SHARED_DECISIONS).decisions is SHARED_DECISIONS
    forced = PathChooser(force="slow")
    assert forced.run("k", {"slow": slow, "fast": fast}) == ("slow", "s")


def test_in_place_composite_while_the_chooser_times_both_paths(ctx, tol):
    """The video engine composites in place (out is the decoded frame). On a session's first frame the
    chooser runs every path several times: each run must start from the untouched photo, not from the
    previous run's composite (the shadow was applied once per run: 17 levels where 88 belong)."""
    from arshadow.frame.session import Session
    from arshadow.geometry.mesh import load_occluder
    from arshadow.gl.gpu_compose import PathChooser
    from arshadow.lights.spec import parse_light
    from arshadow.scene.spec import RenderOptions, Scene
    from arshadow.synth.markers import look_at_pose

    c = CASES["box_point"]
    intr, caster = _intrinsics(), load_occluder(c["caster_spec"])
    pose = look_at_pose(c["eye"], c["target"])
    results = {}
    for where in ("copy", "in_place"):
        photo = np.array(_photo())
        scene = Scene(
            intr,
            caster,
            [parse_light(c["light"])],
            RenderOptions(compose="auto", outline_aa="off"),
            {"marker_length": 0.05},
        )
        with Session(scene, context=ctx) as comp:
            # nothing decided yet: this first frame is timed (on llvmpipe too)
            comp.hooks.compose_chooser = PathChooser(decisions={}, time_software=True)
            out, mask, info = _rendered(comp.render(photo, pose, out=photo if where == "in_place" else None))
            assert set(next(iter(comp.hooks.compose_chooser.decisions.values()))["ms"]) == {"cpu", "gpu"}
        assert (out is photo) == (where == "in_place")
        results[where] = (out.copy(), info.compose)
    (a, ca), (b, cb) = results["copy"], results["in_place"]
    assert np.count_nonzero(np.any(a != _photo(), axis=2)) > 2000
    lim = 0 if ca == cb else tol.gpu_compose_levels
    assert int(np.abs(a.astype(np.int16) - b).max()) <= lim


def test_path_chooser_keeps_the_default_unless_another_is_clearly_faster():
    """The first path is the default: a path within the margin does not displace it (no swapping from run
    to run on noise); one faster by more than the margin does."""
    from arshadow.gl.gpu_compose import PathChooser

    now = [0.0]  # a deterministic clock (s): each path advances it by its cost, whatever the machine's load

    def wait(ms):
        def go():
            now[0] += ms / 1e3
            return ms

        return go

    def clock():
        return now[0]

    close = PathChooser(trials=3, decisions={}, margin=0.5, clock=clock)
    assert close.run("k", {"default": wait(4.0), "other": wait(3.0)})[0] == "default"  # 25 % faster only
    assert close.decisions["k"]["ms"]["other"] < close.decisions["k"]["ms"]["default"]
    clear = PathChooser(trials=3, decisions={}, margin=0.5, clock=clock)
    assert clear.run("k", {"default": wait(8.0), "other": wait(1.0)})[0] == "other"  # 8x faster
    with pytest.raises(Exception, match="margin"):
        PathChooser(margin=1.0)
