"""The frame planner end to end (Compositor with ``plan="auto"`` against the ``general`` reference plan).

- every scene of the render accuracy tests (tests/test_gl_renderer.py, tests/test_pipeline.py): the masks
  of ``auto`` and ``general`` (z-fail, volumes to infinity, whole photo, every pass, geometry rebuilt
  every frame) agree with IoU >= TOL.plan_mask_iou;
- each decision is taken where it should be and never where it must not be: a non-convex drawn occluder
  never goes planar, a camera inside a volume never goes z-pass, a light whose shadow is off screen is
  skipped (and the result does not change), a moved light keeps its geometry only when that is exact.
"""

from __future__ import annotations

import numpy as np
import pytest
import render_scenes
from image_oracle import iou

from arshadow.renderer.request import RenderRequest

pytestmark = pytest.mark.gl

W, H = 1280, 720


def _rendered(res):
    """A :class:`arshadow.frame.session.FrameResult` as ``(composite, mask, report item)``."""
    return res.composite, res.mask, res.item


def _spec(lh, w):
    lh = np.asarray(lh, float)
    kind = "point" if lh[3] else "directional"
    xyz = lh[:3] / (lh[3] if lh[3] else 1.0)
    return f"{kind}:{float(xyz[0])!r},{float(xyz[1])!r},{float(xyz[2])!r}@{float(w)!r}"


def _scenes():
    """(name, caster, light specs, cam_from_world, intrinsics, options) of the accuracy tests' scenes."""

    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.synth.markers import look_at_pose

    out = []
    for sc in render_scenes.scenes():
        out.append(
            (
                f"renderer:{sc.name}",
                sc.caster,
                [_spec(lh, w) for lh, w in sc.lights],
                sc.cam_from_world,
                render_scenes.intrinsics(sc.fx),
                {"ground_size": sc.ground_size},
            )
        )

    def intr(dist=()):
        return Intrinsics(1000.0, 1000.0, 641.3, 358.2, W, H, np.asarray(dist, float))

    knot = load_occluder("samples/meshes/knot.ply")
    k1 = (-0.25, 0.0, 0.0, 0.0, 0.0)
    mild = (-0.045, 0.021, 0.0004, -0.0003, -0.006)
    out += [
        (
            "pipeline:k1_box_point_corner",
            load_occluder("box:0.06,0.05,0.09"),
            ["point:0.25,0.15,0.45"],
            look_at_pose([0.15, -0.55, 0.42], [0.17, -0.12, 0.02]),
            intr(k1),
            {},
        ),
        (
            "pipeline:k1_torus_directional_edge",
            load_occluder("torus:0.06,0.02", rotate=(70, 0, 20), place=(0, 0, 0.09)),
            ["directional:-0.3,0.5,1.0"],
            look_at_pose([-0.5, -0.45, 0.35], [-0.08, 0.12, 0.0]),
            intr(k1),
            {},
        ),
        (
            "pipeline:mask_zero_on_object",
            load_occluder("box:0.06,0.05,0.09"),
            ["point:0.25,0.15,0.45"],
            look_at_pose([0.15, -0.55, 0.42], [0.0, 0.0, 0.02]),
            intr(),
            {},
        ),
        (
            "pipeline:knot_two_lights_mild_distortion",
            knot,
            ["point:0.2,0.1,0.5", "directional:-0.4,0.3,1@0.5"],
            look_at_pose([0.25, -0.45, 0.4], [0.0, 0.02, 0.03]),
            intr(mild),
            {},
        ),
        (
            "pipeline:wall_camera_in_shadow",
            load_occluder("box:0.6,0.02,0.5", place=(0, 0.1, 0)),
            ["directional:0,1,0.35"],
            look_at_pose([0.05, -0.2, 0.15], [0.0, -0.6, 0.0]),
            intr(),
            {},
        ),
        (
            "pipeline:ground_size",
            load_occluder("box:0.04,0.04,0.1"),
            ["directional:1,0,0.08"],
            look_at_pose([0.0, -0.5, 0.4], [0.0, 0.0, 0.0]),
            intr(),
            {"ground_size": 0.3},
        ),
        (
            "pipeline:knot_no_object",
            knot,
            ["point:0.2,0.1,0.5"],
            look_at_pose([0.25, -0.45, 0.4], [0.0, 0.02, 0.03]),
            intr(),
            {"draw_occluder": False},
        ),
    ]
    return out


@pytest.fixture(scope="module")
def scenes():
    return {s[0]: s for s in _scenes()}


def _run(ctx, scene, plan, aa=0, **extra):
    from arshadow.frame.session import Session
    from arshadow.lights.spec import parse_light
    from arshadow.scene.spec import RenderOptions, Scene

    name, caster, specs, pose, intr, opts = scene
    lights = [parse_light(s) for s in specs]
    o = {k: v for k, v in opts.items() if v is not None}
    o.update(extra)
    photo = np.full((H, W, 3), 140, np.uint8)
    scene = Scene(intr, caster, lights, RenderOptions(plan=plan, aa=aa, compose="cpu", **o), {"marker_length": 0.05})
    with Session(scene, context=ctx) as comp:
        out, mask, info = _rendered(comp.render(photo, pose))
    weights = np.array([lt.weight for lt in lights], float)
    return out, mask, info, 0.5 * weights.min() / weights.sum() * 255.0


SCENE_NAMES = [
    "renderer:box_point",
    "renderer:nonconvex_point",
    "renderer:torus_directional",
    "renderer:wall_camera_in_shadow",
    "renderer:box_two_lights",
    "pipeline:k1_box_point_corner",
    "pipeline:k1_torus_directional_edge",
    "pipeline:mask_zero_on_object",
    "pipeline:knot_two_lights_mild_distortion",
    "pipeline:wall_camera_in_shadow",
    "pipeline:ground_size",
    "pipeline:knot_no_object",
]
PLAN_RESULTS: dict = {}


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_auto_equals_general_on_every_accuracy_scene(ctx, tol, scenes, name):
    sc = scenes[name]
    _, m_gen, i_gen, t = _run(ctx, sc, "general")
    _, m_auto, i_auto, _ = _run(ctx, sc, "auto")
    assert i_gen.modes == ["zfail"] * len(sc[2]) and i_gen.roi == [0, 0, W, H]
    a, g = m_auto >= t, m_gen >= t
    assert g.sum() > 1000, "the scene has a shadow in view"
    score = iou(a, g)
    PLAN_RESULTS[name] = (i_auto.modes, score)
    print(f"\n{name}: auto modes {i_auto.modes}, IoU vs general {score:.6f}")
    assert score >= tol.plan_mask_iou
    # every decision of the auto plan is recorded with its reason
    assert len(i_auto.plan["lights"]) == len(sc[2])
    assert all(e["why"] for e in i_auto.plan["lights"]) and i_auto.plan["roi"]


def test_planar_taken_for_convex_and_undrawn_never_for_self_shadowing(ctx, scenes):
    # convex boxes (drawn) -> planar
    for name in ("renderer:box_point", "pipeline:mask_zero_on_object", "renderer:box_two_lights"):
        assert set(_run(ctx, scenes[name], "auto")[2].modes) == {"planar"}, name
    # non-convex occluders drawn (they shadow themselves) -> never planar, whatever the light
    for name in ("renderer:nonconvex_point", "renderer:torus_directional", "pipeline:knot_two_lights_mild_distortion"):
        info = _run(ctx, scenes[name], "auto")[2]
        assert "planar" not in info.modes, name
        assert all("not convex" in e["why"]["planar"] for e in info.plan["lights"])
    # the same non-convex knot, not drawn: only the ground receives -> planar
    assert _run(ctx, scenes["pipeline:knot_no_object"], "auto")[2].modes == ["planar"]
    # a point light below the top of a convex box: volumes
    from arshadow.geometry.mesh import load_occluder

    sc = scenes["renderer:box_point"]
    low = (sc[0], load_occluder("box:0.1,0.08,0.15"), ["point:-0.3,0.1,0.1"], sc[3], sc[4], {})
    assert "planar" not in _run(ctx, low, "auto")[2].modes


def test_camera_inside_a_volume_never_zpass(ctx, scenes):
    for name in ("renderer:wall_camera_in_shadow", "pipeline:wall_camera_in_shadow"):
        info = _run(ctx, scenes[name], "auto", plan_off=("planar",))[2]
        assert info.modes == ["zfail"], name
        assert "inside" in info.plan["lights"][0]["why"]["mode"]
    # outside every volume: z-pass
    info = _run(ctx, scenes["pipeline:knot_two_lights_mild_distortion"], "auto")[2]
    assert info.modes == ["zpass", "zpass"]


def test_light_with_shadow_off_screen_is_skipped(ctx, tol):
    """A box floating 10 cm above the ground in a tele view: light A's shadow falls right below it (in
    view), the low light B's far to the left, off the photo."""
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.synth.markers import look_at_pose

    box = load_occluder("box:0.04,0.04,0.04", place=(0, 0, 0.1))
    intr = Intrinsics(1500.0, 1500.0, 639.5, 359.5, W, H, np.zeros(5))
    pose = look_at_pose([0.0, -0.45, 0.35], [0.0, 0.0, 0.05])
    sc = ("cull", box, ["point:0.0,0.02,0.6", "directional:1,0,0.15@0.5"], pose, intr, {})
    _, m_auto, i_auto, t = _run(ctx, sc, "auto")
    _, m_gen, i_gen, _ = _run(ctx, sc, "general")
    assert i_auto.modes == ["planar", "none"], i_auto.plan
    assert i_auto.plan["lights"][1]["why"]["cull"] == "ground footprint outside the canvas"
    assert iou(m_auto >= t, m_gen >= t) >= tol.plan_mask_iou and (m_gen >= t).sum() > 1000
    # with a non-convex occluder the same light is never skipped (its volume may shadow the occluder)
    knot = load_occluder("torus:0.02,0.008", place=(0, 0, 0.1))
    info = _run(ctx, ("cull_knot", knot, sc[2], pose, intr, {}), "auto")[2]
    assert "none" not in info.modes
    # the whole scene off screen: no render at all
    away = ("away", box, sc[2], look_at_pose([0.0, -0.3, 0.3], [0.0, -1.5, 0.0]), intr, {})
    _, m, info, _ = _run(ctx, away, "auto")
    assert not m.any() and set(info.modes) == {"none"} and info.compose is None


def test_moved_light_reuses_geometry_only_when_exact(ctx):
    from arshadow.frame.session import Session
    from arshadow.geometry.mesh import load_occluder
    from arshadow.lights.spec import parse_light
    from arshadow.scene.spec import RenderOptions, Scene
    from arshadow.synth.markers import look_at_pose

    knot = load_occluder("samples/meshes/knot.ply")
    intr = _scenes()[5][4]
    pose = look_at_pose([0.25, -0.45, 0.4], [0.0, 0.02, 0.03])
    photo = np.full((H, W, 3), 140, np.uint8)
    opts = RenderOptions(compose="cpu")
    scene = Scene(intr, knot, [parse_light("point:0.2,0.1,0.5")], opts, {})
    with Session(scene, context=ctx) as comp:
        _rendered(comp.render(photo, pose))
        vol0 = comp.geometry.lights[0].volumes
        for spec, expect in (
            ("point:0.2,0.1,0.5000000000000001", "reused"),
            ("point:0.200002,0.1,0.5", "re-extruded"),
            ("point:-0.3,0.3,0.4", None),
        ):
            comp.set_lights([parse_light(spec)])
            out, mask, info = _rendered(comp.render(photo, pose))
            why = info.plan["lights"][0]["why"].get("reuse")
            assert (why is None) if expect is None else (expect in why), (spec, why)
            if expect == "reused":
                assert all(comp.geometry.lights[0].volumes[k] is v for k, v in vol0.items())
            with Session(Scene(intr, knot, [parse_light(spec)], opts, {}), context=ctx) as fresh:
                out_f, mask_f, _ = _rendered(fresh.render(photo, pose))
            assert np.array_equal(mask, mask_f) and np.array_equal(out, out_f), spec


@pytest.mark.parametrize("samples", [0, 4])
def test_direct_planar_pass_equals_the_stencil_planar_pass(ctx, samples):
    """Convex closed caster: the light-facing faces flattened straight into the mask (one draw per light,
    no stencil count) give the same mask as the stencil projection pass, levels of two lights included."""

    from arshadow.geometry.mesh import load_occluder
    from arshadow.gl.stencil import ShadowRenderer
    from arshadow.renderer.request import LightPass
    from arshadow.synth.markers import look_at_pose
    from arshadow.transforms import CV_TO_GL

    box = load_occluder("box:0.1,0.08,0.15", rotate=(0, 0, 25))
    intr = render_scenes.intrinsics(1000.0)
    pose = look_at_pose([0.5, -0.45, 0.5], [0.03, 0.03, 0.02])
    lights = [(np.array([-0.25, 0.05, 0.55, 1.0]), 0.5), (np.array([0.3, 0.2, 1.0, 0.0]), 0.5)]
    masks = {}
    with ShadowRenderer(ctx, samples=samples) as r:
        for direct in (False, True):
            res = r.render(
                RenderRequest(
                    projection=intr.gl_projection(0.01, None),
                    view=CV_TO_GL @ pose,
                    width=W,
                    height=H,
                    caster=box,
                    passes=[LightPass(lh, w, None, "planar", direct=direct) for lh, w in lights],
                )
            )
            masks[direct] = res.mask
    a, b = masks[False], masks[True]
    assert (a > 0.4).sum() > 5000 and (np.abs(a - 0.5) < 0.01).sum() > 1000  # both levels present
    assert np.count_nonzero(np.abs(a - b) > 1e-3) <= 20, np.count_nonzero(np.abs(a - b) > 1e-3)
    assert float(b.max()) <= 1.0 + 1e-3  # never counted twice


@pytest.mark.parametrize("light", [[0.1, -0.2, 0.5, 1.0], [-0.3, 0.4, 1.0, 0.0]], ids=["point", "directional"])
def test_footprint_hull_keeps_the_screen_bounds(light):
    """shadow_footprint returns only the vertices of the footprint's 2D convex hull: the screen rectangle of
    the footprint, from a random camera, is that of every vertex's own ground shadow (computed here
    directly: each vertex moved along the light ray to z = 0)."""
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.plan.planner import pinhole_rect, shadow_footprint
    from arshadow.synth.markers import look_at_pose

    v = np.asarray(load_occluder("torus:0.05,0.02", place=(0.0, 0.0, 0.03)).vertices, np.float64)
    L = np.asarray(light, np.float64)
    fp = shadow_footprint(np.array([v.min(0), v.max(0)]), L, points=v)
    if L[3]:
        t = L[2] / (L[2] - v[:, 2])
        every = L[:3] + (v - L[:3]) * t[:, None]
    else:
        every = v - L[:3] * (v[:, 2] / L[2])[:, None]
    assert len(fp) < len(v) / 4 and np.allclose(fp[:, 2], 0.0)
    intr = Intrinsics(900.0, 900.0, 640.0, 360.0, 1280, 720, np.zeros(5))
    rng = np.random.default_rng(3)
    for _ in range(20):
        eye = rng.uniform([-0.6, -0.6, 0.2], [0.6, 0.6, 0.8])
        pose = look_at_pose(eye, rng.uniform(-0.05, 0.05, 3) * [1, 1, 0])
        a, b = pinhole_rect(intr, pose, fp, 1e-3), pinhole_rect(intr, pose, every, 1e-3)
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)


def test_roi_from_the_hull_vertices_equals_the_roi_from_every_vertex(rng):
    """The planner bounds the ROI with the mesh's convex-hull vertices only (plan_geometry.extreme_points):
    the projected bounding box and the in-front test must be those of every vertex, from any camera."""
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.plan.scene_geometry import extreme_points, pinhole_rect
    from arshadow.synth.markers import look_at_pose

    v = np.asarray(load_occluder("samples/meshes/knot.ply").vertices, np.float64)
    ext = extreme_points(v)
    assert len(ext) < len(v) / 4
    intr = Intrinsics(1000.0, 1000.0, 640.0, 360.0, 1280, 720, np.zeros(5))
    in_front = behind = 0
    for _ in range(200):
        eye = rng.normal(size=3) * rng.uniform(0.03, 0.6)
        pose = look_at_pose(eye, rng.normal(size=3) * 0.02)
        a, b = pinhole_rect(intr, pose, v, 1e-3), pinhole_rect(intr, pose, ext, 1e-3)
        assert (a is None) == (b is None)
        if a is None:
            behind += 1
            continue
        in_front += 1
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9)
    assert in_front > 50 and behind > 5  # both branches exercised
