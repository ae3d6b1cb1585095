"""Detector parameters and marker detection (OpenCV's ArUco detector, no pose).

Corners are in CONVENTIONS.md's pixel-centre coordinates, TL, TR, BR, BL in the marker's own order.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..camera import open_storage
from ..errors import UsageError
from ..io import to_bgr8
from .dictionary import get_dictionary

__all__ = [
    "REFINE_METHODS",
    "DEFAULT_REFINE",
    "MIN_MARKER_DISTANCE_RATE",
    "APRILTAG_OFFSET_PX",
    "load_detector_params",
    "make_detector_params",
    "copy_detector_params",
    "Detection",
    "to_gray",
    "detection_from_opencv",
    "detect_markers",
]

#: corner refinement methods (``cv2.aruco.CORNER_REFINE_*``)
REFINE_METHODS = {
    "none": cv2.aruco.CORNER_REFINE_NONE,
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
    "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
    # arshadow's own: OpenCV detects without refinement, then
    # :func:`arshadow.tracking.refine.refine_corners_edges` fits the four border edges at full resolution
    # and intersects them (unbiased at any marker size; docs/tracking.md)
    "edge": cv2.aruco.CORNER_REFINE_NONE,
}

#: the default refinement, chosen by tests/benchmarks/bench_tracking.py (see docs/tracking.md)
DEFAULT_REFINE = "subpix"

#: ``DetectorParameters.minMarkerDistanceRate`` used unless a parameter file is given (OpenCV 4.x's value)
MIN_MARKER_DISTANCE_RATE = 0.05

#: OpenCV's AprilTag corner refinement returns corners in AprilTag's pixel convention (pixel *corner* at
#: 0, centre at 0.5): subtracted to get CONVENTIONS.md's pixel-centre coordinates (measured +0.42 px
#: mean offset on synthetic photos before the correction; see docs/tracking.md)
APRILTAG_OFFSET_PX = 0.5


def load_detector_params(path) -> cv2.aruco.DetectorParameters:
    """Read ``cv2.aruco.DetectorParameters`` from a YAML/XML/JSON file (OpenCV's key names).

    Raises
    ------
    UsageError
        Missing or unreadable file.
    """
    p = Path(path)
    with open_storage(p, "detector parameter file", UsageError) as fs:
        params = cv2.aruco.DetectorParameters()
        try:
            ok = params.readDetectorParameters(fs.root())
        except cv2.error as exc:
            raise UsageError(f"{p}: invalid detector parameters ({str(exc).strip().splitlines()[-1][:100]})") from None
        if not ok:
            raise UsageError(f"{p}: no detector parameters in this file")
    return params


def make_detector_params(refine=DEFAULT_REFINE, base=None) -> cv2.aruco.DetectorParameters:
    """Detector parameters with the corner refinement ``refine`` (None keeps ``base``'s own).

    ``base`` may be a ``DetectorParameters``, a parameter file path, or None (OpenCV's defaults).
    Sub-pixel refinement stops at 0.01 px instead of OpenCV's 0.1 px (measured: see docs/tracking.md).
    """
    if base is None:
        params = cv2.aruco.DetectorParameters()
        # OpenCV 5 raised the default from 0.05 to 0.125 (x perimeter). A marker printed with a white margin
        # under ~0.5 x its side then lies "too close" to the paper's own outline (also a quad) and is
        # dropped: 4 of 60 synthetic photos at 1280x720 missed the marker; 0.05 finds all 60 and adds no
        # false detection (tests/benchmarks, docs/tracking.md)
        params.minMarkerDistanceRate = MIN_MARKER_DISTANCE_RATE
    elif isinstance(base, cv2.aruco.DetectorParameters):
        params = copy_detector_params(base)
    else:
        params = load_detector_params(base)
    if refine is not None:
        key = str(refine).lower()
        if key not in REFINE_METHODS:
            raise UsageError(f"unknown corner refinement '{refine}' (use one of {', '.join(REFINE_METHODS)})")
        params.cornerRefinementMethod = REFINE_METHODS[key]
        if key == "subpix":
            params.cornerRefinementMinAccuracy = 0.01
            params.cornerRefinementMaxIterations = 50
    return params


def copy_detector_params(p: cv2.aruco.DetectorParameters) -> cv2.aruco.DetectorParameters:
    """A copy of ``p`` (every writable attribute; OpenCV's ``DetectorParameters`` has no copy)."""
    q = cv2.aruco.DetectorParameters()
    for name in dir(p):
        if name.startswith("_"):
            continue
        try:
            v = getattr(p, name)
        except Exception:  # pragma: no cover
            continue
        if callable(v):
            continue
        try:
            setattr(q, name, v)
        except (AttributeError, TypeError):  # read-only
            pass
    return q


@dataclass
class Detection:
    """Markers found in one image.

    Attributes
    ----------
    ids : (n,) int
        Marker ids, in detection order (an id may repeat).
    corners : (n, 4, 2) float64
        Corner pixels TL, TR, BR, BL per marker.
    n_rejected : int
        Candidates that were not markers.
    """

    ids: np.ndarray
    corners: np.ndarray
    n_rejected: int = 0

    def __len__(self):
        return int(self.ids.size)

    @property
    def by_id(self) -> dict:
        """id -> (4, 2) corners (the first detection of a repeated id)."""
        out = {}
        for i, c in zip(self.ids.tolist(), self.corners):
            out.setdefault(int(i), c)
        return out


def to_gray(image) -> np.ndarray:
    """(H, W) uint8 gray of an image of any layout or depth (BGR uint8, gray, BGRA, 16-bit, float).

    Examples
    --------
    >>> to_gray(np.zeros((2, 3, 3), np.uint8)).shape
    (2, 3)
    """
    img = np.asarray(image)
    if img.ndim == 2 and img.dtype == np.uint8:
        return img
    if img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return cv2.cvtColor(to_bgr8(img), cv2.COLOR_BGR2GRAY)


def detection_from_opencv(corners, ids, rejected, params=None) -> Detection:
    """A :class:`Detection` from ``detectMarkers``' output; AprilTag-refined corners (``params``) are moved
    to pixel-centre coordinates (:data:`APRILTAG_OFFSET_PX`)."""
    if ids is None or len(ids) == 0:
        return Detection(np.zeros(0, dtype=int), np.zeros((0, 4, 2)), len(rejected) if rejected is not None else 0)
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
    if params is not None and params.cornerRefinementMethod == cv2.aruco.CORNER_REFINE_APRILTAG:
        c = c - APRILTAG_OFFSET_PX
    return Detection(np.asarray(ids).ravel().astype(int), c, len(rejected) if rejected is not None else 0)


def detect_markers(image, dictionary="DICT_6X6_250", params=None, refine=DEFAULT_REFINE) -> Detection:
    """Detect every marker of ``dictionary`` in ``image``.

    Parameters
    ----------
    image : (H, W, 3) uint8 BGR or (H, W) uint8
    dictionary : str, Path or cv2.aruco.Dictionary
    params : DetectorParameters or path, optional
        Base detector parameters (OpenCV's defaults when None).
    refine : str or None
        Corner refinement (``none``, ``subpix``, ``contour``, ``apriltag``); None keeps ``params``'.

    Returns
    -------
    Detection
    """
    p = make_detector_params(refine, params)
    det = cv2.aruco.ArucoDetector(get_dictionary(dictionary), p)
    corners, ids, rejected = det.detectMarkers(to_gray(image))
    return detection_from_opencv(corners, ids, rejected, p)
