"""The photo's own optics, measured from the photo: blur (point-spread width) and sensor noise.

An inserted object rendered sharp and noise-free gives itself away next to a photo that is neither. Both
are measured on things every arshadow photo has:

- **Blur** (:func:`measure_blur`): the marker's outer edges are straight black-to-white steps. Every pixel
  within a few pixels of an edge is a sample of the edge-spread function at its signed distance from the
  edge line; a Gaussian-blurred step ``a + b * Phi((s - s0) / sigma_eff)`` is fitted per edge in linear
  light (the optics blur light, before the camera's tone curve). A pixel integrates over its own area,
  which adds 1/12 px^2 of variance across any edge whatever its angle, so the point-spread width reported
  is ``sigma = sqrt(sigma_eff^2 - 1/12)``: the Gaussian blur (pixels) to apply to an area-sampled render to
  match the photo. The median over the four edges is kept (one edge crossing a shadow or a glare is
  outvoted).
- **Noise** (:func:`measure_noise`): Immerkaer's estimator, robust form: the 3 x 3 kernel
  ``[[1, -2, 1], [-2, 4, -2], [1, -2, 1]]`` cancels any locally linear signal and multiplies white noise's
  standard deviation by 6; the median absolute response (x 1.4826 / 6) over a region is its noise sigma
  per channel, in the image's own code values (noise is added after the tone curve). Measured on the
  marker's paper and on the floor round it, it gives two points of a signal-dependent sigma.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.special import erf

from ..compose.composite import srgb_to_linear
from ..errors import EstimateError, ShapeError

__all__ = ["BlurEstimate", "NoiseEstimate", "measure_blur", "measure_noise", "noise_at"]

#: variance (px^2) a pixel's area adds across an edge of any direction (two uniform widths projected)
PIXEL_VARIANCE = 1.0 / 12.0
_IMMERKAER = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)


@dataclasses.dataclass(frozen=True)
class BlurEstimate:
    """Point-spread width measured on the marker's edges.

    ``sigma_px``: the Gaussian sigma (pixels) beyond a pixel's own area (median of the edges);
    ``per_edge``: each edge's (4,) value (NaN where the fit failed); ``rms``: each fit's residual (linear
    light, the edge's contrast = 1)."""

    sigma_px: float
    per_edge: tuple[float, ...]
    rms: tuple[float, ...]


@dataclasses.dataclass(frozen=True)
class NoiseEstimate:
    """Noise of a region: ``sigma (c,)`` per channel and ``level (c,)`` the region's median value, both in
    the image's code values scaled to 0..1 (8-bit: /255); ``n_pixels`` used."""

    sigma: np.ndarray
    level: np.ndarray
    n_pixels: int


def _linear_grey(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    scale = 65535.0 if img.dtype == np.uint16 else 255.0 if img.dtype.kind in "ui" else 1.0
    x = img.astype(np.float64) / scale
    if x.ndim == 3:
        x = srgb_to_linear(x) @ np.array([0.0722, 0.7152, 0.2126])[: x.shape[2]] if x.shape[2] == 3 else x[..., 0]
        return x
    return srgb_to_linear(x)


def _fit_edge(s: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Fit ``a + b Phi((s - s0) / sig)`` to samples; returns (sig, rms / |b|)."""
    a0, b0 = float(np.percentile(y, 5)), float(np.percentile(y, 95) - np.percentile(y, 5))
    if b0 <= 1e-6:
        return math.nan, math.nan

    def model(p: np.ndarray) -> np.ndarray:
        out: np.ndarray = p[0] + p[1] * 0.5 * (1.0 + erf((s - p[2]) / (math.sqrt(2.0) * abs(p[3]) + 1e-12)))
        return out

    r = least_squares(lambda p: model(p) - y, [a0, b0, 0.0, 1.0], loss="soft_l1", f_scale=0.05 * b0)
    a, b, s0, sig = r.x
    rms = float(np.sqrt(np.mean((model(r.x) - y) ** 2)) / max(abs(b), 1e-12))
    return abs(float(sig)), rms


def measure_blur(image: np.ndarray, corners: np.ndarray, *, cells: int = 6, half_width_px: float = 8.0) -> BlurEstimate:
    """Point-spread width (Gaussian sigma, pixels) from the outer edges of one detected marker.

    Parameters
    ----------
    image : (h, w) or (h, w, 3) uint8 / uint16 / float in 0..1
        The photo, sRGB-encoded (BGR order for colour, as OpenCV reads it).
    corners : (4, 2) float
        The marker's outer corners in pixels, in order round the square (OpenCV's detection order).
    cells : int
        The marker's width in cells including its black border (a 4x4 dictionary: 6); the sampled band
        stays within 0.8 cell of the edge, inside the black border and the white margin.
    half_width_px : float
        The band's half-width at most (pixels).

    Raises
    ------
    EstimateError
        No edge gave a fit (marker too small, no contrast).
    """
    c = np.asarray(corners, np.float64).reshape(-1, 2)
    if c.shape != (4, 2):
        raise ShapeError("marker corners must be (4, 2)", actual_shape=c.shape, expected_shape="(4, 2)")
    # only the marker's neighbourhood is read: decode that crop (a whole 720p frame took 0.19 s), its
    # origin (x0, y0) in the photo
    img = np.asarray(image)
    h, w = img.shape[:2]
    reach = half_width_px + 2.0  # beyond every band below (band + 1 px)
    x0, y0 = np.maximum(np.floor(c.min(axis=0) - reach).astype(int), 0)
    x1, y1 = np.minimum(np.ceil(c.max(axis=0) + reach).astype(int) + 1, [w, h])
    lin = _linear_grey(img[y0:y1, x0:x1])
    centre = c.mean(axis=0)
    sig, rms = [], []
    for k in range(4):
        p, q = c[k], c[(k + 1) % 4]
        length = float(np.linalg.norm(q - p))
        t = (q - p) / max(length, 1e-12)
        n = np.array([t[1], -t[0]])
        if np.dot(centre - p, n) > 0:  # n points out of the marker (towards the white paper)
            n = -n
        band = min(half_width_px, 0.8 * length / cells)
        if length < 8 or band < 2:
            sig.append(math.nan)
            rms.append(math.nan)
            continue
        lo = np.floor(np.minimum(p, q) - band - 1).astype(int)
        hi = np.ceil(np.maximum(p, q) + band + 1).astype(int)
        lo, hi = np.maximum(lo, 0), np.minimum(hi, [w - 1, h - 1])
        xs, ys = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
        d = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float64) - p
        along = d @ t
        across = d @ n
        keep = (np.abs(across) <= band) & (along > 0.15 * length) & (along < 0.85 * length)
        if keep.sum() < 20:
            sig.append(math.nan)
            rms.append(math.nan)
            continue
        s_eff, r = _fit_edge(across[keep], lin[ys.ravel()[keep] - y0, xs.ravel()[keep] - x0])
        sig.append(math.sqrt(max(s_eff**2 - PIXEL_VARIANCE, 0.0)) if math.isfinite(s_eff) else math.nan)
        rms.append(r)
    good = [s for s in sig if math.isfinite(s)]
    if not good:
        raise EstimateError("no marker edge gave a blur measurement (marker too small or without contrast)")
    return BlurEstimate(float(np.median(good)), tuple(sig), tuple(rms))


def measure_noise(image: np.ndarray, mask: np.ndarray | None = None) -> NoiseEstimate:
    """Sensor noise sigma per channel over ``mask (h, w) bool`` (default: the whole image), robust to
    edges and smooth shading (Immerkaer's kernel, median absolute response).

    Values are the image's code values scaled to 0..1 (uint8 / 255); multiply by 255 for 8-bit units.
    Texture finer than 3 pixels counts as noise: measure on plain regions (paper, a plain floor).

    >>> rng = np.random.default_rng(0)
    >>> img = np.clip(np.full((200, 200, 3), 128.0) + rng.normal(0, 4, (200, 200, 3)), 0, 255).astype(np.uint8)
    >>> round(float(measure_noise(img).sigma[0] * 255), 1)
    4.0
    """
    img = np.asarray(image)
    scale = 65535.0 if img.dtype == np.uint16 else 255.0 if img.dtype.kind in "ui" else 1.0
    x = img.astype(np.float32) / np.float32(scale)
    if x.ndim == 2:
        x = x[..., None]
    m = np.ones(x.shape[:2], bool) if mask is None else np.asarray(mask, bool)
    if m.shape != x.shape[:2]:
        raise ShapeError("noise mask must match the image", actual_shape=m.shape, expected_shape=str(x.shape[:2]))
    # the kernel's 3 x 3 support must lie inside the region
    inner = cv2.erode(m.astype(np.uint8), np.ones((3, 3), np.uint8), borderValue=0).astype(bool)
    n = int(inner.sum())
    if n < 50:
        raise EstimateError(f"noise region too small ({n} pixels inside it)")
    sig, lev = [], []
    for ch in range(x.shape[2]):
        resp = cv2.filter2D(x[..., ch], cv2.CV_32F, _IMMERKAER, borderType=cv2.BORDER_REFLECT)
        sig.append(1.4826 * float(np.median(np.abs(resp[inner]))) / 6.0)
        lev.append(float(np.median(x[..., ch][inner])))
    return NoiseEstimate(np.array(sig), np.array(lev), n)


def noise_at(level: np.ndarray, estimates: list[NoiseEstimate]) -> np.ndarray:
    """Noise sigma per channel at code values ``level (..., c)`` (0..1): linear in the level through the
    measured regions' (level, sigma) points (one point: constant), clamped to their range.

    >>> a = NoiseEstimate(np.array([0.01]), np.array([0.2]), 100)
    >>> b = NoiseEstimate(np.array([0.03]), np.array([0.8]), 100)
    >>> noise_at(np.array([[0.5]]), [a, b]).round(4).tolist()
    [[0.02]]
    """
    lv = np.asarray(level, np.float64)
    pts = sorted(estimates, key=lambda e: float(np.mean(e.level)))
    out = np.empty_like(lv)
    for ch in range(lv.shape[-1]):
        xs = np.array([e.level[min(ch, len(e.level) - 1)] for e in pts])
        ys = np.array([e.sigma[min(ch, len(e.sigma) - 1)] for e in pts])
        order = np.argsort(xs)
        out[..., ch] = np.interp(lv[..., ch], xs[order], ys[order])
    return out
