"""The Python API (the Python API work): scene specs, Session, the pure planner, the renderer interface, history state.

Ground truth is independent of the code under test: the synthetic photos' generating poses, analytic
projections of the box's corners, and equality between two routes through the pipeline that share no
shortcut (track + render vs process; a spawned worker vs this process; with vs without the renderer's raw
layers).
"""

from __future__ import annotations

import json
import multiprocessing
import pickle
import re
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
CALIB = str(ROOT / "calib" / "synth_1280x720.yml")

SCENE = {
    "calib": CALIB,
    "marker_length": 0.05,
    "model": "box:0.04,0.04,0.06",
    "rotate": [0, 0, 30],
    "lights": ["point:0.1,0.1,0.4", "directional:-0.3,0.2,1@0.5"],
}


def _volume_spec():
    """:data:`SCENE` with shadow volumes: its box is convex, which the planner would draw with projection
    shadows (no silhouette or volume to cache); the state/reuse tests are about the volume cache."""
    import dataclasses

    import arshadow

    spec = arshadow.scene_from_dict(SCENE)
    return spec.replace(options=dataclasses.replace(spec.options, plan_off=("planar",)))


def _photo(eye=(0.1, -0.3, 0.4), seed=1):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    cam = Intrinsics.from_file(CALIB)
    truth = look_at_pose(list(eye), [0.0, 0.0, 0.0])
    return render_marker_photo(cam, truth, marker_length=0.05, seed=seed).image, truth


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )


# ------------------------------------------------------------------------------------------ imports
def test_import_arshadow_loads_no_opengl():
    r = _run(
        "import sys, arshadow\n"
        "arshadow.Session, arshadow.SceneSpec, arshadow.scene_from_dict, arshadow.render_photo, arshadow.synth\n"
        "import arshadow.plan, arshadow.frame.execute, arshadow.renderer.request, arshadow.frame.session, arshadow.frame.hooks\n"
        "bad = [m for m in sys.modules if m.startswith('moderngl') or m.startswith('arshadow.gl')]\n"
        "assert not bad, bad\nprint('ok')"
    )
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr


def test_sun_does_not_import_lights():
    r = _run("import sys, arshadow.lights.sun\nassert 'arshadow.lights.spec' not in sys.modules\nprint('ok')")
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr


def test_planner_is_pure_and_its_roi_holds_the_projected_object():
    """plan_frame without any GL module loaded; its ROI contains the analytic (distorted) projection of
    the box's corners and of their shadows on the ground; far camera z-pass, camera in the shadow z-fail."""
    code = f"""
import sys, numpy as np
from arshadow.scene import scene_from_dict
from arshadow.plan import SceneGeometry, plan_frame
from arshadow.compose.lens import LensWarp
from arshadow.synth import look_at_pose
spec = scene_from_dict({{"calib": {CALIB!r}, "marker_length": 0.05, "model": "box:0.04,0.04,0.06",
                         "lights": ["point:0.1,0.1,0.4"]}})
sc = spec.build()
import dataclasses
# the box is convex: switch the planar decision off to test the z-pass / z-fail choice (docs/planner.md)
geo = SceneGeometry(sc.caster, dataclasses.replace(sc.options, plan_off=("planar",)), sc.lights)
intr = sc.intrinsics
pose = look_at_pose([0.1, -0.3, 0.4], [0, 0, 0])
plan = plan_frame(geo, intr, pose, 1280, 720, lens=LensWarp(intr))
L = np.array([0.1, 0.1, 0.4])
box = np.array([[x, y, z] for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (0.0, 0.06)])
shadow = L + (box - L) * (L[2] / (L[2] - box[:, 2]))[:, None]   # the corners projected from L onto z = 0
pts = np.concatenate([box, shadow])
uv = intr.project(pts, pose)
x0, y0, w, h = plan.roi
assert np.all(uv[:, 0] >= x0) and np.all(uv[:, 0] <= x0 + w - 1), (uv, plan.roi)
assert np.all(uv[:, 1] >= y0) and np.all(uv[:, 1] <= y0 + h - 1), (uv, plan.roi)
assert plan.modes == ["zpass"], plan.modes
assert [d.name for d in plan.decisions][:3] == ["znear", "roi", "canvas"]
assert all(d.reason for d in plan.decisions)
# a camera whose view towards a low light passes through a box (it stands in the shadow): z-fail; a
# camera beside the shadow: z-pass (the geometry of test_pipeline's mode test)
from arshadow.geometry.mesh import load_occluder
from arshadow.lights.spec import parse_light
from arshadow.scene import RenderOptions
from arshadow.camera import Intrinsics
geo2 = SceneGeometry(load_occluder("box:0.1,0.1,0.1"), RenderOptions(plan_off=("planar", "cull")),
                     [parse_light("directional:1,0,0.2")])
pin = Intrinsics(fx=500.0, fy=500.0, cx=639.5, cy=359.5, width=1280, height=720, dist=np.zeros(0))
for y, mode in ((0.0, "zfail"), (0.1, "zpass")):
    e = np.array([-0.3, y, 0.05])
    p2 = plan_frame(geo2, pin, look_at_pose(e, e + np.array([0.0, 1.0, -0.3])), 1280, 720)
    assert p2.modes == [mode], (y, p2.modes)
    assert p2.lights[0].reason and p2.lights[0].caps == (mode == "zfail") and not p2.lights[0].reuse
bad = [m for m in sys.modules if m.startswith('moderngl') or m.startswith('arshadow.gl')]
assert not bad, bad
print("ok")
"""
    r = _run(code)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stderr


def test_light_pass_carries_the_planar_matrix():
    from arshadow.geometry.projection import GROUND_PLANE, planar_shadow_matrix
    from arshadow.renderer.request import LightPass

    lh = np.array([0.1, 0.2, 0.5, 1.0])
    p = LightPass(lh, 1.0, None, "planar")
    assert np.allclose(p.shadow_matrix, planar_shadow_matrix(GROUND_PLANE, lh))
    # a point on the ground maps to itself; a point above it to the ground along the light ray
    X = p.shadow_matrix @ np.array([0.0, 0.0, 0.1, 1.0])
    X = X[:3] / X[3]
    t = 0.5 / (0.5 - 0.1)
    assert np.allclose(X, lh[:3] + (np.array([0.0, 0.0, 0.1]) - lh[:3]) * t)
    assert LightPass(np.array([0.0, 0.0, -1.0, 0.0]), 1.0, None, "planar").shadow_matrix is None
    assert LightPass(lh, 1.0, None, "zpass").shadow_matrix is None


# ------------------------------------------------------------------------------------------ scene specs
def test_scene_from_yaml_json_and_python_are_equal(tmp_path):
    import arshadow
    from arshadow.scene.spec import ModelSpec, RenderOptions, SceneSpec, TrackerSpec, load_scene, scene_from_dict

    calib_dir = tmp_path / "cal"
    calib_dir.mkdir()
    (calib_dir / "cam.yml").write_text(Path(CALIB).read_text())
    job = {
        "calib": "cal/cam.yml",
        "marker_length": 0.05,
        "marker_id": 0,
        "model": "box:0.04,0.04,0.06",
        "rotate": [0, 0, 30],
        "place": [0.01, 0, 0],
        "color": "200,80,40",
        "lights": ["point:0.1,0.1,0.4", "directional:-0.3,0.2,1@0.5"],
        "opacity": 0.6,
        "soft_samples": 2,
    }
    (tmp_path / "job.json").write_text(json.dumps(job))
    (tmp_path / "job.yml").write_text(
        "# a job file\ncalib: cal/cam.yml\nmarker_length: 0.05\nmarker_id: 0\nmodel: box:0.04,0.04,0.06\n"
        "rotate: [0, 0, 30]\nplace: [0.01, 0, 0]\ncolor: [200, 80, 40]\nlights:\n  - point:0.1,0.1,0.4\n"
        "  - directional:-0.3,0.2,1@0.5\nopacity: 0.6\nsoft_samples: 2\n"
    )
    from_yaml = load_scene(tmp_path / "job.yml")
    from_json = arshadow.load_scene(tmp_path / "job.json")
    from_dict = scene_from_dict(job, base_dir=tmp_path)
    by_hand = SceneSpec(
        camera=str(calib_dir / "cam.yml"),
        tracker=TrackerSpec(marker_length=0.05, marker_id=0),
        model=ModelSpec("box:0.04,0.04,0.06", rotate=(0.0, 0.0, 30.0), place=(0.01, 0.0, 0.0), color="200,80,40"),
        lights=("point:0.1,0.1,0.4", "directional:-0.3,0.2,1@0.5"),
        options=RenderOptions(opacity=0.6, soft_samples=2),
    )
    assert from_yaml == from_json == from_dict == by_hand
    assert pickle.loads(pickle.dumps(from_yaml)) == by_hand
    scene = from_yaml.build()  # the relative calibration path resolved against the job file's folder
    assert scene.intrinsics.width == 1280 and len(scene.lights) == 2 and scene.tracker["marker_length"] == 0.05


def test_scene_errors_are_usage_errors(tmp_path):
    from arshadow.errors import CalibrationError, UsageError
    from arshadow.scene.spec import load_scene, scene_from_dict

    with pytest.raises(UsageError, match="unknown scene key"):
        scene_from_dict({**SCENE, "ligths": ["point:0,0,1"]})
    with pytest.raises(UsageError, match="'model'"):
        scene_from_dict({k: v for k, v in SCENE.items() if k != "model"})
    with pytest.raises(UsageError, match="marker-length"):
        scene_from_dict({k: v for k, v in SCENE.items() if k != "marker_length"}).build()
    with pytest.raises(UsageError, match="--opacity"):
        scene_from_dict({**SCENE, "opacity": 3}).build()
    (tmp_path / "bad.yml").write_text("calib: [unclosed\n")
    with pytest.raises(UsageError, match="bad.yml"):
        load_scene(tmp_path / "bad.yml")
    with pytest.raises(CalibrationError):
        scene_from_dict({**SCENE, "calib": str(tmp_path / "missing.yml")}).build()


# ------------------------------------------------------------------------------------------ the session
def test_readme_python_example_runs():
    text = (ROOT / "README.md").read_text()
    block = re.search(r"## Python\n.*?```python\n(.*?)```", text, re.S)
    assert block, "README has no ## Python example"
    r = subprocess.run(
        [sys.executable, "-c", block.group(1)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert r.returncode == 0, r.stderr
    first = r.stdout.splitlines()[0].split()
    # the README's box is convex: the planner (docs/planner.md) draws its shadow as a projection
    assert first[0] in ("zpass", "zfail", "planar") and first[1] == "[0]", r.stdout
    shadow = re.search(r"shadow pixels: (\d+) at the true pose: (\d+)", r.stdout)
    assert shadow and int(shadow.group(1)) > 1000 and int(shadow.group(2)) > 1000, r.stdout


@pytest.mark.gl
def test_session_routes_agree_and_the_pose_is_the_true_one(gl_ctx, tol):
    """process() == track() + render(); the tracked pose is the generating one; render at the generating
    pose gives (nearly) the same mask; the result is typed and complete."""
    import arshadow

    photo, truth = _photo()
    spec = arshadow.scene_from_dict(SCENE)
    with arshadow.Session(spec, context=gl_ctx) as s:
        res = s.process(photo, name="p")
        pose = s.track(photo)
        res2 = s.render(photo, pose, name="p")
        res3 = s.render(photo, truth)
    assert isinstance(res, arshadow.FrameResult)
    assert res.composite.shape == photo.shape and res.mask.shape == photo.shape[:2]
    assert np.array_equal(res.mask, res2.mask) and np.array_equal(res.composite, res2.composite)
    assert res.item.rvec == res2.item.rvec and res.item.mode == res2.item.mode
    err = np.linalg.norm(res.cam_from_world[:3, 3] - truth[:3, 3]) / np.linalg.norm(truth[:3, 3])
    assert err < tol.fast_detector_distance_rel
    assert np.count_nonzero(res.mask) > tol.shadow_min_pixels
    inter = np.count_nonzero((res.mask > 127) & (res3.mask > 127))
    union = np.count_nonzero((res.mask > 127) | (res3.mask > 127))
    assert inter / union > tol.end_to_end_iou_median
    assert set(res.timings_ms) >= {"detect", "pose", "render", "composite", "total"}
    assert res.plan.roi == tuple(res.item.roi)


def _worker_mask(session, image):
    res = session.process(image, name="worker")
    session.close()
    return res.mask, res.item.rvec


@pytest.mark.gl
def test_session_pickles_as_its_spec_and_a_spawned_worker_gets_the_same_mask(gl_ctx):
    import arshadow

    photo, _ = _photo(eye=(-0.15, -0.25, 0.35), seed=3)
    spec = arshadow.scene_from_dict(SCENE)
    with arshadow.Session(spec, context=gl_ctx) as s:
        here = s.process(photo)
        blob = pickle.dumps(s)
    assert len(blob) < 10_000  # the spec, not the mesh, the caches or the context
    assert pickle.loads(blob).spec == spec
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as ex:
        mask, rvec = ex.submit(_worker_mask, s, photo).result(timeout=300)
    assert np.array_equal(mask, here.mask)
    assert rvec == here.item.rvec


@pytest.mark.gl
def test_state_restore_reuses_geometry_and_gives_the_same_frame(gl_ctx):
    import arshadow

    photo, _ = _photo()
    spec = _volume_spec()
    with arshadow.Session(spec, context=gl_ctx) as a:
        first = a.process(photo)
        state = pickle.loads(pickle.dumps(a.state()))
    assert first.timings_ms["silhouette"] > 0  # built on the first frame
    with arshadow.Session(spec, context=gl_ctx) as b:
        b.restore(state)
        plan = b.plan(first.cam_from_world, photo.shape[1], photo.shape[0])
        assert all(lp.reuse for lp in plan.lights)
        again = b.process(photo)
    assert again.timings_ms["silhouette"] == 0 and again.timings_ms["volume"] == 0
    assert np.array_equal(again.mask, first.mask)


@pytest.mark.gl
def test_a_renderer_without_raw_layers_plugs_in_and_agrees(gl_ctx, tol):
    """The executor needs only the Renderer protocol: a renderer whose results carry no raw layers (as a
    second technique's may not) composites through the result's own arrays, to the same mask."""
    import dataclasses

    import arshadow
    from arshadow.gl.stencil import ShadowRenderer
    from arshadow.renderer.request import Renderer, RendererBase

    class NoLayers(RendererBase):  # the capabilities' defaults: no GPU layers
        def __init__(self, ctx, options):
            self.inner = ShadowRenderer(ctx, samples=int(options.aa))
            self.calls = 0

        def render(self, request):
            self.calls += 1
            return dataclasses.replace(self.inner.render(request), layers=None)

        def release(self):
            self.inner.release()

    made = []

    def factory(ctx, options):
        made.append(NoLayers(ctx, options))
        return made[-1]

    photo, _ = _photo()
    spec = arshadow.scene_from_dict(SCENE)
    with arshadow.Session(spec, context=gl_ctx) as s:
        ref = s.process(photo)
        assert isinstance(s.renderer, Renderer)
    with arshadow.Session(spec, context=gl_ctx, renderer=factory) as s:
        res = s.process(photo)
        assert isinstance(s.renderer, Renderer)
    assert made and made[0].calls == 1
    diff = np.abs(res.mask.astype(int) - ref.mask.astype(int))
    assert np.count_nonzero(diff > 1) <= tol.roi_vs_full_px, np.count_nonzero(diff > 1)


# ------------------------------------------------------------------------------------------ history
def test_sun_track_state_resumes_the_recompute_schedule():
    from datetime import timedelta

    from arshadow.lights.spec import parse_sun_track

    spec = "sun:48,11,2021-06-21T09:00+02:00,0@2"
    t0 = parse_sun_track(spec).start
    times = [t0 + timedelta(seconds=20 * i) for i in range(60)]
    whole = parse_sun_track(spec, recompute_deg=0.2).track(times)
    assert 2 < sum(f.recompute for f in whole) < 40
    k = next(i for i in range(20, 60) if not whole[i].recompute)  # a split between two recomputes
    a = parse_sun_track(spec, recompute_deg=0.2)
    head = a.track(times[:k])
    b = parse_sun_track(spec, recompute_deg=0.2)
    b.restore(pickle.loads(pickle.dumps(a.state())))
    tail = b.track(times[k:])
    assert [f.recompute for f in head + tail] == [f.recompute for f in whole]
    assert all(np.array_equal(x.world_used, y.world_used) for x, y in zip(head + tail, whole, strict=True))
    assert parse_sun_track(spec, recompute_deg=0.2).track(times[k:])[0].recompute  # without the state
    assert b.light(tail[-1]).weight == 2.0


def test_marker_tracker_detector_option():
    from arshadow.camera.model import Intrinsics
    from arshadow.errors import UsageError
    from arshadow.tracking.fastdetect import HalfResolutionDetector
    from arshadow.tracking.tracker import MarkerTracker

    photo, truth = _photo()
    cam = Intrinsics.from_file(CALIB)
    fast = MarkerTracker(cam, marker_length=0.05, detector="fast")
    assert isinstance(fast._detector, HalfResolutionDetector)
    assert fast.params.adaptiveThreshWinSizeMin == fast.params.adaptiveThreshWinSizeMax == 7
    calls = []
    full = MarkerTracker(cam, marker_length=0.05)

    class Spy:
        def detectMarkers(self, gray):  # noqa: N802 (OpenCV's name)
            calls.append(gray.shape)
            return full._detector.detectMarkers(gray)

    custom = MarkerTracker(cam, marker_length=0.05, detector=Spy())
    p1, p2 = fast.estimate(photo), custom.estimate(photo)
    assert calls == [photo.shape[:2]]
    for p in (p1, p2):
        assert np.linalg.norm(p.cam_from_world[:3, 3] - truth[:3, 3]) < 0.01 * np.linalg.norm(truth[:3, 3])
    with pytest.raises(UsageError, match="detector"):
        MarkerTracker(cam, marker_length=0.05, detector="turbo")


@pytest.mark.gl
def test_render_photo_from_a_job_file_and_a_photo_file(tmp_path, gl_ctx):
    """The one-call form reads the job file and the photo itself and equals a session's result."""
    import cv2

    import arshadow

    photo, _ = _photo()
    cv2.imwrite(str(tmp_path / "p.png"), photo)
    (tmp_path / "job.json").write_text(json.dumps(SCENE))
    res = arshadow.render_photo(tmp_path / "job.json", tmp_path / "p.png")
    with arshadow.Session(SCENE, context=gl_ctx) as s:
        ref = s.process(photo)
    assert res.item.input == str(tmp_path / "p.png")
    assert np.array_equal(res.mask, ref.mask) and np.array_equal(res.composite, ref.composite)


def test_time_lapse_lights_and_their_state_without_gl():
    """set_time moves the sun: the geometry is rebuilt only when the track recomputes; the state carries
    the schedule and the cache to a new session (planning needs no GL context)."""
    from datetime import timedelta

    import arshadow
    from arshadow.lights.spec import parse_light, parse_sun_track

    spec = _volume_spec()
    sun = "sun:48,11,2021-06-21T09:00+02:00,0@0.5"
    static = [parse_light("point:0.1,0.1,0.4")]
    t0 = parse_sun_track(sun).start
    pose = _photo()[1]
    s = arshadow.Session(spec, lights=static)
    s.use_sun_tracks([parse_sun_track(sun, recompute_deg=0.2)], static)
    assert s.set_time(t0)[0].recompute
    plan = s.plan(pose, 1280, 720)
    assert len(plan.lights) == 2 and not any(lp.reuse for lp in plan.lights)
    geo = s.geometry
    for lp in plan.lights:  # build what the frame needs, as the executor would
        geo.volume(geo.lights[lp.index], caps=lp.caps)
    f = s.set_time(t0 + timedelta(seconds=10))[0]  # the sun moved ~0.04 deg: no recompute
    assert not f.recompute and f.stale_deg > 0
    assert all(lp.reuse for lp in s.plan(pose, 1280, 720).lights)
    state = pickle.loads(pickle.dumps(s.state()))
    s2 = pickle.loads(pickle.dumps(s))  # a fresh session of the same spec
    s2.use_sun_tracks([parse_sun_track(sun, recompute_deg=0.2)], static)
    s2.restore(state)
    assert all(lp.reuse for lp in s2.plan(pose, 1280, 720).lights)
    f2 = s2.set_time(t0 + timedelta(seconds=20))[0]
    assert not f2.recompute  # resumed schedule: still within 0.2 deg of the last recompute
    assert all(lp.reuse for lp in s2.plan(pose, 1280, 720).lights)
    fresh = arshadow.Session(spec, lights=static)
    fresh.use_sun_tracks([parse_sun_track(sun, recompute_deg=0.2)], static)
    assert fresh.set_time(t0 + timedelta(seconds=20))[0].recompute  # without the state it recomputes
    for x in (s, s2, fresh):
        x.close()


@pytest.mark.gl
def test_two_contexts_in_one_process_interleave(gl_ctx):
    """Each GL object makes its own context current: a second context created (and released) beside a
    session does not take the session's GL calls (before the fix: deleted-name errors and blank masks)."""
    import arshadow
    from arshadow.gl.context import create_context

    photo, _ = _photo()
    with arshadow.Session(SCENE, context=gl_ctx) as a:
        ref = a.process(photo).mask.copy()
        assert ref.max() > 0
        other = create_context()  # now the current context of this thread
        try:
            with arshadow.Session(SCENE, context=other) as b:
                mb = b.process(photo).mask.copy()
                ma = a.process(photo).mask.copy()
                mb2 = b.process(photo).mask.copy()
        finally:
            other.release()
        after = a.process(photo).mask
    for m in (mb, ma, mb2, after):
        assert np.array_equal(m, ref)
    assert gl_ctx.error == "GL_NO_ERROR"


def test_lazy_names_are_all_exported():
    """``__all__`` lists every lazily loaded name (written out for type checkers), and each one loads."""
    import arshadow

    lazy = set(arshadow._LAZY) | {"synth"}
    assert lazy <= set(arshadow.__all__)
    for name in arshadow.__all__:
        assert getattr(arshadow, name) is not None, name
