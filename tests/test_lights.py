"""Lights: parsing (CONVENTIONS.md), validation, homogeneous vectors, area-light sampling."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import TOL
from oracle import disc_segment_fraction, profile_crossing

from arshadow.errors import ArshadowError, LightError
from arshadow.lights.area import sample_area_light, stratified_disc
from arshadow.lights.spec import (
    SUN_ANGULAR_RADIUS_DEG,
    Light,
    lights_homogeneous,
    parse_light,
    total_weight,
)


# ---------------------------------------------------------------------------------------------- parsing
def test_point_light():
    li = parse_light("point:0.5,-1,2")
    assert li.kind == "point" and li.weight == 1.0 and li.radius == 0.0 and li.above_horizon
    assert li.homogeneous.tolist() == [0.5, -1.0, 2.0, 1.0]
    assert li.label == "point:0.5,-1,2"
    assert li.sun is None


def test_directional_light_is_normalised_towards_light():
    li = parse_light("directional:3,0,4@2.5")
    np.testing.assert_allclose(li.vector, [0.6, 0.0, 0.8], atol=1e-15)
    assert li.homogeneous[3] == 0.0 and li.weight == 2.5


def test_weights_and_radius_options():
    li = parse_light("point:0,0,3,radius=0.05@0.25")
    assert li.radius == 0.05 and li.weight == 0.25 and li.is_soft
    d = parse_light("directional:0,0,1,radius=0.5")
    assert d.radius == pytest.approx(math.radians(0.5))
    assert parse_light(" POINT: 1 , 2 , 3 ").vector.tolist() == [1.0, 2.0, 3.0]


@pytest.mark.parametrize(
    "spec, words",
    [
        ("", "empty"),
        ("point", "KIND:VALUES"),
        ("spot:0,0,1", "unknown kind"),
        ("point:0,0", "3 values"),
        ("point:0,0,1,2", "3 values"),
        ("point:a,0,1", "not a number"),
        ("point:nan,0,1", "finite"),
        ("point:0,0,inf", "finite"),
        ("point:0,0,1@0", "weight must be > 0"),
        ("point:0,0,1@-2", "weight must be > 0"),
        ("point:0,0,1@", "empty weight"),
        ("point:0,0,1@x", "not a number"),
        ("point:0,0,-1", "above the ground"),
        ("point:0,0,0", "above the ground"),
        ("directional:0,0,0", "no direction"),
        ("directional:1,0,-1", "point up"),
        ("directional:0,0,1,radius=-1", "radius"),
        ("directional:0,0,1,radius=95", "90"),
        ("point:0,0,1,size=3", "unknown option"),
        ("point:0,0,0.1,radius=0.1", "reaches the ground"),
        ("point:0,0,1,radius=1,radius=2", "twice"),
    ],
)
def test_bad_specs_raise_light_error(spec, words):
    with pytest.raises(LightError) as exc:
        parse_light(spec)
    assert words in str(exc.value)
    assert isinstance(exc.value, ArshadowError)


def test_light_validation_direct():
    with pytest.raises(LightError):
        Light("spot", [0, 0, 1])
    with pytest.raises(LightError):
        Light("point", [0, 0])
    with pytest.raises(LightError):
        Light("point", [0, 0, 1], weight=0.0)
    with pytest.raises(LightError):
        Light("point", [0, 0, 1], weight=float("nan"))
    with pytest.raises(LightError):
        Light("directional", [0, 0, 0])
    with pytest.raises(LightError):
        Light("point", [0, np.nan, 1])


def test_light_does_not_alias_input_and_is_read_only():
    v = np.array([1.0, 2.0, 3.0])
    li = Light("point", v)
    v[0] = 99.0
    assert li.vector[0] == 1.0
    with pytest.raises(ValueError):
        li.vector[0] = 5.0
    h = li.homogeneous
    h[0] = 7.0  # a fresh array: editing it does not touch the light
    assert li.homogeneous[0] == 1.0


def test_light_equality_and_hash():
    a, b = parse_light("point:0,0,2@2"), parse_light("point:0,0,2@2")
    assert a == b and hash(a) == hash(b)
    assert a != parse_light("point:0,0,2@3")


def test_helpers():
    lights = [parse_light("point:0,0,2@2"), parse_light("directional:0,1,1")]
    h = lights_homogeneous(lights)
    assert h.shape == (2, 4) and h[0, 3] == 1.0 and h[1, 3] == 0.0
    assert total_weight(lights) == 3.0
    assert lights_homogeneous([]).shape == (0, 4)


# ---------------------------------------------------------------------------------------------- sampling
def test_stratified_disc_is_in_disc_and_equal_area():
    d = stratified_disc(100, seed=3)
    r2 = np.sum(d**2, axis=1)
    assert np.all(r2 < 1.0)
    # exactly one sample per equal-area annulus [k/n, (k+1)/n) of r^2
    np.testing.assert_array_equal(np.floor(np.sort(r2) * 100), np.arange(100))
    np.testing.assert_array_equal(stratified_disc(100, seed=3), d)  # seeded: reproducible
    assert not np.array_equal(stratified_disc(100, seed=4), d)
    with pytest.raises(LightError):
        stratified_disc(0)


def test_stratified_disc_integrates_half_planes():
    """Fraction of samples beyond any chord vs the exact circular-segment area: the occluded fraction
    of a disc light behind a straight edge, i.e. the penumbra profile."""
    worst = 0.0
    for seed in range(5):
        d = stratified_disc(256, seed)
        for ang in np.linspace(0.0, math.pi, 7):
            p = d @ [math.cos(ang), math.sin(ang)]
            for x in np.linspace(-0.9, 0.9, 19):
                worst = max(worst, abs(np.mean(p > x) - disc_segment_fraction(x)))
    # 256 i.i.d. samples would give a standard deviation of up to 0.031 per value; stratified does better
    assert worst < TOL.area_light_segment


def test_n1_is_the_centre_light_exactly():
    for spec in ("point:0.3,0.2,2,radius=0.2@3", "directional:1,2,3,radius=2@0.5"):
        li = parse_light(spec)
        (s,) = sample_area_light(li, 1)
        np.testing.assert_array_equal(s.homogeneous, li.homogeneous)
        assert s.weight == li.weight and s.radius == 0.0 and s.kind == li.kind and s.label == li.label


def test_hard_light_gives_one_sample():
    li = parse_light("point:0,0,2")
    assert sample_area_light(li, 16) == [li]


@pytest.mark.parametrize("n", [2, 7, 16, 64])
def test_point_samples_on_disc_facing_scene_centre(n):
    li = parse_light("point:1,-0.5,2,radius=0.1@3")
    target = np.array([0.2, 0.1, 0.0])
    s = sample_area_light(li, n, seed=1, towards=target)
    assert len(s) == n
    assert sum(x.weight for x in s) == pytest.approx(3.0, abs=1e-12)
    assert all(x.kind == "point" and x.radius == 0.0 for x in s)
    p = np.array([x.vector for x in s])
    axis = (target - li.vector) / np.linalg.norm(target - li.vector)
    np.testing.assert_allclose((p - li.vector) @ axis, 0.0, atol=1e-12)  # on the perpendicular disc
    assert np.all(np.linalg.norm(p - li.vector, axis=1) <= 0.1 + 1e-12)
    if n >= 16:  # stratified: the centroid is near the centre
        assert np.linalg.norm(p.mean(axis=0) - li.vector) < 0.1 * 2.0 / math.sqrt(n)
    assert len({x.label for x in s}) == n


@pytest.mark.parametrize("n", [4, 32, 128])
def test_directional_samples_fill_cone_uniformly_in_solid_angle(n):
    alpha = math.radians(2.0)
    li = Light("directional", [0.3, -0.2, 1.0], weight=2.0, radius=alpha, label="d")
    s = sample_area_light(li, n, seed=5)
    dirs = np.array([x.vector for x in s])
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-14)
    ang = np.arccos(np.clip(dirs @ li.vector, -1, 1))
    assert np.all(ang <= alpha * (1 + 1e-9))
    # solid angle strata: exactly one sample per equal-solid-angle ring (1 - cos theta uniform)
    u = (1 - np.cos(ang)) / (1 - math.cos(alpha))
    np.testing.assert_array_equal(np.floor(np.sort(u) * n + 1e-9), np.arange(n))
    assert sum(x.weight for x in s) == pytest.approx(2.0, abs=1e-12)
    # the mean direction is close to the centre (stratified spread)
    m = dirs.mean(axis=0)
    assert math.degrees(math.acos(min(1.0, m @ li.vector / np.linalg.norm(m)))) < math.degrees(alpha) * 0.5


def test_setting_sun_keeps_only_the_visible_part_of_its_disc():
    alpha = math.radians(0.266)
    el = math.radians(0.1)  # centre 0.1 deg above the horizon: part of the disc is below
    li = Light("directional", [0.0, math.cos(el), math.sin(el)], weight=3.0, radius=alpha, label="sun")
    s = sample_area_light(li, 64, seed=0)
    assert 32 < len(s) < 64
    assert all(x.vector[2] > 0 for x in s)
    assert sum(x.weight for x in s) == pytest.approx(3.0, abs=1e-12)
    # visible fraction of the disc ~ the segment above the horizon (0.1 / 0.266 of the radius)
    assert len(s) / 64 == pytest.approx(1 - disc_segment_fraction(0.1 / 0.266), abs=0.06)


def test_sampling_does_not_modify_light_and_rejects_bad_n():
    li = parse_light("point:0,0,2,radius=0.1")
    before = li.vector.copy()
    sample_area_light(li, 8)
    np.testing.assert_array_equal(li.vector, before)
    with pytest.raises(LightError):
        sample_area_light(li, 0)
    with pytest.raises(LightError):
        sample_area_light("point:0,0,1", 4)


def test_sun_angular_radius_constant():
    assert SUN_ANGULAR_RADIUS_DEG == pytest.approx(0.266, abs=0.005)


# ------------------------------------------------------------- penumbra from the samples (pure ray casting)
def _blocked_fraction(ground_pts, lights, box_lo, box_hi):
    """Weighted fraction of ``lights`` hidden from each ground point by an axis-aligned box (slab test,
    written here independently of arshadow)."""
    out = np.zeros(len(ground_pts))
    total = sum(li.weight for li in lights)
    for li in lights:
        p = ground_pts
        if li.kind == "point":
            d = li.vector - p
            tmax_seg = np.ones(len(p))
        else:
            d = np.broadcast_to(li.vector, p.shape)
            tmax_seg = np.full(len(p), np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (box_lo - p) / d
            t2 = (box_hi - p) / d
        tnear = np.nanmax(np.minimum(t1, t2), axis=1)
        tfar = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (tnear <= tfar) & (tfar > 0) & (tnear < tmax_seg)
        out += li.weight * hit
    return out / total


def test_point_area_light_penumbra_matches_geometry():
    """Box edge under a spherical light straight above: penumbra full width 2 r h / (H - h) and the exact
    disc profile; the stratified samples reproduce it."""
    r, H, h, a = 0.1, 1.0, 0.3, 0.1
    li = parse_light(f"point:0,0,{H},radius={r}")
    lights = sample_area_light(li, 256, seed=2, towards=(0, 0, 0))
    x = np.linspace(a + 0.001, a + 0.2, 2000)
    pts = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    f = _blocked_fraction(pts, lights, np.array([-a, -1.0, 0.0]), np.array([a, 1.0, h]))
    # exact profile: sample blocked iff its x < c(x) = x - (x - a) H / h
    c = x - (x - a) * H / h
    exact = 1.0 - disc_segment_fraction(c / r)  # fraction of the disc with first coordinate < c / r
    assert np.max(np.abs(f - exact)) < TOL.area_light_segment
    full = 2 * r * h / (H - h)
    w_full = x[np.nonzero(f < 1.0)[0][0]], x[np.nonzero(f > 0.0)[0][-1]]
    assert abs((w_full[1] - w_full[0]) - full) / full < TOL.penumbra_rel
    w1090 = profile_crossing(x, f, 0.1) - profile_crossing(x, f, 0.9)
    e1090 = profile_crossing(x, exact, 0.1) - profile_crossing(x, exact, 0.9)
    assert abs(w1090 - e1090) / e1090 < TOL.penumbra_1090_rel
    # N = 1: the hard shadow edge exactly at a + a h / (H - h)
    f1 = _blocked_fraction(pts, sample_area_light(li, 1), np.array([-a, -1.0, 0.0]), np.array([a, 1.0, h]))
    edge = a + a * h / (H - h)
    np.testing.assert_array_equal(f1, (x < edge).astype(float))


def test_directional_area_light_penumbra_matches_geometry():
    """Wall of height h facing a directional light at elevation e with angular radius alpha: penumbra from
    h / tan(e + alpha) to h / tan(e - alpha) behind the wall."""
    e, alpha, h = math.radians(40.0), math.radians(2.0), 0.5
    li = Light("directional", [-math.cos(e), 0.0, math.sin(e)], radius=alpha)  # sun towards -x
    lights = sample_area_light(li, 128, seed=9)
    x = np.linspace(0.01, 1.2, 4000)  # ground behind the wall (wall at x in [-0.01, 0])
    pts = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    f = _blocked_fraction(pts, lights, np.array([-0.01, -5.0, 0.0]), np.array([0.0, 5.0, h]))
    full = h / math.tan(e - alpha) - h / math.tan(e + alpha)
    w_full = x[np.nonzero(f > 0.0)[0][-1]] - x[np.nonzero(f < 1.0)[0][0]]
    assert abs(w_full - full) / full < TOL.penumbra_rel
    # the umbra/half/lit positions: 50 % at the centre direction's shadow h / tan(e)
    assert profile_crossing(x, f, 0.5) == pytest.approx(h / math.tan(e), rel=TOL.penumbra_centre_rel)
