"""The video engine: decode, track, render, encode, overlapped on four threads.

One video goes through :func:`process_video`::

    decode thread          track thread            main thread (owns the GL context)     encode thread
    AvReader --queue--> track (Y plane) --queue--> PoseStream -> render + composite --queue--> AvWriter
                        (+ colour retry)           (branch by continuity, smoothing,      (+ mask), JSON Lines,
                                                    marker loss)                           sheet, progress
    video/decode.py     run_frames/track_into      video/framejob.py                      video/encode.py

FFmpeg decodes and encodes without holding Python's GIL, and OpenCV's detection releases it too, so
frame ``n + 1`` is decoded and tracked while frame ``n`` renders. Tracking runs in frame order on one
thread (the tracker's window, IPPE continuity and retry schedule are its state), so the poses are those
of tracking on the main thread. The GL context never leaves the main thread.

Colour: frames stay in the decoder's ``yuv420p`` when it gives that (:mod:`arshadow.video.framejob`);
other pixel formats are converted to BGR by FFmpeg and encoded from BGR.

Outputs of one video ``DIR/<stem>``: ``.mp4`` (or ``--format``), ``.frames.jsonl`` (one JSON object per
frame), ``.sheet.jpg`` (contact sheet), and with a mask ``.shadow.mkv`` (lossless FFV1) or ``.shadow/``
(PNG per frame). Every one is written to a temporary name and renamed into place when complete.
"""

from __future__ import annotations

import os
import queue
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias, cast

import numpy as np

from ..errors import ArshadowError, CalibrationError, UsageError
from ..export.layervideo import LayerSink, check_video_layer_format, video_layer_paths
from ..export.stmap import stmap
from ..io import unique_stems
from ..tracking.detect import retry_due
from ..tracking.quality import reprojection_hold
from .avio import VIDEO_CODECS
from .decode import FrameReader, decode_into, open_reader
from .encode import EncodeSink, Progress, SheetThumbs, VideoOutputs, required, write_contact_sheet
from .framejob import FRAME_STAGES, Frame, FrameComposer, FramePayload, SessionBackend, frame_bgr, gray_of
from .hints import other_dictionaries_hint
from .temporal import PoseStream
from .threads import END, Worker, put_or_stop

if TYPE_CHECKING:
    from ..errors import MarkerNotFoundError
    from ..frame.effects import CameraEffects
    from ..frame.report import ReportItem
    from ..tracking.pose import MarkerPose
    from .temporal import FramePose

__all__ = [
    "FRAME_STAGES",
    "EngineOptions",
    "SessionBackend",
    "Span",
    "first_camera",
    "process_video",
    "run_frames",
    "track_frame",
    "unique_stems",
    "video_outputs",
    "write_contact_sheet",
]

#: what the tracking thread hands the main thread: ``(frame, decode_ms, timings, pose or None, reason or None)``
TrackJob: TypeAlias = tuple[Frame, float, dict[str, float], "MarkerPose | None", "str | None"]

#: libx264's speed presets (``--preset``)
X264_PRESETS = (
    "ultrafast",
    "superfast",
    "veryfast",
    "faster",
    "fast",
    "medium",
    "slow",
    "slower",
    "veryslow",
    "placebo",
)


@dataclass
class EngineOptions:
    """How videos are processed and written (the ``arshadow video`` / ``batch`` options).

    Attributes
    ----------
    fmt : str
        Output container (``mp4``, ``mkv``, ``mov``, ``avi``).
    codec : str
        :data:`arshadow.video.avio.VIDEO_CODECS` key (``h264`` default).
    crf : float
        H.264 constant rate factor.
    preset : str
        x264 preset (``ultrafast`` default: measured in docs/video.md).
    mask : str or None
        ``"mkv"`` (lossless FFV1 video), ``"png"`` (a PNG per frame in a folder) or None.
    pose_lag : int or None
        Look-ahead of the IPPE branch choice; None: by reprojection error only.
    smooth : int
        Half-width of the pose smoothing window, frames (0: raw poses).
    hold : int
        Frames a lost marker's last pose is held.
    max_frames : int or None
    contact_sheet : int
        Frames on the contact sheet (0: none).
    keep_audio : bool
    collect_items : bool
        Also return every frame's report item (memory grows with the video; the JSON Lines file does not).
    queue_frames : int
        Frames in flight between the threads.
    encoder_threads : int
        Threads of the video encoder (0: :func:`arshadow.video.encode.default_encoder_threads`, one fewer
        than the cores; chunk workers that fill the cores between them use ``cores // N`` each).
    layers : str or None
        Also write the compositing layers (:mod:`arshadow.export.layervideo`): ``prores``, ``ffv1``, ``png``
        or ``exr`` (photos of a batch: ``exr`` for ``exr``, else 16-bit PNG).
    layers_undistorted : bool
        With ``layers``: also the pinhole (undistorted) layers and their ST-map.
    """

    fmt: str = "mp4"
    codec: str = "h264"
    crf: float = 20.0
    preset: str = "ultrafast"
    mask: str | None = None
    pose_lag: int | None = 16
    smooth: int = 10
    hold: int = 12
    max_frames: int | None = None
    contact_sheet: int = 12
    keep_audio: bool = True
    collect_items: bool = False
    queue_frames: int = 6
    encoder_threads: int = 0
    layers: str | None = None
    layers_undistorted: bool = False

    def check(self) -> EngineOptions:
        if self.fmt not in ("mp4", "mkv", "mov", "avi"):
            raise UsageError(f"--format {self.fmt}: use mp4, mkv, mov or avi")
        if self.codec not in VIDEO_CODECS:
            raise UsageError(f"--codec {self.codec}: use one of {', '.join(VIDEO_CODECS)}")
        if not 0 <= float(self.crf) <= 51:
            raise UsageError(f"--crf {self.crf}: must be 0..51")
        if self.mask not in (None, "mkv", "png"):
            raise UsageError(f"mask format {self.mask}: use mkv or png")
        if self.max_frames is not None and self.max_frames < 1:
            raise UsageError(f"--max-frames {self.max_frames}: must be >= 1")
        if self.pose_lag is not None and self.pose_lag < 0:
            raise UsageError(f"--pose-lag {self.pose_lag}: must be >= 0")
        for opt, v in (("--smooth", self.smooth), ("--hold", self.hold), ("--contact-sheet", self.contact_sheet)):
            if v < 0:
                raise UsageError(f"{opt} {v}: must be >= 0")
        if self.codec == "h264" and self.preset not in X264_PRESETS:
            raise UsageError(f"--preset {self.preset}: use one of {', '.join(X264_PRESETS)}")
        if self.layers is not None:
            check_video_layer_format(self.layers)
        return self


def video_outputs(outdir: str | os.PathLike[str], stem: str, opts: EngineOptions) -> VideoOutputs:
    """The output paths of one video: ``video``, ``mask`` (or None), ``frames`` (JSONL), ``sheet``."""
    d = Path(outdir)
    mask = None
    if opts.mask == "mkv":
        mask = d / f"{stem}.shadow.mkv"
    elif opts.mask == "png":
        mask = d / f"{stem}.shadow"
    out: VideoOutputs = {
        "video": d / f"{stem}.{opts.fmt}",
        "mask": mask,
        "frames": d / f"{stem}.frames.jsonl",
        "sheet": d / f"{stem}.sheet.jpg" if opts.contact_sheet else None,
    }
    if opts.layers is not None:  # "layers:object", ... (or "layers:folder"): arshadow.export.layervideo
        out.update(
            {f"layers:{k}": p for k, p in video_layer_paths(d, stem, opts.layers, opts.layers_undistorted).items()}
        )
    return out


def process_video(
    backend: SessionBackend,
    path: str | os.PathLike[str],
    outputs: VideoOutputs,
    opts: EngineOptions,
    *,
    progress: Progress | None = None,
    name: str | None = None,
) -> tuple[dict[str, Any], list[ReportItem]]:
    """Composite every frame of one video and write its outputs (each atomically).

    Parameters
    ----------
    backend : SessionBackend
        Tracking and rendering (its GL context is used on the calling thread only).
    path : str or Path
        The input video.
    outputs : dict
        From :func:`video_outputs`.
    opts : EngineOptions
    progress : callable, optional
        ``progress(frames_done, frames_total_or_None)`` from the encode thread.

    Returns
    -------
    summary : dict
        ``input``, ``output``, ``mask``, ``frames_report``, ``sheet``, ``status`` (``ok`` | ``no_marker`` |
        ``truncated``), ``warnings``, ``frames``, ``frames_ok``, ``frames_held``, ``frames_no_marker``,
        ``swapped``, ``decode_errors``, ``fps``, ``size``, ``audio``, ``codec``, stage medians, ``wall_s``,
        ``fps_processed``.
    items : list of ReportItem
        Every frame's item when ``opts.collect_items`` (else empty).

    Raises
    ------
    ImageError, CalibrationError, UsageError
        Unreadable or unwritable video, a size the calibration does not fit.
    """
    opts = opts.check()
    name = str(path) if name is None else name
    t_wall = time.perf_counter()
    reader, is_av = open_reader(path, opts.max_frames)
    W, H = reader.width, reader.height
    try:
        backend.start(W, H)
    except CalibrationError as exc:
        reader.close()
        rot = getattr(reader, "rotation", 0)
        if rot in (90, 270):  # a phone video filmed upright: stored sideways, shown turned
            raise CalibrationError(
                f"{exc}; the video's frames are stored {W}x{H} and shown turned by {rot} degrees (a phone "
                f"filmed upright): the calibration must be of the stored {W}x{H} frames"
            ) from None
        raise
    except BaseException:
        reader.close()
        raise
    out_mask = outputs.get("mask")
    composer = FrameComposer(backend, name, required(outputs, "video"), out_mask, (W, H), out_mask is not None)
    total = (
        reader.frame_count if opts.max_frames is None else min(reader.frame_count or opts.max_frames, opts.max_frames)
    )
    sheet = SheetThumbs(opts.contact_sheet, total, (W, H))
    sink = EncodeSink(outputs, opts, reader, path, is_av, composer.stage_ms, sheet, progress, name, total)
    if opts.layers is not None:  # the layers, written on the main thread with the frames
        cal = backend.cal if opts.layers_undistorted else None
        st = None if cal is None else stmap(cal.intrinsics, None if cal.lens is None else cal.lens.maps)
        composer.layer_sink = LayerSink(
            {k[7:]: p for k, p in outputs.items() if k.startswith("layers:") and p is not None},
            opts.layers,
            # an image sequence's rate is its float fps: LayerSink documents "Fraction or float", annotates Fraction | int
            getattr(reader, "rate", reader.fps),
            (W, H),
            stmap=st,
        )
        backend.want_layers = "undistorted" if opts.layers_undistorted else True
    try:
        items = run_frames(reader, composer, sink, opts)
    except BaseException:
        if composer.layer_sink is not None:
            composer.layer_sink.abort()
        raise
    if composer.layer_sink is not None:
        composer.layer_sink.close()
    if (sheet_path := outputs.get("sheet")) is not None and sheet.thumbs:
        write_contact_sheet(sheet_path, sheet.picked())
    summary = _summary(name, outputs, reader, composer, sink, opts, time.perf_counter() - t_wall)
    summary["recomputes"] = backend.recomputes
    return summary, items


@dataclass
class Span:
    """The frames a chunk writes, ``[start, stop)``; the frames before ``start`` only prime the pose
    stream (tracked, not composited), the decisions of those from ``head_from`` on go to :attr:`head`
    (compared with the chunk before's records of them); those from ``stop`` on are the look-ahead its
    last frames need."""

    start: int
    stop: int
    head_from: int = 0
    head: list[dict[str, Any]] = field(default_factory=list)
    #: ``{frame: tracker state after it}`` (:meth:`SessionBackend.tracker_state` and the colour retry's
    #: misses in a row) for the frames before ``start`` and ``stop``: the state a chunk hands over
    states: dict[int, dict[str, Any]] = field(default_factory=dict)
    #: the last frame with a pose before ``start`` / before ``stop`` (its decision and ``time_s``): the IPPE
    #: branch choice's anchor, which may lie before the compared frames (the marker lost up to a second)
    anchor_in: dict[str, Any] | None = None
    anchor_out: dict[str, Any] | None = None


def run_frames(
    reader: FrameReader, composer: FrameComposer, sink: EncodeSink, opts: EngineOptions, span: Span | None = None
) -> list[ReportItem]:
    """Decode, track and encode threads around the main thread's frame jobs; returns the collected items.

    The main thread (the GL context's) smooths, renders and composites; tracking (OpenCV, no GL, the
    tracker's state touched by this thread only) runs ahead on its own thread, in frame order, so a frame
    is tracked while the one before it renders: the same calls in the same order as on one thread, the
    same poses. ``span``: composite and write only its frames (a chunk, :mod:`arshadow.video.chunks`).
    """
    q_in: queue.Queue[object] = queue.Queue(maxsize=opts.queue_frames)
    q_trk: queue.Queue[object] = queue.Queue(maxsize=opts.queue_frames)
    q_out: queue.Queue[object] = queue.Queue(maxsize=opts.queue_frames)
    stop = threading.Event()
    stream = PoseStream(fps=reader.fps, lag=opts.pose_lag, window=opts.smooth, hold_frames=opts.hold)
    dec_t = Worker(lambda: decode_into(reader, q_in, stop), "arshadow-decode")
    trk_t = Worker(
        lambda: track_into(q_in, q_trk, composer.backend, reader.height, stop, dec_t, span), "arshadow-track"
    )
    enc_t = Worker(lambda: sink.run(q_out, stop), "arshadow-encode")
    threads = (dec_t, trk_t, enc_t)
    for t in threads:
        t.start()
    items: list[ReportItem] = []
    # a frame is composited once the next one is decided (its pose gives the motion blur): the frame waiting
    # and the one decided before it; frames outside the span only neighbour the span's
    seq: dict[str, FramePose | None] = {"before": None, "waiting": None, "last": None}

    def finish(fp: FramePose, before: FramePose | None, after: FramePose | None) -> None:
        job = composer.compose(fp, before, after)
        if opts.collect_items:
            items.append(job[3])
        if enc_t.error is not None or not put_or_stop(q_out, job, stop):
            raise enc_t.error or RuntimeError("encoder stopped")

    def emit(fp: FramePose | None) -> None:
        if seq["waiting"] is not None:
            finish(seq["waiting"], seq["before"], fp)
            seq["waiting"] = None
        if fp is None:  # the end of the video
            return
        last, seq["last"] = seq["last"], fp
        index = cast(FramePayload, fp.payload)[0].index
        if span is not None and fp.raw is not None and index < span.stop:
            anchor = {**composer.decision(fp), "time_s": fp.time_s}
            span.anchor_out = anchor
            if index < span.start:
                span.anchor_in = anchor
        if span is not None and not span.start <= index < span.stop:
            if index < span.start:
                composer.prime(fp)  # the exposure match's smoothing gets the frames before the chunk
            if span.head_from <= index < span.start:
                span.head.append(composer.decision(fp))
            return
        seq["before"], seq["waiting"] = last, fp

    try:
        while (job := next_item(q_trk, (trk_t, enc_t))) is not END:
            fr, dec_ms, timings, pose, reason = cast(TrackJob, job)
            for fp in stream.push((fr, dec_ms, timings, getattr(fr, "format", "bgr24"), reason), pose, fr.time_s):
                emit(fp)
        for fp in stream.flush():
            emit(fp)
        emit(None)
        if not put_or_stop(q_out, END, stop):
            raise enc_t.error or RuntimeError("encoder stopped")
        enc_t.join()
        if enc_t.error is not None:
            raise enc_t.error
    except BaseException:
        stop.set()
        for t in threads:
            t.join()
        reader.close()
        if enc_t.error is not None and isinstance(enc_t.error, ArshadowError):
            raise enc_t.error from None
        raise
    dec_t.join()
    trk_t.join()
    return items


def track_into(
    q_in: queue.Queue[object],
    q_trk: queue.Queue[object],
    backend: SessionBackend,
    height: int,
    stop: threading.Event,
    dec_t: Worker,
    span: Span | None = None,
) -> None:
    """The tracking thread: each decoded ``(frame, decode_ms)`` of ``q_in`` tracked, in order, into ``q_trk``
    as ``(frame, decode_ms, timings, pose or None, reason or None)``, then :data:`END`; a failed decode
    thread's error is raised here (and so reaches the main thread). On a miss of a ``yuv420p`` frame's luma,
    the colour frame's grey is tried (the photo path's; :func:`arshadow.tracking.detect.retry_due` says
    when, the real-footage work). A pose that reprojects far worse than its corners allow
    (:func:`arshadow.tracking.quality.reprojection_hold`) is passed on as a miss with that reason.
    ``span``: a chunk's, whose :attr:`Span.states` get the tracker's state after the frames
    before its start and its stop."""
    misses = 0  # frames in a row without the marker
    snap: tuple[int, ...] = () if span is None else (span.start - 1, span.stop - 1)
    while not stop.is_set():
        job = next_item(q_in, (dec_t,), stop)
        if job is END or job is None:
            put_or_stop(q_trk, END, stop)
            return
        fr, dec_ms = cast(tuple[Frame, float], job)
        timings = dict.fromkeys(FRAME_STAGES, 0.0)
        pose, err, misses = track_frame(backend, fr, height, misses, timings)
        if span is not None and fr.index in snap:
            span.states[fr.index] = {"tracker": backend.tracker_state(), "colour_misses": misses}
        if not put_or_stop(q_trk, (fr, dec_ms, timings, pose, None if err is None else str(err)), stop):
            return


def track_frame(
    backend: SessionBackend, fr: Frame, height: int, misses: int, timings: dict[str, float]
) -> tuple[MarkerPose | None, MarkerNotFoundError | str | None, int]:
    """Track one decoded frame as the tracking thread does: ``(pose or None, why not, misses in a row)``
    after ``misses`` frames in a row without the marker (:func:`track_into`: the colour retry, the
    reprojection hold); ``timings`` gets ``detect`` and ``pose``."""
    err: MarkerNotFoundError | str | None
    pose, err = backend.track(gray_of(fr, height), timings)
    if pose is None and getattr(fr, "format", "bgr24") == "yuv420p" and retry_due(misses):
        # the luma is not the colour frame's grey (chroma): on a miss, the photo path's (the real-footage work)
        pose, err = backend.track(gray_of(fr, height, colour=True), timings)
    misses = 0 if pose is not None else misses + 1
    if pose is not None and (why := reprojection_hold(pose)) is not None:
        pose, err = None, why  # a broken pose (the trust fixes): held like a miss, never rendered as ok
    return pose, err, misses


def first_camera(backend: SessionBackend, reader: FrameReader) -> CameraEffects | None:
    """The camera's blur and noise (``--camera-effects on``) as a run of the whole video measures them: on
    its first tracked frame (tracked from the first frame on, as :func:`track_into` does; the whole frame
    in BGR, as the compositor converts it). Reads ``reader`` up to that frame; starts ``backend`` on the
    video (:meth:`SessionBackend.start`). None when off, or when no frame is tracked (nothing is composited
    then).
    A video cut into chunks gets it from here: a chunk's own frames need not hold the first tracked one."""
    backend.start(reader.width, reader.height)
    if backend.session.options.camera_effects != "on":
        return None
    misses = 0
    for fr in reader:
        pose, _, misses = track_frame(backend, fr, reader.height, misses, dict.fromkeys(FRAME_STAGES, 0.0))
        if pose is not None:
            backend.measure_camera(frame_bgr(fr.image, getattr(fr, "format", "bgr24")), pose)
            if (camera := backend.session.camera_effects) is not None:
                return camera
    return None


def next_item(q: queue.Queue[object], workers: Iterable[Worker], stop: threading.Event | None = None) -> object:
    """The next item of ``q``; re-raises the error of any of ``workers`` (threads feeding or draining the
    pipeline) that failed; None when ``stop`` is set first."""
    while stop is None or not stop.is_set():
        try:
            return q.get(timeout=0.1)
        except queue.Empty:
            for w in workers:
                if w.error is not None:
                    raise w.error from None
    return None


def _summary(
    name: str,
    outputs: VideoOutputs,
    reader: FrameReader,
    composer: FrameComposer,
    sink: EncodeSink,
    opts: EngineOptions,
    wall: float,
) -> dict[str, Any]:
    """The video's summary (see :func:`process_video`)."""
    stats, stage_ms = composer.stats, composer.stage_ms
    warnings: list[str] = []
    truncated = bool(reader.truncated)
    dec_err = int(getattr(reader, "n_decode_errors", 0))
    if truncated:
        why = getattr(reader, "end_note", None) or "truncated or damaged file"
        warnings.append(
            f"{name}: the video ends early ({stats['frames']} of {reader.frame_count} frames decoded: {why})"
        )
    if dec_err:
        warnings.append(f"{name}: {dec_err} damaged packet(s) could not be decoded and were skipped")
    flagged = composer.flags.summary(stats["frames"], "frames", outputs["frames"])
    if flagged:
        warnings.append(f"{name}: {flagged}")
    if (switched := composer.refs.summary()) is not None:
        warnings.append(f"{name}: {switched}")
    status = "ok"
    if truncated or dec_err:
        status = "damaged"
    elif stats["frames_ok"] == 0:
        status = "no_marker"
        cal, path = getattr(composer.backend, "cal", None), getattr(reader, "path", None)
        hint = "" if cal is None or path is None else other_dictionaries_hint(path, cal.trackers()[1].dictionary)
        warnings.append(f"{name}: the marker was found in none of the {stats['frames']} frames{hint}")
    out_mask = outputs.get("mask")
    summary: dict[str, Any] = {
        "input": name,
        "output": str(outputs["video"]),
        "mask": None if out_mask is None else str(out_mask),
        "frames_report": str(outputs["frames"]),
        "sheet": str(outputs["sheet"]) if outputs.get("sheet") is not None and sink.sheet.thumbs else None,
        "status": status,
        "error": None,
        "warnings": warnings,
        **stats,
        "recomputes": 0,
        "decode_errors": dec_err,
        "truncated": truncated,
        "frame_count_declared": reader.frame_count,
        "fps": reader.fps,
        "fps_assumed": bool(reader.fps_assumed),
        "size": [reader.width, reader.height],
        "audio": sink.audio_copied,
        "codec": opts.codec,
        "crf": opts.crf,
        "wall_s": round(wall, 3),
        "fps_processed": round(stats["frames"] / wall, 2) if wall > 0 else None,
        "stage_ms_median": {k: round(float(np.median(v)), 3) for k, v in stage_ms.items() if v},
    }
    fm = np.asarray(stage_ms["total"] or [0.0])
    summary.update(
        frame_ms_median=float(np.median(fm)),
        frame_ms_iqr=[float(np.percentile(fm, 25)), float(np.percentile(fm, 75))],
        frame_ms_minmax=[float(fm.min()), float(fm.max())],
    )
    return summary
