"""Decoding: the reader for an input (PyAV for video files, OpenCV for image sequences) and the decode loop.

:func:`open_reader` picks the reader; :func:`decode_into` is the decode thread's body (frames into a
bounded queue, with the time spent decoding each). :class:`VideoReader` iterates over the frames of
anything OpenCV's video I/O decodes (an image-sequence pattern such as ``frames/%04d.png``, a single
image, a video file) as :class:`arshadow.video.avio.VideoFrame` ``(index, time_s, image)``: ``image`` is
``(H, W, 3) uint8`` BGR (read-only), ``time_s`` the frame's presentation time in seconds from the start
of the stream (the decoder's timestamp when it gives a usable one, else ``index / fps``).

Frames (CONVENTIONS.md): images BGR, row 0 at the top.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import queue
import re
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from ..errors import ImageError, UsageError
from ..io import to_bgr8
from .avio import AvReader, RawFrame, VideoFrame
from .threads import END, put_or_stop

__all__ = ["FrameReader", "VideoReader", "decode_into", "looks_like_sequence", "open_reader", "sequence_indices"]


class FrameReader(Protocol):
    """What the engine reads of a video's reader (:class:`VideoReader`, :class:`arshadow.video.avio.AvReader`,
    :class:`arshadow.video.scan.SeekReader`); the others (``rate``, ``pix_fmt``, ``rotation``, ``has_audio``,
    ``path``, ``end_note``, ``n_decode_errors``) are read with ``getattr`` where a reader may lack them."""

    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def fps(self) -> float: ...
    @property
    def fps_assumed(self) -> bool: ...
    @property
    def frame_count(self) -> int | None: ...
    @property
    def n_read(self) -> int: ...
    @property
    def truncated(self) -> bool: ...
    def __iter__(self) -> Iterator[RawFrame | VideoFrame]: ...
    def close(self) -> None: ...


def _quiet_ffmpeg() -> None:
    """FFmpeg prints its own decoder complaints ("moov atom not found") straight to stderr; arshadow
    reports one line of its own instead. Read by OpenCV when its FFmpeg backend is first used, so set
    before the first capture is opened (never at import: importing arshadow changes no environment)."""
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


def looks_like_sequence(path: str | os.PathLike[str]) -> bool:
    """An OpenCV image-sequence pattern (``img_%04d.png``) rather than a file name.

    >>> looks_like_sequence("frames/img_%04d.png"), looks_like_sequence("clip.mp4")
    (True, False)
    """
    return re.search(r"%0?\d*d", str(path)) is not None


def sequence_indices(pattern: str) -> list[int]:
    """The frame numbers of the files an image-sequence pattern (``frames/img_%04d.png``) matches, sorted."""
    p = Path(pattern)
    m = re.search(r"%(0?)(\d*)d", p.name)
    if m is None or not p.parent.is_dir() and str(p.parent) not in ("", "."):
        return []
    width = int(m.group(2) or 0)
    digits = rf"\d{{{width}}}" if m.group(1) and width else r"\d+"
    rx = re.compile(re.escape(p.name[: m.start()]) + f"({digits})" + re.escape(p.name[m.end() :]) + "$")
    return sorted(
        {
            int(g.group(1))
            for f in (p.parent if str(p.parent) else Path(".")).iterdir()
            if f.is_file() and (g := rx.match(f.name))
        }
    )


def open_reader(path: str | os.PathLike[str], max_frames: int | None) -> tuple[VideoReader | AvReader, bool]:
    """The reader of one input: ``(reader, is_av)``; an image-sequence pattern is read by OpenCV
    (:class:`VideoReader`, BGR frames), anything else by PyAV (:class:`AvReader`, raw ``yuv420p`` frames
    where the decoder gives them)."""
    p = str(path)
    if "%" in p:
        return VideoReader(p, max_frames=max_frames), False
    return AvReader(p, max_frames=max_frames, raw=True), True


def decode_into(reader: FrameReader, q: queue.Queue[object], stop: threading.Event) -> None:
    """Decode every frame of ``reader`` into the queue ``q`` as ``(frame, decode_ms)``, then :data:`END`;
    returns early when ``stop`` is set (a consumer failed)."""
    t = time.perf_counter()
    for fr in reader:
        now = time.perf_counter()
        if not put_or_stop(q, (fr, (now - t) * 1e3), stop):
            return
        t = time.perf_counter()
    put_or_stop(q, END, stop)


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
    >>> for i in range(3):
    ...     _ = cv2.imwrite(f"{d}/f{i:03d}.png", np.full((48, 64, 3), 60 * i, np.uint8))
    >>> [(f.index, f.image.shape) for f in VideoReader(d + "/f%03d.png")]
    [(0, (48, 64, 3)), (1, (48, 64, 3)), (2, (48, 64, 3))]
    """

    def __init__(self, path: str | os.PathLike[str], max_frames: int | None = None) -> None:
        self.path = str(path)
        if max_frames is not None and int(max_frames) < 1:
            raise UsageError(f"--max-frames {max_frames}: must be >= 1")
        self.max_frames = None if max_frames is None else int(max_frames)
        if not looks_like_sequence(self.path):
            p = Path(self.path)
            if not p.exists():
                raise ImageError(f"{self.path}: no such video file")
            if p.is_dir():
                raise ImageError(f"{self.path}: is a folder, not a video (use a pattern such as DIR/%04d.png)")
            if p.stat().st_size == 0:
                raise ImageError(f"{self.path}: empty file, not a video")
        self.end_note: str | None = None  # why the frames stop before frame_count (engine warnings)
        seq = sequence_indices(self.path) if looks_like_sequence(self.path) else None
        if seq is not None and not seq:
            raise ImageError(f"{self.path}: no file matches this image-sequence pattern")
        _quiet_ffmpeg()
        cap = cv2.VideoCapture(self.path)
        if not cap.isOpened():
            cap.release()
            raise ImageError(
                f"{self.path}: cannot open as a video (not a video, or a format/codec OpenCV's video I/O cannot decode)"
            )
        ok, first = cap.read()
        if not ok or first is None or first.size == 0:
            cap.release()
            raise ImageError(f"{self.path}: no decodable frame (corrupt or unsupported video)")
        self._cap: cv2.VideoCapture | None = cap
        self._first: np.ndarray | None = first
        fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps_assumed = not (math.isfinite(fps) and 0.0 < fps < 1e4)
        self.fps = 25.0 if self.fps_assumed else fps
        n = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        self.frame_count = int(n) if (math.isfinite(n) and n > 0) else None
        if seq:  # OpenCV stops at the first missing number: count every file, so a gap reads as truncated
            gaps = [i + 1 for i, j in itertools.pairwise(seq) if j != i + 1]
            if gaps:
                self.frame_count = len(seq)
                try:
                    missing = self.path % gaps[0]
                except (TypeError, ValueError):
                    missing = f"number {gaps[0]}"
                self.end_note = (
                    f"image {missing} is missing, the sequence stops there; "
                    f"{len([i for i in seq if i > gaps[0]])} later image(s) not read"
                )
        self.height, self.width = first.shape[:2]
        self.n_read = 0
        self.n_decode_errors = 0
        self._last_t: float | None = None
        self._t0: float | None = None
        self._started = False

    # -- iteration ---------------------------------------------------------------------------------
    def _timestamp(self, index: int) -> float:
        """The decoder's timestamp of the frame just read (s), if usable; else index / fps."""
        assert self._cap is not None  # open while iterated
        ms = self._cap.get(cv2.CAP_PROP_POS_MSEC)
        t: float | None = None
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

    def __iter__(self) -> Iterator[VideoFrame]:
        if self._started:
            raise UsageError(f"{self.path}: a VideoReader can be iterated only once")
        self._started = True
        index = 0
        img = self._first
        self._first = None
        cap = self._cap
        assert cap is not None  # closed at the end of this, the one iteration
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
            ok, nxt = cap.read()
            img = nxt if ok and nxt is not None and nxt.size else None
        self.close()

    @property
    def truncated(self) -> bool:
        """Fewer frames decoded than the container declares (a damaged tail), when reading to the end."""
        return (
            self.frame_count is not None
            and self.max_frames is None
            and self._started
            and self._cap is None
            and self.n_read < self.frame_count - 1
        )

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - best effort
        with contextlib.suppress(Exception):
            self.close()
