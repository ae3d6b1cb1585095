"""When sky occlusion is worth drawing: the planner's ``ambient_occlusion`` decision, and the ground bounce
measured from the photo (GL-free)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..compose.composite import srgb_to_linear

if TYPE_CHECKING:
    from ..scene.options import RenderOptions

__all__ = [
    "MIN_SKY_SHARE",
    "GroundLight",
    "decide_ambient_occlusion",
    "ground_bounce",
    "ground_light",
    "ground_units",
    "sky_share",
]

#: below this mean sky share (of the ground's light) the contact shadow changes a pixel by less than
#: ~1 % (the sky visibility under an object is >= 0 and the share scales it): skipped by ``auto``
MIN_SKY_SHARE = 0.03


def sky_share(opacity: float, shadow_color: npt.ArrayLike) -> np.ndarray:
    """``(3,) float64``: the share of the ground's light a full shadow keeps, ``1 - opacity * (1 - tint)``:
    the sky's share of the light for a measured light (opacity 1, tint = the measured shadow ratio).

    >>> sky_share(1.0, (0.4, 0.5, 0.6)).tolist()
    [0.4, 0.5, 0.6]
    """
    return 1.0 - float(opacity) * (1.0 - np.asarray(shadow_color, np.float64).reshape(3))


def decide_ambient_occlusion(options: RenderOptions) -> tuple[bool, str]:
    """``(on, reason)`` for :class:`arshadow.scene.options.RenderOptions` ``options``.

    >>> from arshadow.scene.options import RenderOptions
    >>> decide_ambient_occlusion(RenderOptions())[0], decide_ambient_occlusion(RenderOptions(ambient_occlusion="on"))[0]
    (False, True)
    """
    mode = options.ambient_occlusion
    if mode == "off":
        return False, "off (--ambient-occlusion off)"
    if options.shadow_method == "shadowmap":
        return False, "off: the shadow-map baseline has no sky occlusion"
    if not options.draw_occluder and mode != "on":
        return False, "off: no object drawn"
    if mode == "on":
        return True, "on (--ambient-occlusion on)"
    if not options.ambient_measured:
        return False, "off: no measured sky share (--light-from / --probe turn it on)"
    share = float(np.mean(sky_share(options.opacity, options.shadow_color)))
    if share < MIN_SKY_SHARE:
        return False, f"off: the measured sky share {share:.3f} is negligible (< {MIN_SKY_SHARE})"
    return True, f"on: measured sky share {share:.2f}"


#: the marker paper's reflectance, the white the object's colour is relative to (printer paper: 0.8-0.9)
PAPER_ALBEDO = 0.8


def ground_bounce(
    image: np.ndarray, pixels: np.ndarray, gain: npt.ArrayLike, paper_albedo: float = PAPER_ALBEDO
) -> np.ndarray | None:
    """``(3,) float64``: the light the ground round the object reflects (linear RGB, in the renderer's units:
    the open ground's irradiance is the paper's, a white object is as bright as the paper): the ground's
    linear colour round the object (``pixels (k, 2)`` in the photo: a ring of ground points round the
    footprint) over the total exposure gain ``gain (3,)`` (paper linear RGB / the paper's irradiance in
    renderer units) is the ground's albedo relative to the paper's times its irradiance; times
    the paper's reflectance ``paper_albedo`` (:data:`PAPER_ALBEDO` by default) it is the ground's albedo times
    its irradiance, the light it sends onto a surface that sees it. The 75th percentile per channel (the part
    of the ring in the object's own shadow is not what lights it). None when no ring point lies in the photo.

    >>> img = np.full((4, 4, 3), 188, np.uint8)  # a ground half as bright as the paper (sRGB 188 ~ 0.5)
    >>> b = ground_bounce(img, np.array([[1.0, 1.0], [2.0, 2.0]]), gain=(1.0, 1.0, 1.0))
    >>> [round(float(v), 3) for v in b]  # 0.8 x 0.503
    [0.402, 0.402, 0.402]
    """
    light, ok = _reflected(image, pixels, gain, paper_albedo)
    if not ok.any():
        return None
    out: np.ndarray = np.percentile(light, 75, axis=0)
    return out


def _reflected(
    image: np.ndarray, pixels: np.ndarray, gain: npt.ArrayLike, paper_albedo: float = PAPER_ALBEDO
) -> tuple[np.ndarray, np.ndarray]:
    """The light the ground reflects at ``pixels (k, 2)`` of the photo ``image (H, W, 3) uint8`` BGR (nearest
    pixel), in the renderer's units (:func:`ground_bounce`): ``(light (n, 3) float64 linear RGB, in the photo
    (k,) bool)``, one row per pixel in the photo."""
    img = np.asarray(image)
    h, w = img.shape[:2]
    px = np.asarray(pixels, np.float64)
    px = np.round(np.where(np.isfinite(px), px, -1.0)).astype(np.int64)
    ok = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
    lin = srgb_to_linear(img[px[ok, 1], px[ok, 0]].astype(np.float64) / 255.0)[:, ::-1]  # RGB
    light: np.ndarray = float(paper_albedo) * lin / np.maximum(np.asarray(gain, np.float64).reshape(3), 1e-6)
    return light, ok


@dataclasses.dataclass(frozen=True, eq=False)
class GroundLight:
    """The light the ground reflects, read from the photo on a texel grid round the object (ground frame):
    ``values[i, j]`` (``(h, w) float32``, NaN where the photo does not show it) at the ground point
    ``(x0 + (j + 0.5) texel, y0 + (i + 0.5) texel)``, in :func:`ground_bounce`'s units (the ground's albedo
    times its irradiance, the paper's white being :data:`PAPER_ALBEDO`; the channels' mean). The object's
    lower faces see the ground round them, the marker's white paper included: one ring's value
    (:func:`ground_bounce`) misses a paper beside the object, three to four times brighter than a floor.

    >>> g = GroundLight(0.0, 0.0, 1.0, np.array([[0.2, np.nan]], np.float32))
    >>> g(np.array([[0.5, 0.5], [1.5, 0.5], [5.0, 0.5]])).tolist()
    [0.20000000298023224, nan, nan]
    """

    x0: float
    y0: float
    texel: float
    values: np.ndarray

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        """``(k,) float64`` at ground points ``xy (k, 2)`` (the nearest texel; NaN off the grid or the photo)."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        h, w = self.values.shape
        j = np.floor((xy[:, 0] - self.x0) / self.texel).astype(np.int64)
        i = np.floor((xy[:, 1] - self.y0) / self.texel).astype(np.int64)
        ok = (i >= 0) & (i < h) & (j >= 0) & (j < w)
        out = np.full(len(xy), np.nan)
        out[ok] = self.values[i[ok], j[ok]]
        return out


def ground_light(
    image: np.ndarray,
    project: Callable[[np.ndarray], np.ndarray],
    gain: npt.ArrayLike,
    grid: tuple[float, float, float],
    res: int = 64,
    paper_albedo: float = PAPER_ALBEDO,
) -> GroundLight:
    """:class:`GroundLight` of the photo ``image (H, W, 3) uint8`` BGR over ``res x res`` texels of the ground
    square ``grid = (x0, y0, side)`` (metres, ground frame: its corner and side); ``project`` maps ground
    points ``(k, 3)`` to pixels ``(k, 2)`` (the camera and its lens); ``gain (3,)`` and ``paper_albedo`` as in
    :func:`ground_bounce` (the field is read relative to the ring's value: both in the same units). Each texel reads the pixel at its centre (nearest): the plate holds no object, so
    it is the open ground's light (a real object in the photo reads as its own colour)."""
    x0, y0, side = (float(v) for v in grid)
    texel = side / res
    c = (np.arange(res) + 0.5) * texel
    xx, yy = np.meshgrid(x0 + c, y0 + c)
    pts = np.c_[xx.ravel(), yy.ravel(), np.zeros(xx.size)]
    light, ok = _reflected(image, np.asarray(project(pts), np.float64), gain, paper_albedo)
    vals = np.full(len(pts), np.nan, np.float32)
    vals[ok] = light.mean(axis=1)
    return GroundLight(x0, y0, texel, vals.reshape(res, res))


def ground_units(light_h: np.ndarray, r: float, ref: np.ndarray, ambient: float) -> float:
    """The ground's measured light (:func:`arshadow.shading.decide.ground_bounce`, in the renderer's units: the
    paper's irradiance under the estimated light is ``ambient + sin(elevation)``, the shading gain's unit)
    over the ground occlusion map's unit, the open ground's light at ``ref (3,)`` where the sky share ``r``
    holds: ``(E_paper / E_ref) / (ambient + sin(elevation))``. A sun's light is the same on the paper and at
    ``ref``; a point lamp's (``light_h (4,)``, world) falls off as ``z / d^3``, and the paper (at the
    origin, the marker) is often nearer to it than the object.

    >>> round(ground_units(np.array([0.0, 0.0, 1.0, 0.0]), 0.4, np.zeros(3), 0.0), 6)  # a sun overhead
    1.0
    >>> round(ground_units(np.array([0.0, 0.0, 1.0, 1.0]), 0.0, np.array([1.0, 0.0, 0.0]), 0.0), 4)  # 2^1.5
    2.8284
    """
    h = np.asarray(light_h, np.float64)
    if h[3] == 0:
        sin_e, k = float(h[2] / np.linalg.norm(h[:3])), 1.0
    else:
        p = h[:3] / h[3]
        sin_e = float(p[2] / np.linalg.norm(p))
        k = float(np.linalg.norm(p - np.asarray(ref, np.float64)) / np.linalg.norm(p)) ** 3
    return (r + (1.0 - r) * k) / max(float(ambient) + max(sin_e, 0.0), 1e-6)
