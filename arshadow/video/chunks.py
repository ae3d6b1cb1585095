"""One video cut at keyframes into chunks, each processed on its own, with the sequential run's output.

Plan (:func:`plan_chunks`): the chunk boundaries are keyframes of the input (from
:func:`arshadow.video.scan.scan_stream`), about evenly spaced. Chunk ``k`` writes frames ``[start, stop)``
and decodes ``[decode_from, decode_stop)``:

- **primer** ``[prime_from, start)``: the ``prime`` frames before ``start`` (:func:`margins`: pose
  look-ahead + 2 x smoothing half-window + hold) are tracked and pushed through the pose stream (IPPE
  continuity, smoothing window, marker-loss hold, tracking window) but not composited; decoding starts at
  the last keyframe at or before ``prime_from`` (``decode_from``), and the frames in
  ``[decode_from, prime_from)`` are only decoded (not converted, not tracked); the sun schedule is
  replayed over every frame time before ``start``
  (:meth:`arshadow.video.framejob.SessionBackend.replay_sun`);
- **tail** ``[stop, decode_stop)``: tracked past ``stop`` so that the last frames get the look-ahead they
  have in the sequential run; the decisions of the first ``check`` frames past ``stop`` are recorded.

Check (:func:`first_mismatch`): chunk ``k``'s first ``check`` records (status, raw and rendered pose,
branch) must equal chunk ``k - 1``'s tail decisions for the same frames, which had the full history. The
pose stream's state is a function of the last ``check`` frames' decisions and tracked poses, so equal
there means equal for the rest of the chunk; a chunk that differs is redone with a primer reaching
further back (from frame 0 at worst: the sequential run itself).

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
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ImageError
from ..io import atomic_path, clean_temporaries, write_json
from .avio import load_av
from .encode import EncodeSink, SheetThumbs, atomic_dir
from .engine import EngineOptions, Span, run_frames
from .framejob import FrameComposer
from .scan import SeekReader, StreamIndex

__all__ = ["Chunk", "ChunkStore", "first_mismatch", "join_chunks", "margins", "plan_chunks", "run_chunk", "widened"]

#: keys of a frame's JSON Lines record the chunk check compares
CHECK_KEYS = ("frame", "status", "raw", "rvec", "tvec", "pose_choice")
STORE = ".arshadow-chunks"


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
    """``(prime, check, tail)`` frames for the pose stream of ``opts``.

    >>> margins(EngineOptions())
    (50, 38, 66)
    """
    lag = opts.pose_lag or 0
    check = 2 * opts.smooth + lag + 2
    return lag + 2 * opts.smooth + opts.hold + 2, check, check + opts.smooth + lag + 2


def plan_chunks(index: StreamIndex, n: int, opts: EngineOptions, count: int) -> tuple[list[Chunk], str | None]:
    """Up to ``count`` chunks of the first ``n`` frames, cut at keyframes; ``(chunks, note)`` where
    ``note`` says why there are fewer (e.g. no keyframe after the first frame).

    >>> idx = StreamIndex(pts=list(range(100)), times=[i / 25 for i in range(100)], keyframes=[0, 30, 60, 90])
    >>> [(c.start, c.stop, c.decode_from, c.decode_stop) for c in plan_chunks(idx, 100, EngineOptions(), 3)[0]]
    [(0, 30, 0, 96), (30, 60, 0, 100), (60, 100, 0, 100)]
    """
    prime, _check, tail = margins(opts)
    cand = [k for k in index.keyframes if 0 < k < n]
    note = None
    if not cand:
        note = "no keyframe after the first frame: processed as one chunk"
    starts = [0]
    for j in range(1, max(1, count)):
        want = j * n / count
        best = min(cand, key=lambda k: abs(k - want), default=None)
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

    def __init__(self, outdir, stem: str, fingerprint: str, opts: EngineOptions):
        self.dir = Path(outdir) / STORE / f"{stem}-{fingerprint[:16]}"
        self.opts = opts

    def open(self) -> ChunkStore:
        self.dir.mkdir(parents=True, exist_ok=True)
        clean_temporaries(self.dir)  # left by a worker killed while writing a chunk
        return self

    def outputs(self, k: int) -> dict:
        """The chunk's files (``video``, ``mask`` or None, ``frames``, ``thumbs``)."""
        d, o = self.dir, self.opts
        mask = None if o.mask is None else d / (f"c{k:05d}.shadow.mkv" if o.mask == "mkv" else f"c{k:05d}.shadow")
        return {
            "video": d / f"c{k:05d}.{o.fmt}",
            "mask": mask,
            "frames": d / f"c{k:05d}.jsonl",
            "thumbs": d / f"c{k:05d}.thumbs.npz",
            "sheet": None,
        }

    def record_path(self, k: int) -> Path:
        return self.dir / f"c{k:05d}.json"

    def done(self, chunk: Chunk):
        """The chunk's record if it finished with this plan and its files are all there, else None."""
        try:
            rec = json.loads(self.record_path(chunk.k).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if rec.get("chunk") != dataclasses.asdict(chunk):
            return None
        outs = [p for key, p in self.outputs(chunk.k).items() if p is not None and key != "sheet"]
        return rec if all(Path(p).exists() for p in outs) else None

    def remove(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)
        with_parent = self.dir.parent
        if with_parent.exists() and not any(with_parent.iterdir()):
            with_parent.rmdir()


def fingerprint(path, recipe_key: str, opts: EngineOptions, n: int) -> str:
    """Input identity (resolved path, size, modification time) + scene + options + frames."""
    st = os.stat(path)
    blob = json.dumps([str(Path(path).resolve()), st.st_size, st.st_mtime_ns, recipe_key, repr(opts), n])
    return hashlib.sha256(blob.encode()).hexdigest()


def run_chunk(
    backend,
    path,
    index: StreamIndex,
    chunk: Chunk,
    opts: EngineOptions,
    store: ChunkStore,
    *,
    name: str,
    final: dict,
    total,
) -> dict:
    """Process one chunk into the store (outputs first, then the record); returns the record.

    ``final``: the video's own outputs (named in the report items); ``total``: the frame count the
    sequential run would declare (contact-sheet spacing).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    reader = SeekReader(
        path, index, chunk.decode_from, chunk.decode_stop, skip_before=chunk.prime_from, threads=opts.encoder_threads
    )
    outs = store.outputs(chunk.k)
    backend.start(reader.width, reader.height)
    backend.replay_sun(index.times[: chunk.start])
    composer = FrameComposer(
        backend, name, final["video"], final.get("mask"), (reader.width, reader.height), final.get("mask") is not None
    )
    sheet = SheetThumbs(opts.contact_sheet, total, (reader.width, reader.height))
    part_opts = dataclasses.replace(opts, keep_audio=False, collect_items=False)
    sink = EncodeSink(outs, part_opts, reader, path, False, composer.stage_ms, sheet, None, name, None)
    span = Span(chunk.start, chunk.stop)
    run_frames(reader, composer, sink, part_opts, span)
    with atomic_path(outs["thumbs"]) as tmp, open(tmp, "wb") as f:
        np.savez(f, **{str(k): v for k, v in sheet.thumbs.items()})
    check = margins(opts)[1]
    ru = resource.getrusage(resource.RUSAGE_SELF)
    rec = {
        "chunk": dataclasses.asdict(chunk),
        "stats": composer.stats,
        "recomputes": backend.recomputes,
        "tail": [{k: d[k] for k in CHECK_KEYS} for d in span.tail[:check]],
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


def first_mismatch(store: ChunkStore, chunks: list[Chunk], records: dict, opts: EngineOptions) -> int | None:
    """The first chunk whose first frames differ from the previous chunk's tail decisions, or None."""
    check = margins(opts)[1]
    for c in chunks[1:]:
        tail = records[c.k - 1]["tail"]
        if not tail:
            continue
        head = []
        with open(store.outputs(c.k)["frames"], encoding="utf-8") as f:
            for line in f:
                d = json.loads(line)
                head.append({k: d.get(k) for k in CHECK_KEYS})
                if len(head) >= min(check, len(tail)):
                    break
        if head != tail[: len(head)]:
            return c.k
    return None


def join_chunks(
    store: ChunkStore, chunks: list[Chunk], outputs: dict, opts: EngineOptions, rate, *, audio_from=None, rotation=0
) -> dict:
    """Join the chunks' outputs into the video's ``outputs`` (each atomic); returns ``{"audio": bool,
    "thumbs": {frame: thumbnail}}``. Entered video first, committed in reverse, as the engine does.
    ``rotation``: the input's display rotation (:attr:`arshadow.video.avio.AvReader.rotation`)."""
    parts = [store.outputs(c.k) for c in chunks]
    with ExitStack() as st:
        jpath = st.enter_context(atomic_path(outputs["frames"]))
        with open(jpath, "wb") as jf:
            for p in parts:
                with open(p["frames"], "rb") as src:
                    shutil.copyfileobj(src, jf)
            jf.flush()
            os.fsync(jf.fileno())
        if outputs.get("mask") is not None and opts.mask == "mkv":
            tmp = st.enter_context(atomic_path(outputs["mask"]))
            concat_packets([p["mask"] for p in parts], tmp, rate)
        elif outputs.get("mask") is not None:
            d = st.enter_context(atomic_dir(Path(outputs["mask"])))
            for p in parts:  # linked (copied where links fail): the store stays whole until the join ends
                for f in sorted(Path(p["mask"]).iterdir()):
                    try:
                        os.link(f, d / f.name)
                    except OSError:
                        shutil.copy2(f, d / f.name)
        tmp = st.enter_context(atomic_path(outputs["video"]))
        audio = concat_packets([p["video"] for p in parts], tmp, rate, audio_from=audio_from, rotation=rotation)
    thumbs = {}
    for p in parts:
        with np.load(p["thumbs"]) as z:
            thumbs.update({int(k): z[k] for k in z.files})
    return {"audio": audio, "thumbs": thumbs}


def concat_packets(parts, target, rate, *, audio_from=None, rotation: int = 0) -> bool:
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


def _open_audio(av, out, audio_from):
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


def _mux_audio(out, audio, until_s) -> None:
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


def _mux_video(av, out, vout, parts, audio, rate):
    """Mux every part's packets, shifted by the frames before it; returns the end time (s) or None."""
    offset, end = 0, None
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
