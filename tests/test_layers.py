"""Compositing layers (the compositing-layers work): ``plate x shadow + object`` in linear light is the composite.

Ground truth: the composite the pipeline wrote (not the layer code), and hand values of the formula.
The recombination is computed here from the IEC 61966-2-1 curve in float64 (not the module's tables)
and must land within one 8-bit level of the composite on every pixel, for a pinhole and a k1 = -0.25
lens, with an object, a grey and a coloured shadow tint, and after writing / reading 16-bit PNG and EXR.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from layer_checks import linear, maxdiff, recombine

from arshadow.compose.composite import Overlay, composite, parse_rgb
from arshadow.compose.layers import layers_from_warped, shadow_factor, shadow_only_alpha
from arshadow.compose.look import Look

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------------------------- pure math
def test_shadow_factor_hand_values():
    mask = np.array([[1.0, 0.5, 0.0, 0.5]], np.float32)
    alpha = np.array([[0.0, 0.0, 1.0, 0.5]], np.float32)
    f = shadow_factor(mask, alpha, 0.8)
    # (1 - a) - 0.8 m: 0.2, 0.6, 0 (covered), 0.5 - 0.4 = 0.1
    assert f[0].tolist() == pytest.approx([0.2, 0.6, 0.0, 0.1], abs=1e-7)
    a_s = shadow_only_alpha(f, alpha)
    # 1 - f / (1 - a): 0.8, 0.4, 0 (covered: irrelevant), 1 - 0.1 / 0.5 = 0.8
    assert a_s[0].tolist() == pytest.approx([0.8, 0.4, 0.0, 0.8], abs=1e-6)
    tint = shadow_factor(mask[:, :1], None, 1.0, shadow_color=(0.0, 0.0, 1.0))
    assert tint.shape == (1, 1, 3) and tint[0, 0].tolist() == [0.0, 0.0, 1.0]


def test_layers_of_random_inputs_recombine_to_the_composite(rng):
    H, W = 40, 60
    plate = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    roi = (7, 5, 30, 20)
    mask = rng.random((20, 30)).astype(np.float32)
    alpha = np.clip(rng.random((20, 30)) * 1.6 - 0.3, 0, 1).astype(np.float32)
    rgb = rng.random((20, 30, 3)).astype(np.float32) * alpha[..., None]
    rgba = np.dstack([rgb, alpha])
    for tint in ((0.0, 0.0, 0.0), parse_rgb("60,60,60"), parse_rgb("40,20,120")):
        comp = composite(plate, Overlay(mask, color=rgba, alpha=alpha), roi, look=Look(opacity=0.7, shadow_color=tint))
        lay = layers_from_warped(mask, rgba, roi, (H, W), opacity=0.7, shadow_color=tint)
        obj, sh = lay.full()
        assert maxdiff(recombine(plate, obj, sh), comp) <= 1
        if tint[0] == tint[1] == tint[2]:  # the shadow-only layer is exact for grey tints
            assert maxdiff(recombine(plate, obj, shadow_only_alpha(sh, obj[..., 3]), over=True), comp) <= 1
        # outside the roi: nothing
        assert np.all(sh[:5] == 1.0) and np.all(obj[:5] == 0.0)


# ------------------------------------------------------------------------------------------- pipeline
def _scene(calib, **extra):
    scene = {
        "calib": str(ROOT / "calib" / calib),
        "marker_length": 0.05,
        "model": "torus:0.03,0.01",
        "place": [0.0, 0.0, 0.02],
        "rotate": [60, 0, 20],
        "color": "200,120,40",
        "lights": ["point:0.1,0.15,0.45", "directional:-0.3,0.2,1@0.5"],
    }
    scene.update(extra)
    return scene


def _photo(calib, eye):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    cam = Intrinsics.from_file(str(ROOT / "calib" / calib))
    truth = look_at_pose(list(eye), [0.0, 0.0, 0.0])
    return render_marker_photo(cam, truth, marker_length=0.05, seed=3).image


CASES = [
    ("synth_1280x720.yml", (0.1, -0.3, 0.4), {}),
    ("synth_1280x720_k1.yml", (0.15, -0.2, 0.3), {}),  # distorted lens
    ("synth_1280x720_k1.yml", (0.15, -0.2, 0.3), {"aa": 4, "shadow_color": "90,40,160"}),
    ("synth_1280x720.yml", (0.1, -0.3, 0.4), {"draw_occluder": False}),
]


@pytest.mark.gl
@pytest.mark.parametrize("calib,eye,extra", CASES)
def test_session_layers_recombine_to_the_composite(gl_ctx, calib, eye, extra):
    import arshadow

    extra = dict(extra)
    no_object = not extra.pop("draw_occluder", True)
    scene = _scene(calib, **extra)
    if no_object:
        scene["no_object"] = True
    photo = _photo(calib, eye)
    with arshadow.Session(arshadow.scene_from_dict(scene), context=gl_ctx) as s:
        plain = s.process(photo, name="p")
        res = s.process(photo, name="p", layers=True)
    assert plain.layers is None
    assert np.array_equal(plain.composite, res.composite)  # layers change nothing in the composite
    lay = res.layers
    obj, sh = lay.full()
    if no_object:
        assert np.all(obj == 0)
    else:
        assert np.count_nonzero(obj[..., 3] > 0.5) > 500
    assert np.count_nonzero(sh < 0.9) > 500  # a real shadow
    assert maxdiff(recombine(photo, obj, sh), res.composite) <= 1
    if "shadow_color" not in extra:
        assert maxdiff(recombine(photo, obj, shadow_only_alpha(sh, obj[..., 3]), over=True), res.composite) <= 1
    assert "layers" not in res.item.to_dict() and "want_layers" not in res.item.to_dict()
    assert res.item.compose == "cpu" and "layers asked for" in res.item.plan["compose"]


@pytest.mark.gl
@pytest.mark.parametrize("fmt", ["png", "exr"])
def test_layer_files_recombine_to_the_composite(gl_ctx, tmp_path, fmt):
    import arshadow
    from arshadow.export.layerfiles import layer_paths, write_layers

    if fmt == "exr":
        OpenEXR = pytest.importorskip("OpenEXR")
    calib, eye = "synth_1280x720_k1.yml", (0.15, -0.2, 0.3)
    photo = _photo(calib, eye)
    with arshadow.Session(arshadow.scene_from_dict(_scene(calib)), context=gl_ctx) as s:
        res = s.process(photo, name="p", layers=True)
    paths = write_layers(layer_paths(tmp_path, "p", fmt), res.layers, fmt)
    if fmt == "png":
        o = cv2.imread(str(paths["object"]), cv2.IMREAD_UNCHANGED)
        m = cv2.imread(str(paths["shadow.mult"]), cv2.IMREAD_UNCHANGED)
        so = cv2.imread(str(paths["shadow.only"]), cv2.IMREAD_UNCHANGED)
        assert o.dtype == np.uint16 and o.shape == photo.shape[:2] + (4,) and m.shape == photo.shape[:2]
        a = o[..., 3] / 65535.0
        obj = np.dstack([linear(o[..., 2::-1].astype(np.float64) / 257.0) * a[..., None], a])  # straight sRGB
        sh = m / 65535.0
        only = so[..., 3] / 65535.0
        assert np.all(so[..., :3] == 0)
    else:

        def read(p):
            return next(iter(OpenEXR.File(str(p)).channels().values())).pixels.astype(np.float64)

        obj, sh, only = read(paths["object"]), read(paths["shadow.mult"]), read(paths["shadow.only"])[..., 3]
    assert maxdiff(recombine(photo, obj, sh), res.composite) <= 1
    assert maxdiff(recombine(photo, obj, only, over=True), res.composite) <= 1


@pytest.mark.gl
def test_undistorted_layers_and_the_stmap_give_the_distorted_layers(gl_ctx):
    """The pinhole layers resampled through the ST-map (decoded here from its s, t definition) are the
    distorted layers: the pipeline's warp is the same bilinear lookup of the same pinhole points."""
    import arshadow
    from arshadow.camera.model import Intrinsics
    from arshadow.export.stmap import stmap, stmap_to_pixels

    calib, eye = "synth_1280x720_k1.yml", (0.15, -0.2, 0.3)
    photo = _photo(calib, eye)
    intr = Intrinsics.from_file(str(ROOT / "calib" / calib))
    with arshadow.Session(arshadow.scene_from_dict(_scene(calib)), context=gl_ctx) as s:
        res = s.process(photo, name="p", layers="undistorted")
    assert res.layers.undistorted is not None
    obj, sh = res.layers.full()
    uobj, ush = res.layers.undistorted.full()
    st = stmap(intr)
    # independent check of the ST-map at one pixel: OpenCV's undistortPoints of the pixel centre
    u, v = 100.0, 80.0
    ref = cv2.undistortPoints(
        np.array([[[u, v]]]),
        intr.K,
        intr.dist,
        P=intr.K,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12),
    ).ravel()
    assert st[80, 100, 0] == pytest.approx((ref[0] + 0.5) / 1280, abs=2e-6)
    assert st[80, 100, 1] == pytest.approx(1 - (ref[1] + 0.5) / 720, abs=2e-6)
    mx, my = stmap_to_pixels(st, 1280, 720)
    warped_a = cv2.remap(uobj[..., 3], mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    warped_s = cv2.remap(ush, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1)
    assert np.count_nonzero(obj[..., 3] > 0.5) > 500
    # cv2.remap rounds coordinates to 1/32 px: float32 s, t (~1e-4 px) may flip that rounding, which moves a
    # sharp edge's value by at most 1/32 of its step; the mean stays at the noise floor
    for warped, ref in ((warped_a, obj[..., 3]), (warped_s, sh)):
        d = np.abs(warped - ref)
        assert d.max() <= 1 / 32 + 1e-3 and d.mean() < 1e-4
    # the pinhole layers are not the distorted ones (k1 = -0.25 moves the object)
    assert np.abs(uobj[..., 3] - obj[..., 3]).max() > 0.5


@pytest.mark.gl
def test_frame_result_shows_itself_as_a_png(gl_ctx):
    import arshadow

    calib, eye = "synth_1280x720.yml", (0.1, -0.3, 0.4)
    photo = _photo(calib, eye)
    with arshadow.Session(arshadow.scene_from_dict(_scene(calib)), context=gl_ctx) as s:
        res = s.process(photo, name="p")
    png = res._repr_png_()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert np.array_equal(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR), res.composite)
