"""The video engine: decode, track + render, encode, overlapped on three threads.

One video goes through :func:`process_video`::

    decode thread            main thread (owns the GL context)                encode thread
    AvReader --queue--> track (Y plane) -> PoseStream -> render + composite --queue--> AvWriter (+ mask)
                        (branch by continuity, smoothing, marker loss)                 JSON Lines report,
                                                                                        contact sheet, progress

FFmpeg decodes and encodes without holding Python's GIL, so the decode and encode threads run on the
other core while the main thread tracks and renders. The GL context never leaves the main thread.

Colour: frames stay in the decoder's ``yuv420p`` when it gives that (the tracker reads the Y plane as
its grey image; OpenCV converts to BGR for the compositor, and back for the encoder only inside the
frame's ROI, the only pixels the compositor changes: every other pixel keeps its decoded value exactly);
other pixel formats are converted to BGR by FFmpeg and encoded from BGR.

Outputs of one video ``DIR/<stem>``: ``.mp4`` (or ``--format``), ``.frames.jsonl`` (one JSON object per
frame), ``.sheet.jpg`` (contact sheet), and with a mask ``.shadow.mkv`` (lossless FFV1) or ``.shadow/``
(PNG per frame). Every one is written to a temporary name and renamed into place when complete.

Rendering goes through :class:`SessionBackend`, the only place that knows the rendering API.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import queue
import re
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass
from datetime import timedelta
from pathlib import Path

import cv2
import numpy as np

from ..errors import ArshadowError, ImageError, MarkerNotFoundError, UsageError
from ..compose.composite import clip_roi
from ..io import resolved_path
from ..transforms import rvec_tvec_from_matrix

__all__ = ["EngineOptions", "SessionBackend", "video_outputs", "process_video", "run_videos", "unique_stems",
           "write_contact_sheet", "FRAME_STAGES"]

#: per-frame ``timings_ms`` keys of the JSON Lines report
FRAME_STAGES = ("decode", "detect", "pose", "silhouette", "volume", "render", "readback", "warp", "composite",
                "convert", "encode", "total")

_END = object()
#: libx264's speed presets (``--preset``)
X264_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow",
                "placebo")


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

    def check(self) -> EngineOptions:
        from .avio import VIDEO_CODECS

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
        return self


def video_outputs(outdir, stem: str, opts: EngineOptions) -> dict:
    """The output paths of one video: ``video``, ``mask`` (or None), ``frames`` (JSONL), ``sheet``."""
    d = Path(outdir)
    mask = None
    if opts.mask == "mkv":
        mask = d / f"{stem}.shadow.mkv"
    elif opts.mask == "png":
        mask = d / f"{stem}.shadow"
    return {"video": d / f"{stem}.{opts.fmt}", "mask": mask, "frames": d / f"{stem}.frames.jsonl",
            "sheet": d / f"{stem}.sheet.jpg" if opts.contact_sheet else None}


# --------------------------------------------------------------------------------------------------
# the rendering side, in one place
# --------------------------------------------------------------------------------------------------
class SessionBackend:
    """Tracking and rendering for the engine, over an :class:`arshadow.session.Session`.

    The only place the engine touches the rendering API. Tracking reads a grey image (the decoder's
    Y plane: no colour conversion for frames that are only tracked).

    Parameters
    ----------
    session : arshadow.session.Session
    tracks : list of arshadow.lights.sun.SunTrack
        Sun lights following the frame times (``time_lapse = (start datetime, speed)``); the session
        must have them (:meth:`Session.use_sun_tracks`).
    """

    def __init__(self, session, tracks=(), time_lapse=None):
        self.session, self.tracks, self.time_lapse = session, list(tracks), time_lapse
        self.cal = None
        self.recomputes = 0

    def start(self, width: int, height: int) -> None:
        """A new video of this size (CalibrationError: the calibration does not fit it)."""
        self.cal = self.session.compositor.calib_for(width, height)
        for tr in self.tracks:
            tr.reset()
        self.recomputes = 0

    def track(self, gray, timings):
        """The marker pose in a grey ``(H, W) uint8`` frame, or ``(None, error)``."""
        try:
            return self.session.compositor.track(gray, self.cal, timings), None
        except MarkerNotFoundError as exc:
            return None, exc

    def lights_at(self, time_s: float):
        """Set the lights for a frame time (time-lapse); returns the report's ``sun`` list or None."""
        if not self.tracks:
            return None
        when = self.time_lapse[0] + timedelta(seconds=time_s * self.time_lapse[1])
        frames = self.session.set_time(when)
        self.recomputes += sum(bool(f.recompute) for f in frames)
        return [{"time": f.when.isoformat(), "zenith_deg": round(f.position.zenith_deg, 5),
                 "azimuth_deg": round(f.position.azimuth_deg, 5), "above_horizon": bool(f.above_horizon),
                 "recompute": bool(f.recompute), "stale_deg": round(f.stale_deg, 5)} for f in frames]

    def render(self, bgr, cam_from_world, want_mask, timings):
        """Composite into ``bgr`` (modified in place); returns ``(mask or None, item extras)``."""
        res = self.session.render(bgr, cam_from_world, want_mask=want_mask, out=bgr, timings=timings)
        it = res.item
        info = {"mode": it.mode, "silhouette_edges": it.silhouette_edges,
                **{k: it.extra[k] for k in ("roi", "canvas", "modes") if k in it.extra}}
        return res.mask, info

    @property
    def notes(self):
        return list(self.session.notes or [])


# --------------------------------------------------------------------------------------------------
# threads
# --------------------------------------------------------------------------------------------------
class _Worker(threading.Thread):
    def __init__(self, target, name):
        super().__init__(name=name, daemon=True)
        self._target_fn = target
        self.error = None

    def run(self):
        try:
            self._target_fn()
        except BaseException as exc:  # handed to the main thread
            self.error = exc


def _put(q, item, stop):
    while not stop.is_set():
        try:
            q.put(item, timeout=0.1)
            return True
        except queue.Full:
            continue
    return False


def _open_reader(path, max_frames):
    from .avio import AvReader

    p = str(path)
    if "%" in p:  # an image-sequence pattern: OpenCV's reader
        from .cvio import VideoReader

        return VideoReader(p, max_frames=max_frames), False
    return AvReader(p, max_frames=max_frames, raw=True), True


def process_video(backend, path, outputs: dict, opts: EngineOptions, *, progress=None, name: str | None = None):
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
    from .avio import AvWriter
    from ..report import ReportItem
    from .temporal import PoseStream

    opts = opts.check()
    name = str(path) if name is None else name
    t_wall = time.perf_counter()
    reader, is_av = _open_reader(path, opts.max_frames)
    W, H = reader.width, reader.height
    try:
        backend.start(W, H)
    except BaseException:
        reader.close()
        raise
    rate = getattr(reader, "rate", reader.fps)
    out_video, out_mask = Path(outputs["video"]), outputs.get("mask")
    want_mask = out_mask is not None
    stream = PoseStream(fps=reader.fps, lag=opts.pose_lag, window=opts.smooth, hold_frames=opts.hold)
    q_in: queue.Queue = queue.Queue(maxsize=opts.queue_frames)
    q_out: queue.Queue = queue.Queue(maxsize=opts.queue_frames)
    stop = threading.Event()
    stats = dict(frames=0, frames_ok=0, frames_held=0, frames_no_marker=0, swapped=0)
    stage_ms: dict = {k: [] for k in FRAME_STAGES}
    items = []
    total = reader.frame_count if opts.max_frames is None else min(reader.frame_count or opts.max_frames,
                                                                   opts.max_frames)
    sheet: dict = {}
    sheet_step = [max(1, (total or 0) // max(opts.contact_sheet, 1))]  # thumbnails of every step-th frame

    # -- decode thread -----------------------------------------------------------------------------
    def decode():
        t = time.perf_counter()
        for fr in reader:
            now = time.perf_counter()
            if not _put(q_in, (fr, (now - t) * 1e3), stop):
                return
            t = time.perf_counter()
        _put(q_in, _END, stop)

    # -- encode thread -----------------------------------------------------------------------------
    enc_state = {}

    def encode():
        from contextlib import ExitStack

        from ..io import atomic_path

        # entered in this order, committed in the reverse one: the video (the likeliest to fail at its end:
        # the encoder's flush, the trailer) first, and a failure there removes the mask and frames report
        with ExitStack() as st:
            jpath = st.enter_context(atomic_path(outputs["frames"]))
            jf = st.enter_context(open(jpath, "w", encoding="utf-8"))
            mw = None
            png_dir = None
            if out_mask is not None and opts.mask == "mkv":
                mw = st.enter_context(AvWriter(out_mask, rate, (W, H), color=False))
            elif out_mask is not None:
                png_dir = st.enter_context(_atomic_dir(Path(out_mask)))
            keep_yuv = opts.codec == "ffv1" and getattr(reader, "pix_fmt", None) == "yuv420p"
            vw = st.enter_context(AvWriter(out_video, rate, (W, H), codec=opts.codec, crf=opts.crf,
                                           pix_fmt="yuv420p" if keep_yuv else None,
                                           preset=opts.preset, audio_from=path if (opts.keep_audio and is_av
                                                                                   and reader.has_audio) else None))
            n = 0
            while True:
                try:
                    job = q_out.get(timeout=0.1)
                except queue.Empty:
                    if stop.is_set():
                        raise RuntimeError("stopped") from None
                    continue
                if job is _END:
                    break
                img, fmt, mask, item, line = job
                t = time.perf_counter()
                if fmt == "yuv420p":
                    vw.write_yuv420p(img)
                else:
                    vw.write(img)
                if mw is not None:
                    mw.write(mask if mask is not None else np.zeros((H, W), np.uint8))
                elif png_dir is not None:
                    cv2.imwrite(str(png_dir / f"{item.extra['frame']:06d}.png"),
                                mask if mask is not None else np.zeros((H, W), np.uint8))
                enc = (time.perf_counter() - t) * 1e3
                line["timings_ms"]["encode"] = round(enc, 3)
                stage_ms["encode"].append(enc)
                jf.write(json.dumps(line, separators=(",", ":")) + "\n")
                fi = item.extra["frame"]
                if opts.contact_sheet and fi % sheet_step[0] == 0:
                    bgr = img if fmt != "yuv420p" else cv2.cvtColor(img, cv2.COLOR_YUV2BGR_I420)
                    sheet[fi] = cv2.resize(bgr, (320, max(1, round(320 * H / W))), interpolation=cv2.INTER_AREA)
                    if len(sheet) > 2 * opts.contact_sheet:  # more frames than declared: keep every other one
                        sheet_step[0] *= 2
                        for k in [k for k in sheet if k % sheet_step[0]]:
                            del sheet[k]
                n += 1
                if progress is not None:
                    progress(n, total)
            if n == 0:
                raise ImageError(f"{name}: no decodable frame" + (" (truncated or damaged file)"
                                                                 if getattr(reader, "truncated", False) else ""))
            jf.flush()
            os.fsync(jf.fileno())
            enc_state["writer"] = vw

    dec_t = _Worker(decode, "arshadow-decode")
    enc_t = _Worker(encode, "arshadow-encode")
    dec_t.start()
    enc_t.start()

    def emit(fp):
        fr, dec_ms, timings, gray_fmt = fp.payload
        img = fr.image
        item = ReportItem(input=name, output=str(out_video), mask=None if out_mask is None else str(out_mask))
        item.extra.update(frame=fr.index, time_s=round(fr.time_s, 6))
        sun = backend.lights_at(fr.time_s)
        if sun is not None:
            item.extra["sun"] = sun
        mask = None
        item.status = fp.status
        if fp.status == "no_marker":
            item.error = "no marker found"
            stats["frames_no_marker"] += 1
            if want_mask:
                mask = np.zeros((H, W), np.uint8)
        else:
            if fp.raw is not None:
                item.set_pose(fp.raw)
                stats["frames_ok"] += 1
            else:
                stats["frames_held"] += 1
            m = fp.cam_from_world
            r, t = rvec_tvec_from_matrix(m)
            item.extra["raw"] = None if fp.raw is None else {
                "rvec": np.asarray(fp.raw.rvec, float).ravel().tolist(),
                "tvec": np.asarray(fp.raw.tvec, float).ravel().tolist()}
            item.rvec, item.tvec = r.tolist(), t.tolist()  # the pose rendered with (smoothed / held)
            item.extra["pose_choice"] = "temporal (alternative IPPE solution)" if fp.swapped else "error"
            stats["swapped"] += int(fp.swapped)
            tc = time.perf_counter()
            bgr = cv2.cvtColor(img, cv2.COLOR_YUV2BGR_I420) if gray_fmt == "yuv420p" else np.array(img)
            timings["convert"] += (time.perf_counter() - tc) * 1e3
            mask, info = backend.render(bgr, m, want_mask, timings)
            item.mode = info["mode"]
            item.silhouette_edges = info["silhouette_edges"]
            item.extra.update({k: v for k, v in info.items() if k in ("roi", "canvas", "modes")})
            tc = time.perf_counter()
            img = _i420_with_roi(img, bgr, info.get("roi")) if gray_fmt == "yuv420p" else bgr
            timings["convert"] += (time.perf_counter() - tc) * 1e3
        timings["decode"] = dec_ms
        timings["total"] = sum(v for k, v in timings.items() if k not in ("total", "decode", "encode"))
        item.timings_ms = {k: round(v, 3) for k, v in timings.items()}
        for k in FRAME_STAGES:
            if k in timings and k != "encode":
                stage_ms[k].append(timings[k])
        if backend.notes:
            item.extra["notes"] = backend.notes
        stats["frames"] += 1
        line = {"frame": fr.index, "time_s": round(fr.time_s, 6), "status": item.status,
                "marker_ids": item.marker_ids, "rvec": item.rvec, "tvec": item.tvec, "raw": item.extra.get("raw"),
                "reprojection_error_px": item.reprojection_error_px, "pose_ambiguity": item.pose_ambiguity,
                "pose_choice": item.extra.get("pose_choice"), "mode": item.mode, "timings_ms": item.timings_ms}
        if sun is not None:
            line["sun"] = sun
        if opts.collect_items:
            items.append(item)
        if enc_t.error is not None or not _put(q_out, (img, gray_fmt, mask, item, line), stop):
            raise enc_t.error or RuntimeError("encoder stopped")

    try:
        while True:
            try:
                job = q_in.get(timeout=0.1)
            except queue.Empty:
                if dec_t.error is not None:
                    raise dec_t.error from None
                if enc_t.error is not None:
                    raise enc_t.error from None
                continue
            if job is _END:
                break
            fr, dec_ms = job
            timings = dict.fromkeys(FRAME_STAGES, 0.0)
            img = fr.image
            fmt = getattr(fr, "format", "bgr24")
            if fmt == "yuv420p":
                gray = img[:H]
            else:
                gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
            pose, _err = backend.track(gray, timings)
            for fp in stream.push((fr, dec_ms, timings, fmt), pose, fr.time_s):
                emit(fp)
        if dec_t.error is not None:
            raise dec_t.error
        for fp in stream.flush():
            emit(fp)
        if not _put(q_out, _END, stop):
            raise enc_t.error or RuntimeError("encoder stopped")
        enc_t.join()
        if enc_t.error is not None:
            raise enc_t.error
    except BaseException:
        stop.set()
        dec_t.join()
        enc_t.join()
        reader.close()
        if enc_t.error is not None and isinstance(enc_t.error, ArshadowError):
            raise enc_t.error from None
        raise
    dec_t.join()
    if outputs.get("sheet") is not None and sheet:
        keys = sorted(sheet)
        pick = {keys[int(round(i))] for i in np.linspace(0, len(keys) - 1, min(opts.contact_sheet, len(keys)))}
        write_contact_sheet(outputs["sheet"], {k: sheet[k] for k in pick})
    wall = time.perf_counter() - t_wall
    warnings = []
    truncated = bool(reader.truncated)
    dec_err = int(getattr(reader, "n_decode_errors", 0))
    if truncated:
        why = getattr(reader, "end_note", None) or "truncated or damaged file"
        warnings.append(f"{name}: the video ends early ({stats['frames']} of {reader.frame_count} frames decoded: "
                        f"{why})")
    if dec_err:
        warnings.append(f"{name}: {dec_err} damaged packet(s) could not be decoded and were skipped")
    status = "ok"
    if truncated or dec_err:
        status = "damaged"
    elif stats["frames_ok"] == 0:
        status = "no_marker"
        warnings.append(f"{name}: the marker was found in none of the {stats['frames']} frames")
    summary = {"input": name, "output": str(out_video), "mask": None if out_mask is None else str(out_mask),
               "frames_report": str(outputs["frames"]),
               "sheet": str(outputs["sheet"]) if outputs.get("sheet") is not None and sheet else None,
               "status": status, "error": None, "warnings": warnings, **stats, "recomputes": backend.recomputes,
               "decode_errors": dec_err, "truncated": truncated, "frame_count_declared": reader.frame_count,
               "fps": reader.fps, "fps_assumed": bool(reader.fps_assumed), "size": [W, H],
               "audio": bool(getattr(enc_state.get("writer"), "audio_copied", False)), "codec": opts.codec, "crf": opts.crf,
               "wall_s": round(wall, 3), "fps_processed": round(stats["frames"] / wall, 2) if wall > 0 else None,
               "stage_ms_median": {k: round(float(np.median(v)), 3) for k, v in stage_ms.items() if v}}
    fm = np.asarray(stage_ms["total"] or [0.0])
    summary.update(frame_ms_median=float(np.median(fm)),
                   frame_ms_iqr=[float(np.percentile(fm, 25)), float(np.percentile(fm, 75))],
                   frame_ms_minmax=[float(fm.min()), float(fm.max())])
    return summary, items


@contextlib.contextmanager
def _atomic_dir(target: Path):
    """Yield a temporary folder beside ``target``; moved onto it only if the block succeeds."""
    tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    try:
        yield tmp
        _replace_dir(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _i420_planes(a: np.ndarray, H: int, W: int):
    """Views ``(Y (H, W), U (H/2, W/2), V (H/2, W/2))`` of a planar ``(H * 3 // 2, W)`` yuv420p frame."""
    c = a[H:].reshape(-1)
    q = (H // 2) * (W // 2)
    return a[:H], c[:q].reshape(H // 2, W // 2), c[q:].reshape(H // 2, W // 2)


def _i420_with_roi(yuv: np.ndarray, bgr: np.ndarray, roi) -> np.ndarray:
    """The planar yuv420p frame ``yuv`` with the rectangle ``roi = (x0, y0, w, h)`` taken from ``bgr``.

    The compositor changes pixels inside the frame's ROI only, so only that rectangle (widened to even
    coordinates: a chroma sample covers 2x2 pixels) is converted back; every other pixel keeps the decoded
    value exactly. Inside it the result equals a whole-frame ``cv2.COLOR_BGR2YUV_I420`` (each chroma
    sample is computed from its own 2x2 block). ``roi`` None: the whole frame.

    Parameters
    ----------
    yuv : (H * 3 // 2, W) uint8
        The decoded frame (not modified), H and W even.
    bgr : (H, W, 3) uint8
        The composited frame.
    roi : sequence of 4 int or None

    Returns
    -------
    (H * 3 // 2, W) uint8
        A new array.
    """
    H, W = bgr.shape[:2]
    if roi is None:
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_I420)
    x0, y0, w, h = clip_roi(roi, W, H)
    out = np.array(yuv)
    if w == 0 or h == 0:
        return out
    x1, y1 = min(W, x0 + w + 1) & ~1, min(H, y0 + h + 1) & ~1
    x0, y0 = x0 & ~1, y0 & ~1
    sub = cv2.cvtColor(np.ascontiguousarray(bgr[y0:y1, x0:x1]), cv2.COLOR_BGR2YUV_I420)
    for dst, src, k in zip(_i420_planes(out, H, W), _i420_planes(sub, y1 - y0, x1 - x0), (1, 2, 2)):
        dst[y0 // k : y1 // k, x0 // k : x1 // k] = src
    return out


def _replace_dir(tmp: Path, target: Path) -> None:
    """Move a completed folder onto ``target`` (an old one is moved aside first, then removed)."""
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.old.{os.getpid()}")
        os.replace(target, old)
    os.replace(tmp, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def write_contact_sheet(path, thumbs: dict, cols: int = 4) -> Path:
    """Tile ``{frame: (h, w, 3) uint8}`` thumbnails (frame order, labelled) into one image, atomically."""
    from ..io import write_image

    keys = sorted(thumbs)
    h, w = thumbs[keys[0]].shape[:2]
    rows = math.ceil(len(keys) / cols)
    sheet = np.full((rows * (h + 4) + 4, cols * (w + 4) + 4, 3), 32, np.uint8)
    for k, f in enumerate(keys):
        r, c = divmod(k, cols)
        y, x = 4 + r * (h + 4), 4 + c * (w + 4)
        tile = thumbs[f].copy()
        cv2.putText(tile, f"#{f}", (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(tile, f"#{f}", (6, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1, cv2.LINE_AA)
        sheet[y : y + h, x : x + w] = tile
    return write_image(path, sheet)


def unique_stems(inputs) -> list[str]:
    """An output stem per input (``clip``, ``clip_2``, ... when names collide, case-insensitively; an
    image-sequence pattern ``frames/img_%04d.png`` gives ``img``, ``frames/%04d.png`` gives ``frames``)."""
    seen: dict[str, int] = {}
    out = []
    for inp in inputs:
        p = Path(str(inp))  # an image-sequence pattern frames/img_%04d.png: "img" (or its folder's name)
        stem = re.sub(r"%0?\d*d", "", p.stem).replace("%", "").strip("_.- ") or p.parent.name or "video"
        n = seen.get(stem.lower(), 0) + 1
        seen[stem.lower()] = n
        out.append(stem if n == 1 else f"{stem}_{n}")
    return out


def run_videos(backend, inputs, outdir, opts: EngineOptions, *, progress_factory=None, on_error=None):
    """Process several videos one after another; a failed video is recorded and the others go on.

    Parameters
    ----------
    backend : SessionBackend
    inputs : list of str
    outdir : Path
    opts : EngineOptions
    progress_factory : callable, optional
        ``progress_factory(input, total) -> (update(done, total), close())`` for each video.
    on_error : callable, optional
        ``on_error(exc)``: re-raise to stop (``--debug``).

    Returns
    -------
    summaries : list of dict
        One per input (:func:`process_video`'s, or ``status: "error"`` with ``error``).
    items : list of ReportItem
        Per-frame items when ``opts.collect_items``; an unreadable video has one item with ``frame: None``.
    """
    from ..report import ReportItem

    summaries, items = [], []
    given = {resolved_path(str(v)) for v in inputs}  # outputs never replace an input
    for inp, stem in zip(inputs, unique_stems(inputs)):
        outs = video_outputs(outdir, stem, opts)
        close = None
        try:
            for p in outs.values():
                if p is not None and resolved_path(p) in given:
                    raise ImageError(f"{p}: output would overwrite an input; choose another -o folder")
            from ..io import clean_temporaries

            clean_temporaries(outdir, stem)  # left by a run killed while writing this video
            update = None
            if progress_factory is not None:
                update, close = progress_factory(str(inp))
            summary, its = process_video(backend, inp, outs, opts, progress=update, name=str(inp))
            items.extend(its)
        except (ArshadowError, OSError, MemoryError) as exc:
            if on_error is not None:
                on_error(exc)
            msg = str(exc) if isinstance(exc, ArshadowError) else f"{type(exc).__name__}: {exc}"
            if str(inp) not in msg:
                msg = f"{inp}: {msg}"
            summary = {"input": str(inp), "output": None, "mask": None, "status": "error", "error": msg,
                       "warnings": []}
            it = ReportItem(input=str(inp), status="error", error=msg)
            it.extra["frame"] = None
            items.append(it)
        finally:
            if close is not None:
                close()
        summaries.append(summary)
    return summaries, items


