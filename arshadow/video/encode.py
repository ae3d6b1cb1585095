"""Encoding: the encode thread's body (video, mask, JSON Lines report, contact-sheet thumbnails), and the
atomic folder and contact sheet it writes.

Every output is written to a temporary name and renamed into place when complete (CONVENTIONS.md): the
video (``.mp4`` or ``--format``), the per-frame ``.frames.jsonl``, the mask (``.shadow.mkv`` lossless FFV1
or a ``.shadow/`` folder of PNGs) and the ``.sheet.jpg`` contact sheet.

Frames (CONVENTIONS.md): images BGR or planar ``yuv420p`` (BT.601, as decoded), row 0 at the top.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import shutil
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import ExitStack
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, TypeAlias, cast

import cv2
import numpy as np

from ..errors import ImageError
from ..io import atomic_path, write_image
from ..photos import contact_sheet
from .avio import AvWriter
from .decode import FrameReader
from .threads import END

if TYPE_CHECKING:
    import threading

    from ..frame.report import ReportItem
    from .engine import EngineOptions

__all__ = [
    "EncodeJob",
    "EncodeSink",
    "Progress",
    "ProgressFactory",
    "SheetThumbs",
    "VideoOutputs",
    "atomic_dir",
    "replace_dir",
    "required",
    "write_contact_sheet",
]

#: one video's (or chunk's) output paths by role (``video``, ``mask``, ``frames``, ``sheet``, ``layers:...``;
#: :func:`arshadow.video.engine.video_outputs`), None for one not written
VideoOutputs: TypeAlias = dict[str, Path | None]
#: ``progress(frames_done, frames_total_or_None)``
Progress: TypeAlias = Callable[[int, "int | None"], object]
#: ``progress_factory(input) -> (update(done, total), close())`` per video (a progress bar)
ProgressFactory: TypeAlias = Callable[[str], tuple[Progress, Callable[[], object]]]
#: what :meth:`arshadow.video.framejob.FrameComposer.compose` hands the encode thread: ``(image, format,
#: mask or None, report item, JSON Lines record)``
EncodeJob: TypeAlias = tuple[np.ndarray, str, "np.ndarray | None", "ReportItem", dict[str, Any]]


def required(outputs: Mapping[str, Path | None], key: str) -> Path:
    """``outputs[key]``, an output every run writes (``video``, ``frames``, a chunk's ``thumbs``)."""
    path = outputs[key]
    assert path is not None, key  # always set by video_outputs / ChunkStore.outputs
    return path


class SheetThumbs:
    """Contact-sheet thumbnails of every ``step``-th frame, 320 px wide; the step doubles (every other
    thumbnail dropped) when the video has more frames than declared.

    Parameters
    ----------
    count : int
        Thumbnails on the sheet (0: none).
    total : int or None
        Frames expected.
    size : (int, int)
        ``(width, height)`` of the frames.
    """

    def __init__(self, count: int, total: int | None, size: tuple[int, int]) -> None:
        self.count = int(count)
        self.step = max(1, (total or 0) // max(self.count, 1))
        self.W, self.H = size
        self.thumbs: dict[int, np.ndarray] = {}

    def add(self, index: int, img: np.ndarray, fmt: str) -> None:
        """Offer frame ``index`` (``(H, W, 3)`` BGR, or planar ``yuv420p`` when ``fmt`` says so)."""
        if not self.count or index % self.step:
            return
        bgr = img if fmt != "yuv420p" else cv2.cvtColor(img, cv2.COLOR_YUV2BGR_I420)
        self.offer(index, cv2.resize(bgr, (320, max(1, round(320 * self.H / self.W))), interpolation=cv2.INTER_AREA))

    def offer(self, index: int, thumb: np.ndarray) -> None:
        """Keep an already made thumbnail of frame ``index`` if it falls on the step (frames in order)."""
        if not self.count or index % self.step:
            return
        self.thumbs[index] = thumb
        if len(self.thumbs) > 2 * self.count:  # more frames than declared: keep every other one
            self.step *= 2
            for k in [k for k in self.thumbs if k % self.step]:
                del self.thumbs[k]

    def picked(self) -> dict[int, np.ndarray]:
        """``count`` thumbnails evenly spread over those kept, ``{frame: (h, 320, 3) uint8}``."""
        keys = sorted(self.thumbs)
        if not keys:
            return {}
        pick = {keys[round(i)] for i in np.linspace(0, len(keys) - 1, min(self.count, len(keys)))}
        return {k: self.thumbs[k] for k in pick}


def default_encoder_threads(cores: int | None = None) -> int:
    """Encoder threads when the options leave them open (``encoder_threads`` 0): one fewer than the cores
    (at least 1). The engine's own threads (decode, track, render and composite, encode) already keep the
    cores busy, and more encoder threads only contend: on 2 cores x264's own choice (1.5 per core) measured
    13.4-14.2 fps at 2160p against 14.8 with one thread, and the same at 720p and 1080p (docs/video.md).

    >>> default_encoder_threads(2), default_encoder_threads(16), default_encoder_threads(1)
    (1, 15, 1)
    """
    n = os.cpu_count() if cores is None else cores
    return max(1, int(n or 1) - 1)


class EncodeSink:
    """The encode thread: writes the jobs of :meth:`arshadow.video.framejob.FrameComposer.compose` from a
    queue until :data:`arshadow.video.threads.END`.

    Parameters
    ----------
    outputs : dict
        From :func:`arshadow.video.engine.video_outputs`.
    opts : arshadow.video.engine.EngineOptions
    reader
        The open reader (frame rate, size, pixel format, audio).
    source : str or Path
        The input (its audio is copied when ``opts.keep_audio``).
    is_av : bool
        The reader is PyAV's (an image sequence has no audio).
    stage_ms : dict
        ``stage_ms["encode"]`` gets each frame's encode milliseconds.
    sheet : SheetThumbs
    progress : callable, optional
        ``progress(frames_done, frames_total_or_None)``.
    name : str
    total : int or None
    """

    def __init__(
        self,
        outputs: VideoOutputs,
        opts: EngineOptions,
        reader: FrameReader,
        source: str | os.PathLike[str],
        is_av: bool,
        stage_ms: dict[str, list[float]],
        sheet: SheetThumbs,
        progress: Progress | None = None,
        name: str = "",
        total: int | None = None,
    ) -> None:
        self.outputs, self.opts, self.reader = outputs, opts, reader
        self.source, self.is_av = source, is_av
        self.stage_ms, self.sheet, self.progress = stage_ms, sheet, progress
        self.name, self.total = name, total
        self.W, self.H = reader.width, reader.height
        self.audio_copied = False

    def run(self, q: queue.Queue[object], stop: threading.Event) -> None:
        """Write every job from ``q``; raises ``RuntimeError("stopped")`` when ``stop`` is set first.

        The outputs are entered in this order and committed in the reverse one: the video (the likeliest
        to fail at its end: the encoder's flush, the trailer) first, and a failure there removes the mask
        and the frames report.
        """
        with ExitStack() as st:
            jpath = st.enter_context(atomic_path(required(self.outputs, "frames")))
            jf = st.enter_context(open(jpath, "w", encoding="utf-8"))
            mw, png_dir = self._open_mask(st)
            vw = st.enter_context(self._video_writer())
            n = 0
            while (job := self._next(q, stop)) is not END:
                self._write(cast(EncodeJob, job), vw, mw, png_dir, jf)  # anything but END is a job
                n += 1
                if self.progress is not None:
                    self.progress(n, self.total)
            if n == 0:
                raise ImageError(
                    f"{self.name}: no decodable frame"
                    + (" (truncated or damaged file)" if getattr(self.reader, "truncated", False) else "")
                )
            jf.flush()
            os.fsync(jf.fileno())
        self.audio_copied = bool(vw.audio_copied)

    @staticmethod
    def _next(q: queue.Queue[object], stop: threading.Event) -> object:
        while True:
            try:
                return q.get(timeout=0.1)
            except queue.Empty:
                if stop.is_set():
                    raise RuntimeError("stopped") from None

    def _open_mask(self, st: ExitStack[bool | None]) -> tuple[AvWriter | None, Path | None]:
        out_mask, opts = self.outputs.get("mask"), self.opts
        if out_mask is not None and opts.mask == "mkv":
            rate = getattr(self.reader, "rate", self.reader.fps)
            return st.enter_context(AvWriter(out_mask, rate, (self.W, self.H), color=False)), None
        if out_mask is not None:
            return None, st.enter_context(atomic_dir(Path(out_mask)))
        return None, None

    def _video_writer(self) -> AvWriter:
        opts, reader = self.opts, self.reader
        keep_yuv = opts.codec == "ffv1" and getattr(reader, "pix_fmt", None) == "yuv420p"
        audio = self.source if (opts.keep_audio and self.is_av and getattr(reader, "has_audio", False)) else None
        return AvWriter(
            required(self.outputs, "video"),
            getattr(reader, "rate", reader.fps),
            (self.W, self.H),
            codec=opts.codec,
            crf=opts.crf,
            pix_fmt="yuv420p" if keep_yuv else None,
            preset=opts.preset,
            audio_from=audio,
            threads=opts.encoder_threads or default_encoder_threads(),
            rotation=getattr(reader, "rotation", 0),
        )

    def _write(self, job: EncodeJob, vw: AvWriter, mw: AvWriter | None, png_dir: Path | None, jf: IO[str]) -> None:
        img, fmt, mask, item, line = job
        assert item.frame is not None  # set by FrameComposer.compose
        t = time.perf_counter()
        if fmt == "yuv420p":
            vw.write_yuv420p(img)
        else:
            vw.write(img)
        if mw is not None:
            mw.write(mask if mask is not None else np.zeros((self.H, self.W), np.uint8))
        elif png_dir is not None:
            cv2.imwrite(
                str(png_dir / f"{item.frame:06d}.png"),
                mask if mask is not None else np.zeros((self.H, self.W), np.uint8),
            )
        enc = (time.perf_counter() - t) * 1e3
        line["timings_ms"]["encode"] = round(enc, 3)
        self.stage_ms["encode"].append(enc)
        jf.write(json.dumps(line, separators=(",", ":")) + "\n")
        self.sheet.add(item.frame, img, fmt)


@contextlib.contextmanager
def atomic_dir(target: Path) -> Iterator[Path]:
    """Yield a temporary folder beside ``target``; moved onto it only if the block succeeds."""
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    try:
        yield tmp
        replace_dir(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def replace_dir(tmp: Path, target: Path) -> None:
    """Move a completed folder onto ``target`` (an old one is moved aside first, then removed)."""
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.old.{os.getpid()}")
        os.replace(target, old)
    os.replace(tmp, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def write_contact_sheet(path: Path | str, thumbs: Mapping[int, np.ndarray], cols: int = 4) -> Path:
    """Tile ``{frame: (h, w, 3) uint8}`` thumbnails (frame order, labelled) into one image, atomically."""
    tiles = []
    for f in sorted(thumbs):
        tile = thumbs[f].copy()
        cv2.putText(tile, f"#{f}", (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(tile, f"#{f}", (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(tile)
    return write_image(path, contact_sheet(tiles, columns=cols, gap=4, background=32))
