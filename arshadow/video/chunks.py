"""One video cut into chunks, each processed on its own, with the sequential run's output.

Plan (:func:`plan_chunks`): the chunks are about evenly spaced, each starting at a keyframe of the input
(from :func:`arshadow.video.scan.scan_stream`) or, better, ``prime`` frames after one, so that its
decoding starts at that keyframe and no frame is decoded in vain. Chunk ``k`` writes frames ``[start, stop)`` and decodes
``[decode_from, decode_stop)``:

- **primer** ``[prime_from, start)``: the ``prime`` frames before ``start`` (:func:`margins`: pose
  look-ahead + 2 x smoothing half-window + hold) are tracked and pushed through the pose stream (IPPE
  continuity, smoothing window, marker-loss hold, tracking window) but not composited; decoding starts at
  the last keyframe at or before ``prime_from`` (``decode_from``; the frames in
  ``[decode_from, prime_from)``, if any, are only decoded); the sun schedule is replayed over every frame
  time before ``start`` (:meth:`arshadow.video.framejob.SessionBackend.replay_sun`). The decisions of the
  primer's last ``check`` frames are recorded (the chunk's ``head``);
- **tail** ``[stop, decode_stop)``: tracked past ``stop`` so that the last frames get the look-ahead they
  have in the sequential run (pose look-ahead + smoothing half-window), and no more.

Check (:func:`first_mismatch`): chunk ``k``'s head (status, raw and rendered pose, branch of the ``check``
frames before its start) must equal chunk ``k - 1``'s records of the same frames, its own last frames,
decided with the full history, and the tracker's state after the frame before the boundary (tracking
window, misses in a row: :meth:`arshadow.frame.session.Session.tracker_state`) and the IPPE branch choice's anchor
(the last pose before the boundary, when less than :data:`MAX_GAP_S` back) must be the same in both. The pose
stream's state at the boundary is a function of those frames' decisions and tracked poses, so equal there
means equal for the rest of the chunk; a chunk that differs
is redone with a primer reaching further back (from frame 0 at worst: the sequential run itself). The
check reads frames both chunks decide anyway: it costs no frame of tracking.

Store (:class:`ChunkStore`): each chunk's outputs (video, mask, JSON Lines, thumbnails) and then its
record, every file atomic, in ``OUT/.arshadow-chunks/<stem>-<fingerprint>/``; a rerun after ``kill -9``
redoes only chunks without a record. Join (:func:`join_chunks`): the chunk videos' packets are copied
into one file (no re-encoding: each chunk starts with a keyframe) with the input's audio copied whole,
the masks likewise (FFV1) or moved (PNG), the JSON Lines concatenated in order; the store is removed.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import resource
import shutil
import time
from collections.abc import Iterator, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

from ..errors import ImageError
from ..io import atomic_path, clean_temporaries, make_folder, remove_empty_folder, write_json
from .avio import load_av
from .encode import EncodeSink, SheetThumbs, VideoOutputs, atomic_dir, required
from .engine import EngineOptions, Span, run_frames
from .framejob import FrameComposer, SessionBackend
from .scan import SeekReader, StreamIndex
from .temporal import MAX_GAP_S

if TYPE_CHECKING:
    import av.container
    import av.packet
    import av.stream

    from ..frame.effects import CameraEffects

#: an audio stream being copied (:func:`_open_audio`): ``(source container, its audio stream, the output's
#: stream, the source's packets, [the packet read but not yet muxed, or None])``
_Audio: TypeAlias = tuple[
    "av.container.InputContainer",
    "av.stream.Stream",
    "av.stream.Stream",
    Iterator["av.packet.Packet"],
    list["av.packet.Packet | None"],
]

__all__ = ["Chunk", "ChunkStore", "first_mismatch", "join_chunks", "margins", "plan_chunks", "run_chunk", "widened"]

#: keys of a frame's JSON Lines record the chunk check compares
CHECK_KEYS = ("frame", "status", "raw", "rvec", "tvec", "pose_choice")
STORE = ".arshadow-chunks"
#: a frame decoded in vain (a primer starting after a keyframe) weighs this many frames of imbalance
#: between chunks when a boundary is chosen (decoding is a fraction of a frame's work)
WASTE_WEIGHT = 0.25
#: a chunk record of another layout (an earlier version's store) is redone, not trusted
RECORD_FORMAT = 2


@dataclass(frozen=True)
class Chunk:
    """Chunk ``k``: writes frames ``[start, stop)``, decodes ``[decode_from, decode_stop)`` and tracks
    ``[prime_from, decode_stop)`` (``decode_from <= prime_from <= start``)."""

    k: int
    start: int
    stop: int
    decode_from: int
    decode_stop: int
    prime_from: int = 0


def margins(opts: EngineOptions) -> tuple[int, int, int]:
    """``(prime, check, tail)`` frames for the pose stream of ``opts``: the primer, the frames before a
    boundary whose decisions are compared (the pose stream's memory: its look-ahead and smoothing window
    either side), the look-ahead past a chunk's end.

    >>> margins(EngineOptions())
    (50, 38, 28)
    """
    lag = opts.pose_lag or 0
    check = 2 * opts.smooth + lag + 2
    return lag + 2 * opts.smooth + opts.hold + 2, check, opts.smooth + lag + 2


def plan_chunks(index: StreamIndex, n: int, opts: EngineOptions, count: int) -> tuple[list[Chunk], str | None]:
    """Up to ``count`` chunks of the first ``n`` frames, starting at keyframes or ``prime`` frames after
    one (whose primer then decodes from that keyframe: nothing decoded in vain); each start the candidate
    nearest an even split, a frame decoded in vain counting as a quarter frame off (:data:`WASTE_WEIGHT`);
    ``(chunks, note)`` where ``note`` says why there are fewer (e.g. no keyframe after the first frame).

    >>> idx = StreamIndex(pts=list(range(100)), times=[i / 25 for i in range(100)], keyframes=[0, 30, 60, 90])
    >>> [(c.start, c.stop, c.decode_from, c.prime_from, c.decode_stop) for c in plan_chunks(idx, 100, EngineOptions(), 3)[0]]
    [(0, 30, 0, 0, 58), (30, 60, 0, 0, 88), (60, 100, 0, 10, 100)]
    """
    prime, _check, tail = margins(opts)
    # a lone keyframe 0 would put every later chunk's decoding at frame 0: one chunk
    kfs = [k for k in index.keyframes if k < n] if len(index.keyframes) > 1 else []
    cand = sorted({c for k in kfs for c in (k, k + prime) if 0 < c < n})
    note = None
    if not cand:
        note = "no keyframe after the first frame: processed as one chunk"

    def waste(c: int) -> int:  # frames decoded only because the primer starts after a keyframe
        first = max(0, c - prime)
        return first - index.keyframe_at_or_before(first)

    starts = [0]
    for j in range(1, max(1, count)):
        want = j * n / count
        best = min(cand, key=lambda c: abs(c - want) + WASTE_WEIGHT * waste(c), default=None)
        if best is not None and best > starts[-1]:
            starts.append(best)
    if cand and len(starts) < count:
        note = f"{len(index.keyframes)} keyframe(s): {len(starts)} chunk(s) instead of {count}"
    out = []
    for k, a in enumerate(starts):
        b = starts[k + 1] if k + 1 < len(starts) else n
        first = max(0, a - prime)
        src = index.keyframe_at_or_before(first)
        out.append(Chunk(k, a, b, src, min(n, b + tail) if b < n else n, first))
    return out, note


def widened(chunk: Chunk, index: StreamIndex, opts: EngineOptions) -> Chunk | None:
    """The chunk with a primer reaching 4x further back (None: it already starts at frame 0)."""
    if chunk.prime_from == 0:
        return None
    prime = margins(opts)[0]
    first = max(0, chunk.start - max(4 * (chunk.start - chunk.prime_from), 4 * prime))
    return dataclasses.replace(chunk, decode_from=index.keyframe_at_or_before(first), prime_from=first)


class ChunkStore:
    """The folder of one video's finished chunks: ``OUT/.arshadow-chunks/<stem>-<fingerprint[:16]>/``.

    Parameters
    ----------
    outdir : Path
    stem : str
    fingerprint : str
        Input identity + scene + options: another input or setting gets another folder.
    opts : EngineOptions
    """

    def __init__(self, outdir: str | os.PathLike[str], stem: str, fingerprint: str, opts: EngineOptions) -> None:
        self.dir = Path(outdir) / STORE / f"{stem}-{fingerprint[:16]}"
        self.opts = opts

    def open(self) -> ChunkStore:
        """Create the folder (tolerating the shared parent removed meanwhile by another video's
        :meth:`remove`) and remove the temporaries a killed worker left in it."""
        make_folder(self.dir)
        clean_temporaries(self.dir)  # left by a worker killed while writing a chunk
        return self

    def outputs(self, k: int) -> VideoOutputs:
        """The chunk's files (``video``, ``mask`` or None, ``frames``, ``thumbs``)."""
        d, o = self.dir, self.opts
        mask = None if o.mask is None else d / (f"c{k:05d}.shadow.mkv" if o.mask == "mkv" else f"c{k:05d}.shadow")
        return {
            "video": d / f"c{k:05d}.{o.fmt}",
            "mask": mask,
            "frames": d / f"c{k:05d}.jsonl",
            "thumbs": d / f"c{k:05d}.thumbs.npz",
            "items": d / f"c{k:05d}.items.jsonl" if o.collect_items else None,
            "sheet": None,
        }

    def record_path(self, k: int) -> Path:
        return self.dir / f"c{k:05d}.json"

    def done(self, chunk: Chunk) -> dict[str, Any] | None:
        """The chunk's record if it finished with this plan and its files are all there, else None."""
        try:
            rec: dict[str, Any] = json.loads(self.record_path(chunk.k).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if rec.get("format") != RECORD_FORMAT or rec.get("chunk") != dataclasses.asdict(chunk):
            return None
        outs = [p for key, p in self.outputs(chunk.k).items() if p is not None and key != "sheet"]
        return rec if all(Path(p).exists() for p in outs) else None

    def remove(self) -> None:
        """Remove this video's folder, then the shared ``OUT/.arshadow-chunks`` if it is empty: in one
        ``rmdir`` (:func:`arshadow.io.remove_empty_folder`), never a look then a removal, so that another
        video's store being opened or removed at the same moment is left whole and raises nothing."""
        shutil.rmtree(self.dir, ignore_errors=True)
        remove_empty_folder(self.dir.parent)


def fingerprint(path: str | os.PathLike[str], recipe_key: str, opts: EngineOptions, n: int) -> str:
    """Input identity (resolved path, size, modification time) + scene + options + frames."""
    st = os.stat(path)
    blob = json.dumps([str(Path(path).resolve()), st.st_size, st.st_mtime_ns, recipe_key, repr(opts), n])
    return hashlib.sha256(blob.encode()).hexdigest()


def run_chunk(
    backend: SessionBackend,
    path: str | os.PathLike[str],
    index: StreamIndex,
    chunk: Chunk,
    opts: EngineOptions,
    store: ChunkStore,
    *,
    name: str,
    final: VideoOutputs,
    total: int | None,
    camera: CameraEffects | None = None,
) -> dict[str, Any]:
    """Process one chunk into the store (outputs first, then the record); returns the record.

    ``final``: the video's own outputs (named in the report items); ``total``: the frame count the
    sequential run would declare (contact-sheet spacing); ``camera``: the video's camera blur and noise
    (:func:`arshadow.video.engine.first_camera`; None: the chunk measures its own, if on).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    reader = SeekReader(
        path, index, chunk.decode_from, chunk.decode_stop, skip_before=chunk.prime_from, threads=opts.encoder_threads
    )
    outs = store.outputs(chunk.k)
    backend.start(reader.width, reader.height)
    if camera is not None:
        backend.use_camera(camera)
    backend.replay_sun(index.times[: chunk.start])
    composer = FrameComposer(
        backend,
        name,
        required(final, "video"),
        final.get("mask"),
        (reader.width, reader.height),
        final.get("mask") is not None,
    )
    sheet = SheetThumbs(opts.contact_sheet, total, (reader.width, reader.height))
    part_opts = dataclasses.replace(opts, keep_audio=False)
    sink = EncodeSink(outs, part_opts, reader, path, False, composer.stage_ms, sheet, None, name, None)
    span = Span(chunk.start, chunk.stop, head_from=chunk.start - margins(opts)[1])
    items = run_frames(reader, composer, sink, part_opts, span)
    with atomic_path(required(outs, "thumbs")) as tmp, open(tmp, "wb") as f:
        # the names are frame numbers ("12"), never savez's allow_pickle keyword
        np.savez(f, **{str(k): v for k, v in sheet.thumbs.items()})  # type: ignore[arg-type]
    if (items_path := outs["items"]) is not None:  # the report's items, as the sequential run makes them
        with atomic_path(items_path) as tmp, open(tmp, "w", encoding="utf-8") as fi:
            fi.writelines(json.dumps(it.to_dict()) + "\n" for it in items)
    ru = resource.getrusage(resource.RUSAGE_SELF)
    rec = {
        "format": RECORD_FORMAT,
        "chunk": dataclasses.asdict(chunk),
        "stats": composer.stats,
        "recomputes": backend.recomputes,
        "head": [{k: d[k] for k in CHECK_KEYS} for d in span.head],
        # the tracker's state after the frame before the start (a primer's) and after the last frame
        "state_in": span.states.get(chunk.start - 1),
        "state_out": span.states.get(chunk.stop - 1),
        "anchor_in": span.anchor_in,
        "anchor_out": span.anchor_out,
        "wall_s": round(time.perf_counter() - t0, 3),
        "cpu_s": round(time.process_time() - c0, 3),
        "frames_decoded": reader.n_read,
        "pid": os.getpid(),
        "max_rss_mb": round(ru.ru_maxrss / 1024.0, 1),
        "process_cpu_s": round(ru.ru_utime + ru.ru_stime, 3),  # this process's so far (start-up included)
        "flags": {"keys": composer.flags.keys, "kinds": composer.flags.kinds},
    }
    write_json(store.record_path(chunk.k), rec)
    return rec


def first_mismatch(
    store: ChunkStore,
    chunks: list[Chunk],
    records: dict[int, dict[str, Any]],
    opts: EngineOptions,
    index: StreamIndex | None = None,
) -> int | None:
    """The first chunk whose primer decided the ``check`` frames before its start otherwise than the
    chunks before it (their JSON Lines records), whose tracker state or IPPE anchor at the boundary differ,
    or None. A chunk primed from frame 0 is the sequential run itself: not checked. ``index``: the frame
    times (without it every anchor is compared, however old)."""
    check = margins(opts)[1]
    for c in chunks[1:]:
        if c.prime_from == 0:
            continue
        want = range(max(0, c.start - check), c.start)
        head = {d["frame"]: d for d in records[c.k]["head"]}
        if sorted(head) != list(want):  # a primer that did not decide them all: not comparable
            return c.k
        before = _records_of(store, [b for b in chunks if b.start < c.start], want)
        if any(before.get(i) != head[i] for i in want):
            return c.k
        prev = next(b for b in chunks if b.stop == c.start)
        if records[c.k].get("state_in") != records[prev.k].get("state_out"):
            return c.k  # e.g. the marker gone for all the compared frames, misses in a row counted apart
        t0 = float(index.times[c.start]) if index is not None else None
        if _anchor(records[c.k].get("anchor_in"), t0) != _anchor(records[prev.k].get("anchor_out"), t0):
            return c.k  # the branch choice's anchor: a pose before the compared frames, less than 1 s back
    return None


def _anchor(a: dict[str, Any] | None, t_start: float | None) -> dict[str, Any] | None:
    """A chunk's anchor (its last pose before the boundary) as far as the frames from ``t_start`` on
    depend on it: None when none, or when it is more than :data:`MAX_GAP_S` before (the IPPE branch choice
    does not link across such a gap)."""
    if a is None or (t_start is not None and t_start - float(a["time_s"]) > MAX_GAP_S):
        return None
    return a


def _records_of(store: ChunkStore, chunks: list[Chunk], frames: range) -> dict[int, dict[str, Any]]:
    """``{frame: CHECK_KEYS of its JSON Lines record}`` for ``frames``, from the files of ``chunks``."""
    out: dict[int, dict[str, Any]] = {}
    for b in chunks:
        if b.stop <= frames.start or b.start >= frames.stop:
            continue
        with open(required(store.outputs(b.k), "frames"), encoding="utf-8") as f:
            for line in f:
                d = json.loads(line)
                if d["frame"] in frames:
                    out[d["frame"]] = {k: d.get(k) for k in CHECK_KEYS}
    return out


def join_chunks(
    store: ChunkStore,
    chunks: list[Chunk],
    outputs: VideoOutputs,
    opts: EngineOptions,
    rate: Fraction | float,
    *,
    audio_from: str | os.PathLike[str] | None = None,
    rotation: int = 0,
) -> dict[str, Any]:
    """Join the chunks' outputs into the video's ``outputs`` (each atomic); returns ``{"audio": bool,
    "thumbs": {frame: thumbnail}, "items": [report item dicts] or None}`` (items when ``opts.collect_items``). Entered video first, committed in reverse, as the engine does.
    ``rotation``: the input's display rotation (:attr:`arshadow.video.avio.AvReader.rotation`)."""
    parts = [store.outputs(c.k) for c in chunks]
    with ExitStack() as st:
        jpath = st.enter_context(atomic_path(required(outputs, "frames")))
        with open(jpath, "wb") as jf:
            for p in parts:
                with open(required(p, "frames"), "rb") as src:
                    shutil.copyfileobj(src, jf)
            jf.flush()
            os.fsync(jf.fileno())
        mask = outputs.get("mask")
        if mask is not None and opts.mask == "mkv":
            tmp = st.enter_context(atomic_path(mask))
            concat_packets([required(p, "mask") for p in parts], tmp, rate)
        elif mask is not None:
            d = st.enter_context(atomic_dir(Path(mask)))
            for p in parts:  # linked (copied where links fail): the store stays whole until the join ends
                for f in sorted(Path(required(p, "mask")).iterdir()):
                    try:
                        os.link(f, d / f.name)
                    except OSError:
                        shutil.copy2(f, d / f.name)
        tmp = st.enter_context(atomic_path(required(outputs, "video")))
        audio = concat_packets(
            [required(p, "video") for p in parts], tmp, rate, audio_from=audio_from, rotation=rotation
        )
    thumbs: dict[int, np.ndarray] = {}
    for p in parts:
        with np.load(required(p, "thumbs")) as z:
            thumbs.update({int(k): z[k] for k in z.files})
    items: list[dict[str, Any]] | None = None
    if opts.collect_items:
        items = []
        for p in parts:
            with open(required(p, "items"), encoding="utf-8") as fh:
                items += [json.loads(line) for line in fh]
    return {"audio": audio, "thumbs": thumbs, "items": items}


def concat_packets(
    parts: Sequence[str | os.PathLike[str]],
    target: str | os.PathLike[str],
    rate: Fraction | float,
    *,
    audio_from: str | os.PathLike[str] | None = None,
    rotation: int = 0,
) -> bool:
    """Copy the video packets of ``parts`` (same codec and settings, each starting with a keyframe) into
    ``target`` one after another, timestamps shifted, without decoding; with ``audio_from``, that file's
    first audio stream is copied whole (up to the video's end), interleaved by time; ``rotation``: the
    display rotation (degrees) written into ``target``. Returns whether audio was copied."""
    av = load_av()
    fmt = {".mkv": "matroska", ".mp4": "mp4", ".mov": "mov", ".avi": "avi"}.get(Path(target).suffix.lower())
    if fmt is None:
        fmt = {".mkv": "matroska", ".mp4": "mp4", ".mov": "mov", ".avi": "avi"}.get(Path(parts[0]).suffix.lower())
    with av.open(str(parts[0])) as first:
        template = first.streams.video[0]
        with av.open(
            str(target), "w", format=fmt, options={"movflags": "+faststart"} if fmt in ("mp4", "mov") else None
        ) as out:
            vout = out.add_stream_from_template(template)
            if rotation:  # the input's display rotation (the template does not carry it)
                vout.set_display_rotation(rotation)
            audio = _open_audio(av, out, audio_from)
            end = _mux_video(av, out, vout, parts, audio, rate)
            if audio is not None:
                _mux_audio(out, audio, end)  # up to the video's end, as the sequential writer copies it
                audio[0].close()
    if end is None:
        raise ImageError(f"{target}: no frame in the chunks")
    return audio is not None


def _open_audio(
    av: ModuleType, out: av.container.OutputContainer, audio_from: str | os.PathLike[str] | None
) -> _Audio | None:
    if audio_from is None:
        return None
    try:
        src = av.open(str(audio_from))
    except (av.FFmpegError, OSError):
        return None
    if not src.streams.audio:
        src.close()
        return None
    try:
        aout = out.add_stream_from_template(src.streams.audio[0])
    except (av.FFmpegError, ValueError):
        src.close()
        return None
    ins = src.streams.audio[0]
    return src, ins, aout, src.demux(ins), [None]


def _mux_audio(out: av.container.OutputContainer, audio: _Audio, until_s: float | None) -> None:
    """Mux the source's audio packets up to ``until_s`` seconds (None: to the end)."""
    _src, _ins, aout, it, pending = audio
    while True:
        pkt = pending[0]
        if pkt is None:
            pkt = next(it, None)
            if pkt is None:
                return
            if pkt.dts is None:
                continue
        t = float(pkt.pts * pkt.time_base) if pkt.pts is not None and pkt.time_base else 0.0
        if until_s is not None and t > until_s:
            pending[0] = pkt
            return
        pending[0] = None
        pkt.stream = aout
        out.mux(pkt)


def _mux_video(
    av: ModuleType,
    out: av.container.OutputContainer,
    vout: av.stream.Stream,
    parts: Sequence[str | os.PathLike[str]],
    audio: _Audio | None,
    rate: Fraction | float,
) -> float | None:
    """Mux every part's packets, shifted by the frames before it; returns the end time (s) or None."""
    offset = 0
    end: float | None = None
    for part in parts:
        with av.open(str(part)) as src:
            vin = src.streams.video[0]
            tb = vin.time_base
            step = max(1, round(1 / (float(rate) * float(tb))))  # one frame, in the part's time base
            last = offset
            for pkt in src.demux(vin):
                if pkt.dts is None and pkt.pts is None:
                    continue
                pkt.pts = None if pkt.pts is None else pkt.pts + offset
                pkt.dts = None if pkt.dts is None else pkt.dts + offset
                last = max(last, (pkt.pts if pkt.pts is not None else pkt.dts) + step)
                if audio is not None:
                    _mux_audio(out, audio, float(pkt.dts * tb) if pkt.dts is not None else None)
                pkt.stream = vout
                out.mux(pkt)
                end = float(last * tb)
            offset = last
    return end
