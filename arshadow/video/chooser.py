"""The look-ahead IPPE branch chooser: a two-state Viterbi path over the frames of a video.

A single square marker has two planar pose solutions (IPPE) that explain its four corners almost
equally well when the marker is small, far or seen nearly face-on: choosing per frame by the lower
reprojection error makes the pose (and the shadow) *flip* between the two from frame to frame.
:class:`TemporalPoseChooser` picks, per frame, the solution consistent with its neighbours: a two-state
Viterbi path over the frames minimising ``sum(data) + sum(motion)`` with

* data cost ``n e^2 / (2 sigma_px^2)`` (``n`` corners, RMS reprojection error ``e`` px): a
  solution that fits clearly worse costs a lot, two that fit equally well cost the same;
* motion cost ``theta^2 / (2 sigma_rot^2 gap)`` for the rotation angle ``theta`` between consecutive
  frames' chosen poses (``gap`` frames apart): a flip costs a lot, smooth motion nearly nothing.

With ``lag = 0`` that is the greedy rule "the solution consistent with the previous frame"; with
``lag = K`` each frame is decided K frames later (fixed-lag smoothing), so that a wrong *first* frame
is corrected by the frames that follow. Measured in docs/video.md and tests/test_video.py.

Frames (CONVENTIONS.md): poses are marker -> OpenCV camera, ``cam_from_marker`` (the tracker's
:attr:`MarkerPose.cam_from_world <arshadow.tracking.pose.MarkerPose>`: its world is the marker).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..errors import UsageError
from ..tracking.pose import MarkerPose
from ..transforms import rotation_error_deg

__all__ = ["Choice", "TemporalPoseChooser"]


# --------------------------------------------------------------------------------------------------
@dataclass
class Choice:
    """What :class:`TemporalPoseChooser` decided for one frame.

    Attributes
    ----------
    payload : object
        Whatever was pushed with the frame (e.g. the decoded frame), returned in order.
    pose : MarkerPose or None
        The chosen pose (None for a frame pushed without a pose).
    swapped : bool
        The chosen pose is the alternative IPPE solution (the one with the larger reprojection error).
    ambiguity : float or None
        The frame's ``pose_ambiguity``.
    """

    payload: object
    pose: MarkerPose | None
    swapped: bool = False
    ambiguity: float | None = None


@dataclass
class _Entry:
    payload: object
    time_s: float
    cands: list[MarkerPose] | None  # [best-by-error pose, alternative pose], or None: no pose
    data: np.ndarray | None = None  # (k,) data cost
    rots: list[np.ndarray] = field(default_factory=list)  # (3, 3) rotations of the candidates (cam_from_marker)
    #: motion costs ``[k_prev][k]`` from the previous frame with a pose (computed once, when pushed;
    #: None: no previous one, or too far apart in time to be linked)
    link: list[list[float]] | None = None
    data_list: list[float] = field(default_factory=list)  # ``data`` as floats


class TemporalPoseChooser:
    """Choose, per frame, the IPPE solution consistent with the neighbouring frames.

    Push each frame's :class:`arshadow.tracking.pose.MarkerPose` (chosen by reprojection error, with its
    ``alternative``) in order; get back, in the same order, each frame's chosen pose ``lag`` frames later
    (:meth:`push`), and the rest at the end (:meth:`flush`).

    Parameters
    ----------
    lag : int
        Frames of look-ahead (0: greedy, the solution consistent with the previous frame).
    sigma_px : float
        Corner noise, pixels, of the data cost ``n e^2 / (2 sigma_px^2)``.
    sigma_rot_deg : float
        Expected frame-to-frame rotation, degrees, of the motion cost ``theta^2 / (2 sigma_rot^2 gap)``
        (``gap`` = frames between the two, from the timestamps and ``fps``).
    fps : float
        Frame rate (turns time gaps into frame gaps).
    max_gap_s : float
        A gap without a pose longer than this (marker lost) starts a new, independent chain.

    Examples
    --------
    >>> ch = TemporalPoseChooser(lag=0)
    >>> ch.push("no pose here", None, 0.0)[0].pose is None
    True
    """

    def __init__(
        self,
        lag: int = 16,
        sigma_px: float = 0.15,
        sigma_rot_deg: float = 3.0,
        fps: float = 25.0,
        max_gap_s: float = 1.0,
        max_motion_cost: float = math.inf,
    ):
        if int(lag) < 0:
            raise UsageError(f"pose lag must be >= 0 frames, got {lag}")
        for name, v in (
            ("sigma_px", sigma_px),
            ("sigma_rot_deg", sigma_rot_deg),
            ("fps", fps),
            ("max_gap_s", max_gap_s),
        ):
            if not (math.isfinite(float(v)) and float(v) > 0):
                raise UsageError(f"{name} must be positive, got {v}")
        self.lag = int(lag)
        self.sigma_px, self.sigma_rot = float(sigma_px), float(sigma_rot_deg)
        self.fps, self.max_gap_s = float(fps), float(max_gap_s)
        self.max_motion_cost = float(max_motion_cost)
        self._buf: deque[_Entry] = deque()
        self._anchor: tuple[np.ndarray, float] | None = None  # (rotation (3,3), time_s) of the last decided posed frame
        self._last_posed: _Entry | None = None  # the last pushed _Entry with a pose (its link to the next one)
        self.n_swapped = 0
        self.n_decided = 0

    # -- costs -------------------------------------------------------------------------------------
    def _data_cost(self, poses: list[MarkerPose]) -> np.ndarray:
        """(k,) float64: each candidate's data cost, less the smallest."""
        c = np.array([p.n_points * float(p.reprojection_error_px) ** 2 / (2.0 * self.sigma_px**2) for p in poses])
        out: np.ndarray = c - c.min()
        return out

    def _motion_cost(self, r_prev: np.ndarray, t_prev: float, r: np.ndarray, t: float) -> float | None:
        """None: too far apart in time to be linked."""
        dt = t - t_prev
        if dt > self.max_gap_s:
            return None
        gap = max(1.0, dt * self.fps)
        th = rotation_error_deg(r, r_prev)
        cost: float = min(th * th / (2.0 * self.sigma_rot**2 * gap), self.max_motion_cost)
        return cost

    # -- interface ---------------------------------------------------------------------------------
    def push(self, payload: object, pose: MarkerPose | None, time_s: float) -> list[Choice]:
        """Add one frame (``pose`` None: no marker in it); returns the frames decided now, in order."""
        if pose is None:
            e = _Entry(payload, float(time_s), None)
        else:
            cands: list[MarkerPose] = [pose]
            if getattr(pose, "alternative", None) is not None:
                cands.append(pose.swapped())
            data = self._data_cost(cands)
            e = _Entry(
                payload,
                float(time_s),
                cands,
                data,
                [np.asarray(c.cam_from_world, np.float64)[:3, :3] for c in cands],  # cam_from_marker's rotations
            )
            e.data_list = data.tolist()
            prev = self._last_posed
            if prev is not None and e.time_s - prev.time_s <= self.max_gap_s:
                # the motion costs of this link, once (the Viterbi pass of every later decision reuses them)
                e.link = [[self._motion_cost(rp, prev.time_s, r, e.time_s) or 0.0 for r in e.rots] for rp in prev.rots]
            self._last_posed = e
        self._buf.append(e)
        out: list[Choice] = []
        while len(self._buf) > self.lag:
            out.append(self._decide_oldest())
        return out

    def flush(self) -> list[Choice]:
        """Decide every frame still waiting (end of the video)."""
        out: list[Choice] = []
        while self._buf:
            out.append(self._decide_oldest())
        return out

    def reset(self) -> None:
        """Forget the past (a new video). Frames still waiting are dropped: :meth:`flush` first."""
        self._buf.clear()
        self._anchor = None
        self._last_posed = None

    # -- Viterbi over the buffer, starting from the decided anchor ---------------------------------
    def _decide_oldest(self) -> Choice:
        first = self._buf[0]
        if first.cands is None:
            self._buf.popleft()
            return Choice(first.payload, None)
        # forward pass over the buffered frames that have poses, linked in time
        chain: list[_Entry] = []
        for e in self._buf:
            if e.cands is None:
                continue
            if chain and e.time_s - chain[-1].time_s > self.max_gap_s:
                break  # the chain is cut: later frames cannot influence this decision
            chain.append(e)
        assert first.data is not None  # set with cands
        cum0 = first.data.copy()
        if self._anchor is not None:
            r_a, t_a = self._anchor
            for j, r in enumerate(first.rots):
                m = self._motion_cost(r_a, t_a, r, first.time_s)
                if m is not None:
                    cum0[j] += m
        backs: list[list[int]] = []
        cum: list[float] = cum0.tolist()  # plain floats: the same float64 arithmetic, without numpy's per-call cost
        for e in chain[1:]:
            link = e.link  # from the chain's previous frame: the frame with a pose pushed just before e
            assert link is not None  # e is within max_gap_s of the frame with a pose pushed before it
            back: list[int] = []
            new: list[float] = []
            for j, dj in enumerate(e.data_list):
                costs = [c + row[j] for c, row in zip(cum, link, strict=True)]
                b = min(range(len(costs)), key=costs.__getitem__)  # the first minimum, as np.argmin
                back.append(b)
                new.append(costs[b] + dj)
            lo = min(new)
            cum = [v - lo for v in new]
            backs.append(back)
        s = min(range(len(cum)), key=cum.__getitem__)
        for back in reversed(backs):
            s = back[s]
        self._buf.popleft()
        chosen = first.cands[s]
        self._anchor = (first.rots[s], first.time_s)
        self.n_decided += 1
        self.n_swapped += int(s == 1)
        return Choice(first.payload, chosen, swapped=(s == 1), ambiguity=getattr(chosen, "pose_ambiguity", None))
