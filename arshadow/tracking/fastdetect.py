"""The fast first detection pass: one adaptive-threshold window, half resolution for big markers.

Used through ``MarkerTracker(..., detector="fast")`` (:mod:`arshadow.tracking.tracker`); a session
(:meth:`arshadow.frame.session.Session.track`) runs it first and the tracker's full search only when it finds
nothing. Measured in docs/tracking.md and ``tests/benchmarks/bench_pipeline.py --detectors``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from .detect import MIN_MARKER_DISTANCE_RATE, AprilTagDetector, DetectorOutput, MarkerDetector

if TYPE_CHECKING:
    from .board import Board

__all__ = ["HalfResolutionDetector", "fast_detector_params", "wrap_fast_detector"]


class HalfResolutionDetector:
    """Drop-in for ``cv2.aruco.ArucoDetector`` in a :class:`~arshadow.tracking.tracker.MarkerTracker`: detect on the
    image downscaled 2x (one 5-px threshold window, no refinement), then refine every corner at full
    resolution with ``cv2.cornerSubPix`` (11 x 11 window, 0.01 px / 50 iterations, as the tracker's own
    sub-pixel refinement). Other methods (``refineDetectedMarkers``...) go to the full-resolution detector.
    When nothing is found, or a detected marker has a side shorter than :data:`MIN_SIDE_PX` (small or
    steeply tilted), the full-resolution detector (same one window) runs instead: a 40-px marker's half-resolution corners are too coarse a start
    (measured at 640 x 360: 2.8 deg rotation error instead of 0.9 deg).

    Measured on 40 synthetic photos (5 cm marker at 0.3-0.8 m, tilt 0-70 deg, noise 2, blur 0.6,
    JPEG 90): 40 of 40 found, rotation error median 0.114 deg (full resolution, 7-px window: 0.141 deg),
    0.96 ms instead of 2.63 ms for ``detectMarkers`` on the 1280 x 720 benchmark photo.
    """

    #: shortest marker side (full-resolution pixels) for which the half-resolution corners are used
    MIN_SIDE_PX = 64.0

    def __init__(self, base: MarkerDetector, dictionary: cv2.aruco.Dictionary):
        self._base = base
        p = cv2.aruco.DetectorParameters()
        p.adaptiveThreshWinSizeMin = 5
        p.adaptiveThreshWinSizeMax = 5
        p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        self._small = cv2.aruco.ArucoDetector(dictionary, p)
        self._criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 0.01)

    def detectMarkers(self, gray: np.ndarray) -> DetectorOutput:  # noqa: N802 (OpenCV's name)
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        h, w = gray.shape[:2]
        if min(h, w) < 2 * self.MIN_SIDE_PX:  # too small to halve (a 1-pixel image crashed cv2.resize)
            return self._base.detectMarkers(gray)
        small = cv2.resize(gray, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
        corners, ids, rejected = self._small.detectMarkers(small)
        if ids is None or len(ids) == 0:  # nothing at half resolution: try full resolution (same window)
            return self._base.detectMarkers(gray)
        # small pixel i covers full pixels 2i and 2i + 1: centre 2i + 0.5
        pts = np.concatenate([np.asarray(c, np.float32).reshape(-1, 2) for c in corners]) * 2.0 + 0.5
        sides = np.linalg.norm(pts.reshape(-1, 4, 2) - np.roll(pts.reshape(-1, 4, 2), 1, axis=1), axis=2)
        if sides.min() < self.MIN_SIDE_PX:
            # small (or steeply tilted) markers: the half-resolution corners are too coarse a start for
            # the 11 x 11 refinement window; detect at full resolution with the tracker's own refinement
            return self._base.detectMarkers(gray)
        pts = np.ascontiguousarray(pts.reshape(-1, 1, 2), dtype=np.float32)
        cv2.cornerSubPix(gray, pts, (5, 5), (-1, -1), self._criteria)
        full = tuple(pts[4 * i : 4 * i + 4].reshape(1, 4, 2) for i in range(len(corners)))
        rej = tuple(np.asarray(r, np.float32) * 2.0 + 0.5 for r in rejected) if rejected is not None else rejected
        return full, ids, rej

    def __getattr__(self, name: str) -> Any:  # the full-resolution detector's other methods
        return getattr(self._base, name)


def wrap_fast_detector(detector: MarkerDetector, board: Board | None = None) -> MarkerDetector:
    """The fast pass's detector around a tracker's full-resolution ``cv2.aruco.ArucoDetector``:
    :class:`HalfResolutionDetector` in single-marker mode (``board`` None), else ``detector`` itself."""
    if isinstance(detector, (cv2.aruco.ArucoDetector, AprilTagDetector)) and board is None:
        return HalfResolutionDetector(detector, detector.getDictionary())
    return detector


def fast_detector_params() -> cv2.aruco.DetectorParameters:
    """ArUco detector parameters for the fast first pass: one adaptive-threshold window (7 px).

    OpenCV's default tries windows 3, 13 and 23 px (three thresholdings and contour searches); one
    window finds the same corners on the benchmark set (tests/benchmarks/bench_pipeline.py
    ``--detectors``: 60 of 60 synthetic photos, identical pose errors) about 5x faster. The
    session (:meth:`arshadow.frame.session.Session.track`) falls back to the full search when this pass finds nothing, so robustness is kept.
    The tracker's corner refinement is applied on top (``make_detector_params``).
    """
    p = cv2.aruco.DetectorParameters()
    p.adaptiveThreshWinSizeMin = 7
    p.adaptiveThreshWinSizeMax = 7
    # OpenCV 5's default (0.125) drops markers printed with a narrow paper margin (docs/tracking.md)
    p.minMarkerDistanceRate = MIN_MARKER_DISTANCE_RATE
    return p
