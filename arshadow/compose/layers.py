"""Compositing layers: the object with alpha and the shadow, apart, so that a compositor rebuilds the frame.

The composite (:func:`arshadow.compose.composite.composite`) is, for every pixel, in **linear light**
(sRGB primaries; the photo decoded from 8-bit sRGB by the exact 256-entry table)::

    shadow  = max(0, (1 - alpha) - opacity * mask * (1 - shadow_color))     # the multiply pass
    object  = (alpha * R, alpha * G, alpha * B, alpha)                       # premultiplied RGBA
    result  = plate * shadow + object.rgb                                    # then encoded to sRGB

``plate`` is the input photo (linear), ``mask`` the renderer's coverage-weighted blocked-light fraction
after the lens warp, ``alpha`` the object's coverage. :class:`Layers` holds exactly these two arrays, so
``plate x shadow + object`` reproduces the composite (within one 8-bit level: the composite's own 16-bit
encoding table; tests/test_layers.py checks every pixel, distorted lens included).

The **shadow-only** layer is black with alpha ``a_s``, meant to go *over* the plate, with the object over
that (the usual "plate, shadow, beauty" stack)::

    result  = object.rgb + (1 - alpha) * (plate * (1 - a_s) + 0 * a_s)
    a_s     = 1 - shadow / (1 - alpha)        where alpha < 1 (0 where alpha = 1)

which equals the multiply-pass formula for any grey ``--shadow-color`` (black included). With a coloured
shadow tint the multiply pass has three channels and is the exact one; the shadow-only alpha then uses
their mean (an approximation, said in docs/export.md).

Arrays live only over the frame's region of interest (``roi``); outside it the shadow is 1 and the object
empty. :meth:`Layers.full` gives photo-sized arrays.

Examples
--------
>>> import numpy as np
>>> mask = np.array([[1.0, 0.0]], np.float32)
>>> lay = layers_from_warped(mask, None, (0, 0, 2, 1), (1, 2), opacity=0.5)
>>> lay.shadow.tolist()
[[0.5, 1.0]]
>>> shadow_only_alpha(lay.shadow, lay.object[..., 3]).tolist()
[[0.5, 0.0]]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ShapeError
from .composite import SRGB_TO_LINEAR, linear_to_srgb8

__all__ = ["Layers", "layers_from_warped", "pinhole_layers", "recombine", "shadow_factor", "shadow_only_alpha"]


def shadow_factor(
    mask: np.ndarray | None, alpha: np.ndarray | None, opacity: float, shadow_color: npt.ArrayLike = (0.0, 0.0, 0.0)
) -> np.ndarray:
    """The multiply pass: the per-pixel linear factor the composite applies to the photo.

    Parameters
    ----------
    mask : (h, w) float32 in [0, 1] or None
        Blocked light fraction (coverage-weighted, after the lens warp).
    alpha : (h, w) float32 in [0, 1] or None
        Object coverage (None: no object drawn).
    opacity : float
    shadow_color : (3,) linear RGB
        The shadow tint.

    Returns
    -------
    (h, w) float32, or (h, w, 3) float32 **RGB** when the tint is not grey
        ``max(0, (1 - alpha) - opacity * mask * (1 - shadow_color))``, the composite's float32 arithmetic.
    """
    sc = np.asarray(shadow_color, np.float64).ravel()
    ref = mask if mask is not None else alpha
    if ref is None:
        raise ShapeError("shadow_factor needs a mask or an alpha")
    shape = np.shape(ref)
    keep = np.ones(shape, np.float32) if alpha is None else np.float32(1.0) - np.asarray(alpha, np.float32)
    if mask is None or opacity <= 0.0:
        return keep
    m = np.asarray(mask, np.float32)
    if sc[0] == sc[1] == sc[2]:
        g: np.ndarray = m * np.float32(-opacity * (1.0 - sc[0]))
        g += keep
        res: np.ndarray = np.maximum(g, np.float32(0.0))
        return res
    dark = (np.float32(opacity) * (1.0 - sc)).astype(np.float32)  # RGB
    f: np.ndarray = m[:, :, None] * -dark
    f += keep[:, :, None]
    res3: np.ndarray = np.maximum(f, np.float32(0.0))
    return res3


def shadow_only_alpha(shadow: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Alpha of the black shadow-only layer: ``1 - shadow / (1 - alpha)`` (0 where alpha = 1).

    ``shadow`` (h, w) or (h, w, 3) float32 (the mean of the channels is used), ``alpha`` (h, w) float32;
    returns (h, w) float32 in [0, 1].
    """
    s = np.asarray(shadow, np.float32)
    if s.ndim == 3:
        s = s.mean(axis=2, dtype=np.float32)
    keep = np.float32(1.0) - np.asarray(alpha, np.float32)
    out = np.zeros(s.shape, np.float32)
    ok = keep > np.float32(1e-6)
    out[ok] = np.float32(1.0) - s[ok] / keep[ok]
    return np.clip(out, np.float32(0.0), np.float32(1.0), out=out)


@dataclass
class Layers:
    """One frame's layers over its region of interest.

    Attributes
    ----------
    size : (W, H)
        The photo's size.
    roi : (x0, y0, w, h)
        Where the arrays sit in the photo (w or h may be 0: nothing drawn).
    object : (h, w, 4) float32
        The object, premultiplied RGBA, **linear** light, RGB order (sRGB primaries: the photo's colour
        space, decoded).
    shadow : (h, w) float32 or (h, w, 3) float32 RGB
        The multiply pass (1 = untouched); three channels only with a coloured shadow tint.
    undistorted : Layers or None
        The same layers in the ideal pinhole camera of the same K and size (no lens distortion), when
        asked for; :func:`arshadow.export.stmap.stmap` maps them onto the photo.
    """

    size: tuple
    roi: tuple
    object: np.ndarray
    shadow: np.ndarray
    undistorted: Layers | None = None

    def full(self) -> tuple[np.ndarray, np.ndarray]:
        """Photo-sized ``(object (H, W, 4) float32, shadow (H, W) or (H, W, 3) float32)``."""
        W, H = self.size
        x0, y0, w, h = self.roi
        obj = np.zeros((H, W, 4), np.float32)
        sh = np.ones((H, W) + self.shadow.shape[2:], np.float32)
        obj[y0 : y0 + h, x0 : x0 + w] = self.object
        sh[y0 : y0 + h, x0 : x0 + w] = self.shadow
        return obj, sh

    def shadow_only(self) -> np.ndarray:
        """Photo-sized ``(H, W, 4) float32`` RGBA: black with the shadow-only alpha."""
        obj, sh = self.full()
        out = np.zeros_like(obj)
        out[..., 3] = shadow_only_alpha(sh, obj[..., 3])
        return out


def layers_from_warped(
    mask: np.ndarray | None,
    rgba: np.ndarray | None,
    roi: Sequence[int],
    shape: Sequence[int],
    *,
    opacity: float,
    shadow_color: npt.ArrayLike = (0.0, 0.0, 0.0),
    premultiplied: bool = True,
) -> Layers:
    """The layers of a frame from the warped render the composite used (copies: the inputs may be scratch).

    Parameters
    ----------
    mask : (h, w) float32 or None
        Blocked light fraction over ``roi``.
    rgba : (h, w, 4) float32 or None
        The object's linear RGB (premultiplied unless ``premultiplied=False``) and coverage, RGB order;
        None when the object is not drawn.
    roi : (x0, y0, w, h)
    shape : (H, W)
        The photo's size.
    opacity, shadow_color
        As the composite.
    """
    x0, y0, w, h = (int(v) for v in roi)
    obj = np.zeros((h, w, 4), np.float32)
    alpha = None
    if rgba is not None:
        np.copyto(obj, rgba)
        if not premultiplied:
            obj[..., :3] *= obj[..., 3:4]
        alpha = obj[..., 3]
    if mask is None and alpha is None:
        sh = np.ones((h, w), np.float32)
    else:
        sh = shadow_factor(mask, alpha, opacity, shadow_color)
    return Layers(size=(int(shape[1]), int(shape[0])), roi=(x0, y0, w, h), object=obj, shadow=sh)


def pinhole_layers(
    mask: np.ndarray, rgba: np.ndarray | None, canvas: Sequence[int], shape: Sequence[int], **kw: Any
) -> Layers:
    """The layers of the rendered pinhole canvas (before the lens warp), clipped to the photo's size.

    ``mask`` (h, w), ``rgba`` (h, w, 4) or None: the canvas, rows top-down; ``canvas`` its
    ``(u0, v0, w, h)`` in the pinhole image; ``shape`` (H, W); ``kw`` as :func:`layers_from_warped`.
    """
    H, W = int(shape[0]), int(shape[1])
    u0, v0, w, h = (int(v) for v in canvas)
    x0, y0 = max(u0, 0), max(v0, 0)
    x1, y1 = min(u0 + w, W), min(v0 + h, H)
    if x1 <= x0 or y1 <= y0:
        return layers_from_warped(None, None, (0, 0, 0, 0), (H, W), opacity=0.0)
    sl = (slice(y0 - v0, y1 - v0), slice(x0 - u0, x1 - u0))
    return layers_from_warped(
        np.asarray(mask)[sl], None if rgba is None else np.asarray(rgba)[sl], (x0, y0, x1 - x0, y1 - y0), (H, W), **kw
    )


def recombine(plate_bgr8: np.ndarray, obj_rgba: np.ndarray, shadow: np.ndarray, *, over: bool = False) -> np.ndarray:
    """Rebuild the composite from the layers: ``plate x shadow + object`` in linear light -> 8-bit sRGB BGR.

    Parameters
    ----------
    plate_bgr8 : (H, W, 3) uint8
        The input photo (BGR, sRGB).
    obj_rgba : (H, W, 4) float
        Premultiplied linear RGBA.
    shadow : (H, W) or (H, W, 3) float
        The multiply pass, or with ``over=True`` the shadow-only layer's alpha ``(H, W)``:
        ``object + (1 - alpha) * plate * (1 - a_s)``.
    """
    lin = SRGB_TO_LINEAR[np.asarray(plate_bgr8)][..., ::-1].astype(np.float64)  # RGB
    obj = np.asarray(obj_rgba, np.float64)
    s = np.asarray(shadow, np.float64)
    if over:
        s = (1.0 - obj[..., 3]) * (1.0 - s)
    if s.ndim == 2:
        s = s[..., None]
    res = lin * s + obj[..., :3]
    return np.ascontiguousarray(linear_to_srgb8(res.astype(np.float32))[..., ::-1])
