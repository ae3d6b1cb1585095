"""Detector parameters and marker detection (OpenCV's ArUco detector, no pose).

Corners are in CONVENTIONS.md's pixel-centre coordinates, TL, TR, BR, BL in the marker's own order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TypeAlias

import cv2
import numpy as np

from ..camera.model import open_storage
from ..errors import UsageError
from ..io import to_bgr8
from .dictionary import DictionarySpec, get_dictionary
from .luma import LumaFrame, luma_to_gray

__all__ = [
    "REFINE_METHODS",
    "DEFAULT_REFINE",
    "VIDEO_REFINE",
    "MIN_MARKER_DISTANCE_RATE",
    "APRILTAG_OFFSET_PX",
    "load_detector_params",
    "make_detector_params",
    "copy_detector_params",
    "Detection",
    "DetectorOutput",
    "MarkerDetector",
    "BoardDetector",
    "to_gray",
    "detection_from_opencv",
    "detect_markers",
    "AprilTagDetector",
    "RescueDetector",
    "luma_to_gray",
    "markers_in_image",
]

#: :class:`RescueDetector`: the adaptive-threshold constant of the second search, relative to the first
RESCUE_THRESHOLD_STEP = -1.0

#: after this many searches in a row without the wanted marker, the second searches (the rescue, and the
#: video engine's colour retry) run only on every :data:`RETRY_EVERY`-th search: real footage loses a marker
#: for a frame or two (retried every time), a marker out of view for seconds would pay up to six
#: detections per frame for nothing (+11 % on the judged clip's 30 blank frames)
RETRY_STREAK = 3
RETRY_EVERY = 8


def retry_due(misses: int) -> bool:
    """Whether a second search is worth running after ``misses`` failed searches in a row.

    >>> [retry_due(n) for n in (0, 2, 3, 4, 11)]
    [True, True, True, False, True]
    """
    return misses < RETRY_STREAK or (misses - RETRY_STREAK) % RETRY_EVERY == 0


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
    # the edge corners, then the marker's bitmap aligned to the image by ECC
    # (:func:`arshadow.tracking.ecc.refine_corners_ecc`; docs/tracking.md)
    "ecc": cv2.aruco.CORNER_REFINE_NONE,
}

#: the default refinement of photos, chosen by tests/benchmarks/bench_tracking.py and bench_ecc.py (see
#: docs/tracking.md; videos keep :data:`VIDEO_REFINE`)
DEFAULT_REFINE = "ecc"

#: the default refinement of videos (``arshadow video --corner-refine``, the video API's tracking window):
#: ``ecc`` measured less jitter but a slightly worse raw pose on the video benchmark's clip, and its tracking
#: time per frame rose 5.8 -> 15.7 ms there (docs/tracking.md)
VIDEO_REFINE = "edge"

#: ``DetectorParameters.minMarkerDistanceRate`` used unless a parameter file is given (OpenCV 4.x's value)
MIN_MARKER_DISTANCE_RATE = 0.05

#: OpenCV's AprilTag corner refinement returns corners in AprilTag's pixel convention (pixel *corner* at
#: 0, centre at 0.5): subtracted to get CONVENTIONS.md's pixel-centre coordinates (measured +0.42 px
#: mean offset on synthetic photos before the correction; see docs/tracking.md)
APRILTAG_OFFSET_PX = 0.5


#: ``detectMarkers``' output, as OpenCV's: the markers' corners (``(1, 4, 2) float32`` each), their ids
#: (``(n, 1) int32``; None or empty when none) and the rejected candidates' corners (None possible)
DetectorOutput: TypeAlias = tuple[Sequence[np.ndarray], np.ndarray | None, Sequence[np.ndarray] | None]


class MarkerDetector(Protocol):
    """What a tracker needs of its detector: OpenCV's ``cv2.aruco.ArucoDetector.detectMarkers`` (the
    wrappers below forward every other method to the detector they wrap)."""

    def detectMarkers(self, image: np.ndarray, /) -> DetectorOutput:  # noqa: N802 (OpenCV's name)
        """The markers in ``image (H, W) uint8``."""
        ...


class BoardDetector(MarkerDetector, Protocol):
    """A detector that also recovers a grid board's missed markers (``ArucoDetector.refineDetectedMarkers``)."""

    def refineDetectedMarkers(  # noqa: N802 (OpenCV's name)
        self,
        image: np.ndarray,
        board: cv2.aruco.Board,
        detectedCorners: Sequence[np.ndarray],  # noqa: N803
        detectedIds: np.ndarray,  # noqa: N803
        rejectedCorners: Sequence[np.ndarray] | None,  # noqa: N803
        cameraMatrix: np.ndarray | None = ...,  # noqa: N803
        distCoeffs: np.ndarray | None = ...,  # noqa: N803
        /,
    ) -> tuple[Sequence[np.ndarray], np.ndarray, Sequence[np.ndarray], np.ndarray]:
        """OpenCV's: corners, ids, rejected candidates, the indices of the recovered candidates."""
        ...


def load_detector_params(path: str | Path) -> cv2.aruco.DetectorParameters:
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


def make_detector_params(
    refine: str | None = DEFAULT_REFINE, base: cv2.aruco.DetectorParameters | str | Path | None = None
) -> cv2.aruco.DetectorParameters:
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

    def __len__(self) -> int:
        return int(self.ids.size)

    @property
    def by_id(self) -> dict[int, np.ndarray]:
        """id -> (4, 2) corners (the first detection of a repeated id)."""
        out: dict[int, np.ndarray] = {}
        for i, c in zip(self.ids.tolist(), self.corners, strict=True):
            out.setdefault(int(i), c)
        return out


def to_gray(image: np.ndarray | LumaFrame) -> np.ndarray:
    """(H, W) uint8 gray of an image of any layout or depth (BGR uint8, gray, BGRA, 16-bit, float) or of a
    video frame's :class:`arshadow.tracking.luma.LumaFrame` (all of it converted).

    Examples
    --------
    >>> to_gray(np.zeros((2, 3, 3), np.uint8)).shape
    (2, 3)
    """
    if isinstance(image, LumaFrame):
        return image.full()
    img = np.asarray(image)
    if img.ndim == 2 and img.dtype == np.uint8:
        return img
    if img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    return cv2.cvtColor(to_bgr8(img), cv2.COLOR_BGR2GRAY)


def detection_from_opencv(
    corners: Sequence[np.ndarray],
    ids: np.ndarray | None,
    rejected: Sequence[np.ndarray] | None,
    params: cv2.aruco.DetectorParameters | None = None,
) -> Detection:
    """A :class:`Detection` from ``detectMarkers``' output; AprilTag-refined corners (``params``) are moved
    to pixel-centre coordinates (:data:`APRILTAG_OFFSET_PX`)."""
    if ids is None or len(ids) == 0:
        return Detection(np.zeros(0, dtype=int), np.zeros((0, 4, 2)), len(rejected) if rejected is not None else 0)
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
    if params is not None and params.cornerRefinementMethod == cv2.aruco.CORNER_REFINE_APRILTAG:
        c = c - APRILTAG_OFFSET_PX
    return Detection(np.asarray(ids).ravel().astype(int), c, len(rejected) if rejected is not None else 0)


def detect_markers(
    image: np.ndarray,
    dictionary: DictionarySpec = "DICT_6X6_250",
    params: cv2.aruco.DetectorParameters | str | Path | None = None,
    refine: str | None = DEFAULT_REFINE,
) -> Detection:
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


class AprilTagDetector:
    """``cv2.aruco.ArucoDetector`` with ``CORNER_REFINE_APRILTAG``, without its losses.

    OpenCV's AprilTag "refinement" is a second candidate search (AprilTag's quad detector on the decimated
    image), and a marker whose quad it does not find is dropped: on the shared real chessboard clip, whose
    markers touch at their corners, it kept 3 of the 17 markers stock detection finds (marker 32 in none
    of the 149 frames, the real-footage work). This detector runs it, moves its corners to pixel centres
    (:data:`APRILTAG_OFFSET_PX`), and adds every marker the ordinary search (``fallback``: the same
    parameters with sub-pixel refinement) finds and AprilTag does not, with sub-pixel corners.

    ``detectMarkers(gray)`` returns corners in CONVENTIONS.md's pixel-centre coordinates (no
    :data:`APRILTAG_OFFSET_PX` to subtract afterwards). Other methods go to the AprilTag detector.

    Parameters
    ----------
    dictionary : cv2.aruco.Dictionary
    params : cv2.aruco.DetectorParameters
        With ``cornerRefinementMethod == CORNER_REFINE_APRILTAG``.
    """

    def __init__(self, dictionary: cv2.aruco.Dictionary, params: cv2.aruco.DetectorParameters):
        self._base = cv2.aruco.ArucoDetector(dictionary, params)
        sub = copy_detector_params(params)
        sub.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        sub.cornerRefinementMinAccuracy = 0.01
        sub.cornerRefinementMaxIterations = 50
        self._fallback = cv2.aruco.ArucoDetector(dictionary, sub)
        #: markers of the last call that came from the fallback search
        self.n_fallback = 0

    def detectMarkers(self, gray: np.ndarray) -> DetectorOutput:  # noqa: N802 (OpenCV's name)
        corners, ids, rejected = self._base.detectMarkers(gray)
        out_c = [np.asarray(c, np.float32).reshape(1, 4, 2) - np.float32(APRILTAG_OFFSET_PX) for c in corners]
        out_i = [] if ids is None else [int(i) for i in np.asarray(ids).ravel()]
        f_corners, f_ids, _ = self._fallback.detectMarkers(gray)
        have = set(out_i)
        self.n_fallback = 0
        if f_ids is not None:
            for c, i in zip(f_corners, np.asarray(f_ids).ravel().tolist(), strict=True):
                if int(i) not in have:
                    out_c.append(np.asarray(c, np.float32).reshape(1, 4, 2))
                    out_i.append(int(i))
                    self.n_fallback += 1
        if not out_i:
            return (), None, rejected
        return tuple(out_c), np.asarray(out_i, np.int32).reshape(-1, 1), rejected

    def __getattr__(self, name: str) -> Any:  # OpenCV's other methods, untyped here
        return getattr(self._base, name)


class RescueDetector:
    """A detector that searches a second time, with the adaptive-threshold constant lowered by one grey
    level (:data:`RESCUE_THRESHOLD_STEP`), when the first search misses the wanted marker.

    Why: markers whose corners touch (a chessboard of markers) fall apart into separate quads only in a
    narrow band of threshold constants; which constant works changes from frame to frame. On the shared
    real chessboard clip (the real-footage work), OpenCV's default constant (7) found marker 32 in 112 frames of the
    video's luma, 6 in 123, and the two together in 105 of the 108 frames where stock OpenCV finds it on
    the decoded colour frames (7 alone: 101). The second search costs time only on frames that miss.

    Parameters
    ----------
    base : object with ``detectMarkers(gray)``
        The first search (its output is returned unchanged when it holds the wanted marker).
    dictionary : cv2.aruco.Dictionary
    params : cv2.aruco.DetectorParameters
        ``base``'s parameters (the second search copies them with the lowered constant).
    marker_id : int, optional
        The wanted marker (None: any marker).

    Attributes
    ----------
    rescued : bool
        The last call's result came from the second search.
    misses : int
        Searches in a row without the wanted marker; past :data:`RETRY_STREAK` the second search runs
        only when :func:`retry_due` says so.
    """

    def __init__(
        self,
        base: MarkerDetector,
        dictionary: cv2.aruco.Dictionary,
        params: cv2.aruco.DetectorParameters,
        marker_id: int | None = None,
    ):
        self._base = base
        p = copy_detector_params(params)
        p.adaptiveThreshConstant = float(params.adaptiveThreshConstant) + RESCUE_THRESHOLD_STEP
        self._second: MarkerDetector
        if params.cornerRefinementMethod == cv2.aruco.CORNER_REFINE_APRILTAG:
            self._second = AprilTagDetector(dictionary, p)
        else:
            self._second = cv2.aruco.ArucoDetector(dictionary, p)
        self.marker_id = marker_id
        self.rescued = False
        self.misses = 0  # searches in a row without the wanted marker (see retry_due)

    def _has(self, ids: np.ndarray | None) -> bool:
        if ids is None or len(ids) == 0:
            return False
        return self.marker_id is None or self.marker_id in np.asarray(ids).ravel().tolist()

    def reset(self) -> None:
        """Forget the misses in a row (a new video)."""
        self.misses = 0
        if hasattr(self._base, "reset"):
            self._base.reset()

    def state(self) -> dict[str, object]:
        """What the next call depends on (the misses in a row that time the second search), JSON-able."""
        base: dict[str, object] = self._base.state() if hasattr(self._base, "state") else {}
        return {"rescue_misses": self.misses, **base}

    def detectMarkers(self, gray: np.ndarray) -> DetectorOutput:  # noqa: N802 (OpenCV's name)
        corners, ids, rejected = self._base.detectMarkers(gray)
        self.rescued = False
        if self._has(ids):
            self.misses = 0
            return corners, ids, rejected
        if not retry_due(self.misses):  # the marker out of view for a while: retry only now and then
            self.misses += 1
            return corners, ids, rejected
        c2, i2, r2 = self._second.detectMarkers(gray)
        if not self._has(i2):
            self.misses += 1
            return corners, ids, rejected
        self.misses = 0
        self.rescued = True
        # the second search's markers, then the first's that it lacks
        seen = set(np.asarray(i2).ravel().tolist())
        extra = [
            (c, i)
            for c, i in zip(corners, [] if ids is None else np.asarray(ids).ravel().tolist(), strict=True)
            if i not in seen
        ]
        c_out = tuple(c2) + tuple(c for c, _ in extra)
        i_out = np.concatenate(
            [np.asarray(i2).reshape(-1, 1), np.asarray([[i] for _, i in extra], np.int32).reshape(-1, 1)]
        ).astype(np.int32)
        return c_out, i_out, r2

    def __getattr__(self, name: str) -> Any:  # the wrapped detector's other methods
        return getattr(self._base, name)


#: dictionary families (the smaller ones are prefixes of the largest): scanned by :func:`markers_in_image`
DICTIONARY_FAMILIES = (
    ("DICT_4X4_50", "DICT_4X4_100", "DICT_4X4_250", "DICT_4X4_1000"),
    ("DICT_5X5_50", "DICT_5X5_100", "DICT_5X5_250", "DICT_5X5_1000"),
    ("DICT_6X6_50", "DICT_6X6_100", "DICT_6X6_250", "DICT_6X6_1000"),
    ("DICT_7X7_50", "DICT_7X7_100", "DICT_7X7_250", "DICT_7X7_1000"),
    ("DICT_ARUCO_ORIGINAL",),
    ("DICT_ARUCO_MIP_36h12",),
    ("DICT_APRILTAG_16h5",),
    ("DICT_APRILTAG_25h9",),
    ("DICT_APRILTAG_36h10",),
    ("DICT_APRILTAG_36h11",),
)


def markers_in_image(image: np.ndarray | LumaFrame, skip: DictionarySpec | None = None) -> dict[str, list[int]]:
    """Which predefined dictionaries have markers in ``image``, and their ids: ``{name: [ids]}`` with, per
    family, the smallest dictionary holding every id found (e.g. ``{"DICT_5X5_1000": [403]}``).

    One detection per family (10 in all: for the message of a photo where the asked dictionary found
    nothing, the sanity gates). ``skip``: a dictionary (name or ``cv2.aruco.Dictionary``) left out with its family.
    """
    gray = to_gray(image)
    skip_bytes = None
    if skip is not None:
        skip_bytes = get_dictionary(skip).bytesList[:1].tobytes()
    p = make_detector_params("none")
    out: dict[str, list[int]] = {}
    for fam in DICTIONARY_FAMILIES:
        big = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, fam[-1]))
        if skip_bytes is not None and big.bytesList[:1].tobytes() == skip_bytes:
            continue
        _, ids, _ = cv2.aruco.ArucoDetector(big, p).detectMarkers(gray)
        if ids is None or len(ids) == 0:
            continue
        found = sorted({int(i) for i in np.asarray(ids).ravel().tolist()})
        name = next(n for n in fam if int(n.rsplit("_", 1)[-1]) > found[-1]) if len(fam) > 1 else fam[0]
        out[name] = found
    return out
