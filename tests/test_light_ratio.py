"""The shadow ratio's colour through a chroma-subsampled JPEG (arshadow.estimate.ratio, docs/light.md).

An independent computation: :func:`arshadow.synth.lit.render_lit_photo` lights a plain floor with a known
blue ambient and a warm direct light (its ``shadow_ratio`` is ``ambient / (ambient + direct sin(e))``), at
about 1.2 mm per pixel, and codes the photo as a JPEG (quality 90, cv2's 4:2:0 chroma subsampling), so the
pairs a few pixels from the shadow's edge see the lit side's colour. Read beyond the chroma blur
(``chroma_px=CHROMA_PX``, measured and not the default: docs/reference.md, "the shadow's colour") the
estimate recovers the generating ratio's colour (each channel over its luminance) and keeps the level; the
default reading (near the edge) shows the JPEG's bias, so the test is not vacuous.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import arshadow.estimate.api as api
from arshadow.camera.model import Intrinsics
from arshadow.compose.composite import SRGB_TO_LINEAR
from arshadow.estimate import estimate_light
from arshadow.estimate.checks import RATIO_TEXTURE
from arshadow.estimate.ratio import CHROMA_PX, shadow_ratio
from arshadow.estimate.shadow import LUMA
from arshadow.geometry.exact import ground_shadow_triangles
from arshadow.geometry.mesh import load_occluder
from arshadow.shading.decide import PAPER_ALBEDO
from arshadow.synth.lit import light_vector, render_lit_photo
from arshadow.synth.markers import look_at_pose

CALIB = "calib/synth_640x360.yml"
PROBE = "box:0.05,0.05,0.1"
PLACE = (0.1, 0.02, 0.0)


def _chroma(r) -> np.ndarray:
    """(3,) each channel of a ratio over its luminance."""
    r = np.asarray(r, np.float64)
    return r / float(r @ LUMA)


def _lit_photo(light, ambient, direct, seed, floor="plain"):
    """A JPEG (quality 90, noise 1) of the probe lit by ``light`` (a unit vector) from 0.6 m: ~1.2 mm a pixel."""
    return render_lit_photo(
        Intrinsics.from_file(CALIB),
        look_at_pose((0.05, -0.45, 0.396), (0.08, 0.04, 0.0)),
        probe=PROBE,
        probe_place=PLACE,
        light=light,
        ambient=ambient,
        direct=direct,
        jpeg_quality=90,
        noise_sigma=1.0,
        seed=seed,
        floor=floor,
    )


@pytest.fixture(scope="module")
def blue_sky_jpeg():
    return _lit_photo(light_vector(200.0, 40.0), (0.22, 0.3, 0.5), (1.0, 0.9, 0.72), seed=5)


def _estimate(photo):
    return estimate_light(
        photo.image, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE, sky_occlusion=False
    )


def test_the_ratio_keeps_its_colour_through_a_subsampled_jpeg(blue_sky_jpeg, monkeypatch):
    truth = _chroma(blue_sky_jpeg.shadow_ratio)
    assert truth[2] > 1.4  # a blue shadow
    # the default reading, near the edge: the JPEG's chroma blur greys the ratio (redder, less blue)
    near = _estimate(blue_sky_jpeg)
    near_err = _chroma(near.shadow_ratio) / truth - 1.0
    assert near_err[0] > 0.02 and near_err[2] < -0.03, near_err
    # read beyond the chroma blur: the generating colour within 3 % per channel, the same level
    monkeypatch.setattr(api, "shadow_ratio", functools.partial(shadow_ratio, chroma_px=CHROMA_PX))
    est = _estimate(blue_sky_jpeg)
    err = _chroma(est.shadow_ratio) / truth - 1.0
    assert np.abs(err).max() < 0.03, err
    lum = float(np.asarray(est.shadow_ratio) @ LUMA)
    assert lum == pytest.approx(float(np.asarray(near.shadow_ratio) @ LUMA), rel=1e-9)
    assert lum / float(blue_sky_jpeg.shadow_ratio @ LUMA) == pytest.approx(1.0, abs=0.02)


@pytest.mark.parametrize("floor", ["plain", "texture"])
def test_the_texture_check_measures_the_floors_pattern(floor, tol):
    """:func:`arshadow.estimate.ratio.texture_uncertainty` on a synthetic lit photo (the generating ratio known):
    on a plain floor the shadow's pairs read on lit floor give 0 (the JPEG's noise only) and nothing is
    flagged; on arshadow.synth's patterned floor, where this light's ratio reads 6.3 % off, the check reads
    the pattern (measured 2026-11-29: 0.109, over the flag's 0.08, so flagged) and covers the error. Flagging
    on the path-traced plates: tests/test_reference.py."""
    photo = _lit_photo(light_vector(300.0, 35.0), (0.3, 0.32, 0.36), (1.0, 0.95, 0.9), seed=7, floor=floor)
    est = _estimate(photo)
    err = float(np.asarray(est.shadow_ratio) @ LUMA) / float(photo.shadow_ratio @ LUMA) - 1.0
    texture = est.fit["ratio_texture"]
    flagged = [w for w in est.warnings if "moves the shadow ratio" in w]
    if floor == "plain":
        assert texture < 0.01 and abs(err) < 0.01 and not flagged, (texture, err, est.warnings)
    else:
        assert abs(err) > 0.05, err  # the pattern moves this light's ratio: the check has something to see
        assert texture > 0.04 and abs(err) <= tol.ratio_texture_cover * texture, (err, texture)
        assert bool(flagged) == (texture > RATIO_TEXTURE), (texture, est.warnings)


@pytest.mark.parametrize("az, el", [(200.0, 40.0), (300.0, 35.0), (120.0, 55.0)])
def test_the_lit_floors_change_allows_for_a_floor_darker_under_the_shadow(az, el, monkeypatch):
    """A smooth dark patch of the floor centred under the probe's shadow (codes 170 - 60 exp(-r^2 / 2 (6 cm)^2),
    grey): the pairs read the patch's slope across the edge as a darker shadow (the generating ratio known:
    4-9 % low without it, measured 2026-11-29). :func:`arshadow.estimate.ratio.shadow_ratio`'s
    ``lit_gradient`` (the default: the lit floor's change beside each side of the edge, read outside and
    carried across it) brings it within 2 %."""
    light = light_vector(az, el)
    caster = load_occluder(PROBE, place=PLACE)
    tri = ground_shadow_triangles(np.asarray(caster.vertices), np.asarray(caster.faces), np.append(light, 0.0))
    cx, cy = tri.reshape(-1, 2).mean(axis=0)

    def floor(x, y):
        return 170.0 - 60.0 * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2.0 * 0.06**2))

    photo = _lit_photo(light, (0.3, 0.32, 0.36), (1.0, 0.95, 0.9), seed=3, floor=floor)
    truth = float(photo.shadow_ratio @ LUMA)
    est = _estimate(photo)
    assert abs(float(np.asarray(est.shadow_ratio) @ LUMA) / truth - 1.0) < 0.02, est.shadow_ratio
    assert est.fit["ratio_texture"] < 0.02, est.fit  # a smooth floor: the check reads it so too
    monkeypatch.setattr(api, "shadow_ratio", functools.partial(shadow_ratio, lit_gradient=False))
    plain = _estimate(photo)
    assert float(np.asarray(plain.shadow_ratio) @ LUMA) / truth - 1.0 < -0.035, plain.shadow_ratio


@pytest.mark.parametrize("albedo", [0.3, 0.5, 1.2])
def test_probe_reflectance_is_read_off_its_top_face(albedo, tol):
    """The probe's reflectance (``fit.probe_albedo``, for the light it reflects onto the floor beside its
    shadow) is read off its top face against the marker's paper: the truth is the generating reflectance over
    the printed paper's (sRGB 235, 0.83) times the paper's assumed ``PAPER_ALBEDO``. A top face brighter than
    any matte surface (an impossible 1.2 here: what a glossy probe, or one lit by something the paper is not,
    reads) is named in a warning and its reflected light left out of the ratio."""
    photo = render_lit_photo(
        Intrinsics.from_file(CALIB),
        look_at_pose((0.05, -0.45, 0.396), (0.08, 0.04, 0.0)),
        probe=PROBE,
        probe_place=PLACE,
        probe_albedo=(albedo, albedo, albedo),
        light=light_vector(200.0, 40.0),
        jpeg_quality=90,
        noise_sigma=1.0,
        seed=9,
        floor="plain",
    )
    est = estimate_light(photo.image, calib=CALIB, marker_length=0.05, probe=PROBE, probe_place=PLACE)
    want = PAPER_ALBEDO * albedo / float(SRGB_TO_LINEAR[235])
    assert est.fit["probe_albedo"] == pytest.approx(want, rel=tol.probe_albedo_rel), est.fit
    warned = [w for w in est.warnings if "brighter than any matte surface" in w]
    assert bool(warned) == (want > 1.0), est.warnings
