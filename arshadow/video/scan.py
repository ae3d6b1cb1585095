"""The frame index of a video file, read from its packets without decoding, and a reader that starts at a
keyframe: what cutting one video into chunks needs.

:func:`scan_stream` demuxes the video stream once (no decoding: milliseconds per thousand frames) and
returns a :class:`StreamIndex`: every frame's presentation timestamp in presentation order, the frames that
start a keyframe (where decoding can begin), and each frame's ``time_s`` by the rule the sequential reader
(:class:`arshadow.video.avio.AvReader`) applies, so that a chunk's frames carry exactly the indices and
times they have in a run over the whole video. :class:`SeekReader` decodes from a keyframe to a stop frame
and yields :class:`arshadow.video.avio.RawFrame` s with those global indices and times.

Frames (CONVENTIONS.md): images planar ``yuv420p`` (H, W even) or BGR, row 0 at the top.
"""

from __future__ import annotations

import itertools
import math
import os
from bisect import bisect_right
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import ImageError
from ..scene.sanity import sun_set_warning
from .avio import RawFrame, load_av, pts_time

if TYPE_CHECKING:
    import av.container
    import av.video.stream

    from ..lights.suntrack import SunTrack

__all__ = ["SeekReader", "StreamIndex", "scan_stream"]


@dataclass
class StreamIndex:
    """What :func:`scan_stream` read from a video's packets.

    Attributes
    ----------
    pts : list of int
        Every frame's presentation timestamp (stream time base), in presentation order.
    times : list of float
        ``time_s`` of each frame, seconds from the first frame (as :class:`arshadow.video.avio.AvReader`).
    keyframes : list of int
        Indices of the frames decoding can start at (keyframes), ascending; ``keyframes[0] == 0``.
    fps : float
    vfr : bool
        The frame intervals differ by more than 1 % (variable frame rate).
    problem : str or None
        Why the video cannot be cut (then it is processed in one piece), or None.
    """

    pts: list[int] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    keyframes: list[int] = field(default_factory=list)
    fps: float = 25.0
    vfr: bool = False
    problem: str | None = None

    @property
    def n(self) -> int:
        return len(self.pts)

    def keyframe_at_or_before(self, index: int) -> int:
        """The last keyframe index <= ``index`` (0 at least)."""
        k = bisect_right(self.keyframes, index) - 1
        return self.keyframes[max(k, 0)]


def scan_stream(path: str | os.PathLike[str]) -> StreamIndex:
    """Index the frames of a video file from its packets (no decoding).

    Raises
    ------
    ImageError
        The file cannot be opened or has no video stream.
    """
    av = load_av()
    try:
        c = av.open(str(path), "r")
    except (av.FFmpegError, OSError, ValueError) as exc:
        raise ImageError(f"{path}: cannot open as a video ({exc})") from None
    with c:
        if not c.streams.video:
            raise ImageError(f"{path}: no video stream")
        vs = c.streams.video[0]
        rate = vs.average_rate or vs.guessed_rate
        fps = float(rate) if rate and 0 < float(rate) < 1e4 else 25.0
        tb = vs.time_base
        pts: list[int] = []
        keys: set[int] = set()
        problem: str | None = None
        try:
            for pkt in c.demux(vs):
                if pkt.size == 0:
                    continue  # the demuxer's end-of-stream flush packet
                if pkt.pts is None:
                    problem = "packets without timestamps"
                    break
                pts.append(int(pkt.pts))
                if pkt.is_keyframe:
                    keys.add(int(pkt.pts))
        except (av.FFmpegError, OSError) as exc:
            problem = f"unreadable packets ({exc})"
    return _index(pts, keys, tb, fps, problem)


def _index(pts: list[int], keys: set[int], tb: Fraction, fps: float, problem: str | None) -> StreamIndex:
    pts = sorted(pts)
    if not pts:
        return StreamIndex(fps=fps, problem=problem or "no video packets")
    if len(set(pts)) != len(pts):
        problem = problem or "duplicate timestamps"
    t0 = pts_time(pts[0], tb)
    times: list[float] = []
    last = -math.inf
    for i, p in enumerate(pts):
        t = pts_time(p, tb) - t0
        if not t > last:
            t = max(i / fps, last + 1e-6)
        times.append(t)
        last = t
    pos = {p: i for i, p in enumerate(pts)}
    kf = sorted(pos[p] for p in keys if p in pos)
    if not kf or kf[0] != 0:
        problem = problem or "the first frame is not a keyframe"
    d = [b - a for a, b in itertools.pairwise(times)]
    vfr = bool(d) and (max(d) - min(d)) > 0.01 * (sum(d) / len(d))
    return StreamIndex(pts, times, kf or [0], fps, vfr, problem)


class SeekReader:
    """The frames ``[start, stop)`` of a video, decoded from the keyframe ``start`` (an index of ``index``).

    Parameters
    ----------
    path : str or Path
    index : StreamIndex
    start : int
        A keyframe index.
    stop : int
        One past the last frame wanted.
    skip_before : int
        Frames before this index are decoded (the decoder needs them) but not converted or yielded:
        a chunk's primer tracks only the frames its pose stream needs (default ``start``: none skipped).
    threads : int
        Decoder threads (0: FFmpeg's choice, one per core and one more; a chunk worker sharing the cores
        with others gets its share).

    Attributes
    ----------
    width, height, fps, rate, pix_fmt, has_audio, frame_count
        As :class:`arshadow.video.avio.AvReader` (``frame_count``: the index's).

    Raises
    ------
    ImageError
        A decoded frame whose timestamp is not in the index (the index does not describe this file).
    """

    _c: av.container.InputContainer | None  # None once closed
    _vs: av.video.stream.VideoStream

    def __init__(
        self,
        path: str | os.PathLike[str],
        index: StreamIndex,
        start: int,
        stop: int,
        *,
        skip_before: int = 0,
        threads: int = 0,
    ) -> None:
        av = load_av()
        self.path, self.index, self.start, self.stop = str(path), index, int(start), int(stop)
        self.skip_before = max(self.start, int(skip_before))
        self._c = c = av.open(self.path, "r")
        vs = self._vs = c.streams.video[0]
        vs.thread_type = "AUTO"
        if threads:
            vs.codec_context.thread_count = int(threads)
        rate = vs.average_rate or vs.guessed_rate
        self.fps_assumed = not (rate and 0 < float(rate) < 1e4)
        self.rate = Fraction(25, 1) if self.fps_assumed else Fraction(rate.numerator, rate.denominator)
        self.fps = float(self.rate)
        self.width, self.height = int(vs.codec_context.width), int(vs.codec_context.height)
        self.pix_fmt = vs.codec_context.pix_fmt
        self.has_audio = bool(c.streams.audio)
        self.frame_count = index.n
        self.truncated, self.n_decode_errors = False, 0
        self.end_note: str | None = None
        self.n_read = 0

    def __iter__(self) -> Iterator[RawFrame]:
        av = load_av()
        try:
            yield from self._frames()
        except av.FFmpegError as exc:
            raise ImageError(
                f"{self.path}: cannot decode frames {self.start}-{self.stop - 1} of a chunk ({exc})"
            ) from None

    def _frames(self) -> Iterator[RawFrame]:
        pos = {p: i for i, p in enumerate(self.index.pts[self.start : self.stop + 64], self.start)}
        first = self.index.pts[self.start]
        c = self._c
        assert c is not None  # open until its one iteration ends
        try:
            if self.start > 0:
                c.seek(first, stream=self._vs, backward=True, any_frame=False)
            for f in c.decode(self._vs):
                if f.pts is None or f.pts < first:
                    continue  # leading frames of an open GOP, decoded from before the keyframe
                i = pos.get(int(f.pts))
                if i is None:
                    raise ImageError(f"{self.path}: frame at pts {f.pts} is not in the stream's index")
                if i >= self.stop:
                    return
                if i < self.skip_before:
                    continue  # decoded for the frames after it, not needed by the pose stream
                fmt = "yuv420p" if (f.format.name == "yuv420p" and not (f.width % 2 or f.height % 2)) else "bgr24"
                img = f.to_ndarray(format=fmt)
                img.setflags(write=False)
                self.n_read += 1
                yield RawFrame(i, float(self.index.times[i]), img, fmt)
        finally:
            self.close()

    def close(self) -> None:
        c, self._c = self._c, None
        if c is not None:
            c.close()


def chunk_name(path: str | os.PathLike[str]) -> str:
    """A file-name-safe label of ``path`` (for chunk folders)."""
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in Path(str(path)).name)[:60]


def time_lapse_warnings(
    videos: Sequence[str | os.PathLike[str]],
    tracks: Sequence[SunTrack],
    time_lapse: tuple[datetime, float] | None,
    max_frames: int | None = None,
) -> dict[str, str]:
    """:func:`sun_set_warning` for each video of a time-lapse, read before any frame is decoded (the
    container's frame count and rate).

    Parameters
    ----------
    videos : list of str
    tracks : list of SunTrack
    time_lapse : (datetime, float) or None
        ``(start, speed)`` of ``arshadow video --time-lapse``.
    max_frames : int, optional

    Returns
    -------
    dict
        ``{video: message}`` for the videos in which a sun sets (a video that cannot be opened is left to
        the engine, which reports it).
    """
    # deferred: PyAV is loaded only when a time-lapse is asked for (sanity is imported by every path)
    from ..errors import ArshadowError
    from .avio import AvReader

    out: dict[str, str] = {}
    if not tracks or time_lapse is None:
        return out
    for v in videos:
        try:
            reader = AvReader(v, max_frames=max_frames)
        except (ArshadowError, OSError):
            continue
        try:
            n, fps = reader.frame_count, reader.fps
        finally:
            reader.close()
        if n is None:
            continue
        n = min(n, int(max_frames)) if max_frames else n
        msg = sun_set_warning(tracks, time_lapse[0], time_lapse[1], fps, n, label=str(v))
        if msg:
            out[str(v)] = msg
    return out
