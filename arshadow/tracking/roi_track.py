"""Tracking ROI for video: search the marker near where the last frame found it, the whole frame otherwise.

:class:`TrackingDetector` wraps the detector of a single-marker :class:`~arshadow.tracking.tracker.MarkerTracker`
(``cv2.aruco.ArucoDetector`` or the pipeline's half-resolution detector) the way that detector wraps
OpenCV's: ``detectMarkers(gray)`` first searches a window around the last detection's corners
(:func:`tracking_roi`: the corners' box grown by half its size, at least 32 px) and
shifts the corners found back to full-frame pixels; when the window holds no marker (or not the one asked
for), the whole frame is searched (the fallback). Corner refinement is local (sub-pixel windows of a few
pixels), so a marker found well inside the window gets the corners of a full-frame search (measured: pose
matrix entries within 2e-7, tests/test_plan_rules.py).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from .detect import DetectorOutput, MarkerDetector
from .luma import LumaFrame

__all__ = ["TrackingDetector"]


class TrackingDetector:
    """Drop-in for a tracker's ``_detector``: window search around the last detection, full-frame fallback.

    Parameters
    ----------
    base : object with ``detectMarkers(gray)``
    marker_id : int, optional
        A window result counts only if it holds this id.

    Attributes
    ----------
    last : str or None
        ``"window"`` or ``"full"``: how the last call found its markers (None before the first call).
    window : (x0, y0, w, h) or None
        The window searched by the last call (None: the whole frame).
    """

    def __init__(self, base: MarkerDetector, marker_id: int | None = None):
        self._base = base
        self.marker_id = marker_id
        self._corners: np.ndarray | None = None
        self.last: str | None = None
        self.window: tuple[int, int, int, int] | None = None

    def reset(self) -> None:
        """Forget the last detection (e.g. at a cut, or a new video): the next call searches the whole
        frame (and the wrapped detector forgets too)."""
        self._corners = None
        if hasattr(self._base, "reset"):
            self._base.reset()

    def detectMarkers(self, gray: np.ndarray | LumaFrame) -> DetectorOutput:  # noqa: N802 (OpenCV's name)
        """``gray``: (H, W) uint8, or a video frame's :class:`arshadow.tracking.luma.LumaFrame` (only the
        window is converted unless the whole frame is searched)."""
        h, w = gray.shape[:2]
        self.window = win = None if self._corners is None else tracking_roi(self._corners, w, h)
        if win is not None:
            x0, y0, ww, hh = win
            crop = gray.region(x0, y0, ww, hh) if isinstance(gray, LumaFrame) else gray[y0 : y0 + hh, x0 : x0 + ww]
            corners, ids, rejected = self._base.detectMarkers(np.ascontiguousarray(crop))
            ok = (
                ids is not None
                and len(ids) > 0
                and (self.marker_id is None or self.marker_id in np.asarray(ids).ravel().tolist())
            )
            if ok:
                off = np.array([x0, y0], np.float32)
                corners = tuple(np.asarray(c, np.float32) + off for c in corners)
                rejected = (
                    tuple(np.asarray(r, np.float32) + off for r in rejected) if rejected is not None else rejected
                )
                self._remember(corners)
                self.last = "window"
                return corners, ids, rejected
        corners, ids, rejected = self._base.detectMarkers(gray.full() if isinstance(gray, LumaFrame) else gray)
        self.window = None
        self.last = "full"
        if ids is not None and len(ids) > 0:
            self._remember(corners)
        else:
            self._corners = None
        return corners, ids, rejected

    def state(self) -> dict[str, object]:
        """What the next call depends on (the corners its window is cut around, and the wrapped detector's
        :meth:`state` if it has one), JSON-able: compared across a video's chunks."""
        base: dict[str, object] = self._base.state() if hasattr(self._base, "state") else {}
        return {"window_corners": None if self._corners is None else self._corners.tolist(), **base}

    def _remember(self, corners: Sequence[np.ndarray]) -> None:
        self._corners = np.concatenate([np.asarray(c, np.float64).reshape(-1, 2) for c in corners])

    def __getattr__(self, name: str) -> Any:  # the wrapped detector's other methods
        return getattr(self._base, name)


def tracking_roi(
    corners: npt.ArrayLike, width: int, height: int, grow: float = 0.5, min_margin: int = 32
) -> tuple[int, int, int, int] | None:
    """Window ``(x0, y0, w, h)`` around the last detection's corners for the next frame's marker search.

    Parameters
    ----------
    corners : (n, 2) float
        All corners (pixels) of the last frame's detection.
    grow : float
        Margin as a fraction of the corners' box size (per axis), at least ``min_margin`` pixels.

    Returns
    -------
    (x0, y0, w, h) int, or None when the window would cover most of the frame (then search it all).
    """
    c = np.asarray(corners, np.float64).reshape(-1, 2)
    if c.size == 0 or not np.all(np.isfinite(c)):
        return None
    lo, hi = c.min(axis=0), c.max(axis=0)
    m = np.maximum(grow * (hi - lo), min_margin)
    x0 = max(0, int(math.floor(lo[0] - m[0])))
    y0 = max(0, int(math.floor(lo[1] - m[1])))
    x1 = min(int(width), int(math.ceil(hi[0] + m[0])) + 1)
    y1 = min(int(height), int(math.ceil(hi[1] + m[1])) + 1)
    if x1 <= x0 or y1 <= y0 or (x1 - x0) * (y1 - y0) > 0.6 * width * height:
        return None
    return (x0, y0, x1 - x0, y1 - y0)
