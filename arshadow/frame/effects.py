"""Camera effects on the inserted layers: the photo's blur and sensor noise, measured on the photo.

:func:`measure_camera` measures them once (:mod:`arshadow.estimate.optics`: the point-spread width on the
marker's outer edges, the noise on the marker's paper margin and on the floor round it);
:func:`blur_layers` blurs the rendered layers (shadow mask, sky occlusion, object coverage and its
premultiplied colour) by that Gaussian before they are composited, as the lens blurred the real scene;
:func:`add_noise` adds noise matched to the photo's at each pixel's level where the object covers it (the
ground's own noise is the photo's: it is darkened, not replaced).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..compose.composite import clip_roi
from ..errors import EstimateError
from ..estimate.optics import NoiseEstimate, measure_blur, measure_noise, noise_at

if TYPE_CHECKING:
    from .motion import MotionBlur

__all__ = [
    "NOISE_FIELD_PX",
    "CameraEffects",
    "add_noise",
    "blur_kernel",
    "blur_layers",
    "measure_camera",
    "noise_table",
    "noise_window",
    "pad_for",
    "touched_roi",
]

#: the side of the standard normal field (made once per process) whose windows are the object's noise: a
#: window at an offset drawn from the frame's seed costs a slice, fresh draws ~1.4 ms a 200 x 300 region
#: (numpy's generator), a seventh of a 720p video frame's compositing
NOISE_FIELD_PX = 1024


@dataclasses.dataclass(frozen=True, eq=False)
class CameraEffects:
    """The photo's measured optics: ``blur_px`` (Gaussian sigma, pixels; 0: none) and the noise
    estimates (paper, floor; code values 0..1) the object's noise is interpolated from."""

    blur_px: float
    noise: tuple[NoiseEstimate, ...] = ()

    @functools.cached_property
    def noise_table(self) -> np.ndarray | None:
        """:func:`noise_table` of the measured noise (made once per scene, not per frame); None without it."""
        return noise_table(self.noise) if self.noise else None

    @functools.cached_property
    def blur_kernel(self) -> np.ndarray | None:
        """:func:`blur_kernel` of the measured blur (the shader path's); None without blur."""
        return blur_kernel(self.blur_px)

    @property
    def pad(self) -> int:
        """Pixels the blur reaches beyond the layers' content (:func:`pad_for`)."""
        return pad_for(self.blur_px)

    @staticmethod
    def noise_seed(image: np.ndarray) -> int:
        """The noise's seed for the photo ``image (H, W, 3) uint8``: the sum of a sparse grid of its values
        (reproducible per photo, different between photos and video frames)."""
        return int(np.asarray(image[::61, ::53], np.int64).sum())

    def report(self) -> dict[str, object]:
        """The measured values for the report (noise sigma in 8-bit units, per channel B, G, R)."""
        return {
            "blur_sigma_px": round(float(self.blur_px), 3),
            "noise": [
                {
                    "level": [round(float(v) * 255, 1) for v in n.level],
                    "sigma": [round(float(v) * 255, 2) for v in n.sigma],
                }
                for n in self.noise
            ],
        }


def _ring(shape: Sequence[int], corners: np.ndarray, inner: float, outer: float) -> np.ndarray:
    """``shape`` (h, w[, c]) -> ``(h, w) bool``: between the marker quad scaled by ``inner`` and by ``outer`` about its centre."""
    c = corners.mean(axis=0)
    m = np.zeros(shape[:2], np.uint8)
    cv2.fillConvexPoly(m, np.round(c + outer * (corners - c)).astype(np.int32), 1)
    cv2.fillConvexPoly(m, np.round(c + inner * (corners - c)).astype(np.int32), 0)
    return m.astype(bool)


def measure_camera(image: np.ndarray, corners: np.ndarray, cells: int = 6) -> CameraEffects:
    """Blur on the marker's outer edges, noise on its paper margin (1.1-1.25 x the marker about its centre:
    inside the usual print margin) and on the floor (1.8-2.4 x). ``corners (4, 2)`` px, the marker's."""
    corners = np.asarray(corners, np.float64).reshape(4, 2)
    try:
        blur = measure_blur(image, corners, cells=cells).sigma_px
    except EstimateError:
        blur = 0.0
    noise: list[NoiseEstimate] = []
    for inner, outer in ((1.1, 1.25), (1.8, 2.4)):
        try:
            noise.append(measure_noise(image, _ring(image.shape, corners, inner, outer)))
        except EstimateError:
            pass
    return CameraEffects(float(blur), tuple(noise))


def blur_layers(sigma: float, *layers: np.ndarray | None) -> list[np.ndarray | None]:
    """Each ``(h, w[, c]) float32`` layer blurred by a Gaussian of ``sigma`` px (border: 0, nothing drawn
    beyond the arrays); returned as new arrays (None passes through)."""
    out: list[np.ndarray | None] = []
    for a in layers:
        if a is None or sigma <= 0:
            out.append(a)
            continue
        out.append(
            cv2.GaussianBlur(np.ascontiguousarray(a, np.float32), (0, 0), float(sigma), borderType=cv2.BORDER_CONSTANT)
        )
    return out


def noise_table(noise: Sequence[NoiseEstimate], channels: int = 3) -> np.ndarray:
    """``(1, 256, channels) float32``: the noise sigma per channel (8-bit units) at each code value,
    :func:`arshadow.estimate.optics.noise_at` (a table looked up per pixel: no interpolation per pixel)."""
    levels = np.repeat(np.arange(256, dtype=np.float64)[:, None] / 255.0, channels, axis=1)
    return (noise_at(levels, list(noise)) * 255.0).astype(np.float32).reshape(1, 256, channels)


def add_noise(region: np.ndarray, alpha: np.ndarray, noise: Sequence[NoiseEstimate] | np.ndarray, seed: int) -> None:
    """Add Gaussian noise to ``region (h, w, 3) uint8`` (BGR, in place) where the object covers it
    (``alpha (h, w)``), its sigma per channel :func:`arshadow.estimate.optics.noise_at` the pixel's level;
    ``noise``: the estimates, or their :func:`noise_table` (:attr:`CameraEffects.noise_table`)."""
    if len(noise) == 0:
        return
    rows, cols = np.nonzero(np.asarray(alpha).any(axis=1))[0], np.nonzero(np.asarray(alpha).any(axis=0))[0]
    if rows.size == 0:
        return
    sub = (slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1))
    region, alpha = region[sub], np.asarray(alpha)[sub]  # only where the object is (views: in place)
    table = noise if isinstance(noise, np.ndarray) else noise_table(noise, region.shape[2])
    sig = cv2.LUT(np.ascontiguousarray(region), table)
    n = noise_window(region.shape, seed)
    n *= sig
    n *= np.asarray(alpha, np.float32)[:, :, None]
    n += region
    np.clip(np.round(n, out=n), 0, 255, out=n)
    region[...] = n.astype(np.uint8)


@functools.lru_cache(maxsize=1)
def _noise_field(side: int, channels: int) -> np.ndarray:
    """``(side, side, channels) float32`` standard normal values (a fixed seed), read-only."""
    field = np.random.default_rng(20261129).standard_normal((side, side, channels), dtype=np.float32)
    field.setflags(write=False)
    return field


def noise_window(shape: Sequence[int], seed: int) -> np.ndarray:
    """``(h, w, c) float32`` standard normal noise for a region of ``shape``: a new array holding the window
    of the process's noise field (:data:`NOISE_FIELD_PX` square) at an offset drawn from ``seed`` (each
    value N(0, 1), independent of its neighbours; two frames' windows at independent offsets), or fresh draws
    from ``seed`` when the region is larger than the field.

    >>> a, b = noise_window((4, 5, 3), 7), noise_window((4, 5, 3), 7)
    >>> a.shape, a.dtype.name, bool(np.array_equal(a, b)), bool(np.array_equal(a, noise_window((4, 5, 3), 8)))
    ((4, 5, 3), 'float32', True, False)
    """
    h, w, c = (int(v) for v in shape)
    rng = np.random.default_rng(seed)
    if h > NOISE_FIELD_PX or w > NOISE_FIELD_PX:
        return rng.standard_normal((h, w, c), dtype=np.float32)
    y, x = (int(v) for v in rng.integers(0, [NOISE_FIELD_PX - h + 1, NOISE_FIELD_PX - w + 1]))
    return np.array(_noise_field(NOISE_FIELD_PX, c)[y : y + h, x : x + w])


def blur_kernel(sigma: float) -> np.ndarray | None:
    """``(k,) float32``: the Gaussian :func:`blur_layers` applies (``cv2.GaussianBlur`` of ``float32`` layers
    with ``ksize`` (0, 0): ``k = round(8 sigma + 1) | 1``, :func:`cv2.getGaussianKernel`); None for
    ``sigma <= 0``.

    >>> k = blur_kernel(1.5)
    >>> k.size, round(float(k.sum()), 6), bool(k[6] == k.max())
    (13, 1.0, True)
    """
    if sigma <= 0:
        return None
    k = int(round(float(sigma) * 8.0 + 1.0)) | 1
    kernel: np.ndarray = cv2.getGaussianKernel(k, float(sigma), cv2.CV_32F).ravel()
    return kernel


def pad_for(sigma: float) -> int:
    """Pixels the blur reaches beyond a layer's content (3 sigma, rounded up)."""
    return int(math.ceil(3.0 * sigma)) if sigma > 0 else 0


def touched_roi(
    roi: Sequence[float], camera: CameraEffects | None, motion: MotionBlur | None, width: int, height: int
) -> tuple[int, int, int, int]:
    """``roi = (x0, y0, w, h)`` grown by the reach of the blurs the layers go through (the photo's blur,
    :attr:`CameraEffects.pad`, and a video frame's motion, :attr:`arshadow.frame.motion.MotionBlur.reach`),
    within the ``width x height`` frame: the pixels a composite may write.

    >>> touched_roi((10, 10, 20, 20), None, None, 64, 48), touched_roi((2, 10, 20, 20), CameraEffects(1.0), None, 64, 48)
    ((10, 10, 20, 20), (0, 7, 25, 26))
    >>> touched_roi((0, 0, 0, 0), CameraEffects(1.0), None, 64, 48)  # an empty ROI: nothing to write
    (0, 0, 0, 0)
    """
    x0, y0, w, h = (int(v) for v in roi)
    if w <= 0 or h <= 0:  # nothing drawn: nothing written
        return clip_roi((x0, y0, w, h), width, height)
    p = (0 if camera is None else camera.pad) + (0 if motion is None else motion.reach)
    return clip_roi((x0 - p, y0 - p, w + 2 * p, h + 2 * p), width, height)
