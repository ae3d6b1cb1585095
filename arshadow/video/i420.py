"""Planar ``yuv420p`` frames converted to and from BGR inside a rectangle only (the video engine's frame job,
:mod:`arshadow.video.framejob`: the compositor reads and changes the frame's ROI only, every other pixel
keeps its decoded value exactly)."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from ..compose.composite import clip_roi

__all__ = ["even_box", "i420_planes", "i420_roi_to_bgr", "i420_with_roi"]


def i420_planes(a: np.ndarray, H: int, W: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Views ``(Y (H, W), U (H/2, W/2), V (H/2, W/2))`` of a planar ``(H * 3 // 2, W)`` yuv420p frame."""
    c = a[H:].reshape(-1)
    q = (H // 2) * (W // 2)
    return a[:H], c[:q].reshape(H // 2, W // 2), c[q:].reshape(H // 2, W // 2)


def even_box(roi: Sequence[float], W: int, H: int) -> tuple[int, int, int, int] | None:
    """``(x0, y0, x1, y1)`` of ``roi = (x0, y0, w, h)`` clipped to the frame and widened to even
    coordinates (a chroma sample of yuv420p covers 2x2 pixels); None for an empty ROI.

    >>> even_box((3, 5, 10, 4), 64, 48)
    (2, 4, 14, 10)
    """
    x0, y0, w, h = clip_roi(roi, W, H)
    if w == 0 or h == 0:
        return None
    return x0 & ~1, y0 & ~1, min(W, x0 + w + 1) & ~1, min(H, y0 + h + 1) & ~1


def i420_roi_to_bgr(yuv: np.ndarray, bgr: np.ndarray, roi: Sequence[float] | None) -> None:
    """Convert the planar yuv420p frame to BGR into ``bgr`` inside ``roi`` only (even-aligned); equal there
    to a whole-frame ``cv2.COLOR_YUV2BGR_I420`` (each 2x2 block has its own chroma sample). ``roi`` None:
    the whole frame.

    Parameters
    ----------
    yuv : (H * 3 // 2, W) uint8
    bgr : (H, W, 3) uint8
        Written inside the ROI; other pixels are left as they are.
    roi : sequence of 4 int or None
    """
    H, W = bgr.shape[:2]
    if roi is None:
        cv2.cvtColor(yuv, cv2.COLOR_YUV2BGR_I420, dst=bgr)
        return
    box = even_box(roi, W, H)
    if box is None:
        return
    x0, y0, x1, y1 = box
    y, u, v = i420_planes(yuv, H, W)
    hh, ww = y1 - y0, x1 - x0
    sub = np.empty((hh * 3 // 2, ww), np.uint8)
    sy, su, sv = i420_planes(sub, hh, ww)
    sy[:] = y[y0:y1, x0:x1]
    su[:] = u[y0 // 2 : y1 // 2, x0 // 2 : x1 // 2]
    sv[:] = v[y0 // 2 : y1 // 2, x0 // 2 : x1 // 2]
    bgr[y0:y1, x0:x1] = cv2.cvtColor(sub, cv2.COLOR_YUV2BGR_I420)


def i420_with_roi(
    yuv: np.ndarray, bgr: np.ndarray, roi: Sequence[float] | None, out: np.ndarray | None = None
) -> np.ndarray:
    """The planar yuv420p frame ``yuv`` with the rectangle ``roi = (x0, y0, w, h)`` taken from ``bgr``.

    The compositor changes pixels inside the frame's ROI only, so only that rectangle (widened to even
    coordinates: a chroma sample covers 2x2 pixels) is converted back; every other pixel keeps the decoded
    value exactly. Inside it the result equals a whole-frame ``cv2.COLOR_BGR2YUV_I420`` (each chroma
    sample is computed from its own 2x2 block). ``roi`` None: the whole frame.

    Parameters
    ----------
    yuv : (H * 3 // 2, W) uint8
        The decoded frame (not modified), H and W even.
    bgr : (H, W, 3) uint8
        The composited frame.
    roi : sequence of 4 int or None
    out : (H * 3 // 2, W) uint8, optional
        Where to write the result; may be ``yuv`` itself (only the ROI's pixels are then written: no copy
        of the frame). A new array when None.

    Returns
    -------
    (H * 3 // 2, W) uint8
        ``out``, or a new array.
    """
    H, W = bgr.shape[:2]
    if roi is None:
        whole: np.ndarray = cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_I420, dst=out)
        return whole
    x0, y0, w, h = clip_roi(roi, W, H)
    if out is None:
        out = np.array(yuv)
    elif out is not yuv:
        np.copyto(out, yuv)
    if w == 0 or h == 0:
        return out
    x1, y1 = min(W, x0 + w + 1) & ~1, min(H, y0 + h + 1) & ~1
    x0, y0 = x0 & ~1, y0 & ~1
    sub = cv2.cvtColor(np.ascontiguousarray(bgr[y0:y1, x0:x1]), cv2.COLOR_BGR2YUV_I420)
    for dst, src, k in zip(i420_planes(out, H, W), i420_planes(sub, y1 - y0, x1 - x0), (1, 2, 2), strict=True):
        dst[y0 // k : y1 // k, x0 // k : x1 // k] = src
    return out
