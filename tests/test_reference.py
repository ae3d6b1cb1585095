"""The path-traced reference (the realism work): arshadow against Mitsuba 3 renders, without Mitsuba.

The committed cases (tests/data/reference/{own,heldout}, made by tests/reference/make_reference.py) hold the
plate as a user photographs it and the truth's (smoothed) change of it. These tests check that the path
tracer's camera is arshadow's camera, that the scoring behaves (0 for the truth, 1 for no insert), and that
today's renderer does no worse than its recorded baseline (Tolerances.ref_*; the issue's targets are lower).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from arshadow.bench.reference import case_residuals, load_cases, plate_alignment, run_case, to_plate8
from arshadow.bench.reference_scene import intrinsics_of, pose_of
from arshadow.bench.reference_score import decode8, residuals_smoothed, smooth_regions
from arshadow.errors import EstimateError
from arshadow.synth.markers import render_marker_photo
from arshadow.tracking.dictionary import marker_object_points
from arshadow.tracking.tracker import MarkerTracker

DATA = Path(__file__).parent / "data" / "reference"


@pytest.fixture(scope="module")
def own():
    return load_cases(DATA / "own")


@pytest.fixture(scope="module")
def heldout():
    return load_cases(DATA / "heldout")


@pytest.fixture(scope="module")
def plain():
    return load_cases(DATA / "plain")


def test_reference_sets_committed(own, heldout, plain):
    assert len(own) == 6 and len(heldout) == 6 and len(plain) == 4
    assert not {c.scene.name for c in own} & {c.scene.name for c in heldout}
    assert {c.scene.floor for c in plain} == {"plain"}
    for c in own + heldout + plain:
        assert c.plate8.shape == (c.scene.height, c.scene.width, 3)
        y0, y1, x0, x1 = c.crop
        assert c.smoothed_truth.shape == (y1 - y0, x1 - x0, 3)
        assert c.masks["object"].any() and c.masks["contact"].any()
        assert not (c.masks["ground"] & c.masks["object"]).any()
        assert not (c.masks["contact"] & ~c.masks["ground"]).any()


def test_reference_camera_is_arshadows(own, heldout, tol):
    """Mitsuba's sensor images the printed paper where arshadow's pinhole does (its own exact render of the
    print, averaged in linear light), to a small fraction of a pixel and 0.1 % of scale; a 0.3 px principal
    point error is seen, and a 0.25 % scale (the field of view over W - 1 pixels the plates had until
    2026-11-28, mitsuba_fov)."""
    for c in own + heldout:
        dx, dy, scale = plate_alignment(c.plate8, c.scene)
        assert np.hypot(dx, dy) < tol.ref_camera_shift_px, (c.scene.name, dx, dy)
        assert abs(scale) < tol.ref_camera_scale, (c.scene.name, scale)
    c = own[0]
    x0, y0 = c.scene.principal_offset
    dx, _, _ = plate_alignment(c.plate8, dataclasses.replace(c.scene, principal_offset=(x0 + 0.3, y0)))
    assert abs(dx + 0.3) < tol.ref_camera_shift_px
    W, fx = c.scene.width, intrinsics_of(c.scene).fx
    wide = math.degrees(2 * math.atan(W / 2 / (fx * (W - 1) / W)))  # a focal length 0.25 % short
    assert abs(plate_alignment(c.plate8, dataclasses.replace(c.scene, fov_x_deg=wide))[2]) > tol.ref_camera_scale


def test_reference_marker_corners(own, tol):
    """The marker corners detected on the path-traced plates agree with those detected on arshadow's exact
    render at the same camera, and their centroid with the projected corners' (the per-corner detector bias,
    0.2-0.5 px here, depends on the image's lighting and noise; the detector-free check is above)."""
    for c in own:
        K = intrinsics_of(c.scene)
        tr = MarkerTracker(K, dictionary="DICT_6X6_250", marker_length=c.scene.marker_length)
        a = tr.estimate(c.plate8).corners
        b = tr.estimate(render_marker_photo(K, pose_of(c.scene), marker_length=c.scene.marker_length).image).corners
        assert np.linalg.norm((a - b).mean(axis=0)) < tol.ref_corner_centroid_px, c.scene.name
        assert np.abs(a - b).max() < tol.ref_corner_px, c.scene.name
        projected = intrinsics_of(c.scene).project(marker_object_points(c.scene.marker_length), pose_of(c.scene))
        assert np.linalg.norm((a - projected).mean(axis=0)) < tol.ref_corner_centroid_px, c.scene.name


def test_reference_scoring_bounds(own):
    """The truth itself scores 0; not inserting anything scores 1 on the ground and in the contact band."""
    c = own[0]
    r = residuals_smoothed(c.smoothed_truth, c.smoothed_truth, c.masks, c.threshold)  # scalar threshold
    assert r["ground"] == r["contact"] == r["object"] == 0.0
    r = case_residuals(c, c.plate8)
    assert r["ground"] == pytest.approx(1.0) and r["contact"] == pytest.approx(1.0)
    # a composite that changes the ground by the truth's own (smoothed) change, as 8-bit codes, scores near 0
    y0, y1, x0, x1 = c.crop
    lin = decode8(c.plate8)[y0:y1, x0:x1] + c.smoothed_truth * c.masks["ground"][:, :, None]
    comp = c.plate8.copy()
    comp[y0:y1, x0:x1] = to_plate8(lin)
    g = case_residuals(c, comp)["ground"]
    assert g < 0.1, g  # the 8-bit rounding, and smoothing twice: not exactly 0
    assert smooth_regions(np.zeros_like(c.smoothed_truth), c.masks).max() == 0.0


def _residuals(cases, light, refusals=2):
    """Each case's residuals by the case's name, at most ``refusals`` cases refused by the light estimate."""
    rs = {}
    for c in cases:
        try:
            rs[c.scene.name] = run_case(c, light)
        except EstimateError:  # the estimate refuses the case
            continue
    assert len(rs) >= len(cases) - refusals, f"the light estimate refused {len(cases) - len(rs)} of {len(cases)} cases"
    return rs


def _median(rs, skip=()):
    """The medians of the residuals ``rs`` (:func:`_residuals`) of the cases not named in ``skip``."""
    names = [n for n in rs if n not in skip]
    return {k: float(np.median([rs[n][k] for n in names])) for k in ("ground", "contact", "object")}


@pytest.mark.gl
def test_reference_baseline_own(own, gl_ctx, tol):
    """Today's renderer on the project's own scenes, light measured by `arshadow light`, no worse than the
    baseline (Tolerances.ref_own_*), and with the true light given."""
    m = _median(_residuals(own, "measured"))
    assert m["ground"] <= tol.ref_own_ground, m
    assert m["contact"] <= tol.ref_own_contact, m
    assert m["object"] <= tol.ref_own_object, m
    t = _median(_residuals(own, "true"))
    assert t["ground"] <= tol.ref_own_true_ground, t


@pytest.mark.gl
def test_reference_baseline_heldout(heldout, gl_ctx, tol):
    """The held-out scenes (judging; tune nothing on them): none refused, no worse than the baseline over
    all six, and no worse than the five-case baseline over the five it was measured on (ho_box_rotated_tiles
    was refused then: its probe's crease read as a missing outline)."""
    rs = _residuals(heldout, "measured", refusals=0)
    m, m5 = _median(rs), _median(rs, skip=("ho_box_rotated_tiles",))
    assert m["ground"] <= tol.ref_heldout_ground, m
    assert m["contact"] <= tol.ref_heldout_contact, m
    assert m["object"] <= tol.ref_heldout_object, m
    assert m5["ground"] <= tol.ref_heldout5_ground, m5
    assert m5["contact"] <= tol.ref_heldout5_contact, m5
    assert m5["object"] <= tol.ref_heldout5_object, m5


@pytest.mark.gl
def test_realism_bench_rows(own, gl_ctx, monkeypatch):
    """`arshadow bench`'s realism table: one row per option, a positive cost, the residuals of the scoring
    harness itself (the defaults' row is the harness's median), the planner's choices recorded."""
    from arshadow.bench import realism

    monkeypatch.setattr(realism, "OPTIONS", [realism.OPTIONS[0], ("true light, aa off", {"aa": 0}, "true")])
    rows = realism.run({"quick": True, "render_repeat": 1, "warmup": 0}, None, lambda *a: None)
    assert [r["option"] for r in rows] == ["measured light (defaults)", "true light, aa off"]
    for r in rows:
        assert r["ms_720p"] > 0 and r["render_ms_720p"] > 0 and r["planner"]
        assert 0.0 < r["own_ground"] < 2.0 and 0.0 < r["own_object"] < 2.0
    direct = []
    for c in own:  # the first three plates the light estimate accepts, as the bench takes them
        try:
            direct.append(run_case(c, "measured"))
        except EstimateError:
            continue
    direct = direct[:3]
    assert rows[0]["own_ground"] == pytest.approx(float(np.median([r["ground"] for r in direct])), abs=1e-9)


def test_load_cases_names_a_missing_plate(tmp_path):
    """A case whose plate JPEG is missing (half-committed) is refused by name when loaded, not kept as a None
    plate that fails deep in the scoring (mypy's find: ``cv2.imread`` returns None)."""
    import json
    import shutil

    from arshadow.errors import ImageError

    cases = json.loads((DATA / "own" / "cases.json").read_text())
    name = sorted(cases)[0]
    (tmp_path / "cases.json").write_text(json.dumps({name: cases[name]}))
    shutil.copy(DATA / "own" / f"{name}.npz", tmp_path / f"{name}.npz")  # the plate's .jpg left out
    with pytest.raises(ImageError, match=f"{name}.jpg"):
        load_cases(tmp_path)


def _sky_share(sc, at) -> np.ndarray:
    """The scene's own sky share of the open ground's light, ``sky / (sky + E)``, (3,): a sun's ``E`` from its
    elevation, a lamp's at the ground point ``at (2,)`` (its ``cos / d^2``)."""
    v, sky, direct = (np.asarray(a, np.float64) for a in (sc.light_vec, sc.sky, sc.direct))
    if sc.light == "sun":
        e = direct * max(v[2] / np.linalg.norm(v), 0.0)
    else:
        rel = v - np.array([at[0], at[1], 0.0])
        e = direct * max(rel[2], 0.0) / np.linalg.norm(rel) ** 3
    return sky / (sky + e)


def test_light_estimate_on_a_plain_floor(plain, tol):
    """The light estimate on the plain-floor plates (tests/data/reference/plain: four scenes on one neutral grey
    of reflectance 0.25, no pattern to confound the shadow ratio) against each scene's own light and sky share.

    Every plate is fitted (until the sixth session of 2026-11-29 the marker's paper class took in every neutral
    cell brighter than a fifth of the paper within 2.5 marker sides, and its edge then ran along the probe's
    shadow: on twelve such plates 9 were refused as ambiguous, the others 22-65 degrees off;
    arshadow.estimate.paper.paper_cells), the light
    close (measured: suns 0.10 / 0.16 degrees, lamps 0.30 / 1.97 %), and the shadow ratio allows for the sky the
    probe hides from both sides of its shadow's edge and for the light it reflects onto them (its reflectance
    read off its top face, 0.481-0.511 against the plates' 0.5 grey seen through the paper's 0.8 / 0.8308,
    i.e. 0.481): the suns' ratio +0.007 / +0.009 of the truth (sky occlusion only: +0.026 / +0.057; neither:
    -0.025 / -0.052), the lamps' +0.042 / +0.046 (sky occlusion only: +0.071 / +0.088)."""
    from arshadow.estimate import estimate_light
    from arshadow.estimate.shadow import LUMA

    for c in plain:
        sc = c.scene
        kw = dict(calib=intrinsics_of(sc), marker_length=sc.marker_length, probe=sc.probe, probe_place=sc.probe_place)
        kw["kind"] = "point" if sc.light == "point" else "directional"
        est = estimate_light(c.plate8, **kw)
        at = est.ratio_at if est.ratio_at is not None else sc.probe_place[:2]
        err = float(np.asarray(est.shadow_ratio) @ LUMA) / float(_sky_share(sc, at) @ LUMA) - 1.0
        assert est.fit["probe_albedo"] == pytest.approx(0.5 * 0.8 / 0.8308, abs=tol.plain_albedo), (sc.name, est.fit)
        assert est.fit["floor_albedo"] == pytest.approx(0.25 * 0.8 / 0.8308, abs=tol.plain_albedo), (sc.name, est.fit)
        if sc.light == "sun":
            assert math.degrees(math.acos(min(1.0, _cos(est.direction, sc.light_vec)))) <= tol.plain_sun_deg, sc.name
            assert abs(err) <= tol.plain_ratio_sun, (sc.name, err)
            none = estimate_light(c.plate8, sky_occlusion=False, **kw)  # the probe's effect on the ground ignored
            err0 = float(np.asarray(none.shadow_ratio) @ LUMA) / float(_sky_share(sc, at) @ LUMA) - 1.0
            assert abs(err) < 0.5 * abs(err0), (sc.name, err, err0)
        else:
            off = np.linalg.norm(np.subtract(est.position, sc.light_vec)) / np.linalg.norm(sc.light_vec)
            assert off <= tol.plain_lamp_rel, (sc.name, est.position)
            assert abs(err) <= tol.plain_ratio_lamp, (sc.name, err)


def _cos(a, b) -> float:
    """The cosine of the angle between two 3-vectors."""
    return float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))


def test_shadow_ratio_texture_check_covers_its_error(own, heldout, tol):
    """The light estimate's texture check (:func:`arshadow.estimate.ratio.texture_uncertainty`: the shadow's
    pairs read on the lit floor round it) against each plate's real ratio error: the estimate's luminance
    ratio over the scene's own ``sky / (sky + E)`` where it was read (a lamp's ``E`` at ``ratio_at``). It covers
    every plate's error within ``tol.ratio_texture_cover`` of its sigmas (measured 2026-11-29: at most 2.10), and
    it flags every plate whose ratio reads more than 10 % off (three; seven before the lit floor's change was
    carried across the edge). An uncertain ratio may still come out right: the own suns read within 1.2 % and
    are flagged."""
    from arshadow.bench.reference import measure_light
    from arshadow.estimate.checks import RATIO_TEXTURE
    from arshadow.estimate.shadow import LUMA

    for c in [*own, *heldout]:
        sc = c.scene
        est = measure_light(c.plate8, sc)
        v, sky = np.asarray(sc.light_vec, np.float64), np.asarray(sc.sky, np.float64)
        if sc.light == "sun":
            e = np.asarray(sc.direct) * v[2] / np.linalg.norm(v)
        else:
            rel = v - np.r_[est.ratio_at, 0.0]
            e = np.asarray(sc.direct) * rel[2] / np.linalg.norm(rel) ** 3
        err = float(np.asarray(est.shadow_ratio) @ LUMA) / float((sky / (sky + e)) @ LUMA) - 1.0
        texture = est.fit["ratio_texture"]
        assert abs(err) <= tol.ratio_texture_cover * texture, (sc.name, err, texture)
        flagged = any("moves the shadow ratio" in w for w in est.warnings)
        assert flagged == (texture > RATIO_TEXTURE), (sc.name, texture, est.warnings)
        if abs(err) > 0.1:
            assert flagged, (sc.name, err, texture)


def test_probe_outline_is_read_past_its_own_crease(own, tol):
    """The light estimate's probe check on the path-traced plates, at the scenes' own camera: the box probe's
    lit and unlit faces meet in a crease, the strongest edge near the unlit side's outline (that side stands
    against its own shadow), which the check read as "no edge on the outline" (0.73-0.86 on these plates,
    0.39 on a held-out one, refused as "not where it is given"). Given 4 cm off, still chance."""
    from arshadow.estimate.outline import outline_agreement
    from arshadow.geometry.mesh import load_occluder

    for c in own:
        sc = c.scene
        intr = intrinsics_of(sc).for_image(c.plate8.shape[1], c.plate8.shape[0])[0]

        def agree(place, sc=sc, intr=intr, c=c):
            m = load_occluder(sc.probe, place=place)
            return outline_agreement(c.plate8, intr, pose_of(sc), np.asarray(m.vertices), np.asarray(m.faces))[0]

        x, y, _ = sc.probe_place
        assert agree(sc.probe_place) >= tol.outline_in_place, sc.name
        assert agree((x, y - 0.04, 0.0)) < tol.outline_away, sc.name
