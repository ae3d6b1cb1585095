"""Planar pose (IPPE, polished by Levenberg-Marquardt) and the pose record :class:`MarkerPose`.

Pose: ``(rvec, tvec)`` world -> OpenCV camera, as ``cv2.solvePnP`` gives them (world frames:
:mod:`arshadow.tracking.dictionary` for a marker, :mod:`arshadow.tracking.board` for a board).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TypeAlias

import cv2
import numpy as np
import numpy.typing as npt

from ..camera.model import Intrinsics
from ..errors import MarkerNotFoundError, UsageError
from .quality import (
    AMBIGUITY_FLAG,
    MAX_BORDER_OCCLUSION,
    MAX_CORNER_INSTABILITY,
    MIN_CONFIDENT_SIDE_PX,
    pose_notes,
)
from .quality import flag_reasons as quality_flag_reasons  # MarkerPose.flag_reasons shadows the name

__all__ = ["AltPose", "MarkerPose", "rms_reprojection_px", "solve_general", "solve_planar"]

#: one pose solution: ``(rvec (3,) float64, tvec (3,) float64, rms reprojection error px)``
Solution: TypeAlias = tuple[np.ndarray, np.ndarray, float]
#: what the solvers return: the solutions (best first) and the ambiguity ratio (None: one solution)
Solved: TypeAlias = tuple[list[Solution], float | None]


@dataclass
class AltPose:
    """The other IPPE solution (kept for sequences: the video layer may prefer it)."""

    rvec: np.ndarray
    tvec: np.ndarray
    cam_from_world: np.ndarray
    reprojection_error_px: float


@dataclass
class MarkerPose:
    """Pose of the marker (or board) in one image.

    Attributes
    ----------
    rvec, tvec : (3,) float64
        World -> OpenCV camera (as ``cv2.solvePnP`` gives them).
    cam_from_world : (4, 4) float64
    marker_ids : list[int]
        The reference marker first, then every other detected id (single marker), or the board's
        detected ids.
    reprojection_error_px : float
        RMS distance between the detected and re-projected points, pixels.
    pose_ambiguity : float or None
        ``err_best / err_second`` of the two planar (IPPE) solutions, in (0, 1]; high = ambiguous
        (flagged when >= :data:`AMBIGUITY_FLAG`). None when there is no second solution.
    corners : (n, 2) float64
        The detected image points used for the pose.
    object_points : (n, 3) float64
        Their world coordinates.
    n_points : int
    alternative : AltPose or None
        The other IPPE solution.
    chosen_by : str
        ``"error"`` (lower reprojection error) or ``"previous"`` (closer to the previous frame's pose).
    intrinsics : Intrinsics
        The intrinsics used (scaled to the image when ``scaled``).
    scaled : bool
        The calibration was scaled to this image's size (same aspect ratio).
    all_corners : dict[int, (4, 2)]
        Every detected marker's corners.
    kind : str
        ``"marker"``, ``"gridboard"`` or ``"charuco"``.
    timings_ms : dict
        ``{"detect": ms, "pose": ms}`` spent in :meth:`MarkerTracker.estimate`.
    """

    rvec: np.ndarray
    tvec: np.ndarray
    cam_from_world: np.ndarray
    marker_ids: list[int]
    reprojection_error_px: float
    pose_ambiguity: float | None
    corners: np.ndarray
    object_points: np.ndarray
    n_points: int
    alternative: AltPose | None = None
    chosen_by: str = "error"
    intrinsics: Intrinsics | None = None
    scaled: bool = False
    all_corners: dict[int, np.ndarray] = field(default_factory=dict)
    ambiguity_threshold: float = AMBIGUITY_FLAG
    kind: str = "marker"
    timings_ms: dict[str, float] = field(default_factory=dict)
    #: single marker: how far its corners move between sub-pixel refinement windows of 5 and 13 px, as a
    #: share of its shortest side (:func:`corner_instability`); None for boards
    corner_instability: float | None = None
    #: single marker: how light the lightest cell of its black border ring is, between its black (0) and
    #: white (1) (:func:`border_occlusion`); None for boards
    border_occlusion: float | None = None
    #: the corner refinement the tracker used (``"subpix"``, ``"edge"``, ...): which reasons are flags and
    #: which report fields (:data:`arshadow.tracking.quality.REPORT_ONLY`); None: every reason is a flag
    refine: str | None = None
    #: why the requested refinement was not used for some markers (``"ecc"``: the alignment failed and the
    #: edge corners were kept, :mod:`arshadow.tracking.ecc`); None when it was used throughout
    refine_note: str | None = None

    @property
    def ambiguous(self) -> bool:
        """True when the two IPPE solutions explain the corners almost equally well, or (single marker)
        when the marker is under :data:`MIN_CONFIDENT_SIDE_PX` across: its corners cannot tell the two
        solutions apart reliably (the stress suite ('s)'s stress suite: a 20-px marker gave a pose 69 deg off with
        ratio 0.20), its corners are blurred (:data:`MAX_CORNER_INSTABILITY`) or something lies over it
        (:data:`MAX_BORDER_OCCLUSION`)."""
        if self.pose_ambiguity is not None and self.pose_ambiguity >= self.ambiguity_threshold:
            return True
        if self.corner_instability is not None and self.corner_instability > MAX_CORNER_INSTABILITY:
            return True
        if self.border_occlusion is not None and self.border_occlusion > MAX_BORDER_OCCLUSION:
            return True
        if self.kind == "marker" and self.pose_ambiguity is not None and len(self.corners) >= 4:
            q = np.asarray(self.corners, np.float64)[:4]
            return bool(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).min() < MIN_CONFIDENT_SIDE_PX)
        return False

    @property
    def flag_reasons(self) -> list[str]:
        """Why this pose is flagged, one sentence per reason with its number ([] when it is not):
        :func:`arshadow.tracking.quality.flag_reasons` (the ambiguity tests of :attr:`ambiguous`, and a
        reprojection error far above what the detected corners allow), less those that are report fields
        for this pose's refinement (:attr:`notes`)."""
        return quality_flag_reasons(self)

    @property
    def notes(self) -> list[str]:
        """The reasons that are report fields, not flags, for this pose's refinement
        (:func:`arshadow.tracking.quality.pose_notes`: measured to be wrong more often than right)."""
        return pose_notes(self)

    @property
    def flagged(self) -> bool:
        """A flag reason holds (:attr:`flag_reasons`): one of :attr:`ambiguous`'s tests that are flags for
        this pose's refinement, or a reprojection error far above what the detected corners allow."""
        return bool(self.flag_reasons)

    def swapped(self) -> MarkerPose:
        """This pose with the alternative IPPE solution chosen instead (for sequences)."""
        if self.alternative is None:
            raise UsageError("this pose has no alternative solution")
        a = self.alternative
        alt = AltPose(self.rvec, self.tvec, self.cam_from_world, self.reprojection_error_px)
        return replace(
            self,
            rvec=a.rvec,
            tvec=a.tvec,
            cam_from_world=a.cam_from_world,
            reprojection_error_px=a.reprojection_error_px,
            alternative=alt,
            chosen_by="previous",
            timings_ms=dict(self.timings_ms),
        )


def rms_reprojection_px(
    intr: Intrinsics, obj: np.ndarray, img: np.ndarray, rvec: np.ndarray, tvec: np.ndarray
) -> float:
    """RMS distance (pixels) between ``img (n, 2)`` and ``obj (n, 3)`` projected by ``(rvec, tvec)``."""
    proj = cv2.projectPoints(obj, rvec, tvec, intr.K, intr.dist_cv)[0].reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=1))))


def solve_planar(intr: Intrinsics, obj: npt.ArrayLike, img: npt.ArrayLike, square: bool, lm: bool = True) -> Solved:
    """Both planar (IPPE) solutions, sorted by RMS reprojection error, and their ambiguity ratio.

    The ratio ``err_best / err_second`` is taken from the two IPPE solutions as IPPE returns them
    (each is the exact pose of one of the two homography-consistent interpretations). Then each
    solution is polished by Levenberg-Marquardt on the reprojection error (``lm``); a second solution
    that LM drags onto the first is kept unrefined, so the alternative stays a distinct pose.

    Returns
    -------
    sols : list of (rvec (3,), tvec (3,), rms_px)
    ratio : float or None
    """
    flags = cv2.SOLVEPNP_IPPE_SQUARE if square else cv2.SOLVEPNP_IPPE
    K, dist = intr.K, intr.dist_cv
    obj = np.ascontiguousarray(obj, dtype=np.float64).reshape(-1, 3)
    img = np.ascontiguousarray(img, dtype=np.float64).reshape(-1, 2)
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, K, dist, flags=flags)
    except cv2.error as exc:
        raise MarkerNotFoundError(f"pose estimation failed ({str(exc).strip().splitlines()[-1][:80]})") from None
    raw = []
    for r, t in zip(rvecs[:n], tvecs[:n], strict=True):
        r = np.asarray(r, np.float64).reshape(3, 1).copy()
        t = np.asarray(t, np.float64).reshape(3, 1).copy()
        raw.append((r, t, rms_reprojection_px(intr, obj, img, r, t)))
    if not raw:
        raise MarkerNotFoundError("pose estimation found no solution")
    raw.sort(key=lambda s: s[2])
    ratio = None
    if len(raw) > 1:
        e0, e1 = raw[0][2], raw[1][2]
        ratio = 1.0 if e1 <= 0 else float(min(1.0, e0 / e1))
    sols: list[Solution] = []
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12)
    for k, (r, t, e) in enumerate(raw[:2]):
        if lm:
            r2, t2 = cv2.solvePnPRefineLM(obj, img, K, dist, r.copy(), t.copy(), criteria=crit)
            e2 = rms_reprojection_px(intr, obj, img, r2, t2)
            collapsed = k > 0 and np.linalg.norm(r2.ravel() - sols[0][0]) < 1e-5
            if e2 <= e and not collapsed:
                r, t, e = r2, t2, e2
        sols.append((r.ravel(), t.ravel(), e))
    return sols, ratio


def solve_general(intr: Intrinsics, obj: npt.ArrayLike, img: npt.ArrayLike, lm: bool = True) -> Solved:
    """The pose of non-coplanar points ``obj (n, 3)`` seen at ``img (n, 2)`` (a generic board whose markers
    are not on one plane): ``cv2.SOLVEPNP_SQPNP`` (globally optimal), polished by Levenberg-Marquardt
    (``lm``). Returns ``([(rvec (3,), tvec (3,), rms_px)], None)`` like :func:`solve_planar` (one
    solution: no planar ambiguity).
    """
    K, dist = intr.K, intr.dist_cv
    obj = np.ascontiguousarray(obj, dtype=np.float64).reshape(-1, 3)
    img = np.ascontiguousarray(img, dtype=np.float64).reshape(-1, 2)
    try:
        ok, r, t = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_SQPNP)
    except cv2.error as exc:
        raise MarkerNotFoundError(f"pose estimation failed ({str(exc).strip().splitlines()[-1][:80]})") from None
    if not ok:
        raise MarkerNotFoundError("pose estimation found no solution")
    if lm:
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12)
        r, t = cv2.solvePnPRefineLM(obj, img, K, dist, r.copy(), t.copy(), criteria=crit)
    return [(r.ravel(), t.ravel(), rms_reprojection_px(intr, obj, img, r, t))], None
