"""The GPU-resident compose path (arshadow/gl/gpu_compose.py) against the numpy path (lens warp + composite).

Both paths are fed the same render of the same canvas; the numpy path's result is the reference (it is
tested against hand values and analytic oracles in test_composite.py / test_lens.py / test_pipeline.py).
The shader must give the same 8-bit photo and mask within TOL.gpu_compose_levels, with and without lens
distortion, with MSAA 0 and 4, grey and tinted shadows, with and without the occluder, with and without sky
occlusion (the ground occlusion map's channel, darkening the ground beyond the shadow's mask).
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
            intr, caster, [parse_light(light)], RenderOptions(aa=aa, compose=path, **opts), {"marker_length": 0.05}
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
    (o_cpu, m_cpu, i_cpu), (o_gpu, m_gpu, i_gpu) = res["cpu"], res["gpu"]
    assert i_cpu.roi == i_gpu.roi and i_cpu.canvas == i_gpu.canvas
    # the scene really puts a shadow (and the occluder, when drawn) into the photo
    assert np.count_nonzero(m_cpu) > 2000
    assert np.count_nonzero(np.any(o_cpu != photo, axis=2)) > 2000
    d = np.abs(o_gpu.astype(np.int16) - o_cpu)
    dm = np.abs(m_gpu.astype(np.int16) - m_cpu)
    print(
        f"\n{case} {dist} aa={aa}: photo max {d.max()} ({np.count_nonzero(d)} values), "
        f"mask max {dm.max()} ({np.count_nonzero(dm)})"
    )
    assert int(d.max()) <= tol.gpu_compose_levels
    assert int(dm.max()) <= tol.gpu_compose_levels
    # outside the ROI both leave the photo as it was
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
}


@pytest.mark.parametrize("aa", [0, 4])
@pytest.mark.parametrize("dist", [(), (-0.25, 0.05, 0.001, -0.002, 0.0)], ids=["pinhole", "distorted"])
@pytest.mark.parametrize("case", sorted(SKY_CASES))
def test_shader_compose_equals_numpy_compose_with_sky_occlusion(ctx, tol, case, dist, aa):
    """The shader composites the sky-occlusion channel as the numpy path does (composite._darken_sky), over
    the same region: the sky darkens (or, with the reflected light, brightens) the ground beyond the mask."""
    photo, res = _both_paths(ctx, None, dist=dist, aa=aa, **SKY_CASES[case])
    (o_cpu, m_cpu, i_cpu), (o_gpu, m_gpu, i_gpu) = res["cpu"], res["gpu"]
    assert i_cpu.plan["ambient_occlusion"].startswith("on") and i_gpu.plan["ambient_occlusion"].startswith("on")
    assert i_cpu.roi == i_gpu.roi and i_cpu.canvas == i_gpu.canvas
    # what the sky term changes: the numpy composite of the same frame without sky occlusion
    off = _both_paths(ctx, ("cpu",), dist=dist, aa=aa, **{**SKY_CASES[case], "ambient_occlusion": "off"})
    o_off = off[1]["cpu"][0]
    sky = np.abs(o_cpu.astype(np.int16) - o_off).max(axis=2) > tol.gpu_compose_levels
    assert np.count_nonzero(sky & (m_cpu == 0)) > 2000  # beyond the shadow's mask too
    if "bounce" in case:  # the ground's reflected light: brighter than without sky occlusion somewhere
        assert np.count_nonzero(o_cpu.astype(np.int16).sum(axis=2) - o_off.astype(np.int16).sum(axis=2) > 3) > 100
    d = np.abs(o_gpu.astype(np.int16) - o_cpu)
    dm = np.abs(m_gpu.astype(np.int16) - m_cpu)
    print(
        f"\n{case} {dist} aa={aa}: sky changes {np.count_nonzero(sky)} px; photo max {d.max()} "
        f"({np.count_nonzero(d)} values), mask max {dm.max()} ({np.count_nonzero(dm)})"
    )
    assert int(d.max()) <= tol.gpu_compose_levels
    assert int(dm.max()) <= tol.gpu_compose_levels
    x0, y0, w, h = i_cpu.roi
    outside = np.ones((H, W), bool)
    outside[y0 : y0 + h, x0 : x0 + w] = False
    assert np.array_equal(o_gpu[outside], photo[outside]) and not np.any(m_gpu[outside])


def _sky_session(ctx, chooser=None, renderer=None, **opts):
    """A Session of the box_point case with sky occlusion on (compose "auto" unless ``opts`` say), its pose."""
    from arshadow.frame.session import Session
    from arshadow.geometry.mesh import load_occluder
    from arshadow.lights.spec import parse_light
    from arshadow.scene.spec import RenderOptions, Scene
    from arshadow.synth.markers import look_at_pose

    c = CASES["box_point"]
    options = RenderOptions(**{"compose": "auto", "ambient_occlusion": "on", **opts})
    scene = Scene(_intrinsics(), load_occluder(c["caster_spec"]), [parse_light(c["light"])], options, {})
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
        scene = Scene(intr, caster, [parse_light(c["light"])], RenderOptions(compose="auto"), {"marker_length": 0.05})
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
