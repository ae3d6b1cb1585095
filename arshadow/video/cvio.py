"""Batch AR video: frames with timestamps in, atomic video files out, and temporally consistent poses.

Three pieces, all without OpenGL:

:class:`VideoReader`
    Iterates over the frames of anything OpenCV's video I/O decodes (a video file, an image-sequence
    pattern such as ``frames/%04d.png``, a single image) as :class:`VideoFrame` ``(index, time_s, image)``:
    ``image`` is ``(H, W, 3) uint8`` BGR (read-only), ``time_s`` the frame's presentation time in seconds
    from the start of the stream (the decoder's timestamp when it gives a usable one, else
    ``index / fps``).
:class:`AtomicVideoWriter`
    Writes frames into a temporary file in the target folder and renames it onto the target only when the
    ``with`` block ends without an error: an interrupted or failed run leaves the old file (or none), never
    a truncated video (CONVENTIONS.md). The codec follows the extension (:data:`CODECS`); ``.mkv`` is
    lossless FFV1 (used for the 8-bit shadow-mask video, whose values must survive exactly).
:class:`TemporalPoseChooser`
    A single square marker has two planar pose solutions (IPPE) that explain its four corners almost
    equally well when the marker is small, far or seen nearly face-on: choosing per frame by the lower
    reprojection error makes the pose (and the shadow) *flip* between the two from frame to frame.
    The chooser picks, per frame, the solution consistent with its neighbours: a two-state Viterbi
    path over the frames minimising ``sum(data) + sum(motion)`` with

    * data cost ``n e^2 / (2 sigma_px^2)`` (``n`` corners, RMS reprojection error ``e`` px): a
      solution that fits clearly worse costs a lot, two that fit equally well cost the same;
    * motion cost ``theta^2 / (2 sigma_rot^2 gap)`` for the rotation angle ``theta`` between consecutive
      frames' chosen poses (``gap`` frames apart): a flip costs a lot, smooth motion nearly nothing.

    With ``lag = 0`` that is the greedy rule "the solution consistent with the previous frame"; with
    ``lag = K`` each frame is decided K frames later (fixed-lag smoothing), so that a wrong *first* frame
    is corrected by the frames that follow. Measured in docs/video.md and tests/test_video.py.

Frames (CONVENTIONS.md): poses are world (marker) -> OpenCV camera; images BGR, row 0 at the top.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ImageError, UsageError
from ..transforms import rotation_error_deg

# FFmpeg prints its own decoder complaints ("moov atom not found") straight to stderr; arshadow reports
# one line of its own instead. Must be set before OpenCV's FFmpeg backend is first used.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

import cv2  # noqa: E402  (after the environment variable above)

__all__ = [
    "CODECS",
    "VideoFrame",
    "VideoReader",
    "AtomicVideoWriter",
    "TemporalPoseChooser",
    "Choice",
]

#: output extension -> FourCC (all available in OpenCV's FFmpeg backend; ``.mkv`` FFV1 is lossless)
CODECS = {".mp4": "mp4v", ".m4v": "mp4v", ".mov": "mp4v", ".avi": "MJPG", ".mkv": "FFV1"}


# --------------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VideoFrame:
    """One decoded frame.

    Attributes
    ----------
    index : int
        0-based frame number in decoding order.
    time_s : float
        Presentation time, seconds from the start of the stream.
    image : (H, W, 3) uint8
        BGR, read-only.
    """

    index: int
    time_s: float
    image: np.ndarray


def _looks_like_sequence(path: str) -> bool:
    """An OpenCV image-sequence pattern (``img_%04d.png``) rather than a file name."""
    import re

    return re.search(r"%0?\d*d", path) is not None


def sequence_indices(pattern: str) -> list[int]:
    """The frame numbers of the files an image-sequence pattern (``frames/img_%04d.png``) matches, sorted."""
    import re

    p = Path(pattern)
    m = re.search(r"%(0?)(\d*)d", p.name)
    if m is None or not p.parent.is_dir() and str(p.parent) not in ("", "."):
        return []
    width = int(m.group(2) or 0)
    digits = rf"\d{{{width}}}" if m.group(1) and width else r"\d+"
    rx = re.compile(re.escape(p.name[: m.start()]) + f"({digits})" + re.escape(p.name[m.end():]) + "$")
    return sorted({int(g.group(1)) for f in (p.parent if str(p.parent) else Path(".")).iterdir()
                   if f.is_file() and (g := rx.match(f.name))})


class VideoReader:
    """The frames of a video (anything OpenCV's video I/O decodes), with timestamps.

    Parameters
    ----------
    path : str or Path
        A video file, an image-sequence pattern (``frames/%04d.png``) or a single image.
    max_frames : int, optional
        Stop after this many frames.

    Attributes
    ----------
    fps : float
        Frames per second the container declares (25 is assumed, and ``fps_assumed`` set, when it
        declares none).
    width, height : int
        Frame size (from the first decoded frame).
    frame_count : int or None
        Frames the container declares (an estimate for some formats; None if unknown).
    n_read : int
        Frames decoded so far.

    Raises
    ------
    ImageError
        Missing file, or nothing OpenCV can decode (not a video, unsupported codec, no frame).

    Examples
    --------
    >>> import tempfile, numpy as np
    >>> d = tempfile.mkdtemp()
    >>> with AtomicVideoWriter(d + "/a.avi", 10.0, (64, 48)) as w:
    ...     for i in range(3):
    ...         w.write(np.full((48, 64, 3), 60 * i, np.uint8))
    >>> [(f.index, round(f.time_s, 3), f.image.shape) for f in VideoReader(d + "/a.avi")]
    [(0, 0.0, (48, 64, 3)), (1, 0.1, (48, 64, 3)), (2, 0.2, (48, 64, 3))]
    """

    def __init__(self, path, max_frames: int | None = None):
        self.path = str(path)
        if max_frames is not None and int(max_frames) < 1:
            raise UsageError(f"--max-frames {max_frames}: must be >= 1")
        self.max_frames = None if max_frames is None else int(max_frames)
        if not _looks_like_sequence(self.path):
            p = Path(self.path)
            if not p.exists():
                raise ImageError(f"{self.path}: no such video file")
            if p.is_dir():
                raise ImageError(f"{self.path}: is a folder, not a video (use a pattern such as DIR/%04d.png)")
            if p.stat().st_size == 0:
                raise ImageError(f"{self.path}: empty file, not a video")
        self.end_note = None  # why the frames stop before frame_count (engine warnings)
        seq = sequence_indices(self.path) if _looks_like_sequence(self.path) else None
        if seq is not None and not seq:
            raise ImageError(f"{self.path}: no file matches this image-sequence pattern")
        cap = cv2.VideoCapture(self.path)
        if not cap.isOpened():
            cap.release()
            raise ImageError(f"{self.path}: cannot open as a video (not a video, or a format/codec OpenCV's "
                             f"video I/O cannot decode)")
        ok, first = cap.read()
        if not ok or first is None or first.size == 0:
            cap.release()
            raise ImageError(f"{self.path}: no decodable frame (corrupt or unsupported video)")
        self._cap = cap
        self._first = first
        fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps_assumed = not (math.isfinite(fps) and 0.0 < fps < 1e4)
        self.fps = 25.0 if self.fps_assumed else fps
        n = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        self.frame_count = int(n) if (math.isfinite(n) and n > 0) else None
        if seq:  # OpenCV stops at the first missing number: count every file, so a gap reads as truncated
            gaps = [i + 1 for i, j in zip(seq, seq[1:]) if j != i + 1]
            if gaps:
                self.frame_count = len(seq)
                try:
                    missing = self.path % gaps[0]
                except (TypeError, ValueError):
                    missing = f"number {gaps[0]}"
                self.end_note = (f"image {missing} is missing, the sequence stops there; "
                                 f"{len([i for i in seq if i > gaps[0]])} later image(s) not read")
        self.height, self.width = first.shape[:2]
        self.n_read = 0
        self.n_decode_errors = 0
        self._last_t = None
        self._t0 = None
        self._started = False

    # -- iteration ---------------------------------------------------------------------------------
    def _timestamp(self, index: int) -> float:
        """The decoder's timestamp of the frame just read (s), if usable; else index / fps."""
        ms = self._cap.get(cv2.CAP_PROP_POS_MSEC)
        t = None
        if math.isfinite(ms) and ms >= 0.0:
            t = ms / 1000.0
            if self._t0 is None:
                self._t0 = t
            t -= self._t0
            if self._last_t is not None and not t > self._last_t:
                t = None  # not increasing: the container gives no per-frame timestamps
        if t is None:
            t = index / self.fps if self._last_t is None else max(index / self.fps, self._last_t + 1e-6)
        self._last_t = t
        return t

    def __iter__(self):
        if self._started:
            raise UsageError(f"{self.path}: a VideoReader can be iterated only once")
        self._started = True
        from ..io import to_bgr8

        index = 0
        img = self._first
        self._first = None
        while img is not None:
            if self.max_frames is not None and index >= self.max_frames:
                break
            t = self._timestamp(index)
            try:
                img = to_bgr8(img, name=f"{self.path} frame {index}")
            except ImageError:
                self.n_decode_errors += 1
                raise
            img.setflags(write=False)
            self.n_read += 1
            yield VideoFrame(index, t, img)
            index += 1
            ok, nxt = self._cap.read()
            img = nxt if ok and nxt is not None and nxt.size else None
        self.close()

    @property
    def truncated(self) -> bool:
        """Fewer frames decoded than the container declares (a damaged tail), when reading to the end."""
        return (self.frame_count is not None and self.max_frames is None and self._started
                and self._cap is None and self.n_read < self.frame_count - 1)

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):  # pragma: no cover - best effort
        with contextlib.suppress(Exception):
            self.close()


# --------------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------------
class AtomicVideoWriter:
    """Write a video into a temporary file beside ``path``; rename it into place on success.

    Parameters
    ----------
    path : str or Path
        Target file; its extension chooses the container and the codec (:data:`CODECS`).
    fps : float
    size : (int, int)
        ``(width, height)`` of every frame.
    color : bool
        ``(H, W, 3)`` BGR frames (True) or ``(H, W)`` single-channel frames (False; lossless with ``.mkv``).
    fourcc : str, optional
        Override the codec.

    Use as a context manager: the file appears at ``path`` only when the block ends without an
    exception and at least one frame was written; otherwise the temporary file is removed and an existing
    ``path`` is left untouched.

    Raises
    ------
    ImageError
        The extension has no known codec, or OpenCV cannot open a writer for it; a frame of the wrong
        size or type.
    """

    def __init__(self, path, fps: float, size, *, color: bool = True, fourcc: str | None = None):
        self.path = Path(path)
        ext = self.path.suffix.lower()
        if fourcc is None:
            if ext not in CODECS:
                raise ImageError(f"{self.path}: unknown video format {ext or '(no extension)'} "
                                 f"(use one of {', '.join(sorted(CODECS))})")
            fourcc = CODECS[ext]
        if len(fourcc) != 4:
            raise UsageError(f"codec {fourcc!r}: a FourCC has 4 characters")
        fps = float(fps)
        if not (math.isfinite(fps) and fps > 0):
            raise UsageError(f"{self.path}: frame rate must be positive, got {fps}")
        self.fps, self.fourcc, self.color = fps, fourcc, bool(color)
        self.size = (int(size[0]), int(size[1]))
        if min(self.size) < 1:
            raise ImageError(f"{self.path}: bad frame size {self.size}")
        self.n_written = 0
        self._stack = None
        self._writer = None
        self.tmp_path = None

    def __enter__(self):
        from ..io import atomic_path

        stack = contextlib.ExitStack()
        try:
            self.tmp_path = stack.enter_context(atomic_path(self.path))
            w = cv2.VideoWriter(str(self.tmp_path), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*self.fourcc),
                                self.fps, self.size, self.color)
            if not w.isOpened():
                w = cv2.VideoWriter(str(self.tmp_path), cv2.VideoWriter_fourcc(*self.fourcc), self.fps,
                                    self.size, self.color)
            if not w.isOpened():
                raise ImageError(f"{self.path}: cannot write {self.path.suffix} video with codec "
                                 f"{self.fourcc} (not supported by this OpenCV build)")
        except BaseException:
            stack.__exit__(*sys.exc_info())
            raise
        self._writer, self._stack = w, stack
        return self

    def write(self, frame: np.ndarray) -> None:
        """Append one frame: ``(H, W, 3) uint8`` BGR (``color``) or ``(H, W) uint8``."""
        if self._writer is None:
            raise UsageError("AtomicVideoWriter.write outside its with-block")
        f = np.asarray(frame)
        want = (self.size[1], self.size[0], 3) if self.color else (self.size[1], self.size[0])
        if f.shape != want or f.dtype != np.uint8:
            raise ImageError(f"{self.path}: frame {self.n_written} is {f.shape} {f.dtype}, expected {want} uint8")
        self._writer.write(np.ascontiguousarray(f))
        self.n_written += 1

    def __exit__(self, exc_type, exc, tb):
        w, stack = self._writer, self._stack
        self._writer = self._stack = None
        if w is not None:
            w.release()
        if stack is None:
            return False
        if exc_type is None and self.n_written == 0:
            err = ImageError(f"{self.path}: no frame to write")
            stack.__exit__(ImageError, err, None)  # removes the temporary file
            raise err
        return stack.__exit__(exc_type, exc, tb)


# --------------------------------------------------------------------------------------------------
# temporal pose choice
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
    pose: object
    swapped: bool = False
    ambiguity: float | None = None


@dataclass
class _Entry:
    payload: object
    time_s: float
    cands: list | None  # [best-by-error pose, alternative pose] (MarkerPose), or None: no pose
    data: np.ndarray | None = None  # (k,) data cost
    rots: list = field(default_factory=list)  # (3, 3) rotations of the candidates
    #: motion costs ``[k_prev][k]`` from the previous frame with a pose (computed once, when pushed;
    #: None: no previous one, or too far apart in time to be linked)
    link: list | None = None
    data_list: list = field(default_factory=list)  # ``data`` as floats


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

    def __init__(self, lag: int = 16, sigma_px: float = 0.15, sigma_rot_deg: float = 3.0, fps: float = 25.0,
                 max_gap_s: float = 1.0, max_motion_cost: float = math.inf):
        if int(lag) < 0:
            raise UsageError(f"pose lag must be >= 0 frames, got {lag}")
        for name, v in (("sigma_px", sigma_px), ("sigma_rot_deg", sigma_rot_deg), ("fps", fps),
                        ("max_gap_s", max_gap_s)):
            if not (math.isfinite(float(v)) and float(v) > 0):
                raise UsageError(f"{name} must be positive, got {v}")
        self.lag = int(lag)
        self.sigma_px, self.sigma_rot = float(sigma_px), float(sigma_rot_deg)
        self.fps, self.max_gap_s = float(fps), float(max_gap_s)
        self.max_motion_cost = float(max_motion_cost)
        self._buf: deque[_Entry] = deque()
        self._anchor = None  # (rotation (3,3), time_s) of the last decided frame with a pose
        self._last_posed = None  # the last pushed _Entry with a pose (its link to the next one)
        self.n_swapped = 0
        self.n_decided = 0

    # -- costs -------------------------------------------------------------------------------------
    def _data_cost(self, poses) -> np.ndarray:
        c = np.array([p.n_points * float(p.reprojection_error_px) ** 2 / (2.0 * self.sigma_px ** 2) for p in poses])
        return c - c.min()

    def _motion_cost(self, r_prev, t_prev, r, t) -> float | None:
        """None: too far apart in time to be linked."""
        dt = t - t_prev
        if dt > self.max_gap_s:
            return None
        gap = max(1.0, dt * self.fps)
        th = rotation_error_deg(r, r_prev)
        return min(th * th / (2.0 * self.sigma_rot ** 2 * gap), self.max_motion_cost)

    # -- interface ---------------------------------------------------------------------------------
    def push(self, payload, pose, time_s: float) -> list[Choice]:
        """Add one frame (``pose`` None: no marker in it); returns the frames decided now, in order."""
        if pose is None:
            e = _Entry(payload, float(time_s), None)
        else:
            cands = [pose]
            if getattr(pose, "alternative", None) is not None:
                cands.append(pose.swapped())
            e = _Entry(payload, float(time_s), cands, self._data_cost(cands),
                       [np.asarray(c.cam_from_world, np.float64)[:3, :3] for c in cands])
            e.data_list = e.data.tolist()
            prev = self._last_posed
            if prev is not None and e.time_s - prev.time_s <= self.max_gap_s:
                # the motion costs of this link, once (the Viterbi pass of every later decision reuses them)
                e.link = [[self._motion_cost(rp, prev.time_s, r, e.time_s) or 0.0 for r in e.rots]
                          for rp in prev.rots]
            self._last_posed = e
        self._buf.append(e)
        out = []
        while len(self._buf) > self.lag:
            out.append(self._decide_oldest())
        return out

    def flush(self) -> list[Choice]:
        """Decide every frame still waiting (end of the video)."""
        out = []
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
        chain = []
        for e in self._buf:
            if e.cands is None:
                continue
            if chain and e.time_s - chain[-1].time_s > self.max_gap_s:
                break  # the chain is cut: later frames cannot influence this decision
            chain.append(e)
        cum = first.data.copy()
        if self._anchor is not None:
            r_a, t_a = self._anchor
            for j, r in enumerate(first.rots):
                m = self._motion_cost(r_a, t_a, r, first.time_s)
                if m is not None:
                    cum[j] += m
        backs = []
        cum = cum.tolist()  # plain floats: the same float64 arithmetic, without numpy's per-call cost
        for e in chain[1:]:
            link = e.link  # from the chain's previous frame: the frame with a pose pushed just before e
            back, new = [], []
            for j, dj in enumerate(e.data_list):
                costs = [c + row[j] for c, row in zip(cum, link)]
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
