"""Quality gates of a single-marker pose: the thresholds of :attr:`MarkerPose.ambiguous
<arshadow.tracking.pose.MarkerPose.ambiguous>` and the image measurements behind them (corner stability
across refinement windows, occlusion of the black border ring)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import cv2
import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from .pose import MarkerPose

__all__ = [
    "AMBIGUITY_FLAG",
    "MIN_CONFIDENT_SIDE_PX",
    "MAX_CORNER_INSTABILITY",
    "MAX_BORDER_OCCLUSION",
    "MAX_REPROJECTION_PX",
    "MAX_REPROJECTION_SIDE_SHARE",
    "border_occlusion",
    "corner_instability",
    "reprojection_limit_px",
    "REPROJECTION_HOLD_FACTOR",
    "REPORT_ONLY",
    "reprojection_hold",
    "all_reasons",
    "flag_reasons",
    "pose_notes",
]

#: pose_ambiguity (err_best / err_second of the two IPPE solutions) at or above which a single-marker
#: pose is flagged as ambiguous (see docs/tracking.md for how it was chosen)
AMBIGUITY_FLAG = 0.3
#: a single marker with a side shorter than this (pixels) is always flagged ambiguous (see MarkerPose)
MIN_CONFIDENT_SIDE_PX = 32.0
#: a single marker whose corners move by more than this share of its side between refinement windows is
#: flagged ambiguous: blurred corners (the stress suite: heavy blur gave confident poses 2-4 deg off; their
#: corners moved by 0.010-0.068 of the side, sharp ones by < 0.006)
MAX_CORNER_INSTABILITY = 0.008
#: a single marker whose black border ring has a cell lighter than this share of the way from the marker's
#: black to its white (:func:`border_occlusion`) is flagged ambiguous: something covers the marker (issue
#: 12: a grey patch over one corner gave a pose 3.7 deg off with ratio 0.25 and stable corners; its ring
#: cells read 0.45, sharp unoccluded markers <= 0.15 in the stress suite)
MAX_BORDER_OCCLUSION = 0.3
#: a pose whose RMS reprojection error exceeds ``max(MAX_REPROJECTION_PX, MAX_REPROJECTION_SIDE_SHARE x
#: the shortest marker side in pixels)`` is flagged: the detector's corners are good to a fraction of a
#: pixel (real 640x480 webcam clips with strong distortion: 0.1-0.4 px for one marker, 1.1 px median for
#: a whole 18-marker board), a board file that does not match the photo gives tens of pixels (the sanity gates: 74)
MAX_REPROJECTION_PX = 4.0
MAX_REPROJECTION_SIDE_SHARE = 0.05
#: a video frame whose pose reprojects worse than this many times :func:`reprojection_limit_px` is not
#: rendered: the frame is held like a frame without the marker (the trust fixes: on the 2x upscaled chessboard
#: clip, 7 frames at 43-148 px, the median 2.2 px, the frames between 4 and 8 px agreeing with their
#: neighbours; the smoothing hid the broken ones within ~10 px of the path)
REPROJECTION_HOLD_FACTOR = 3.0
#: corner refinement -> the reasons (their kind, before the colon) that are report fields (``pose_notes``),
#: not flags: measured by tests/benchmarks/bench_flags.py (docs/tracking.md, "Calibrated flags"), with the
#: edge refinement (arshadow video's default) a pose with blurred corners or a marker under 32 px is more
#: than 1 deg or 2 % off in only 34-47 % / 38-47 % of cases at every threshold tried (precision < 0.5), and
#: the sample video's 60 frames (0.15 deg median from the truth) were all flagged for both. The ECC
#: refinement starts from the edge corners and keeps them when it fails: the same, and its fallback
#: (``refinement``: the corners are the edge refinement's, as good as ``edge`` gives) is a note too
REPORT_ONLY: dict[str, tuple[str, ...]] = {
    "edge": ("blurred corners", "small marker"),
    "ecc": ("blurred corners", "small marker", "refinement"),
}


class ReprojectedPose(Protocol):
    """What :func:`reprojection_hold` reads of a pose (a :class:`~arshadow.tracking.pose.MarkerPose`)."""

    @property
    def corners(self) -> npt.ArrayLike:
        """(n, 2) image points, the reference marker's quad first."""

    @property
    def reprojection_error_px(self) -> float:
        """RMS reprojection error, pixels."""


def border_occlusion(gray: np.ndarray, quad: npt.ArrayLike, bits: np.ndarray) -> float:
    """How light the lightest cell of a marker's black border ring is, as a share of the way from the
    marker's black (0) to its white (1).

    The marker ``quad (4, 2)`` (OpenCV's corner order: the marker's own top-left first) is rectified onto
    its cell grid; each cell's central quarter is averaged; black and white are the medians of the cells
    the dictionary says are black / white. Shadows and light gradients leave the ring near 0 (they darken
    the white cells, not lighten the black ring); something lighter than black lying over the marker (a
    hand, a sticker, glare) lifts its ring cells. Cells outside the image are ignored.

    Parameters
    ----------
    gray : (H, W) uint8
    quad : (4, 2) float
    bits : (n, n) uint8
        The marker's inner bits (1 = white), ``Dictionary.getBitsFromByteList``.
    """
    n, c = int(bits.shape[0]) + 2, 8
    dst = np.array([[0, 0], [n * c, 0], [n * c, n * c], [0, n * c]], np.float32)
    H = cv2.getPerspectiveTransform(np.asarray(quad, np.float32).reshape(4, 2), dst)
    can = cv2.warpPerspective(
        gray, H, (n * c, n * c), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0
    ).astype(np.float32)
    cells = can.reshape(n, c, n, c)[:, 2:6, :, 2:6].mean(axis=(1, 3))
    h, w = gray.shape[:2]
    q = np.asarray(quad, np.float64).reshape(4, 2)
    inside = np.ones((n, n), bool)
    if q.min() < 0 or q[:, 0].max() > w - 1 or q[:, 1].max() > h - 1:
        # part of the marker is off the image: a cell counts when the corners of its sampled centre are in it
        g = np.arange(n, dtype=np.float32) * c
        corners = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 1, 2)[:, :, ::-1]  # (x, y)
        for dx, dy in ((2, 2), (6, 2), (2, 6), (6, 6)):
            p = cv2.perspectiveTransform(corners + np.array([dx, dy], np.float32), np.linalg.inv(H)).reshape(n, n, 2)
            inside &= (p[..., 0] >= 0) & (p[..., 1] >= 0) & (p[..., 0] <= w - 1) & (p[..., 1] <= h - 1)
    white = np.zeros((n, n), bool)
    white[1:-1, 1:-1] = np.asarray(bits) > 0
    ring = np.ones((n, n), bool)
    ring[1:-1, 1:-1] = False
    if not (inside & white).any() or not (inside & ~white).any() or not (inside & ring).any():
        return 0.0
    black_level, white_level = np.median(cells[inside & ~white]), np.median(cells[inside & white])
    if white_level - black_level < 1.0:
        return 0.0
    return float(((cells[inside & ring] - black_level) / (white_level - black_level)).max())


def corner_instability(gray: np.ndarray, quad: npt.ArrayLike) -> float:
    """How far the 4 corners ``quad (4, 2)`` of a marker move between ``cv2.cornerSubPix`` windows of 5 and
    13 px, as a share of the quad's shortest side: ~0 for a sharp corner (any window finds the same
    point), large for a blurred or disturbed one."""
    q = np.ascontiguousarray(np.asarray(quad, np.float32).reshape(-1, 1, 2)[:4])
    side = float(np.linalg.norm(q[:, 0] - np.roll(q[:, 0], 1, axis=0), axis=1).min())
    h, w = gray.shape[:2]
    inside = (q[:, 0, 0] >= 7) & (q[:, 0, 1] >= 7) & (q[:, 0, 0] < w - 7) & (q[:, 0, 1] < h - 7)
    if side <= 0 or not np.all(inside):
        return 0.0  # too close to the border for the large window
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 0.001)
    a = cv2.cornerSubPix(gray, q.copy(), (2, 2), (-1, -1), crit)
    b = cv2.cornerSubPix(gray, q.copy(), (6, 6), (-1, -1), crit)
    return float(np.linalg.norm((a - b)[:, 0], axis=1).max() / side)


def reprojection_limit_px(corners: npt.ArrayLike) -> float:
    """The RMS reprojection error (pixels) above which a pose is flagged, for image points ``corners
    (n, 2)`` (the first 4 = the reference marker's quad): see :data:`MAX_REPROJECTION_PX`."""
    q = np.asarray(corners, np.float64).reshape(-1, 2)[:4]
    side = float(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).min()) if len(q) == 4 else 0.0
    return max(MAX_REPROJECTION_PX, MAX_REPROJECTION_SIDE_SHARE * side)


def reprojection_hold(pose: ReprojectedPose) -> str | None:
    """Why a video frame's pose must not be rendered (the frame is held instead), or None: its RMS
    reprojection error is above :data:`REPROJECTION_HOLD_FACTOR` x :func:`reprojection_limit_px`.

    >>> from types import SimpleNamespace
    >>> quad = [[0, 0], [100, 0], [100, 100], [0, 100]]
    >>> reprojection_hold(SimpleNamespace(corners=quad, reprojection_error_px=1.2)) is None
    True
    >>> reprojection_hold(SimpleNamespace(corners=quad, reprojection_error_px=40.0))
    'reprojection error 40.0 px, above 3 x the 5.0 px the detected corners allow: pose not used'
    """
    lim = reprojection_limit_px(pose.corners)
    if not pose.reprojection_error_px > REPROJECTION_HOLD_FACTOR * lim:
        return None
    return (
        f"reprojection error {pose.reprojection_error_px:.1f} px, above {REPROJECTION_HOLD_FACTOR:g} x the "
        f"{lim:.1f} px the detected corners allow: pose not used"
    )


def _report_only(pose: MarkerPose) -> tuple[str, ...]:
    """The reasons' kinds that are report fields for the pose's ``refine`` (:data:`REPORT_ONLY`)."""
    refine: str | None = getattr(pose, "refine", None)
    return () if refine is None else REPORT_ONLY.get(refine, ())


def flag_reasons(pose: MarkerPose) -> list[str]:
    """Why a pose (:class:`arshadow.tracking.pose.MarkerPose`) is flagged (:func:`all_reasons` but those
    that :data:`REPORT_ONLY` makes report fields for the pose's ``refine``); empty when it is not."""
    quiet = _report_only(pose)
    return [r for r in all_reasons(pose) if r.split(":", 1)[0] not in quiet]


def pose_notes(pose: MarkerPose) -> list[str]:
    """The reasons of :func:`all_reasons` that are report fields, not flags, for the pose's ``refine``
    (:data:`REPORT_ONLY`): said in the report and the per-frame records, not warned of."""
    quiet = _report_only(pose)
    return [r for r in all_reasons(pose) if r.split(":", 1)[0] in quiet]


def all_reasons(pose: MarkerPose) -> list[str]:
    """Every reason a pose (:class:`arshadow.tracking.pose.MarkerPose`) may be off, one sentence per
    reason with its number (empty when none): the two planar solutions nearly equal, blurred corners, a
    covered border, a marker under :data:`MIN_CONFIDENT_SIDE_PX`, the requested refinement not used for some
    marker (``MarkerPose.refine_note``), a reprojection error far above what the detector's corners allow."""
    out: list[str] = []
    ratio, thr = pose.pose_ambiguity, pose.ambiguity_threshold
    if ratio is not None and ratio >= thr:
        out.append(
            f"ambiguous: the two planar solutions explain the corners almost equally (ratio {ratio:.3g} >= {thr:g})"
        )
    ci = pose.corner_instability
    if ci is not None and ci > MAX_CORNER_INSTABILITY:
        out.append(
            f"blurred corners: they move by {ci:.3g} of the marker's side between refinement windows "
            f"(> {MAX_CORNER_INSTABILITY:g})"
        )
    bo = pose.border_occlusion
    if bo is not None and bo > MAX_BORDER_OCCLUSION:
        out.append(
            f"marker partly covered: a border cell reads {bo:.2f} of the way to white (> {MAX_BORDER_OCCLUSION:g})"
        )
    if pose.kind == "marker" and pose.pose_ambiguity is not None and len(pose.corners) >= 4:
        q = np.asarray(pose.corners, np.float64)[:4]
        side = float(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).min())
        if side < MIN_CONFIDENT_SIDE_PX:
            out.append(
                f"small marker: {side:.1f} px across, under the {MIN_CONFIDENT_SIDE_PX:g} px a pose can be trusted at"
            )
    note = getattr(pose, "refine_note", None)
    if note:
        out.append(f"refinement: {note}")
    lim = reprojection_limit_px(pose.corners)
    if pose.reprojection_error_px > lim:
        out.append(
            f"reprojection error: {pose.reprojection_error_px:.1f} px, far above the {lim:.1f} px the "
            "detected corners allow (a board file or marker length that does not match the print?)"
        )
    return out
