"""Shadow-catcher compositing against values computed by hand from the sRGB formulas."""

from __future__ import annotations

import numpy as np
import pytest

from arshadow.compose.composite import (
    LINEAR_TO_SRGB16,
    SRGB_TO_LINEAR,
    Overlay,
    clip_roi,
    composite,
    linear_to_srgb8,
    parse_rgb,
    srgb8_to_linear,
)
from arshadow.compose.look import Look
from arshadow.errors import ShapeError, UsageError


def _lin(code):
    """sRGB 8-bit code -> linear, straight from IEC 61966-2-1 (independent of the module's tables)."""
    c = code / 255.0
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def _srgb(x):
    x = min(max(x, 0.0), 1.0)
    c = 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055
    return int(np.floor(c * 255.0 + 0.5))


def test_hand_values_of_the_srgb_curve():
    # 128 -> 0.2158605 (textbook value), 255 -> 1, 0 -> 0, 10 -> 10/255/12.92
    assert SRGB_TO_LINEAR[128] == pytest.approx(0.2158605, abs=1e-6)
    assert SRGB_TO_LINEAR[255] == 1.0 and SRGB_TO_LINEAR[0] == 0.0
    assert SRGB_TO_LINEAR[10] == pytest.approx(10 / 255 / 12.92, rel=1e-6)
    # half the linear light of mid grey is sRGB 92.37 -> 92 (computed by hand: 1.055*0.10793^(1/2.4)-0.055)
    assert linear_to_srgb8(np.float32(0.2158605 / 2)) == 92
    assert LINEAR_TO_SRGB16[65535] == 255 and LINEAR_TO_SRGB16[0] == 0


def test_unchanged_codes_round_trip_exactly():
    codes = np.arange(256, dtype=np.uint8)
    assert np.array_equal(linear_to_srgb8(srgb8_to_linear(codes)), codes)


def test_linear_to_srgb_off_by_at_most_one_level_near_ties(rng):
    x = rng.random(200_000)
    got = linear_to_srgb8(x.astype(np.float32)).astype(int)
    ref = np.array([_srgb(v) for v in x[:20000]])
    d = got[:20000] - ref
    assert np.abs(d).max() <= 1
    assert np.mean(d != 0) < 0.005  # only near rounding ties (table step <= 0.05 level)


def test_shadow_darkens_in_linear_light_hand_values():
    photo = np.zeros((3, 4, 3), np.uint8)
    photo[:] = (200, 128, 30)  # B, G, R
    mask = np.zeros((2, 2), np.float32)
    mask[0, 0] = 1.0
    mask[0, 1] = 0.5
    out = composite(photo, Overlay(mask), roi=(1, 1, 2, 2), look=Look(opacity=0.8))
    # pixels outside the ROI and with mask 0 are untouched
    assert np.array_equal(out[0], photo[0])
    assert np.array_equal(out[:, 0], photo[:, 0])
    assert np.array_equal(out[2, 2], photo[2, 2])
    for (r, c), m in (((1, 1), 1.0), ((1, 2), 0.5)):
        f = 1 - 0.8 * m
        assert out[r, c].tolist() == [_srgb(_lin(v) * f) for v in (200, 128, 30)]
    # concrete numbers for the full shadow: 128 -> lin 0.21586 * 0.2 = 0.043172 -> sRGB 58.6 -> 59
    assert out[1, 1, 1] == 59
    assert photo[1, 1].tolist() == [200, 128, 30]  # input untouched


def test_shadow_tint():
    photo = np.full((1, 1, 3), 255, np.uint8)
    mask = np.ones((1, 1), np.float32)
    tint = parse_rgb("0,0,255")  # blue shadow: R and G blocked, B kept
    out = composite(photo, Overlay(mask), look=Look(opacity=1.0, shadow_color=tint))
    assert out[0, 0].tolist() == [255, 0, 0]  # BGR
    # half opacity, grey tint 128: factor = 1 - 0.5 * (1 - 0.21586) = 0.60793 -> sRGB 0.8033*255 = 204.8
    out = composite(photo, Overlay(mask), look=Look(opacity=0.5, shadow_color=parse_rgb("128,128,128")))
    assert out[0, 0].tolist() == [_srgb(1 - 0.5 * (1 - _lin(128)))] * 3 == [205] * 3


def test_occluder_over_premultiplied_and_straight():
    photo = np.full((1, 2, 3), 100, np.uint8)
    color = np.array([[[0.5, 0.25, 0.0], [0.5, 0.25, 0.0]]], np.float32)  # linear RGB
    alpha = np.array([[1.0, 0.5]], np.float32)
    # fully blocked ground wherever the ground is seen: the mask is coverage-weighted like the renderer's
    # (0 under the object, 1 - alpha where alpha is partial); it was 1 everywhere before the stress suite ('s)'s fix
    mask = np.array([[0.0, 0.5]], np.float32)
    out = composite(photo, Overlay(mask, color=color, alpha=alpha, premultiplied=False), look=Look(opacity=0.5))
    bg = _lin(100) * 0.5
    # full coverage: the occluder's colour alone (BGR order!)
    assert out[0, 0].tolist() == [_srgb(0.0), _srgb(0.25), _srgb(0.5)]
    assert out[0, 1].tolist() == [_srgb(0.5 * c + 0.5 * bg) for c in (0.0, 0.25, 0.5)]
    # premultiplied colour (the renderer's convention): colour already times alpha
    out2 = composite(photo, Overlay(mask, color=color * alpha[..., None], alpha=alpha), look=Look(opacity=0.5))
    assert np.array_equal(out, out2)


def test_out_buffer_and_in_place():
    photo = np.full((4, 4, 3), 77, np.uint8)
    keep = photo.copy()
    buf = np.zeros_like(photo)
    res = composite(photo, Overlay(np.ones((2, 2), np.float32)), roi=(0, 0, 2, 2), look=Look(opacity=1.0), out=buf)
    assert res is buf and np.array_equal(photo, keep)
    assert buf[0, 0].tolist() == [0, 0, 0] and buf[3, 3].tolist() == [77, 77, 77]
    res = composite(photo, Overlay(np.ones((2, 2), np.float32)), roi=(2, 2, 2, 2), look=Look(opacity=1.0), out=photo)
    assert res is photo and photo[3, 3].tolist() == [0, 0, 0]


def test_bad_input():
    photo = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(ShapeError):
        composite(photo, Overlay(np.ones((2, 3), np.float32)), roi=(0, 0, 2, 2))
    with pytest.raises(ShapeError):
        composite(photo, Overlay(np.ones((2, 2), np.float32)), roi=(3, 3, 2, 2))
    with pytest.raises(ShapeError):
        composite(photo.astype(np.float32), Overlay(None))
    with pytest.raises(UsageError):
        composite(photo, Overlay(None), look=Look(opacity=1.5))
    with pytest.raises(UsageError):
        parse_rgb("1,2")
    with pytest.raises(UsageError):
        parse_rgb("1,2,300")
    with pytest.raises(UsageError):
        parse_rgb("a,b,c")
    assert clip_roi((-5, 2, 10, 10), 8, 6) == (0, 2, 5, 4)
    assert clip_roi((20, 2, 10, 10), 8, 6)[2] == 0


def test_sky_channel_darkens_by_the_sky_share():
    # the ground keeps direct share x (1 - mask) + sky share x (1 - sky occlusion), per channel: with a
    # measured light (opacity 1, tint = the shadow ratio r) that is 1 - (1 - r) m - r s
    from arshadow.compose.composite import LINEAR_TO_SRGB16, SRGB_TO_LINEAR, Overlay, composite
    from arshadow.compose.look import Look

    rng = np.random.default_rng(3)
    photo = rng.integers(40, 250, (20, 30, 3), dtype=np.uint8)
    m = rng.uniform(0, 1, (20, 30)).astype(np.float32)
    s = rng.uniform(0, 1, (20, 30)).astype(np.float32)
    r = np.array([0.4, 0.5, 0.6])  # RGB
    out = composite(photo, Overlay(m, sky=s), look=Look(opacity=1.0, shadow_color=r))
    lin = SRGB_TO_LINEAR[photo].astype(np.float64)  # BGR
    k = 1.0 - (1.0 - r[::-1]) * m[..., None] - r[::-1] * s[..., None]
    expect = LINEAR_TO_SRGB16[np.clip(lin * k * 65535 + 0.5, 0, 65535).astype(np.uint16)]
    assert np.abs(out.astype(int) - expect.astype(int)).max() <= 1
    # no sky occlusion: the plain composite
    assert np.array_equal(
        composite(photo, Overlay(m, sky=np.zeros_like(s)), look=Look(opacity=1.0, shadow_color=r)),
        composite(photo, Overlay(m), look=Look(opacity=1.0, shadow_color=r)),
    )


def test_sky_per_colour_channel_darkens_each_channel_by_its_own_sky():
    """A per-channel sky (colour bleeding, ``sky_planes``) gives each channel the darkening its own sky plane
    gives a grey composite: the (h, w, 3) sky composited equals three grey-sky composites, channel by channel."""
    from arshadow.compose.composite import Overlay, composite, sky_planes
    from arshadow.compose.look import Look

    rng = np.random.default_rng(5)
    photo = rng.integers(40, 220, (6, 7, 3), dtype=np.uint8)
    sky = rng.uniform(-0.2, 0.6, (6, 7)).astype(np.float32)
    refl = rng.uniform(0.0, 0.3, (6, 7)).astype(np.float32)
    mask = rng.uniform(0.0, 1.0, (6, 7)).astype(np.float32)
    bleed = (0.9, -0.2, -0.7)
    look = Look(opacity=0.8, shadow_color=(0.3, 0.35, 0.45))
    got = composite(photo, Overlay(mask=mask, sky=sky_planes(sky, refl, bleed)), look=look)
    for c in range(3):  # RGB channel c is photo channel 2 - c (BGR)
        one = composite(photo, Overlay(mask=mask, sky=sky - refl * bleed[c]), look=look)
        assert np.array_equal(got[:, :, 2 - c], one[:, :, 2 - c]), c
    assert not np.array_equal(got, composite(photo, Overlay(mask=mask, sky=sky), look=look))
