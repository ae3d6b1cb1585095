"""The tracker: detect a marker or board in an image and estimate its pose (:class:`MarkerTracker`).

Frames: :mod:`arshadow.tracking.dictionary` (single marker), :mod:`arshadow.tracking.board` (boards).
Pose: ``(rvec, tvec)`` world -> OpenCV camera, as ``cv2.solvePnP`` gives them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np

from ..camera.model import Intrinsics
from ..errors import ImageError, MarkerNotFoundError, UsageError
from ..transforms import matrix_from_rvec_tvec, rotation_error_deg
from .board import OPENCV_BOARD_TO_WORLD, Board, load_board
from .detect import (
    DEFAULT_REFINE,
    AprilTagDetector,
    BoardDetector,
    Detection,
    DetectorOutput,
    MarkerDetector,
    RescueDetector,
    detection_from_opencv,
    make_detector_params,
    markers_in_image,
    to_gray,
)
from .dictionary import (
    DEFAULT_DICTIONARY,
    DictionarySpec,
    dictionary_label,
    get_dictionary,
    marker_bits,
    marker_object_points,
)
from .ecc import refine_corners_ecc
from .edgelock import EdgeSpaceLock
from .fastdetect import fast_detector_params, wrap_fast_detector
from .luma import LumaFrame
from .pose import AltPose, MarkerPose, Solved, solve_general, solve_planar
from .quality import AMBIGUITY_FLAG, border_occlusion, corner_instability
from .reference import ReferenceLock
from .refine import refine_edges
from .roi_track import TrackingDetector

__all__ = ["MarkerTracker", "make_fast_tracker"]


class MarkerTracker:
    """Detect a marker or board and estimate its pose.

    Parameters
    ----------
    intrinsics : Intrinsics
        The calibration (scaled automatically to a same-aspect image size).
    dictionary : str, Path or cv2.aruco.Dictionary, optional
        Marker dictionary (single-marker mode, default :data:`DEFAULT_DICTIONARY`). A board brings its own:
        a different one given here is a :class:`~arshadow.errors.UsageError`.
    marker_length : float
        Marker side in metres (single-marker mode).
    marker_id : int, optional
        The reference marker; default: the lowest id found.
    board : Board or path, optional
        A grid or ChArUco board (board file path accepted).
    refine : str or None
        Corner refinement (default :data:`DEFAULT_REFINE`, chosen by the benchmark); None keeps the
        detector parameters' own setting. ``"ecc"``: the edge corners, then the marker's bitmap aligned to
        the image (:mod:`arshadow.tracking.ecc`; single marker: the reference marker; grid boards keep the
        edge corners: their many corners average out, docs/tracking.md); a marker whose alignment fails keeps its edge corners and the pose says so
        (``MarkerPose.refine_note``, a report note).
    detector_params : DetectorParameters or path, optional
        Base detector parameters.
    detector : str or object
        ``"full"`` (default): ``cv2.aruco.ArucoDetector`` with ``detector_params``; ``"fast"``: the fast
        first pass of :mod:`arshadow.tracking.fastdetect` (one 7-px threshold window unless ``detector_params`` are
        given, half-resolution detection for a single marker); or any object with OpenCV's
        ``detectMarkers(gray)`` (and ``refineDetectedMarkers`` for grid boards).
    ambiguity_threshold : float
        ``pose_ambiguity`` at or above which a pose is flagged.
    inverted : bool, optional
        Also detect markers printed white on black (``DetectorParameters.detectInvertedMarker``); None:
        the board's ``inverted`` (False for a single marker). Without it, a photo with only inverted
        markers gets a :class:`~arshadow.errors.MarkerNotFoundError` that says so.
    pnp_refine : bool
        Polish the IPPE pose with Levenberg-Marquardt (``cv2.solvePnPRefineLM``) on the reprojection
        error (default; measured in docs/tracking.md).
    track_roi : bool
        Video: search a window around the last detection first, the whole frame when it holds no marker
        (:class:`arshadow.tracking.roi_track.TrackingDetector`; single markers and ChArUco, not grid boards).
    reference : ReferenceLock, optional
        Video, single marker without ``marker_id``: the reference marker is chosen once and kept
        (:mod:`arshadow.tracking.reference`); shared by the trackers of one video (the fast pass gives it
        ``"peek"`` use: a miss of its own is followed by the full search, which counts it). Not reset by
        :meth:`reset` (the fast pass resets the full search's memory on every hit): reset it at a new video.
    edge_lock : EdgeSpaceLock, optional
        Video: the ``edge`` refinement's space check skipped for a marker once the video has shown it
        blurs in code values (:mod:`arshadow.tracking.edgelock`); shared by the trackers of one video, in
        their :meth:`state`, and, like ``reference``, reset by its owner at a new video. Photos: None.

    Examples
    --------
    >>> from arshadow.synth import look_at_pose, render_marker_photo
    >>> cam = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    >>> photo = render_marker_photo(cam, look_at_pose([0.1, -0.2, 0.4], [0, 0, 0]), marker_length=0.05)
    >>> pose = MarkerTracker(cam, marker_length=0.05).estimate(photo.image)
    >>> pose.marker_ids, bool(np.allclose(pose.tvec, photo.cam_from_world[:3, 3], atol=2e-3))
    ([0], True)
    """

    def __init__(
        self,
        intrinsics: Intrinsics,
        dictionary: DictionarySpec | None = None,
        marker_length: float | None = None,
        marker_id: int | None = None,
        board: Board | str | Path | None = None,
        refine: str | None = DEFAULT_REFINE,
        detector_params: cv2.aruco.DetectorParameters | str | Path | None = None,
        ambiguity_threshold: float = AMBIGUITY_FLAG,
        pnp_refine: bool = True,
        detector: str | MarkerDetector = "full",
        track_roi: bool = False,
        inverted: bool | None = None,
        reference: ReferenceLock | None = None,
        edge_lock: EdgeSpaceLock | None = None,
    ) -> None:
        if not isinstance(intrinsics, Intrinsics):
            raise UsageError("intrinsics must be an arshadow.camera.Intrinsics")
        self.intrinsics = intrinsics
        if board is not None and not isinstance(board, Board):
            board = load_board(board)
        self.board = board
        if board is None:
            if marker_length is None:
                raise UsageError("give the marker side length (marker_length, metres) or a board")
            ml = float(marker_length)
            if not (math.isfinite(ml) and ml > 0):
                raise UsageError(f"marker length must be a positive number of metres, got {marker_length}")
            self.marker_length = ml
            dictionary = DEFAULT_DICTIONARY if dictionary is None else dictionary
            self.dictionary = get_dictionary(dictionary)
            self.dictionary_name = dictionary_label(dictionary)
        else:
            if dictionary is not None and dictionary_label(dictionary) != dictionary_label(board.dictionary):
                raise UsageError(
                    f"dictionary {dictionary_label(dictionary)} conflicts with the board file's "
                    f"dictionary {dictionary_label(board.dictionary)} (a board names its own: leave "
                    "the dictionary out or make them agree)"
                )
            if marker_length is not None and abs(float(marker_length) - board.marker_length) > 1e-9:
                raise UsageError("marker_length conflicts with the board file's marker_length")
            self.marker_length = board.marker_length
            self.dictionary = board.cv_dictionary
            self.dictionary_name = f"the board's dictionary ({dictionary_label(board.dictionary)})"
        if marker_id is not None:
            marker_id = int(marker_id)
            if not 0 <= marker_id < len(self.dictionary.bytesList):
                raise UsageError(
                    f"marker id {marker_id} is not in {self.dictionary_name} "
                    f"(ids 0..{len(self.dictionary.bytesList) - 1})"
                )
        self.marker_id = marker_id
        self.reference = None if (marker_id is not None or board is not None) else reference
        self.edge_lock = edge_lock
        self.refine = refine
        self.pnp_refine = bool(pnp_refine)
        fast = isinstance(detector, str) and detector == "fast"
        self._counts_misses = not fast  # the full search has the last word on a frame (ReferenceLock)
        if isinstance(detector, str) and detector not in ("full", "fast"):
            raise UsageError(f"detector {detector!r}: choose 'full', 'fast' or a detector object")
        if fast and detector_params is None:
            detector_params = fast_detector_params()
        self.params = make_detector_params(refine, detector_params)
        self.inverted = bool(board.inverted if (inverted is None and board is not None) else inverted)
        #: a miss names the other dictionaries found in the image (photos; not per video frame: ``track_roi``)
        self.explain_misses = not track_roi and not fast  # (the fast pass falls back to the full one)
        if self.inverted:
            self.params.detectInvertedMarker = True
        self.ambiguity_threshold = float(ambiguity_threshold)
        self.detector_kind = detector if isinstance(detector, str) else "custom"
        apriltag = self.params.cornerRefinementMethod == cv2.aruco.CORNER_REFINE_APRILTAG
        custom = not isinstance(detector, str)
        # the built-in detectors give pixel-centre corners; a custom one, OpenCV's raw output (AprilTag's
        # corners shifted by APRILTAG_OFFSET_PX when the parameters ask for it)
        self._shift_params = self.params if custom else None
        self._detector: MarkerDetector
        if apriltag and not custom:
            self._detector = AprilTagDetector(self.dictionary, self.params)
        else:
            self._detector = cv2.aruco.ArucoDetector(self.dictionary, self.params)
        if not custom and not fast and (board is None or board.kind == "markers"):
            # a second search with a lower threshold constant when the first misses (the real-footage work)
            self._detector = RescueDetector(self._detector, self.dictionary, self.params, marker_id)
        if fast:
            self._detector = wrap_fast_detector(self._detector, board)
        elif not isinstance(detector, str):
            self._detector = detector
        if track_roi:
            self._detector = TrackingDetector(self._detector, marker_id)
        self._charuco: cv2.aruco.CharucoDetector | None = None
        if board is not None and board.kind == "charuco":
            cp = cv2.aruco.CharucoParameters()
            cp.minMarkers = 1
            self._charuco_params = cp
        self._charuco_for: Intrinsics | None = None
        self._t_detect: float | None = None  # when the last estimate's detection ended (perf_counter)
        self._bits: dict[int, np.ndarray] = {}  # marker id -> its cells (the ECC refinement's templates)

    # -- helpers ---------------------------------------------------------------------------------------
    def _intrinsics_for(self, image: np.ndarray | LumaFrame) -> tuple[Intrinsics, bool]:
        h, w = (image if isinstance(image, LumaFrame) else np.asarray(image)).shape[:2]
        return self.intrinsics.for_image(w, h)

    @property
    def last_search(self) -> str | None:
        """With ``track_roi``: where the last detection searched, ``"window"`` (around the previous marker)
        or ``"full"`` (the whole frame); None without ``track_roi``."""
        last: str | None = getattr(self._detector, "last", None)
        return last

    def _charuco_detector(self, intr: Intrinsics, board: Board) -> cv2.aruco.CharucoDetector:
        det = self._charuco
        if det is None or self._charuco_for != intr:
            cp = self._charuco_params
            cp.cameraMatrix = intr.K
            cp.distCoeffs = intr.dist_cv
            det = self._charuco = cv2.aruco.CharucoDetector(board.cv_charuco, cp, self.params)
            self._charuco_for = intr
        return det

    def _detect_in(self, gray: np.ndarray | LumaFrame) -> DetectorOutput:
        """``detectMarkers`` of this tracker's detector; a video frame's luma goes only to the tracking
        window (:meth:`estimate` keeps it unconverted only then)."""
        d = self._detector
        if isinstance(d, TrackingDetector):
            return d.detectMarkers(gray)
        return d.detectMarkers(gray.full() if isinstance(gray, LumaFrame) else gray)

    def detect(self, image: np.ndarray | LumaFrame) -> Detection:
        """Detect the markers of this tracker's dictionary (no pose)."""
        gray = to_gray(image)
        corners, ids, rejected = self._detector.detectMarkers(gray)
        det = detection_from_opencv(corners, ids, rejected, self._shift_params)
        if self.refine in ("edge", "ecc") and len(det):
            intr = self._intrinsics_for(gray)[0]
            det.corners = self._edges(gray, det.corners, det.ids, intr)
            if self.refine == "ecc":
                det.corners = self._ecc(gray, det.corners, det.ids, intr)[0]
        return det

    def _edges(
        self, gray: np.ndarray, corners: np.ndarray, ids: Sequence[int] | np.ndarray, intr: Intrinsics
    ) -> np.ndarray:
        """The edge refinement of corners ``(n, 4, 2)`` (distorted pixels) of markers ``ids``, told the
        markers' cells across and their border (the border's width tells blur in linear light from blur in
        code values; in a video, a marker the lock has decided skips that check: :attr:`edge_lock`)."""
        border = int(self.params.markerBorderBits)
        lock = self.edge_lock
        space = "auto" if lock is None else lock.spaces(ids)
        res = refine_edges(
            gray, corners, intr, bits=self.dictionary.markerSize + 2 * border, border=border, space=space
        )
        if lock is not None:
            lock.observe(ids, res.linear_weight)
        return res.corners

    def _ecc(
        self, gray: np.ndarray, corners: np.ndarray, ids: Sequence[int] | np.ndarray, intr: Intrinsics
    ) -> tuple[np.ndarray, str | None]:
        """The ECC refinement of edge corners ``(n, 4, 2)`` (distorted pixels) of markers ``ids``: the
        refined corners and a note naming the markers that kept their edge corners (None: none did)."""
        for i in ids:
            if int(i) not in self._bits:
                self._bits[int(i)] = marker_bits(self.dictionary, int(i), int(self.params.markerBorderBits))
        res = refine_corners_ecc(gray, corners, [self._bits[int(i)] for i in ids], intr)
        kept = [f"marker {int(i)}: {why}" for i, why in zip(ids, res.fallback, strict=True) if why is not None]
        note = f"ECC alignment not used, edge corners kept ({'; '.join(kept)})" if kept else None
        return res.corners, note

    # -- pose ------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the frames before (a new video): the next search is the first frame's."""
        if hasattr(self._detector, "reset"):
            self._detector.reset()

    def state(self) -> dict[str, object]:
        """What the next frame's search depends on (its detectors' memory of the last frames: tracking
        window, misses in a row), JSON-able; ``{}`` for a tracker without memory.

        >>> from arshadow.camera import Intrinsics
        >>> MarkerTracker(Intrinsics.from_file("calib/synth_1280x720.yml"), marker_length=0.05).state()
        {'rescue_misses': 0}
        """
        st: dict[str, object] = self._detector.state() if hasattr(self._detector, "state") else {}
        for shared in (self.reference, self.edge_lock):
            if shared is not None:
                st = {**st, **shared.state()}
        return st

    def estimate(
        self, image_bgr: np.ndarray | LumaFrame, previous: MarkerPose | np.ndarray | None = None
    ) -> MarkerPose:
        """Detect and estimate the pose in one image.

        Parameters
        ----------
        image_bgr : (H, W, 3) uint8
            The photo (its size must match the calibration or have the same aspect ratio).
        previous : MarkerPose or (4, 4) float64, optional
            The previous frame's pose. When this frame's pose is ambiguous, the IPPE solution whose
            rotation is closer to ``previous`` is chosen (``chosen_by = "previous"``).

        Raises
        ------
        MarkerNotFoundError
            No marker (or not the requested id, or too few board points).
        CalibrationError
            The image size does not fit the calibration.
        """
        img = image_bgr if isinstance(image_bgr, LumaFrame) else np.asarray(image_bgr)
        if img.ndim not in (2, 3) or 0 in img.shape:
            raise ImageError(f"not an image (shape {img.shape})")
        intr, scaled = self._intrinsics_for(img)
        # a video frame's luma is converted only where it is read: the tracking window and the found
        # corners' neighbourhood (the whole frame for boards and full searches)
        lazy = isinstance(img, LumaFrame) and self.board is None and isinstance(self._detector, TrackingDetector)
        gray = img if lazy else to_gray(img)
        self._t_detect = None
        t0 = time.perf_counter()
        board = self.board
        if board is None:
            pose = self._estimate_marker(gray, intr)
        elif board.kind == "charuco":
            pose = self._estimate_charuco(to_gray(gray), intr, board)
        else:
            pose = self._estimate_gridboard(to_gray(gray), intr, board)
        total = 1e3 * (time.perf_counter() - t0)
        det_ms = total if self._t_detect is None else 1e3 * (self._t_detect - t0)
        pose.timings_ms = {"detect": det_ms, "pose": total - det_ms}
        pose.intrinsics, pose.scaled = intr, scaled
        pose.ambiguity_threshold = self.ambiguity_threshold
        pose.refine = self.refine
        if isinstance(gray, LumaFrame):
            gray = gray.near(pose.corners[:4])
        if pose.kind == "marker":
            pose.corner_instability = corner_instability(gray, pose.corners[:4])
            ref = pose.marker_ids[0]
            bits = self.dictionary.getBitsFromByteList(
                self.dictionary.bytesList[ref : ref + 1], self.dictionary.markerSize
            )
            pose.border_occlusion = border_occlusion(gray, pose.corners[:4], bits)
            if self.inverted:  # a white-on-black marker's ring is white: measure it on the negative too
                pose.border_occlusion = min(pose.border_occlusion, border_occlusion(255 - gray, pose.corners[:4], bits))
        if previous is not None and pose.alternative is not None and pose.ambiguous:
            prev = previous.cam_from_world if isinstance(previous, MarkerPose) else np.asarray(previous, float)
            if rotation_error_deg(pose.alternative.cam_from_world[:3, :3], prev[:3, :3]) < rotation_error_deg(
                pose.cam_from_world[:3, :3], prev[:3, :3]
            ):
                pose = pose.swapped()
        return pose

    def miss_hint(self, gray: np.ndarray) -> str:
        """The end of a "no marker found" message: markers printed inverted (:meth:`inverted_hint`), or
        (``explain_misses``) the other dictionaries' markers in the image (:func:`markers_in_image`)."""
        if not self.explain_misses:
            return ""
        hint = self.inverted_hint(gray)
        if hint:
            return hint
        other = markers_in_image(gray, skip=self.dictionary)
        if not other:
            return ""
        listed = "; ".join(
            f"{n} ids {', '.join(map(str, ids[:8]))}{' ...' if len(ids) > 8 else ''}" for n, ids in other.items()
        )
        return f"; the image has markers of other dictionaries: {listed} (give --dictionary)"

    def inverted_hint(self, gray: np.ndarray) -> str:
        """``""``, or (no marker found, not in inverted mode) a sentence saying that the image holds markers
        of this dictionary printed white on black, for the error message (one extra detection)."""
        if self.inverted:
            return ""
        p = make_detector_params("none", self.params)
        p.detectInvertedMarker = False
        _, ids, _ = cv2.aruco.ArucoDetector(self.dictionary, p).detectMarkers(255 - np.asarray(gray))
        if ids is None or len(ids) == 0:
            return ""
        found = ", ".join(map(str, sorted(set(np.asarray(ids).ravel().tolist()))))
        return (
            f"; the image has inverted (white-on-black) markers, ids {found}: use --inverted (or "
            "'inverted: 1' in the board file)"
        )

    def _want(self, marker_id: int | None) -> None:
        """Tell the wrapped detectors (tracking window, second search) which marker the next frame wants."""
        d: object = self._detector
        while hasattr(d, "__dict__"):  # the wrappers (Python objects) around OpenCV's detector
            if "marker_id" in vars(d):
                vars(d)["marker_id"] = marker_id
            d = vars(d).get("_base")

    def _make_pose(
        self,
        solved: Solved,
        obj: np.ndarray,
        img: np.ndarray,
        ids: Sequence[int],
        all_corners: dict[int, np.ndarray],
        kind: str,
    ) -> MarkerPose:
        sols, ratio = solved
        r, t, e = sols[0]
        alt = None
        if len(sols) > 1:
            r2, t2, e2 = sols[1]
            alt = AltPose(r2, t2, matrix_from_rvec_tvec(r2, t2), e2)
        return MarkerPose(
            r,
            t,
            matrix_from_rvec_tvec(r, t),
            [int(i) for i in ids],
            e,
            ratio,
            np.asarray(img, np.float64).reshape(-1, 2),
            np.asarray(obj, np.float64).reshape(-1, 3),
            int(len(obj)),
            alt,
            "error",
            None,
            False,
            all_corners,
            self.ambiguity_threshold,
            kind,
        )

    def _estimate_marker(self, gray: np.ndarray | LumaFrame, intr: Intrinsics) -> MarkerPose:
        corners, ids, rejected = self._detect_in(gray)
        self._t_detect = time.perf_counter()
        det = detection_from_opencv(corners, ids, rejected, self._shift_params)
        if len(det) == 0:
            raise MarkerNotFoundError(f"no marker of {self.dictionary_name} found{self.miss_hint(to_gray(gray))}")
        if isinstance(gray, LumaFrame):  # the found markers' neighbourhood is all the rest reads
            gray = gray.near(det.corners)
        if self.refine in ("edge", "ecc"):
            det.corners = self._edges(gray, det.corners, det.ids, intr)
        found = sorted(set(det.ids.tolist()))
        by_id = det.by_id
        if self.marker_id is not None:
            if self.marker_id not in found:
                raise MarkerNotFoundError(f"marker id {self.marker_id} not found (found {', '.join(map(str, found))})")
            ref = self.marker_id
        elif self.reference is not None:
            try:
                ref = self.reference.choose(by_id, count=self._counts_misses)
            finally:
                self._want(self.reference.id)  # the tracking window and the second search look for it
        else:
            ref = found[0]
        note = None
        if self.refine == "ecc":  # the reference marker only: the pose's (the others keep their edge corners)
            ecc, note = self._ecc(gray, by_id[ref][None], [ref], intr)
            by_id[ref] = ecc[0]
        img = by_id[ref]
        obj = marker_object_points(self.marker_length)
        sols = solve_planar(intr, obj, img, square=True, lm=self.pnp_refine)
        pose = self._make_pose(sols, obj, img, [ref] + [i for i in found if i != ref], by_id, "marker")
        pose.refine_note = note
        return pose

    def _estimate_gridboard(self, gray: np.ndarray, intr: Intrinsics, board: Board) -> MarkerPose:
        corners, ids, rejected = self._detector.detectMarkers(gray)
        if ids is None or len(ids) == 0:
            raise MarkerNotFoundError(f"no marker of {self.dictionary_name} found{self.miss_hint(gray)}")
        if board.kind == "gridboard":  # the detector given for a grid board has refineDetectedMarkers (docstring)
            corners, ids, rejected, _ = cast(BoardDetector, self._detector).refineDetectedMarkers(
                gray, board.cv_board, corners, ids, rejected, intr.K, intr.dist_cv
            )
        det = detection_from_opencv(corners, ids, rejected, self._shift_params)
        self._t_detect = time.perf_counter()
        # as for one marker (the video default; the marker-map work). Not ECC: a board's many corners average
        # their errors out (a 5 x 7 board: no rotation gain, 0.05 -> 0.015 mm, for 46 -> 90-98 ms a photo)
        if self.refine in ("edge", "ecc") and len(det):
            det.corners = self._edges(gray, det.corners, det.ids, intr)
        obj, img = board.cv_board.matchImagePoints(
            tuple(c.reshape(1, 4, 2).astype(np.float32) for c in det.corners), det.ids.reshape(-1, 1).astype(np.int32)
        )
        if obj is None or len(obj) < 4:
            raise MarkerNotFoundError(
                f"none of the board's markers found (found ids {', '.join(map(str, sorted(set(det.ids.tolist()))))})"
            )
        obj = np.asarray(obj, np.float64).reshape(-1, 3) @ OPENCV_BOARD_TO_WORLD.T
        img = np.asarray(img, np.float64).reshape(-1, 2)
        if board.planar:
            sols = solve_planar(intr, obj, img, square=False, lm=self.pnp_refine)
        else:
            sols = solve_general(intr, obj, img, lm=self.pnp_refine)
        board_ids = set(board.marker_ids)
        used = [i for i in sorted(set(det.ids.tolist())) if i in board_ids]
        return self._make_pose(sols, obj, img, used, det.by_id, board.kind)

    def _estimate_charuco(self, gray: np.ndarray, intr: Intrinsics, board: Board) -> MarkerPose:
        det = self._charuco_detector(intr, board)
        ch_corners, ch_ids, m_corners, m_ids = det.detectBoard(gray)
        self._t_detect = time.perf_counter()
        if m_ids is None or len(m_ids) == 0:
            raise MarkerNotFoundError(f"no marker of {self.dictionary_name} found{self.miss_hint(gray)}")
        n = 0 if ch_ids is None else len(ch_ids)
        if n < 4:
            raise MarkerNotFoundError(f"ChArUco board: only {n} chessboard corners found (need at least 4)")
        if board.cv_charuco.checkCharucoCornersCollinear(ch_ids):
            raise MarkerNotFoundError("ChArUco board: the detected corners are collinear (no pose)")
        # OpenCV's stubs want a sequence of corner arrays; ChArUco corners are one (n, 1, 2) array
        obj, img = board.cv_charuco.matchImagePoints(ch_corners, ch_ids)  # type: ignore[call-overload]
        obj = np.asarray(obj, np.float64).reshape(-1, 3) @ OPENCV_BOARD_TO_WORLD.T
        img = np.asarray(img, np.float64).reshape(-1, 2)
        sols = solve_planar(intr, obj, img, square=False, lm=self.pnp_refine)
        mdet = detection_from_opencv(m_corners, m_ids, None, self.params)
        return self._make_pose(sols, obj, img, sorted(set(mdet.ids.tolist())), mdet.by_id, "charuco")


def make_fast_tracker(intrinsics: Intrinsics, **tracker_kwargs: Any) -> MarkerTracker:
    """The tracker of the pipeline's fast first pass: ``MarkerTracker(intrinsics, detector="fast", ...)``.

    A :class:`MarkerTracker` with one 7-px threshold window
    (:func:`~arshadow.tracking.fastdetect.fast_detector_params`) and, for single markers, detection at half
    resolution (:class:`~arshadow.tracking.fastdetect.HalfResolutionDetector`). The session falls back to
    the tracker's full search when this finds nothing. With several markers in view and no ``marker_id``,
    the reference is the lowest id found, so give ``marker_id`` for a frame that cannot change between
    passes.
    """
    return MarkerTracker(intrinsics, **tracker_kwargs, detector="fast")
