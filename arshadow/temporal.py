"""Streaming pose decisions for video: IPPE branch by continuity, smoothing without lag, marker loss.

:class:`PoseStream` takes each frame's tracked pose (or None) in order and gives back, a fixed number of
frames later and in the same order, a :class:`FramePose`:

1. the IPPE branch chosen by continuity (:class:`arshadow.video.TemporalPoseChooser`, fixed lag);
2. the pose smoothed by a **centred local-linear fit** over ``2 * window + 1`` frames (tricube weights in
   time), of the rotation (as rotation vectors relative to the frame's own rotation) and of the camera
   centre in the world frame. A centred fit reproduces any motion that is linear over the window
   exactly — a steady pan (constant angular velocity about the camera centre: the centre does not move,
   the rotation vector grows linearly) comes out with **zero lag** — while it averages the detector's
   frame-to-frame noise over the window. Video is processed offline, so looking ``window`` frames ahead
   costs latency (frames are buffered), never lag in the picture. Frames whose pose disagrees with the
   fit by more than ``outlier_deg`` (a bad detection) are left out of their neighbours' fits;
3. marker loss: a frame without a pose within ``hold_frames`` of the last frame with one gets that
   frame's (smoothed) pose (``status = "held"``); later frames are passed through untouched
   (``status = "no_marker"``).

Frames (CONVENTIONS.md): poses are world (marker) -> OpenCV camera, ``cam_from_world`` (4, 4) float64.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np

from .errors import UsageError
from .video import TemporalPoseChooser

__all__ = ["FramePose", "PoseStream", "smooth_poses"]


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
    cam_from_world : (4, 4) float64 or None
        The pose to render with (smoothed; held; None for ``no_marker``).
    raw : MarkerPose or None
        The tracked pose on the chosen IPPE branch, unsmoothed (None when not tracked in this frame).
    swapped : bool
        The chooser took the alternative IPPE solution.
    """

    payload: object
    time_s: float
    status: str
    cam_from_world: np.ndarray | None
    raw: object = None
    swapped: bool = False


def _rvec(R):
    return cv2.Rodrigues(np.ascontiguousarray(R))[0].ravel()


def _rmat(r):
    return cv2.Rodrigues(np.asarray(r, np.float64).reshape(3, 1))[0]


def _local_linear(ts, w, t0, ys):
    """Weighted least-squares line through ``(ts, ys)`` evaluated at ``t0``: ``(d,)``."""
    dt = ts - t0
    sw, st, stt = w.sum(), (w * dt).sum(), (w * dt * dt).sum()
    den = sw * stt - st * st
    sy = (w[:, None] * ys).sum(axis=0)
    if abs(den) < 1e-12 * max(sw * stt, 1e-300):
        return sy / sw  # one point (or all at one time): the weighted mean
    sty = (w[:, None] * dt[:, None] * ys).sum(axis=0)
    return (stt * sy - st * sty) / den  # intercept at t0


def smooth_poses(times, poses, i, *, window_s, outlier_deg=3.0):
    """The smoothed pose of frame ``i`` from its neighbours (:class:`PoseStream` step 2).

    Parameters
    ----------
    times : (n,) float64
        Frame times, seconds (the neighbours of frame ``i`` that may take part).
    poses : (n, 4, 4) float64
        Their ``cam_from_world``.
    i : int
        The frame to smooth.
    window_s : float
        Half-width of the tricube weight, seconds.
    outlier_deg : float
        Neighbours farther than this (rotation) from a first fit are left out.

    Returns
    -------
    (4, 4) float64
    """
    times = np.asarray(times, np.float64)
    P = np.asarray(poses, np.float64)
    R = P[:, :3, :3]
    Rc = R[i]
    centres = -np.einsum("nji,nj->ni", R, P[:, :3, 3])  # camera centre in the world: -R^T t
    rv = np.array([_rvec(Rj @ Rc.T) for Rj in R])  # rotation relative to frame i's
    u = np.abs(times - times[i]) / (window_s * (1.0 + 1e-9))
    w = np.where(u < 1.0, (1.0 - u ** 3) ** 3, 0.0)
    keep = w > 0
    for _ in range(2):
        ys = np.concatenate([rv, centres], axis=1)
        fit = _local_linear(times[keep], w[keep], times[i], ys[keep])
        # residual of each neighbour against the line (rotation part, degrees)
        dt = times - times[i]
        if keep.sum() >= 3:
            slope = _local_slope(times[keep], w[keep], times[i], rv[keep])
            res = np.degrees(np.linalg.norm(rv - (fit[:3] + dt[:, None] * slope), axis=1))
            new_keep = (w > 0) & (res <= outlier_deg)
            new_keep[i] |= not new_keep.any()
            if np.array_equal(new_keep, keep):
                break
            keep = new_keep
        else:
            break
    out = np.eye(4)
    Rs = _rmat(fit[:3]) @ Rc
    out[:3, :3] = Rs
    out[:3, 3] = -Rs @ fit[3:]
    return out


def _local_slope(ts, w, t0, ys):
    dt = ts - t0
    sw, st, stt = w.sum(), (w * dt).sum(), (w * dt * dt).sum()
    den = sw * stt - st * st
    if abs(den) < 1e-12 * max(sw * stt, 1e-300):
        return np.zeros(ys.shape[1])
    sy = (w[:, None] * ys).sum(axis=0)
    sty = (w[:, None] * dt[:, None] * ys).sum(axis=0)
    return (sw * sty - st * sy) / den


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

    def __init__(self, fps: float = 25.0, lag: int | None = 16, window: int = 6, hold_frames: int = 12,
                 outlier_deg: float = 3.0, max_gap_s: float = 1.0):
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
        self.max_gap_s = float(max_gap_s)
        self._buf: deque = deque()  # (payload, time_s, raw pose or None, swapped) awaiting the look-ahead
        self._hist: deque = deque()  # (time_s, (4, 4)) of decided frames with a pose, within the window
        self._last = None  # (time_s, frame count since, pose) of the last frame with a pose
        self._since = 0

    # -- interface -------------------------------------------------------------------------------
    def push(self, payload, pose, time_s: float) -> list[FramePose]:
        """Add a frame (``pose``: the tracker's MarkerPose, or None); returns the frames decided now."""
        if self.chooser is None:
            return self._smooth_push(payload, float(time_s), pose, False)
        out = []
        for ch in self.chooser.push((payload, float(time_s)), pose, time_s):
            out += self._smooth_push(ch.payload[0], ch.payload[1], ch.pose, ch.swapped)
        return out

    def flush(self) -> list[FramePose]:
        """Decide every frame still waiting (end of the video)."""
        out = []
        if self.chooser is not None:
            for ch in self.chooser.flush():
                out += self._smooth_push(ch.payload[0], ch.payload[1], ch.pose, ch.swapped)
        while self._buf:
            out.append(self._decide_oldest())
        return out

    # -- smoothing over the buffered look-ahead -------------------------------------------------------
    def _smooth_push(self, payload, t, pose, swapped):
        self._buf.append((payload, t, pose, swapped))
        out = []
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
                return FramePose(payload, t, "held", self._last[1].copy(), None, False)
            return FramePose(payload, t, "no_marker", None, None, False)
        raw = np.asarray(pose.cam_from_world, np.float64)
        if self.window == 0:
            sm = raw.copy()
        else:
            # neighbours: decided past frames (raw poses) and the buffered future ones, linked in time
            times, mats = [], []
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
            sm = smooth_poses(times, mats, i, window_s=self.window_s, outlier_deg=self.outlier_deg)
        self._hist.append((t, raw))
        self._last = (t, sm)
        self._since = 0
        return FramePose(payload, t, "ok", sm, pose, bool(swapped))
