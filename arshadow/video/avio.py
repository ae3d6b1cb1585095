"""Video input and output through PyAV (FFmpeg): decoding with timestamps, H.264 encoding, audio kept.

:class:`AvReader`
    The frames of a video file as :class:`VideoFrame` (BGR, presentation time), with the
    stream's declared frame count (a damaged tail is reported as ``truncated``), packets that fail to
    decode counted (``n_decode_errors``) instead of ending the video, and the audio stream's presence.
:class:`AvWriter`
    Encodes frames into a temporary file beside the target and renames it into place when the ``with``
    block ends without an error (CONVENTIONS.md: never half-written): H.264 (``libx264``, CRF) by default,
    FFV1 (lossless) for single-channel masks; the input's audio packets are copied unchanged.

Why PyAV rather than OpenCV's writer: OpenCV's wheel has no H.264 encoder (MPEG-4 part 2 only, ~2x the
bits for the same quality), no audio, and no CRF; measured in docs/video.md.

Frames (CONVENTIONS.md): images are ``(H, W, 3) uint8`` BGR, row 0 at the top.

(About 630 lines, over the project's ~600: the reader and the writer share PyAV's loading, its error
handling and the frame plumbing, annotated with PyAV's own types; the next part that grows moves out.)
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from types import ModuleType, TracebackType
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # PyAV loads on first use (load_av): importing arshadow does not load FFmpeg
    import av

from ..errors import ImageError, UsageError, write_error

__all__ = [
    "VIDEO_CODECS",
    "AvReader",
    "AvWriter",
    "RawFrame",
    "VideoFrame",
    "display_rotation",
    "frame_rotation",
    "fill_plane",
    "load_av",
    "pts_time",
]

#: FFmpeg's ``AVCOL_RANGE_JPEG``: a frame whose samples use the full 0..255 range
FULL_RANGE = 2

#: ``--codec`` choices -> (FFmpeg encoder, pixel format, container extensions it suits)
VIDEO_CODECS = {
    "h264": ("libx264", "yuv420p"),
    "mpeg4": ("mpeg4", "yuv420p"),
    "mjpeg": ("mjpeg", "yuvj420p"),
    "ffv1": ("ffv1", "bgr0"),
}


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


@dataclass(frozen=True)
class RawFrame:
    """A decoded frame as the decoder gave it (:class:`AvReader` with ``raw=True``).

    Attributes
    ----------
    index : int
    time_s : float
    image : ndarray
        ``(H * 3 // 2, W) uint8`` planar Y, U, V when ``format == "yuv420p"`` (limited-range frames of even
        size only); else ``(H, W, 3) uint8`` BGR.
    format : str
        ``"yuv420p"`` or ``"bgr24"``.
    """

    index: int
    time_s: float
    image: np.ndarray
    format: str = "bgr24"


def load_av() -> ModuleType:
    """PyAV, with FFmpeg's own log silenced (a UsageError naming the package when it is missing)."""
    try:
        import av  # deferred: importing arshadow does not load FFmpeg; the error names the package
    except ImportError:
        raise UsageError("video needs PyAV, a dependency of arshadow: pip install av") from None
    av.logging.set_level(av.logging.PANIC)  # FFmpeg's own chatter: arshadow reports one line of its own
    return av


def pts_time(pts: int, time_base: Fraction | float) -> float:
    """Seconds of a timestamp, ``pts * time_base`` rounded once (the same float in every reader).

    >>> from fractions import Fraction
    >>> pts_time(512, Fraction(1, 12800))
    0.04
    """
    return float(int(pts) * Fraction(time_base))


class AvReader:
    """The frames of a video file, decoded by FFmpeg (PyAV), with timestamps.

    Parameters
    ----------
    path : str or Path
    max_frames : int, optional
        Stop after this many frames.
    threads : int
        Decoder threads (0: FFmpeg's choice).
    raw : bool
        Yield :class:`RawFrame` (planar ``yuv420p`` kept when the stream has it) instead of BGR
        :class:`VideoFrame`.

    Attributes
    ----------
    fps : Fraction-like float
        The stream's average frame rate (25 assumed, ``fps_assumed``, when it declares none).
    rate : Fraction
        The same as an exact fraction (for the writer).
    width, height : int
    frame_count : int or None
        Frames the container declares (None if it declares none).
    has_audio : bool
    rotation : int
        Degrees a player turns the stored frames for display (the stream's display matrix: a phone video
        filmed upright is stored sideways with 90 or 270); the frames are read as stored.
    n_read, n_decode_errors : int
        Frames decoded so far; packets that failed to decode (skipped).

    Raises
    ------
    ImageError
        Missing, empty, or not a decodable video.
    """

    _c: av.container.InputContainer | None  # None once closed
    _vs: av.video.stream.VideoStream

    def __init__(
        self, path: str | os.PathLike[str], max_frames: int | None = None, threads: int = 0, raw: bool = False
    ) -> None:
        av = load_av()
        self.raw = bool(raw)
        self.path = str(path)
        p = Path(self.path)
        if not p.exists():
            raise ImageError(f"{self.path}: no such video file")
        if p.is_dir():
            raise ImageError(f"{self.path}: is a folder, not a video")
        if p.stat().st_size == 0:
            raise ImageError(f"{self.path}: empty file, not a video")
        if max_frames is not None and int(max_frames) < 1:
            raise UsageError(f"--max-frames {max_frames}: must be >= 1")
        self.max_frames = None if max_frames is None else int(max_frames)
        try:
            c = av.open(self.path, "r")
        except (av.FFmpegError, OSError, ValueError) as exc:
            raise ImageError(f"{self.path}: cannot open as a video ({_short(exc)})") from None
        self._c = c
        if not c.streams.video:
            c.close()
            raise ImageError(f"{self.path}: no video stream")
        vs = self._vs = c.streams.video[0]
        vs.thread_type = "AUTO"
        if threads:
            vs.codec_context.thread_count = int(threads)
        rate = vs.average_rate or vs.guessed_rate
        self.fps_assumed = not (rate and 0 < float(rate) < 1e4)
        self.rate = Fraction(25, 1) if self.fps_assumed else Fraction(rate.numerator, rate.denominator)
        self.fps = float(self.rate)
        n = int(vs.frames or 0)
        if n <= 0 and vs.duration and vs.time_base:
            n = int(round(float(vs.duration * vs.time_base) * self.fps))
        if n <= 0 and c.duration:  # e.g. Matroska: the container's duration (microseconds)
            n = int(round(c.duration / 1e6 * self.fps))
        self.frame_count = n if n > 0 else None
        self.width, self.height = int(vs.codec_context.width), int(vs.codec_context.height)
        self.has_audio = bool(c.streams.audio)
        self.pix_fmt = vs.codec_context.pix_fmt
        self._rotation: int | None = None  # read from the first frame decoded (or on demand: rotation)
        self.n_read = 0
        self.n_decode_errors = 0
        self.ended_with_error = False
        self._started = False
        if self.width <= 0 or self.height <= 0:
            self.close()
            raise ImageError(f"{self.path}: no decodable frame (unknown frame size)")

    def __iter__(self) -> Iterator[RawFrame | VideoFrame]:
        if self._started:
            raise UsageError(f"{self.path}: an AvReader can be iterated only once")
        self._started = True
        t0 = None
        last_t = -math.inf
        index = 0
        try:
            for f in self._decoded():
                if self.max_frames is not None and index >= self.max_frames:
                    return
                # planar only for limited-range ("TV") frames: a full-range yuv420p frame (FFV1, HEVC from
                # some phones; H.264 decodes those as yuvj420p) goes through FFmpeg's BGR conversion, which
                # honours the range (the planar path's conversions assume 16..235)
                fmt = (
                    "yuv420p"
                    if (
                        self.raw
                        and f.format.name == "yuv420p"
                        and getattr(f, "color_range", 0) != FULL_RANGE
                        and not (f.width % 2 or f.height % 2)
                    )
                    else "bgr24"
                )
                img = f.to_ndarray(format=fmt)
                t = pts_time(f.pts, f.time_base) if f.pts is not None and f.time_base else f.time
                if t is None or not math.isfinite(t):
                    t = index / self.fps
                else:
                    t0 = t if t0 is None else t0
                    t -= t0
                if not t > last_t:
                    t = max(index / self.fps, last_t + 1e-6)
                last_t = t
                img.setflags(write=False)
                self.n_read += 1
                yield RawFrame(index, float(t), img, fmt) if self.raw else VideoFrame(index, float(t), img)
                index += 1
        finally:
            self.close()

    @property
    def rotation(self) -> int:
        """Degrees a player turns the stored frames (see the class): from the first frame this reader
        decoded, or, before any, from a frame decoded for the purpose (:func:`display_rotation`)."""
        if self._rotation is None:
            self._rotation = display_rotation(self.path)
        return self._rotation

    def _decoded(self) -> Iterator[av.VideoFrame]:
        """The decoded ``av.VideoFrame`` s in order, damaged packets skipped and counted.

        Frame threading (fast) drops the frames in flight when a packet fails to decode or the file ends
        early; at the first sign of either, decoding starts again from the top without frame threads and
        goes on after the frames already given (damaged files only pay for the second pass).
        """
        av = load_av()
        given = 0
        trouble = False
        assert self._c is not None  # open until this iteration ends (the reader is iterated once)
        try:
            for packet in self._c.demux(self._vs):
                try:
                    frames = packet.decode()
                except av.FFmpegError:
                    trouble = True
                    break
                for f in frames:
                    if self._rotation is None:  # the display matrix rides on the frames (no second decode)
                        self._rotation = frame_rotation(f)
                    given += 1
                    yield f
        except av.FFmpegError:
            trouble = True
        if not trouble and not (self.frame_count is not None and given < self.frame_count - 1):
            return
        self.close()
        try:
            self._c = c = av.open(self.path, "r")
            vs = c.streams.video[0]
            vs.thread_type = "SLICE"
            k = 0
            for packet in c.demux(vs):
                try:
                    frames = packet.decode()
                except av.FFmpegError:
                    self.n_decode_errors += 1
                    continue
                for f in frames:
                    k += 1
                    if k > given:
                        yield f
        except (av.FFmpegError, OSError, IndexError):
            self.ended_with_error = True

    @property
    def truncated(self) -> bool:
        """The stream ended early: fewer frames than declared, or a read error ended it."""
        if self.max_frames is not None and self.n_read >= self.max_frames:
            return False
        got = self.n_read + self.n_decode_errors  # a damaged packet is not a missing tail
        return self.ended_with_error or (self.frame_count is not None and got < self.frame_count - 1)

    def close(self) -> None:
        c, self._c = getattr(self, "_c", None), None
        if c is not None:
            with contextlib.suppress(Exception):
                c.close()

    def __enter__(self) -> AvReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _short(exc: BaseException) -> str:
    """FFmpeg's own reason (``Invalid data found when processing input``) without the file name and log."""
    reason = getattr(exc, "strerror", None)
    if reason:
        return str(reason)
    return str(exc).strip().splitlines()[-1][:120] if str(exc).strip() else type(exc).__name__


class AvWriter:
    """Encode frames into ``path`` atomically (temporary file, renamed when the block succeeds).

    Parameters
    ----------
    path : str or Path
        Target; its extension chooses the container (``.mp4``, ``.mkv``, ``.mov``, ``.avi``).
    rate : Fraction or float
        Frame rate (frames get consecutive timestamps at this rate).
    size : (int, int)
        ``(width, height)``.
    codec : str
        A key of :data:`VIDEO_CODECS` (``h264`` default), ignored for ``color=False`` (FFV1 gray).
    crf : float
        Constant rate factor of ``h264`` (0 lossless .. 51; 18-23 visually transparent to good).
    preset : str
        x264 speed preset (``veryfast`` default: measured in docs/video.md).
    color : bool
        ``(H, W, 3)`` BGR frames (True) or ``(H, W)`` uint8 frames (False: lossless FFV1 gray).
    audio_from : str or Path, optional
        Copy this file's first audio stream (packets unchanged) into the output.
    threads : int
        Encoder threads (0: the encoder's choice).
    gop : int, optional
        H.264: a keyframe every ``gop`` frames exactly (no scene-cut keyframes); None: x264's choice.
    pix_fmt : str, optional
        Encode in this pixel format instead of the codec's default (``ffv1`` of ``yuv420p`` input: keep
        ``yuv420p``, so frames written with :meth:`write_yuv420p` stay bit-exact).
    rotation : int
        Display rotation (degrees) written into the stream (the input's :attr:`AvReader.rotation`): a
        phone video filmed upright plays upright. The frames themselves are stored as given.

    Raises
    ------
    ImageError
        Unwritable target, a codec the container refuses, a frame of the wrong size.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        rate: Fraction | float,
        size: tuple[int, int],
        *,
        codec: str = "h264",
        crf: float = 20,
        preset: str = "veryfast",
        color: bool = True,
        audio_from: str | os.PathLike[str] | None = None,
        threads: int = 0,
        pix_fmt: str | None = None,
        gop: int | None = None,
        rotation: int = 0,
    ) -> None:
        self.path = Path(path)
        if codec not in VIDEO_CODECS:
            raise UsageError(f"--codec {codec}: use one of {', '.join(VIDEO_CODECS)}")
        if not (0 <= float(crf) <= 51):
            raise UsageError(f"--crf {crf}: must be 0..51")
        self.rate = Fraction(rate).limit_denominator(1_000_000) if not isinstance(rate, Fraction) else rate
        if not self.rate > 0:
            raise UsageError(f"{self.path}: frame rate must be positive, got {rate}")
        self.size = (int(size[0]), int(size[1]))
        self.codec, self.crf, self.preset, self.color = codec, float(crf), preset, bool(color)
        self.audio_from, self.threads, self.pix_fmt = audio_from, int(threads), pix_fmt
        self.gop = None if gop is None else int(gop)
        self.rotation = int(rotation) % 360
        self.n_written = 0
        self.audio_copied = False
        self._stack: contextlib.ExitStack[bool | None] | None = None
        self._c: av.container.OutputContainer | None = None
        self._vs: av.video.stream.VideoStream | None = None
        # (source container, its audio stream, the output's copy) while the audio is copied
        self._audio: tuple[av.container.InputContainer, av.stream.Stream, av.stream.Stream] | None = None
        self._frames: dict[str, av.VideoFrame] = {}  # pixel format -> the reused av.VideoFrame (see _frame)

    def __enter__(self) -> AvWriter:
        from ..io import atomic_path

        av = load_av()
        stack = contextlib.ExitStack()
        try:
            self.tmp_path = stack.enter_context(atomic_path(self.path))
            try:
                fmt = _container_format(self.path)
                c = av.open(
                    str(self.tmp_path),
                    "w",
                    format=fmt,
                    options={"movflags": "+faststart"} if fmt in ("mp4", "mov") else None,
                )
            except (av.FFmpegError, OSError, ValueError) as exc:
                raise write_error(f"{self.path}: cannot write ({_short(exc)})", exc) from None
            stack.callback(self._close_container, av, c)
            name, pix = VIDEO_CODECS[self.codec] if self.color else ("ffv1", "gray")
            if self.pix_fmt is not None and self.color:
                pix = self.pix_fmt
            try:
                vs = c.add_stream(name, rate=self.rate)
            except (av.FFmpegError, ValueError) as exc:
                raise ImageError(f"{self.path}: cannot encode {name} ({_short(exc)})") from None
            vs.width, vs.height = self.size
            vs.pix_fmt = pix
            if self.rotation:  # the input's display rotation: players show the output as they showed it
                vs.set_display_rotation(self.rotation)
            if self.threads:
                vs.codec_context.thread_count = self.threads
            if name == "libx264":
                vs.options = {"crf": f"{self.crf:g}", "preset": self.preset}
                if self.gop:  # a keyframe every gop frames, and only there (chunk boundaries)
                    vs.options["x264-params"] = f"keyint={self.gop}:min-keyint={self.gop}:scenecut=0"
                if self.size[0] % 2 or self.size[1] % 2:
                    raise ImageError(
                        f"{self.path}: H.264 (yuv420p) needs an even frame size, got {self.size}; "
                        f"use --codec ffv1 or mpeg4"
                    )
            elif name == "mpeg4":
                vs.options = {"qscale": "3"}
                vs.codec_context.qmin = 2
            self._audio = None
            if self.audio_from is not None:
                self._audio = self._open_audio(av, c)
            self._c, self._vs, self._stack = c, vs, stack
        except BaseException:
            stack.__exit__(*sys.exc_info())
            raise
        return self

    def _open_audio(
        self, av: ModuleType, c: av.container.OutputContainer
    ) -> tuple[av.container.InputContainer, av.stream.Stream, av.stream.Stream] | None:
        try:
            src = av.open(str(self.audio_from), "r")
        except (av.FFmpegError, OSError):
            return None
        if not src.streams.audio:
            src.close()
            return None
        try:
            out = c.add_stream_from_template(src.streams.audio[0])
        except (av.FFmpegError, ValueError):
            src.close()
            return None  # the container cannot hold this audio codec: the video is written without it
        return src, src.streams.audio[0], out

    def write(self, frame: np.ndarray) -> None:
        """Append one frame: ``(H, W, 3) uint8`` BGR (``color``) or ``(H, W) uint8``."""
        av = load_av()
        vs, cont = self._vs, self._c
        if vs is None or cont is None:  # both set in __enter__, cleared in __exit__
            raise UsageError("AvWriter.write outside its with-block")
        f = np.asarray(frame)
        want = (self.size[1], self.size[0], 3) if self.color else (self.size[1], self.size[0])
        if f.shape != want or f.dtype != np.uint8:
            raise ImageError(f"{self.path}: frame {self.n_written} is {f.shape} {f.dtype}, expected {want} uint8")
        vf = self._frame(av, "bgr24" if self.color else "gray")
        fill_plane(vf.planes[0], f.reshape(f.shape[0], -1))
        self._encode(av, vf, vs, cont)

    def write_yuv420p(self, planes: np.ndarray) -> None:
        """Append one frame given as planar ``(H * 3 // 2, W) uint8`` Y, U, V (BT.601, as decoded)."""
        av = load_av()
        vs, cont = self._vs, self._c
        if vs is None or cont is None:  # both set in __enter__, cleared in __exit__
            raise UsageError("AvWriter.write_yuv420p outside its with-block")
        f = np.asarray(planes)
        if f.shape != (self.size[1] * 3 // 2, self.size[0]) or f.dtype != np.uint8 or not self.color:
            raise ImageError(f"{self.path}: frame {self.n_written} is {f.shape} {f.dtype}, expected planar yuv420p")
        vf = self._frame(av, "yuv420p")
        H, W = self.size[1], self.size[0]
        c = f[H:].reshape(-1)
        q = (H // 2) * (W // 2)
        fill_plane(vf.planes[0], f[:H])
        fill_plane(vf.planes[1], c[:q].reshape(H // 2, W // 2))
        fill_plane(vf.planes[2], c[q:].reshape(H // 2, W // 2))
        self._encode(av, vf, vs, cont)

    def _frame(self, av: ModuleType, fmt: str) -> av.VideoFrame:
        """The writer's one ``av.VideoFrame`` of format ``fmt``, allocated at the first frame and refilled for
        every later one: a fresh frame per write (``VideoFrame.from_ndarray``) cost 1.8 ms of CPU per 3840x2160
        frame against 0.6 ms refilled (and up to ~7 ms while a fresh allocation page-faults). Reusing it is safe: FFmpeg takes its own copy of a frame that
        is not reference-counted (PyAV's) when it is sent, and x264 copies the picture as it encodes."""
        vf = self._frames.get(fmt)
        if vf is None:
            vf = self._frames[fmt] = av.VideoFrame(self.size[0], self.size[1], fmt)
        return vf

    def _encode(
        self,
        av: ModuleType,
        vf: av.VideoFrame | None,
        vs: av.video.stream.VideoStream,
        c: av.container.OutputContainer,
    ) -> None:
        """Encode and mux one frame (``None``: flush); a failing encoder or write (disk full) is an ImageError
        naming the target (the temporary file is removed when the with-block ends)."""
        if vf is not None:
            vf.pts = self.n_written
            vf.time_base = 1 / self.rate
        try:
            for pkt in vs.encode(vf):
                c.mux(pkt)
        except (av.FFmpegError, OSError) as exc:
            raise write_error(f"{self.path}: cannot write ({_short(exc)}); nothing written", exc) from None
        if vf is not None:
            self.n_written += 1

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> bool | None:
        c, vs, stack = self._c, self._vs, self._stack
        self._c = self._vs = self._stack = None
        if stack is None:
            return False
        assert c is not None and vs is not None  # opened with the stack (__enter__)
        av = load_av()
        try:
            if exc_type is None:
                if self.n_written == 0:
                    raise ImageError(f"{self.path}: no frame to write")
                self._encode(av, None, vs, c)
                if self._audio is not None:
                    try:
                        self._copy_audio(c)
                    except (av.FFmpegError, OSError) as e:
                        raise write_error(f"{self.path}: cannot write ({_short(e)}); nothing written", e) from None
        except BaseException:
            if stack.__exit__(*sys.exc_info()):
                return True
            raise
        finally:
            if self._audio is not None:
                with contextlib.suppress(Exception):
                    self._audio[0].close()
        return stack.__exit__(exc_type, exc, tb)

    def _close_container(self, av: ModuleType, c: av.container.OutputContainer) -> None:
        try:
            c.close()  # writes the trailer
        except (av.FFmpegError, OSError) as exc:
            raise write_error(f"{self.path}: cannot write ({_short(exc)}); nothing written", exc) from None

    def _copy_audio(self, c: av.container.OutputContainer) -> None:
        """Copy the source's audio packets up to the video's duration."""
        assert self._audio is not None  # called when the audio is copied
        src, ins, out = self._audio
        end = self.n_written / float(self.rate)
        for pkt in src.demux(ins):
            if pkt.dts is None:
                continue
            if pkt.pts is not None and pkt.time_base and float(pkt.pts * pkt.time_base) > end:
                break
            pkt.stream = out
            c.mux(pkt)
        self.audio_copied = True


def fill_plane(plane: av.video.plane.VideoPlane, rows: np.ndarray) -> None:
    """Copy ``rows (h, n) uint8`` (``n`` bytes of pixels per row) into a PyAV frame plane, whose rows may be
    padded to a longer ``line_size``.

    >>> import av
    >>> vf = av.VideoFrame(6, 2, "gray")
    >>> fill_plane(vf.planes[0], np.arange(12, dtype=np.uint8).reshape(2, 6))
    >>> vf.to_ndarray().tolist()
    [[0, 1, 2, 3, 4, 5], [6, 7, 8, 9, 10, 11]]
    """
    h, n = rows.shape
    ls = plane.line_size  # the plane's buffer holds line_size * h bytes
    # a VideoPlane has the buffer protocol; PyAV's stubs do not declare it
    np.frombuffer(plane, np.uint8)[: h * ls].reshape(h, ls)[:, :n] = rows  # type: ignore[call-overload]


def frame_rotation(frame: av.VideoFrame) -> int:
    """The display rotation (degrees: 0, 90, 180 or 270) of a decoded ``av.VideoFrame`` (its display matrix)."""
    return int(round(float(getattr(frame, "rotation", 0) or 0))) % 360


def display_rotation(path: str | os.PathLike[str]) -> int:
    """The rotation (degrees, FFmpeg's display matrix: 0, 90, 180 or 270) a player applies to the stored
    frames of ``path``, e.g. a phone video filmed upright: read from its first decoded frame (PyAV keeps
    no stream-level side data), 0 when there is none or the file does not decode."""
    av = load_av()
    try:
        with av.open(str(path), "r") as c:
            for f in c.decode(video=0):
                return frame_rotation(f)
    except (av.FFmpegError, OSError, ValueError):
        pass
    return 0


def _container_format(path: Path) -> str | None:
    return {".mkv": "matroska", ".mp4": "mp4", ".m4v": "mp4", ".mov": "mov", ".avi": "avi"}.get(path.suffix.lower())
