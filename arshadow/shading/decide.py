"""When sky occlusion is worth drawing: the planner's ``ambient_occlusion`` decision, and the ground bounce
measured from the photo (GL-free)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..compose.composite import srgb_to_linear

if TYPE_CHECKING:
    from ..scene.options import RenderOptions

__all__ = ["MIN_SKY_SHARE", "decide_ambient_occlusion", "ground_bounce", "sky_share"]

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


def ground_bounce(image: np.ndarray, pixels: np.ndarray, gain: npt.ArrayLike) -> np.ndarray | None:
    """``(3,) float64``: the light the ground round the object reflects (linear RGB, in the renderer's units:
    the open ground's irradiance is the paper's, a white object is as bright as the paper): the ground's
    linear colour round the object (``pixels (k, 2)`` in the photo: a ring of ground points round the
    footprint) over the total exposure gain ``gain (3,)`` (paper linear RGB / the paper's irradiance in
    renderer units) is the ground's albedo relative to the paper's times its irradiance; times
    :data:`PAPER_ALBEDO` it is the ground's albedo times its irradiance, the light it sends onto a surface
    that sees it. The 75th percentile per channel (the part of the ring in the object's own shadow is not
    what lights it). None when no ring point lies in the photo.

    >>> img = np.full((4, 4, 3), 188, np.uint8)  # a ground half as bright as the paper (sRGB 188 ~ 0.5)
    >>> b = ground_bounce(img, np.array([[1.0, 1.0], [2.0, 2.0]]), gain=(1.0, 1.0, 1.0))
    >>> [round(float(v), 3) for v in b]  # 0.8 x 0.503
    [0.402, 0.402, 0.402]
    """
    img = np.asarray(image)
    h, w = img.shape[:2]
    px = np.round(np.asarray(pixels, np.float64)).astype(np.int64)
    ok = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
    if not ok.any():
        return None
    bgr = img[px[ok, 1], px[ok, 0]].astype(np.float64) / 255.0
    lin = np.percentile(srgb_to_linear(bgr), 75, axis=0)[::-1]  # RGB
    out: np.ndarray = PAPER_ALBEDO * lin / np.maximum(np.asarray(gain, np.float64).reshape(3), 1e-6)
    return out
