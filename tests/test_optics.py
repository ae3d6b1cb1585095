"""Blur and noise measured from the photo (arshadow.estimate.optics) on synthetic photos made here with
plain OpenCV: a marker-like black square on white paper over a grey floor, area-sampled (16 x 16
supersampling), blurred in linear light by a known Gaussian, sRGB-encoded, noised by a known sigma."""

import math

import cv2
import numpy as np
import pytest

from arshadow.errors import EstimateError
from arshadow.estimate.optics import measure_blur, measure_noise, noise_at
from tests.conftest import TOL

SS = 16  # supersampling per pixel side


def synth_marker(sigma_blur, sigma_noise, *, angle_deg=17.0, size=(240, 320), side=120.0, seed=0):
    """(h, w, 3) uint8 BGR photo and the marker's corners (4, 2) px.

    Linear light: floor 0.18, paper 0.8 (a 1.5 x side square), marker black 0.03 with a white inner
    cell pattern one cell in from its border (6 cells wide). Area-sampled, blurred with ``sigma_blur`` px
    in linear light, encoded to sRGB, noise ``sigma_noise`` (8-bit units, per channel), rounded."""
    h, w = size
    c = np.array([w / 2, h / 2])
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])

    def square(half):
        return c + (np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half) @ rot.T

    big = np.full((h * SS, w * SS), 0.18, np.float32)
    for half, val in ((0.75 * side, 0.8), (0.5 * side, 0.03), (0.5 * side * 4 / 6, 0.8), (0.5 * side * 2 / 6, 0.03)):
        pts = np.round((square(half) * SS - 0.5) * 256 + 128).astype(np.int32)  # pixel-centre convention
        cv2.fillConvexPoly(big, pts, val, lineType=cv2.LINE_AA, shift=8)
    lin = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA).astype(np.float64)
    if sigma_blur > 0:
        lin = cv2.GaussianBlur(lin, (0, 0), sigma_blur)
    enc = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.clip(lin, 0, 1) ** (1 / 2.4) - 0.055) * 255
    img = np.repeat(enc[..., None], 3, axis=2)
    if sigma_noise > 0:
        img = img + np.random.default_rng(seed).normal(0, sigma_noise, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8), square(0.5 * side)


@pytest.mark.parametrize("sigma", [0.0, 0.6, 1.0, 1.8, 3.0])
def test_blur_recovered(sigma):
    img, corners = synth_marker(sigma, 1.0)
    est = measure_blur(img, corners)
    assert abs(est.sigma_px - sigma) <= TOL.psf_sigma_px, est


def test_blur_with_corner_error_and_axis_aligned_edges():
    img, corners = synth_marker(1.2, 2.0, angle_deg=0.0)
    noisy = corners + np.random.default_rng(1).normal(0, 0.3, corners.shape)  # detector-like corner error
    assert abs(measure_blur(img, noisy).sigma_px - 1.2) <= TOL.psf_sigma_px


def test_blur_reads_only_the_markers_neighbourhood():
    # the estimate is the same with the photo beyond the marker's edges (+ the band) replaced by noise, and
    # with the marker cut by the photo's border (its corners partly outside): measured on what is left
    img, corners = synth_marker(1.0, 1.0)
    ref = measure_blur(img, corners)
    far = np.random.default_rng(3).integers(0, 256, img.shape, dtype=np.uint8)
    x0, y0 = np.floor(corners.min(axis=0) - 10).astype(int)
    x1, y1 = np.ceil(corners.max(axis=0) + 10).astype(int)
    far[y0:y1, x0:x1] = img[y0:y1, x0:x1]
    assert measure_blur(far, corners) == ref
    cut = img[:, : int(corners[:, 0].max()) - 20]
    est = measure_blur(cut, corners)
    assert abs(est.sigma_px - 1.0) <= TOL.psf_sigma_px


def test_blur_refuses_a_flat_image():
    with pytest.raises(EstimateError):
        measure_blur(np.full((100, 100), 128, np.uint8), np.array([[30, 30], [70, 30], [70, 70], [30, 70.0]]))


@pytest.mark.parametrize("sigma_noise", [1.0, 3.0, 6.0])
def test_noise_recovered_on_paper_and_floor(sigma_noise):
    img, corners = synth_marker(1.0, sigma_noise)
    h, w = img.shape[:2]
    paper = np.zeros((h, w), np.uint8)
    c = corners.mean(axis=0)
    cv2.fillConvexPoly(paper, np.round(c + 1.4 * (corners - c)).astype(np.int32), 1)
    cv2.fillConvexPoly(paper, np.round(c + 1.1 * (corners - c)).astype(np.int32), 0)
    floor = np.ones((h, w), np.uint8)
    cv2.fillConvexPoly(floor, np.round(c + 1.6 * (corners - c)).astype(np.int32), 0)
    for mask in (paper, floor):
        est = measure_noise(img, mask.astype(bool))
        # quantisation to integers adds 1/12 of a code value's variance
        expect = math.sqrt(sigma_noise**2 + 1 / 12)
        assert np.all(np.abs(est.sigma * 255 / expect - 1) <= TOL.noise_sigma_rel), (est.sigma * 255, expect)
    lo = measure_noise(img, floor.astype(bool))
    hi = measure_noise(img, paper.astype(bool))
    assert np.all(lo.level < hi.level)
    mid = noise_at(0.5 * (lo.level + hi.level)[None, :], [lo, hi])
    assert np.allclose(mid, 0.5 * (lo.sigma + hi.sigma))


def test_camera_effects_blur_and_noise_layers():
    # blur_layers: a Gaussian of the given sigma, zero outside (the layer's content ends at the array);
    # add_noise: noise of the measured sigma only where the object covers
    from arshadow.estimate.optics import NoiseEstimate
    from arshadow.frame.effects import add_noise, blur_layers

    a = np.zeros((41, 41), np.float32)
    a[20, 20] = 1.0
    (b,) = blur_layers(1.5, a)
    yy, xx = np.mgrid[-20:21, -20:21]
    g = np.exp(-(xx**2 + yy**2) / (2 * 1.5**2))
    assert np.abs(b - g / g.sum()).max() < 2e-3
    region = np.full((200, 200, 3), 128, np.uint8)
    alpha = np.zeros((200, 200), np.float32)
    alpha[:, 100:] = 1.0
    add_noise(region, alpha, (NoiseEstimate(np.full(3, 4.0 / 255), np.full(3, 0.5), 100),), seed=1)
    assert np.all(region[:, :100] == 128)
    assert abs(region[:, 100:].astype(float).std() - 4.0) < 0.3


def test_noise_window_is_standard_normal_per_frame_and_falls_back_beyond_the_field():
    """The object's noise is a window of one standard normal field at an offset drawn from the frame's seed:
    each window's values have mean 0 and deviation 1 and no correlation between neighbours; frames (seeds)
    get different windows; a region larger than the field gets fresh draws of the same law."""
    from arshadow.frame.effects import NOISE_FIELD_PX, noise_window

    windows = [noise_window((200, 300, 3), seed) for seed in range(8)]
    for n in windows:
        assert abs(float(n.mean())) < 0.01 and abs(float(n.std()) - 1.0) < 0.01
        assert abs(float(np.corrcoef(n[:, :-1].ravel(), n[:, 1:].ravel())[0, 1])) < 0.01
    assert len({n.tobytes() for n in windows}) == len(windows)
    big = noise_window((NOISE_FIELD_PX + 1, 8, 3), 3)
    assert big.shape == (NOISE_FIELD_PX + 1, 8, 3) and abs(float(big.std()) - 1.0) < 0.02
