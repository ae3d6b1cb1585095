"""The light / exposure / shadow-colour estimate (the light estimate) against the generating truth of synthetic photos.

Truth: :func:`arshadow.synth.lit.render_lit_photo` renders the light, the reflectances and the camera it is
given (exact ray / triangle hits and the exact ground shadow, supersampled); nothing of the estimator is
used to make or judge a photo. The full distribution's figures come from tests/benchmarks/bench_light.py.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import ROOT, TOL

from arshadow.camera.model import Intrinsics
from arshadow.errors import EstimateError, MarkerNotFoundError, UsageError
from arshadow.estimate import LightEstimate, estimate_light, measure_exposure
from arshadow.estimate.record import scene_overrides
from arshadow.synth.lit import light_vector, random_lit_case, render_lit_photo
from arshadow.synth.markers import look_at_pose

CALIB = "calib/synth_1280x720.yml"
PROBE = "box:0.05,0.05,0.1"
PLACE = (0.1, 0.02, 0.0)


@pytest.fixture(scope="module")
def cam():
    return Intrinsics.from_file(CALIB)


def _angle(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.degrees(math.acos(float(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def _estimate(case, **kw):
    # synth_lit renders no sky occlusion (its ground sees the whole sky beside the probe): the estimate's
    # allowance for the probe's (real photos, the path tracer: test_reference.py) is off here
    kw.setdefault("sky_occlusion", False)
    return estimate_light(
        case["photo"].image,
        calib=CALIB,
        marker_length=0.05,
        probe=case["probe"],
        probe_place=case["probe_place"],
        probe_rotate=case["probe_rotate"],
        kind=case["kind"],
        **kw,
    )


@pytest.fixture(scope="module")
def directional_cases(cam):
    rng = np.random.default_rng(1717)
    return [random_lit_case(rng, cam, "directional") for _ in range(3)]


def test_exposure_matches_the_paper(cam):
    pose = look_at_pose([0.15, -0.35, 0.45], [0.1, 0.0, 0.0])
    p = render_lit_photo(
        cam,
        pose,
        light=light_vector(120, 40),
        probe=PROBE,
        probe_place=PLACE,
        exposure=0.7,
        white_balance=(1.1, 1.0, 0.85),
        noise_sigma=1.5,
        blur_sigma=0.6,
        jpeg_quality=90,
        seed=3,
        supersample=1,
    )
    e = measure_exposure(p.image, cam, pose, 0.05)
    assert np.allclose(e.paper_rgb, p.paper_linear, rtol=0.02), (e.paper_rgb, p.paper_linear)
    # the white balance that makes the paper grey: the inverse of the camera's gains (green = 1)
    assert np.allclose(e.white_balance, [1 / 1.1, 1.0, 1 / 0.85], rtol=0.03)
    assert e.contrast > 10


def test_directional_light_from_one_photo(directional_cases):
    errs, ratio_errs = [], []
    for case in directional_cases:
        est = _estimate(case)
        p = case["photo"]
        errs.append(_angle(est.direction, p.light))
        ratio_errs.append(np.abs(np.array(est.shadow_ratio) - p.shadow_ratio))
        assert est.kind == "directional" and est.light.startswith("directional:")
        assert np.isfinite(est.uncertainty_deg) and est.uncertainty_deg > 0
        assert np.allclose(est.exposure.paper_rgb, p.paper_linear, rtol=0.03)
    assert np.median(errs) <= 1.0 and max(errs) <= 3.0, errs
    # the target: the shadow ratio within 0.03 per channel (median)
    assert np.all(np.median(ratio_errs, axis=0) <= 0.03), ratio_errs


def test_sun_north_from_one_photo(cam):
    rng = np.random.default_rng(99)
    case = random_lit_case(rng, cam, "sun")
    est = _estimate(case)
    d = (est.north_deg - case["north_deg"] + 180.0) % 360.0 - 180.0
    assert abs(d) <= 1.0, (est.north_deg, case["north_deg"])
    assert _angle(est.direction, case["photo"].light) <= 1.0
    assert est.light.startswith("sun:") and est.light.endswith(f",{est.north_deg:.4f}")


@pytest.fixture(scope="module")
def point5(cam):
    """Seed 5's first point-light case and its estimate (shared: a point fit takes seconds)."""
    case = random_lit_case(np.random.default_rng(5), cam, "point")
    return case, _estimate(case)


def test_point_light_from_one_photo(point5):
    case, est = point5
    p = case["photo"]
    foot = np.r_[np.asarray(case["probe_place"])[:2], 0.0]
    rel = np.linalg.norm(np.array(est.position) - p.light) / np.linalg.norm(p.light - foot)
    assert rel <= 0.05, (est.position, p.light.tolist())
    assert est.position_uncertainty is not None and est.position_uncertainty > 0


def test_point_light_never_confident_and_wrong(cam):
    """Seed 17's cases 3, 11 and 17 of the benchmark's distribution: faint or texture-dominated shadows whose
    fitted distance is off by 10..80 % (case 17: a light fitted at the search's near edge). Each must be
    right within 15 % of its distance from the probe, or flagged (truth: the generating light)."""
    rng = np.random.default_rng(17)
    cases = [random_lit_case(rng, cam, "point") for _ in range(18)]
    for i in (3, 11, 17):
        case = cases[i]
        est = _estimate(case)
        p = case["photo"]
        foot = np.r_[np.asarray(case["probe_place"])[:2], 0.0]
        rel = np.linalg.norm(np.array(est.position) - p.light) / np.linalg.norm(p.light - foot)
        assert rel <= 0.15 or not est.confident, (i, rel, est.warnings)


def test_json_round_trip_and_scene_overrides(directional_cases):
    est = _estimate(directional_cases[0])
    again = LightEstimate.from_json(est.to_json())
    assert again.light == est.light and np.allclose(again.exposure.paper_rgb, est.exposure.paper_rgb, atol=1e-6)
    d = json.loads(est.to_json())
    for key in ("light", "direction", "position", "north_deg", "shadow_ratio", "uncertainty_deg", "exposure"):
        assert key in d
    o = scene_overrides(again, "255,255,255")
    assert o["opacity"] == 1.0 and np.allclose(o["shadow_color"], est.shadow_ratio, atol=1e-4)


# ---- bad inputs: one clear error each, never a confident wrong light -------------------------------------
def test_no_marker(cam):
    img = np.full((720, 1280, 3), 120, np.uint8)
    with pytest.raises(MarkerNotFoundError, match="no marker"):
        estimate_light(img, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE)


def test_probe_not_in_view(cam):
    pose = look_at_pose([0.05, -0.3, 0.35], [0.0, 0.0, 0.0])
    p = render_lit_photo(cam, pose, light=light_vector(120, 40), probe=PROBE, probe_place=PLACE, supersample=1)
    with pytest.raises(EstimateError, match="probe is not in view"):
        estimate_light(p.image, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=(0.6, 0.6, 0.0))


def test_flat_light_has_no_shadow(cam):
    pose = look_at_pose([0.15, -0.35, 0.45], [0.1, 0.0, 0.0])
    p = render_lit_photo(
        cam,
        pose,
        light=light_vector(120, 40),
        probe=PROBE,
        probe_place=PLACE,
        ambient=(0.9, 0.9, 0.9),
        direct=(0.0, 0.0, 0.0),
        supersample=1,
    )
    with pytest.raises(EstimateError, match="no shadow of the probe found"):
        estimate_light(p.image, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE)


def test_shadow_off_image(cam):
    """A low light throws most of the shadow out of the frame: a refusal, or a result flagged as
    low-confidence (never a confident light from a shadow mostly out of view)."""
    pose = look_at_pose([0.05, -0.25, 0.3], [0.05, 0.0, 0.0])
    p = render_lit_photo(cam, pose, light=light_vector(200, 14), probe=PROBE, probe_place=PLACE, supersample=1)
    try:
        est = estimate_light(p.image, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE)
    except EstimateError as exc:
        # named as what it is: the shadow out of view, or too little of it in view to fix the light
        assert any(m in str(exc) for m in ("out of view", "no shadow", "frame the whole shadow")), exc
        return
    assert est.fit["visible"] < 0.7
    assert not est.confident and any("low confidence" in w for w in est.warnings), est.to_json()


def test_shadow_hidden_behind_the_probe(cam):
    # the camera on the light's side, low: the shadow lies behind the probe
    light = light_vector(270, 50)
    pose = look_at_pose(np.array([0.1, 0.02, 0.0]) + 0.5 * light_vector(270, 12), [0.08, 0.0, 0.05])
    p = render_lit_photo(cam, pose, light=light, probe=PROBE, probe_place=PLACE, supersample=1)
    with pytest.raises(EstimateError, match="out of view|hidden|no shadow"):
        estimate_light(p.image, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE)


def test_bad_kind_is_a_usage_error(directional_cases):
    with pytest.raises(UsageError, match="--kind"):
        estimate_light(directional_cases[0]["photo"].image, calib=CALIB, marker_length=0.05, probe=PROBE, kind="spot")


def test_frames_of_a_video_add_up(cam, tmp_path):
    """One light fixed in the world, three viewpoints written as a video: one estimate from its frames."""
    import cv2

    light = light_vector(200, 35)
    eyes = ([0.25, -0.3, 0.4], [0.0, 0.35, 0.42], [0.2, -0.4, 0.35])
    frames = [
        render_lit_photo(
            cam,
            look_at_pose(e, [0.08, 0.0, 0.0]),
            light=light,
            probe=PROBE,
            probe_place=PLACE,
            noise_sigma=1.5,
            seed=i,
            supersample=1,
        )
        for i, e in enumerate(eyes)
    ]
    path = tmp_path / "clip.avi"
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (cam.width, cam.height))
    for f in frames:
        vw.write(f.image)
    vw.release()
    est = estimate_light(path, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE, sky_occlusion=False)
    assert est.frames == 3
    assert _angle(est.direction, light) <= 1.0
    assert np.all(np.abs(np.array(est.shadow_ratio) - frames[0].shadow_ratio) <= 0.05)


@pytest.mark.parametrize("radius", [0.0, 2.0, 4.0])
def test_penumbra_gives_the_light_size(cam, radius):
    """A disc light of angular radius 0 / 2 / 4 degrees (synth_lit: the mean of 64 exact hard shadows over
    its cone): the fitted angular diameter within 25 % of the truth (0: below 0.5 degrees, a hard spec)."""
    pose = look_at_pose([0.15, -0.35, 0.45], [0.1, 0.0, 0.0])
    p = render_lit_photo(
        cam,
        pose,
        light=light_vector(160, 40),
        probe=PROBE,
        probe_place=PLACE,
        noise_sigma=1.0,
        seed=4,
        supersample=1,
        light_radius_deg=radius,
    )
    est = estimate_light(p.image, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE)
    assert _angle(est.direction, p.light) <= 1.5
    if radius == 0.0:
        assert est.angular_diameter_deg < 0.5 and "radius" not in est.light
    else:
        assert est.angular_diameter_deg == pytest.approx(2 * radius, rel=0.25)
        assert f"radius={est.angular_diameter_deg / 2:.3f}" in est.light
    assert LightEstimate.from_json(est.to_json()).angular_diameter_deg == pytest.approx(
        est.angular_diameter_deg, abs=1e-4
    )


# ---- never a confident wrong light (the trust fixes items 2-4) ---------------------------------------------------
def _shifted_sun(kind: str, hours: int) -> str:
    from datetime import datetime, timedelta

    lat, lon, when = kind.split(":", 1)[1].split(",")
    t = datetime.fromisoformat(when) + timedelta(hours=hours)
    return f"sun:{lat},{lon},{t.isoformat(timespec='minutes')}"


def test_no_probe_in_the_photo_is_refused():
    """samples/knot_point.jpg has no box where it is given (a virtual knot stands nearby): the old estimate
    answered a confident light (shadow ratio 0.87, 2 % of the variation explained)."""
    with pytest.raises(EstimateError, match="probe is not in the photo where it is given"):
        estimate_light("samples/knot_point.jpg", calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE)


def test_photo_without_the_probe_is_refused(cam):
    """The same photo as a good one, rendered without the probe (a 2 mm box): its floor alone."""
    pose = look_at_pose([0.15, -0.35, 0.45], [0.1, 0.0, 0.0])
    p = render_lit_photo(
        cam, pose, light=light_vector(120, 40), probe="box:0.002,0.002,0.002", probe_place=PLACE, supersample=1
    )
    with pytest.raises(EstimateError, match="not in the photo"):
        estimate_light(p.image, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE)


def test_misplaced_probe_is_refused(cam):
    """The probe given 4 cm from where it stands: the old estimate gave a confident light several degrees off."""
    rng = np.random.default_rng(1717)
    case = random_lit_case(rng, cam, "directional")
    x, y, _ = case["probe_place"]
    with pytest.raises(EstimateError, match="not in the photo where it is given"):
        _estimate({**case, "probe_place": (x + 0.04, y, 0.0)})


def test_probe_outline_agreement(cam):
    """The outline check itself: high with the probe in place (the generating pose), chance with it 4 cm away."""
    from arshadow.estimate.outline import outline_agreement
    from arshadow.geometry.mesh import load_occluder

    pose = look_at_pose([0.15, -0.35, 0.45], [0.1, 0.0, 0.0])
    p = render_lit_photo(cam, pose, light=light_vector(120, 40), probe=PROBE, probe_place=PLACE, supersample=1)

    def agree(place):
        m = load_occluder(PROBE, place=place)
        return outline_agreement(p.image, cam, pose, np.asarray(m.vertices), np.asarray(m.faces))

    a, n = agree(PLACE)
    b, _ = agree((PLACE[0] - 0.04, PLACE[1], 0.0))
    assert n > 50 and a >= 0.55 and b < 0.4, (a, b, n)


def test_face_shading_tests_the_light(cam):
    """The probe's faces, shaded by the generating light, fit the model (ambient fixed by the true shadow
    ratio); a light 70 degrees away does not."""
    from arshadow.estimate.shading import face_shading_residual
    from arshadow.estimate.shadow import LUMA
    from arshadow.geometry.mesh import load_occluder

    pose = look_at_pose([0.15, -0.35, 0.45], [0.1, 0.0, 0.0])
    light = light_vector(200, 40)
    p = render_lit_photo(cam, pose, light=light, probe=PROBE, probe_place=PLACE, supersample=2)
    m = load_occluder(PROBE, place=PLACE)
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    r = float(p.shadow_ratio @ LUMA)
    good, k = face_shading_residual(p.image, cam, pose, v, f, np.append(light, 0.0), r)
    bad, _ = face_shading_residual(p.image, cam, pose, v, f, np.append(light_vector(270, 40), 0.0), r)
    assert k >= 2 and good <= TOL.light_face_shading_true and bad > 0.25, (good, bad, k)


def test_wrong_sun_time_is_refused(cam):
    """The sun two hours off: the shadow's own elevation (a free fit) disagrees with the sun's, and the
    error names both (the old estimate: a confident light ~20 degrees off)."""
    rng = np.random.default_rng(7)
    case = random_lit_case(rng, cam, "sun")
    with pytest.raises(EstimateError, match=r"the shadow says \d+ deg elevation, the sun at .* is at \d+ deg"):
        _estimate({**case, "kind": _shifted_sun(case["kind"], 2)})


def _hidden_case(cam, seed):
    """bench_light_trust.py's ``hidden`` scenario: the camera on the light's side."""
    return random_lit_case(
        np.random.default_rng([seed, 4]), cam, "directional", view="light", point_distance=(0.35, 0.6)
    )


def test_partly_hidden_shadow_is_measured(cam):
    """Tuning case 106 of the hidden scenario: the probe hides much of its shadow (the old estimate refused:
    "33 % of it visible"); what is visible fixes the light."""
    case = _hidden_case(cam, 106)
    est = _estimate(case)
    assert _angle(est.direction, case["photo"].light) <= TOL.light_hidden_deg, est.to_json()


def test_hidden_shadow_is_never_confident(cam):
    """Tuning case 103: the shadow entirely behind the probe. The old estimate fitted the floor's pattern and
    answered a confident light 81 degrees off; now refused or flagged."""
    case = _hidden_case(cam, 103)
    try:
        est = _estimate(case)
    except EstimateError:
        return
    assert not est.confident or _angle(est.direction, case["photo"].light) <= TOL.light_confident_deg, est.to_json()


def test_point_light_distance_interval(point5):
    """A point light's distance interval (2 sigma) is in the result and its JSON; a flagged fit names it."""
    case, est = point5
    d = json.loads(est.to_json())
    lo, hi = d["distance_interval"]
    height = float(case["probe"].split(",")[-1])
    top = np.r_[np.asarray(case["probe_place"])[:2], height]
    dist = float(np.linalg.norm(np.array(est.position) - top))
    assert 0 < lo < dist < hi and est.distance_interval == pytest.approx((lo, hi), abs=1e-4)
    assert all("between" in w for w in est.warnings if "point light" in w)
    assert LightEstimate.from_json(est.to_json()).distance_interval == pytest.approx((lo, hi), abs=1e-4)


@pytest.mark.parametrize("name", ["box_point", "torus_point"])
def test_face_shading_of_a_point_light_on_the_path_traced_plates(name):
    """A point light 30-40 cm from the probe (the path tracer's own plates, tests/data/reference/own) lights
    its top a third more than its sides' centres, and the shadow ratio at its foot differs from the one at its
    shadow's edge: with the true lamp and the true ratio at the foot (the scene's irradiances: never the
    estimator's) the faces fit the model within the check's limit (it flagged them 40 % off before)."""
    from arshadow.bench.reference import load_cases
    from arshadow.bench.reference_scene import intrinsics_of, pose_of
    from arshadow.estimate.checks import SHADING_LOG
    from arshadow.estimate.shading import face_shading_residual
    from arshadow.estimate.shadow import LUMA
    from arshadow.geometry.mesh import load_occluder

    (case,) = [c for c in load_cases(ROOT / "tests" / "data" / "reference" / "own") if c.scene.name == name]
    sc = case.scene
    probe = load_occluder(sc.probe, place=sc.probe_place)
    v, f = np.asarray(probe.vertices), np.asarray(probe.faces)
    lamp = np.asarray(sc.light_vec, np.float64)
    foot = np.r_[0.5 * (v[:, :2].min(axis=0) + v[:, :2].max(axis=0)), 0.0]
    lamp_e = np.asarray(sc.direct, np.float64) * (lamp - foot)[2] / np.linalg.norm(lamp - foot) ** 3
    sky = np.asarray(sc.sky, np.float64)
    ratio = float((sky / (sky + lamp_e)) @ LUMA)
    res, k = face_shading_residual(case.plate8, intrinsics_of(sc), pose_of(sc), v, f, np.r_[lamp, 1.0], ratio)
    assert k >= 2 and res <= SHADING_LOG, (res, k)


def test_directional_light_fitted_as_a_point_says_so(cam):
    """A sun's shadow fitted with ``--kind point``: the fit runs far away (the shadow's outline is parallel).
    Never a confident lamp: refused at the search's far edge (100 m) or flagged, both naming --kind
    directional."""
    rng = np.random.default_rng(5)
    for _ in range(2):
        case = random_lit_case(rng, cam, "directional")
        try:
            est = _estimate({**case, "kind": "point"})
        except EstimateError as exc:
            assert "far edge" in str(exc) and "--kind directional" in str(exc), exc
            continue
        assert not est.confident and any("--kind directional" in w for w in est.warnings), est.to_json()
        assert np.linalg.norm(est.position) > 2.0  # far: what a directional light looks like to one probe
