"""Streaming pose decisions for video: IPPE branch by continuity, smoothing without lag, marker loss.

:class:`PoseStream` takes each frame's tracked pose (or None) in order and gives back, a fixed number of
frames later and in the same order, a :class:`FramePose`:

1. the IPPE branch chosen by continuity (:class:`arshadow.video.chooser.TemporalPoseChooser`, fixed lag);
2. the pose smoothed by a **centred local-quadratic fit** (``degree=2``) over ``2 * window + 1`` frames
   (tricube weights in time), of the rotation (as rotation vectors relative to the frame's own rotation)
   and of the camera centre in the world frame. A centred fit reproduces any motion that is polynomial
   of its degree over the window exactly — a steady pan (constant angular velocity about the camera centre: the centre does not move,
   the rotation vector grows linearly) comes out with **zero lag** — while it averages the detector's
   frame-to-frame noise over the window. Video is processed offline, so looking ``window`` frames ahead
   costs latency (frames are buffered), never lag in the picture. Frames whose pose disagrees with the
   fit by more than ``outlier_deg`` (a bad detection) are left out of their neighbours' fits;
3. marker loss: a frame without a pose within ``hold_frames`` of the last frame with one gets that
   frame's (smoothed) pose (``status = "held"``); later frames are passed through untouched
   (``status = "no_marker"``).

Frames (CONVENTIONS.md): poses are marker -> OpenCV camera, ``cam_from_marker`` (4, 4) float64 (the
tracker's :attr:`MarkerPose.cam_from_world <arshadow.tracking.pose.MarkerPose>`: its world is the marker).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
import numpy.typing as npt

from ..errors import UsageError
from ..tracking.pose import MarkerPose
from ..transforms import rotation_vectors
from .chooser import TemporalPoseChooser

__all__ = ["MAX_GAP_S", "FramePose", "PoseStream", "smooth_poses"]

#: frames farther apart than this (seconds: the marker lost for longer) are not linked by the IPPE branch
#: choice nor smoothed together
MAX_GAP_S = 1.0


@dataclass
class FramePose:
    """One frame's decision.

    Attributes
    ----------
    payload : object
        What was pushed with the frame.
    time_s : float
    status : str
        ``"ok"`` (tracked), ``"held"`` (marker lost, last pose held) or ``"no_marker"``.
    cam_from_marker : (4, 4) float64 or None
        The marker's pose to render with (smoothed; held; None for ``no_marker``).
    raw : MarkerPose or None
        The tracked pose on the chosen IPPE branch, unsmoothed (None when not tracked in this frame).
    swapped : bool
        The chooser took the alternative IPPE solution.
    reference_id : int or None
        The marker whose frame ``cam_from_marker`` is in (a held frame: the last tracked frame's); None for
        a board or without a pose.
    """

    payload: object
    time_s: float
    status: str
    cam_from_marker: np.ndarray | None
    raw: MarkerPose | None = None
    swapped: bool = False
    reference_id: int | None = None


def _rmat(r: npt.ArrayLike) -> np.ndarray:
    """(3, 3) float64 rotation matrix of the rotation vector ``r`` (3,)."""
    m: np.ndarray = cv2.Rodrigues(np.asarray(r, np.float64).reshape(3, 1))[0]
    return m


def _local_poly(dt: np.ndarray, w: np.ndarray, ys: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares polynomial in ``dt`` (n,) with weights ``w`` (n,) through ``ys`` (n, d):
    ``(value at dt = 0 (d,), fitted (n, d))``."""
    deg = int(min(degree, max(0, int((w > 0).sum()) - 1)))
    X = np.vander(dt, deg + 1, increasing=True)
    sw = np.sqrt(w)[:, None]
    beta = np.linalg.lstsq(X * sw, ys * sw, rcond=None)[0]
    return beta[0], X @ beta


def smooth_poses(
    times: npt.ArrayLike,
    poses: npt.ArrayLike,
    i: int,
    *,
    window_s: float,
    degree: int = 2,
    outlier_deg: float = 3.0,
    max_span_deg: float = 6.0,
    trust_i: bool = True,
) -> np.ndarray:
    """The smoothed pose of frame ``i`` from its neighbours (:class:`PoseStream` step 2).

    A local polynomial (``degree`` 2: constant acceleration is followed exactly, so an arc of a camera
    path is not cut short) fitted by weighted least squares with tricube weights
    ``(1 - |dt / window_s|^3)^3``, to the rotation vectors relative to frame ``i``'s rotation and to the
    camera centres ``-R^T t``, evaluated at frame ``i``'s time.

    Parameters
    ----------
    times : (n,) float64
        Frame times, seconds (the neighbours of frame ``i`` that may take part).
    poses : (n, 4, 4) float64
        Their ``cam_from_marker``.
    i : int
        The frame to smooth.
    window_s : float
        Half-width of the tricube weight, seconds.
    degree : int
        Degree of the local polynomial (0 mean, 1 line, 2 parabola).
    outlier_deg : float
        Neighbours whose rotation is farther than this from a first fit are left out.
    max_span_deg : float
        Fast motion narrows the window: to the time in which the camera turns by this angle (median
        rotation speed of the neighbours), so that a quick swing is followed, not averaged away; at least
        two frames either side.
    trust_i : bool
        Frame ``i`` always takes part in its own fit. False (its pose is flagged, e.g. blurred corners):
        it is left out like any neighbour when it disagrees with the fit, provided frames on both sides
        take part (the real-footage work: a blurred frame of the real 5-fps clip sat 8 deg off its neighbours' path).

    Returns
    -------
    (4, 4) float64
        The smoothed ``cam_from_marker``.
    """
    times = np.asarray(times, np.float64)
    P = np.asarray(poses, np.float64)
    R = P[:, :3, :3]
    Rc = R[i]
    centres = -np.einsum("nji,nj->ni", R, P[:, :3, 3])  # camera centre in the world: -R^T t
    rv = rotation_vectors(R @ Rc.T)  # rotation relative to frame i's
    if max_span_deg and len(times) > 2:
        order = np.argsort(times)
        steps = np.diff(times[order])
        ang = np.degrees(np.linalg.norm(np.diff(rv[order], axis=0), axis=1))
        ok = steps > 0
        if ok.any():
            speed = float(np.median(ang[ok] / steps[ok]))  # degrees per second
            frame_s = float(np.median(steps[ok]))
            if speed > 0:
                window_s = min(window_s, max(max_span_deg / speed, 2.5 * frame_s))
    dt = (times - times[i]) / window_s
    u = np.abs(dt) / (1.0 + 1e-9)
    w0 = np.where(u < 1.0, (1.0 - u**3) ** 3, 0.0)
    w = w0.copy()
    ys = np.concatenate([rv, centres], axis=1)
    for _ in range(2):
        fit, fitted = _local_poly(dt, w, ys, degree)
        res = np.degrees(np.linalg.norm(rv - fitted[:, :3], axis=1))
        keep = (w0 > 0) & (res <= outlier_deg)
        both_sides = bool(np.any(keep & (dt < 0))) and bool(np.any(keep & (dt > 0)))
        keep[i] = keep[i] or trust_i or not both_sides
        new_w = np.where(keep, w0, 0.0)
        if np.array_equal(new_w > 0, w > 0):
            break
        w = new_w
    out = np.eye(4)
    Rs = _rmat(fit[:3]) @ Rc
    out[:3, :3] = Rs
    out[:3, 3] = -Rs @ fit[3:]
    return out


class PoseStream:
    """Per-frame poses for a video, decided in order a fixed number of frames late (see the module).

    Parameters
    ----------
    fps : float
        Frame rate (converts the window and the chooser's gaps between frames and seconds).
    lag : int or None
        Look-ahead of the IPPE branch choice (:class:`TemporalPoseChooser`); None: by error only.
    window : int
        Half-width of the smoothing window, frames (0: no smoothing).
    hold_frames : int
        Frames a lost marker's last pose is held for.
    outlier_deg : float
        See :func:`smooth_poses`.
    max_gap_s : float
        Frames farther apart than this (marker lost for longer) are not smoothed together.

    Examples
    --------
    >>> ps = PoseStream(fps=25.0, lag=0, window=0, hold_frames=1)
    >>> [d.status for d in ps.push("a", None, 0.0) + ps.flush()]
    ['no_marker']
    """

    def __init__(
        self,
        fps: float = 25.0,
        lag: int | None = 16,
        window: int = 10,
        hold_frames: int = 12,
        outlier_deg: float = 3.0,
        max_gap_s: float = MAX_GAP_S,
        degree: int = 2,
    ) -> None:
        if not (math.isfinite(fps) and fps > 0):
            raise UsageError(f"frame rate must be positive, got {fps}")
        if int(window) < 0 or int(hold_frames) < 0:
            raise UsageError("--smooth and --hold must be >= 0 frames")
        self.fps = float(fps)
        self.chooser = None if lag is None else TemporalPoseChooser(lag=int(lag), fps=fps, max_gap_s=max_gap_s)
        self.window = int(window)
        self.window_s = (self.window + 1) / self.fps
        self.hold_frames = int(hold_frames)
        self.outlier_deg = float(outlier_deg)
        self.degree = int(degree)
        self.max_gap_s = float(max_gap_s)
        # (payload, time_s, raw pose or None, swapped) awaiting the look-ahead
        self._buf: deque[tuple[object, float, MarkerPose | None, bool]] = deque()
        # (time_s, (4, 4) cam_from_marker) of decided frames with a pose, within the window
        self._hist: deque[tuple[float, np.ndarray]] = deque()
        # (time_s, cam_from_marker, reference id) of the last frame with a pose
        self._last: tuple[float, np.ndarray, int | None] | None = None
        self._since = 0

    # -- interface -------------------------------------------------------------------------------
    def push(self, payload: object, pose: MarkerPose | None, time_s: float) -> list[FramePose]:
        """Add a frame (``pose``: the tracker's MarkerPose, or None); returns the frames decided now."""
        if self.chooser is None:
            return self._smooth_push(payload, float(time_s), pose, False)
        out: list[FramePose] = []
        for ch in self.chooser.push((payload, float(time_s)), pose, time_s):
            pl, t = cast(tuple[object, float], ch.payload)  # what push gave the chooser
            out += self._smooth_push(pl, t, ch.pose, ch.swapped)
        return out

    def flush(self) -> list[FramePose]:
        """Decide every frame still waiting (end of the video)."""
        out: list[FramePose] = []
        if self.chooser is not None:
            for ch in self.chooser.flush():
                pl, t = cast(tuple[object, float], ch.payload)  # what push gave the chooser
                out += self._smooth_push(pl, t, ch.pose, ch.swapped)
        while self._buf:
            out.append(self._decide_oldest())
        return out

    # -- smoothing over the buffered look-ahead -------------------------------------------------------
    def _smooth_push(self, payload: object, t: float, pose: MarkerPose | None, swapped: bool) -> list[FramePose]:
        self._buf.append((payload, t, pose, swapped))
        out: list[FramePose] = []
        while self._buf and self._buf[-1][1] - self._buf[0][1] >= self.window_s - 0.5 / self.fps:
            out.append(self._decide_oldest())
        return out

    def _decide_oldest(self) -> FramePose:
        payload, t, pose, swapped = self._buf.popleft()
        while self._hist and t - self._hist[0][0] > min(self.window_s, self.max_gap_s):
            self._hist.popleft()
        if pose is None:
            self._since += 1
            if self._last is not None and self._since <= self.hold_frames and t - self._last[0] <= self.max_gap_s:
                return FramePose(payload, t, "held", self._last[1].copy(), None, False, self._last[2])
            return FramePose(payload, t, "no_marker", None, None, False)
        raw = np.asarray(pose.cam_from_world, np.float64)
        if self.window == 0:
            sm = raw.copy()
        else:
            # neighbours: decided past frames (raw poses) and the buffered future ones, linked in time
            times: list[float] = []
            mats: list[np.ndarray] = []
            for th, mh in self._hist:
                times.append(th)
                mats.append(mh)
            i = len(times)
            times.append(t)
            mats.append(raw)
            prev_t = t
            for _, tf, pf, _ in self._buf:
                if tf - t > self.window_s or tf - prev_t > self.max_gap_s:
                    break
                if pf is not None:
                    times.append(tf)
                    mats.append(np.asarray(pf.cam_from_world, np.float64))
                    prev_t = tf
            if self._hist and t - self._hist[-1][0] > self.max_gap_s:
                times, mats, i = times[i:], mats[i:], 0
            sm = smooth_poses(
                times,
                mats,
                i,
                window_s=self.window_s,
                degree=self.degree,
                outlier_deg=self.outlier_deg,
                trust_i=not getattr(pose, "ambiguous", False),
            )
        self._hist.append((t, raw))
        ids = getattr(pose, "marker_ids", None)
        ref = int(ids[0]) if ids and getattr(pose, "kind", "marker") == "marker" else None
        self._last = (t, sm, ref)
        self._since = 0
        return FramePose(payload, t, "ok", sm, pose, bool(swapped), ref)
