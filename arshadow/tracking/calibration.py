"""Camera calibration from photos of a chessboard or a ChArUco board.

Each photo becomes a *view* (object points + detected image points) or is rejected with a reason
(unreadable, wrong size, pattern not found, too few corners); :func:`calibrate` then runs
``cv2.calibrateCameraExtended`` and returns the intrinsics with the RMS and per-view errors.
The chessboard path is OpenCV's calibration sample (``findChessboardCorners`` with adaptive threshold and
normalisation, ``cornerSubPix`` 11x11), so it reproduces OpenCV's own calibrations.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np

from ..camera.model import Intrinsics
from ..errors import ArshadowError, CalibrationError, UsageError
from ..io import read_image
from .board import Board
from .detect import to_gray
from .dictionary import get_dictionary

__all__ = ["Pattern", "parse_pattern", "View", "find_view", "CalibrationResult", "calibrate", "MIN_VIEWS"]

#: fewest usable views accepted by :func:`calibrate` (each gives 6 pose unknowns on top of the
#: intrinsics; fewer than this is poorly conditioned in practice)
MIN_VIEWS = 5
#: a ChArUco view needs at least this many corners
MIN_CHARUCO_CORNERS = 6


@dataclass(frozen=True)
class Pattern:
    """A calibration target.

    ``kind`` "chessboard": ``cols x rows`` *inner* corners, ``square`` metres; object points
    ``(i * square, j * square, 0)`` with i fastest (OpenCV's sample). ``kind`` "charuco": ``cols x rows``
    squares, ``square`` and ``marker`` metres, ``dictionary`` name.
    """

    kind: str
    cols: int
    rows: int
    square: float
    marker: float = 0.0
    dictionary: str = ""

    def describe(self) -> str:
        if self.kind == "chessboard":
            return f"chessboard {self.cols}x{self.rows} inner corners, {1000 * self.square:g} mm squares"
        return (
            f"charuco {self.cols}x{self.rows} squares, {1000 * self.square:g} mm squares, "
            f"{1000 * self.marker:g} mm {self.dictionary} markers"
        )

    @property
    def spec(self) -> str:
        if self.kind == "chessboard":
            return f"chessboard:{self.cols},{self.rows},{self.square:g}"
        return f"charuco:{self.cols},{self.rows},{self.square:g},{self.marker:g},{self.dictionary}"

    @property
    def object_points(self) -> np.ndarray:
        """Chessboard: (cols*rows, 3) float32 object points."""
        obj = np.zeros((self.cols * self.rows, 3), np.float32)
        obj[:, :2] = np.mgrid[0 : self.cols, 0 : self.rows].T.reshape(-1, 2) * self.square
        return obj

    @cached_property
    def charuco(self) -> tuple[Board, cv2.aruco.CharucoDetector]:
        """ChArUco: ``(Board, cv2.aruco.CharucoDetector)``, built once per pattern, not per photo."""
        board = Board(
            "charuco", (self.cols, self.rows), self.marker, dictionary=self.dictionary, square_length=self.square
        )
        return board, cv2.aruco.CharucoDetector(board.cv_charuco)


def parse_pattern(spec: str) -> Pattern:
    """Parse ``chessboard:COLS,ROWS,SQUARE`` or ``charuco:COLS,ROWS,SQUARE,MARKER,DICT`` (metres).

    Examples
    --------
    >>> parse_pattern("chessboard:9,6,0.025").describe()
    'chessboard 9x6 inner corners, 25 mm squares'
    """
    s = str(spec).strip()
    kind, _, rest = s.partition(":")
    kind = kind.lower()
    parts = [p.strip() for p in rest.split(",")] if rest else []
    bad = UsageError(
        f"bad pattern '{s}' (use chessboard:COLS,ROWS,SQUARE or charuco:COLS,ROWS,SQUARE,MARKER,DICT; "
        "lengths in metres, chessboard COLS,ROWS = inner corners)"
    )
    try:
        if kind == "chessboard" and len(parts) == 3:
            p = Pattern("chessboard", int(parts[0]), int(parts[1]), float(parts[2]))
        elif kind == "charuco" and len(parts) == 5:
            p = Pattern("charuco", int(parts[0]), int(parts[1]), float(parts[2]), float(parts[3]), parts[4])
        else:
            raise bad
    except (TypeError, ValueError):
        raise bad from None
    if p.kind == "chessboard" and (p.cols < 2 or p.rows < 2):
        raise UsageError(f"pattern '{s}': a chessboard needs at least 2x2 inner corners")
    if p.kind == "charuco":
        get_dictionary(p.dictionary)
        if p.cols < 3 or p.rows < 3:
            raise UsageError(f"pattern '{s}': a ChArUco board needs at least 3x3 squares")
        if not (0 < p.marker < p.square):
            raise UsageError(f"pattern '{s}': the marker must be smaller than the square")
    if not (math.isfinite(p.square) and p.square > 0):
        raise UsageError(f"pattern '{s}': the square length must be positive (metres)")
    return p


@dataclass
class View:
    """One photo's contribution: ``object_points (n, 3) float32``, ``image_points (n, 1, 2) float32``;
    or ``reason`` (why it was rejected) with no points."""

    path: str
    size: tuple[int, int] | None = None
    object_points: np.ndarray | None = None
    image_points: np.ndarray | None = None
    reason: str | None = None

    @property
    def ok(self) -> bool:
        return self.reason is None


def find_view(path: str | Path, pattern: Pattern, image: np.ndarray | None = None) -> View:
    """Detect the pattern in one photo. Never raises for a bad photo: the View carries the reason."""
    name = str(path)
    try:
        img = read_image(path) if image is None else image
    except ArshadowError as exc:
        return View(name, reason=str(exc))
    gray = to_gray(img)  # any layout or depth a caller passes as image=, like the marker detector
    size = (gray.shape[1], gray.shape[0])
    if pattern.kind == "chessboard":
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        found, corners = cv2.findChessboardCorners(gray, (pattern.cols, pattern.rows), flags=flags)
        if not found:
            return View(
                name,
                size,
                reason=f"no {pattern.cols}x{pattern.rows} chessboard found (all inner corners must be visible)",
            )
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 1e-4)
        corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), crit)
        return View(name, size, pattern.object_points, corners.astype(np.float32))
    board, det = pattern.charuco
    ch_corners, ch_ids, _, m_ids = det.detectBoard(gray)
    n = 0 if ch_ids is None else len(ch_ids)
    if n < MIN_CHARUCO_CORNERS:
        nm = 0 if m_ids is None else len(m_ids)
        return View(name, size, reason=f"only {n} ChArUco corners found ({nm} markers; need {MIN_CHARUCO_CORNERS})")
    if board.cv_charuco.checkCharucoCornersCollinear(ch_ids):
        return View(name, size, reason="the ChArUco corners found are collinear")
    # OpenCV's stubs want a sequence of corner arrays; ChArUco corners are one (n, 1, 2) array
    obj, imgp = board.cv_charuco.matchImagePoints(ch_corners, ch_ids)  # type: ignore[call-overload]
    return View(name, size, np.asarray(obj, np.float32).reshape(-1, 3), np.asarray(imgp, np.float32).reshape(-1, 1, 2))


@dataclass
class CalibrationResult:
    """Intrinsics plus the quality figures of a calibration."""

    intrinsics: Intrinsics
    rms: float
    per_view_errors: np.ndarray
    views: list[View]
    rejected: list[View]
    flags: int
    pattern: Pattern | None
    intrinsics_std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rvecs: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    tvecs: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def to_file(self, path: str | Path) -> Path:
        """Write the calibration (OpenCV keys) with RMS, per-view errors, views, extrinsics."""
        return self.intrinsics.to_file(
            path,
            calibration_time=_dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            nframes=len(self.views),
            pattern=None if self.pattern is None else self.pattern.spec,
            flags=int(self.flags),
            avg_reprojection_error=float(self.rms),
            per_view_reprojection_errors=np.asarray(self.per_view_errors, float),
            views=[v.path for v in self.views],
            rejected_views=[f"{v.path}: {v.reason}" for v in self.rejected] or None,
            intrinsics_std=np.asarray(self.intrinsics_std, float) if np.size(self.intrinsics_std) else None,
            extrinsic_parameters=np.hstack([self.rvecs, self.tvecs]) if len(self.rvecs) else None,
        )


def _view_size(v: View) -> tuple[int, int]:
    """A usable view's image size ``(W, H)`` (:func:`find_view` sets it)."""
    if v.size is None:
        raise CalibrationError(f"{v.path}: the view has no image size")
    return v.size


def _view_points(v: View) -> tuple[np.ndarray, np.ndarray]:
    """A usable view's ``object_points (n, 3) float32`` and ``image_points (n, 1, 2) float32``."""
    if v.object_points is None or v.image_points is None:
        raise CalibrationError(f"{v.path}: the view has no points")
    return v.object_points, v.image_points


def calibrate(
    views: Iterable[View],
    *,
    flags: int = 0,
    min_views: int = MIN_VIEWS,
    max_view_error: float | None = None,
    pattern: Pattern | None = None,
) -> CalibrationResult:
    """Calibrate from views (:func:`find_view` results; rejected ones are carried along).

    Parameters
    ----------
    views : list of View
    flags : int
        ``cv2.CALIB_*`` flags (e.g. ``cv2.CALIB_FIX_ASPECT_RATIO``).
    min_views : int
        Fewest usable views (CalibrationError otherwise).
    max_view_error : float, optional
        Reject views whose RMS error exceeds this (pixels) and calibrate again without them.

    Raises
    ------
    CalibrationError
        Too few usable views, mixed image sizes, or OpenCV failed.
    """
    views = list(views)
    rejected = [v for v in views if not v.ok]
    good = [v for v in views if v.ok]
    if good:
        size = _view_size(good[0])
        for v in good[1:]:
            if v.size != size:
                w, h = _view_size(v)
                v.reason = f"image size {w}x{h} differs from the first view's {size[0]}x{size[1]}"
        rejected += [v for v in good if not v.ok]
        good = [v for v in good if v.ok]
    if len(good) < min_views:
        why = "; ".join(f"{Path(v.path).name}: {v.reason}" for v in rejected[:5])
        raise CalibrationError(
            f"only {len(good)} usable view(s), need at least {min_views}"
            + (f" (rejected: {why}{' ...' if len(rejected) > 5 else ''})" if rejected else "")
        )
    size = _view_size(good[0])
    for _ in range(3):
        K0 = np.eye(3)
        try:
            # OpenCV's stubs lack None for the output-only distCoeffs
            rms, K, dist, rvecs, tvecs, std_int, _, per_view = cv2.calibrateCameraExtended(  # type: ignore[call-overload]
                [_view_points(v)[0] for v in good],
                [_view_points(v)[1] for v in good],
                size,
                K0,
                None,
                flags=flags,
            )
        except cv2.error as exc:
            raise CalibrationError(f"calibration failed: {str(exc).strip().splitlines()[-1][:120]}") from None
        per_view = np.asarray(per_view, float).ravel()
        if max_view_error is None or per_view.max() <= max_view_error:
            break
        worst = [v for v, e in zip(good, per_view, strict=True) if e > max_view_error]
        for v, e in zip(good, per_view, strict=True):
            if e > max_view_error:
                v.reason = f"reprojection error {e:.2f} px > {max_view_error} px"
        rejected += worst
        good = [v for v in good if v.ok]
        if len(good) < min_views:
            raise CalibrationError(
                f"only {len(good)} view(s) left after rejecting those above "
                f"{max_view_error} px, need at least {min_views}"
            )
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CalibrationError("calibration diverged (non-finite or non-positive focal length)")
    intr = Intrinsics.from_K(K, size[0], size[1], np.asarray(dist, float).ravel()[:14])
    return CalibrationResult(
        intr,
        float(rms),
        per_view,
        good,
        rejected,
        flags,
        pattern,
        np.asarray(std_int, float).ravel(),
        np.asarray(rvecs, float).reshape(-1, 3),
        np.asarray(tvecs, float).reshape(-1, 3),
    )
