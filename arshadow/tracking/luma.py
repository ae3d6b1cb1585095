"""A video frame's luma as the tracker's grey, converted only where the tracker reads it.

A ``yuv420p`` video frame's Y plane is limited-range ("TV": 16 = black, 235 = white). The detector needs
the full-range grey (:func:`luma_to_gray`; the real-footage work: on the Y plane itself markers whose corners touch
merge into one blob). Converting a whole 720p plane costs ~0.2 ms alone but ~1 ms per frame inside the
video engine, where the decoder, the encoder and the rasteriser share the cores (measured: 1.0-1.7 ms
median per frame with ``cv2.LUT``, ``cv2.convertScaleAbs`` or ``numpy.take``); a tracked marker needs
only its search window. :class:`LumaFrame` converts a region the first time it is read and remembers it:
the tracking window, the neighbourhood of the found corners (refinement and quality measures), or the
whole frame for a full search. Every pixel a reader gets is exactly :func:`luma_to_gray`'s.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

__all__ = ["LUMA_LUT", "LumaFrame", "luma_to_gray"]

#: limited-range ("TV", BT.601/709) luma 16..235 -> full-range gray 0..255 (:func:`luma_to_gray`)
LUMA_LUT = np.clip(np.round((np.arange(256) - 16.0) * 255.0 / 219.0), 0, 255).astype(np.uint8)


def luma_to_gray(y: np.ndarray) -> np.ndarray:
    """(H, W) uint8 full-range gray from the limited-range luma plane ``y (H, W) uint8`` of a ``yuv420p``
    video frame (16 = black, 235 = white), as ``cv2.cvtColor(BGR -> GRAY)`` of the decoded frame gives it
    (within rounding).

    Why: the detector's adaptive threshold subtracts a constant (7 grey levels) from the local mean; on the
    Y plane, whose contrast is 219/255 of the gray image's, markers whose corners touch (a chessboard of
    markers) fall apart into one blob: stock OpenCV found marker 32 of the shared real chessboard clip in
    59 frames of the Y plane against 108 of the gray frames, 112 after this conversion (the real-footage work).

    Examples
    --------
    >>> luma_to_gray(np.array([[16, 235, 0, 255]], np.uint8)).tolist()
    [[0, 255, 0, 255]]
    """
    return cv2.LUT(np.ascontiguousarray(y), LUMA_LUT)


class LumaFrame:
    """The full-range grey of a limited-range luma plane, converted region by region as it is read.

    Parameters
    ----------
    y : (H, W) uint8
        The frame's limited-range luma (a view of the decoder's plane is fine: it is only read).

    Attributes
    ----------
    shape : (int, int)
        ``(H, W)``, as the grey image's.
    converted : list of (x0, y0, x1, y1)
        The regions converted so far (pixels ``[y0, y1) x [x0, x1)``).

    Examples
    --------
    >>> y = np.full((4, 6), 235, np.uint8)
    >>> f = LumaFrame(y)
    >>> f.region(1, 1, 2, 2).tolist()
    [[255, 255], [255, 255]]
    >>> f.converted
    [(1, 1, 3, 3)]
    >>> bool((f.full() == 255).all())
    True
    """

    ndim = 2
    dtype = np.dtype(np.uint8)

    def __init__(self, y: np.ndarray):
        y = np.asarray(y)
        if y.ndim != 2 or y.dtype != np.uint8:
            raise ValueError(f"a luma plane is (H, W) uint8, not {y.shape} {y.dtype}")
        self.y = y
        self.shape = y.shape
        self._gray = np.empty(y.shape, np.uint8)
        self.converted: list[tuple[int, int, int, int]] = []
        self._whole = False

    def _clip(self, x0: int, y0: int, x1: int, y1: int) -> tuple[int, int, int, int]:
        h, w = self.shape
        return max(0, x0), max(0, y0), min(w, x1), min(h, y1)

    def _covers(self, x0: int, y0: int, x1: int, y1: int) -> bool:
        x0, y0, x1, y1 = self._clip(x0, y0, x1, y1)
        return (
            self._whole
            or x1 <= x0
            or y1 <= y0
            or any(a <= x0 and b <= y0 and x1 <= c and y1 <= d for a, b, c, d in self.converted)
        )

    def _ensure(self, x0: int, y0: int, x1: int, y1: int) -> None:
        if self._covers(x0, y0, x1, y1):
            return
        x0, y0, x1, y1 = self._clip(x0, y0, x1, y1)
        cv2.LUT(self.y[y0:y1, x0:x1], LUMA_LUT, dst=self._gray[y0:y1, x0:x1])
        self.converted.append((x0, y0, x1, y1))

    def region(self, x0: int, y0: int, w: int, h: int) -> np.ndarray:
        """The ``(h, w) uint8`` grey of the window at ``(x0, y0)`` (a view of the frame's grey)."""
        self._ensure(x0, y0, x0 + w, y0 + h)
        return self._gray[y0 : y0 + h, x0 : x0 + w]

    def near(self, points: npt.ArrayLike, margin: float = 16.0, grow: float = 0.15) -> np.ndarray:
        """The frame's ``(H, W) uint8`` grey, converted (at least) around ``points (..., 2)`` (pixels): their
        bounding box grown by ``grow`` of its larger side plus ``margin`` pixels on every side. For readers
        that look only near the found corners (edge refinement reaches < 0.08 of a marker's side, the
        corner stability test 13-pixel windows); the rest of the array is not the frame's grey. A region
        that is not yet converted is converted with 4 more pixels of slack, so that the same corners moved
        by refinement need no second conversion."""
        p = np.asarray(points, np.float64).reshape(-1, 2)
        lo, hi = p.min(axis=0), p.max(axis=0)
        pad = grow * float((hi - lo).max()) + margin
        box = (
            int(np.floor(lo[0] - pad)),
            int(np.floor(lo[1] - pad)),
            int(np.ceil(hi[0] + pad)) + 1,
            int(np.ceil(hi[1] + pad)) + 1,
        )
        if not self._covers(*box):
            self._ensure(box[0] - 4, box[1] - 4, box[2] + 4, box[3] + 4)
        return self._gray

    def full(self) -> np.ndarray:
        """The whole frame's ``(H, W) uint8`` grey."""
        if not self._whole:
            cv2.LUT(self.y, LUMA_LUT, dst=self._gray)
            self._whole = True
            self.converted = [(0, 0, self.shape[1], self.shape[0])]
        return self._gray
