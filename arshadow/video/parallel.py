"""One video across processes: its chunks (:mod:`arshadow.video.chunks`) on local worker processes
(``arshadow video --jobs N``) or as Dask tasks (``arshadow batch --dask``), then joined.

Each worker process builds its own :class:`arshadow.frame.session.Session` (and OpenGL context) from a picklable
:class:`BackendRecipe` once and keeps it for its later chunks. With ``--jobs N`` the calling process runs
one chunk itself (it would only wait) and ``N - 1`` local workers the others: one interpreter start-up
and one set of imports fewer (~1 CPU-second, a tenth of a 300-frame 720p run). Local workers are started
(:func:`start_method`) with ``fork`` on Linux while this process has made no OpenGL context yet (the pool is
made before the calling process runs its chunk: the workers inherit the imported modules, 0.3-0.8
CPU-second each with the mesh loader), else with ``spawn`` (a fresh interpreter: an OpenGL context does not
survive ``fork``); ``$ARSHADOW_START_METHOD`` (``fork`` / ``spawn`` / ``forkserver``) overrides. A worker that
dies (killed, out of memory) takes its chunk with it: the chunk is run again once in a fresh pool, and if
it dies again the video fails with one line naming the chunk; never a silently missing range.

Threads: every process gets its share of the cores, ``cores // N`` (:func:`encoder_threads`), for the x264
encoder, the FFmpeg decoder and Mesa llvmpipe's rasterizer threads (``LP_NUM_THREADS``, set before the
process's first GL context when not set already): N processes each running as many threads as there are
cores only contend (measured in docs/video.md).
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from datetime import datetime
from fractions import Fraction
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np

from ..errors import ArshadowError, ImageError, UsageError
from ..frame.session import Session
from ..gl.context import contexts_made
from ..io import make_folder
from ..scene.sanity import FlagTally, quiet_notes
from ..tracking.dictionary import DEFAULT_DICTIONARY
from ..tracking.reference import ReferenceTally
from .avio import AvReader, display_rotation
from .chunks import (
    Chunk,
    ChunkStore,
    fingerprint,
    first_mismatch,
    join_chunks,
    plan_chunks,
    run_chunk,
    widened,
)
from .decode import open_reader
from .encode import Progress, SheetThumbs, VideoOutputs, required, write_contact_sheet
from .engine import EngineOptions, first_camera
from .framejob import FRAME_STAGES, SessionBackend
from .hints import other_dictionaries_hint
from .scan import StreamIndex, scan_stream

if TYPE_CHECKING:
    from ..frame.effects import CameraEffects
    from ..lights.spec import Light
    from ..lights.suntrack import SunTrack
    from ..scene.spec import SceneSpec

__all__ = [
    "BackendRecipe",
    "ChunkPool",
    "Prepared",
    "chunk_task",
    "finish_chunked",
    "prepare_chunked",
    "process_video_chunked",
]


@dataclass
class BackendRecipe:
    """How a worker builds its :class:`arshadow.video.framejob.SessionBackend` (picklable).

    Attributes
    ----------
    spec : arshadow.scene.SceneSpec
    lights : list of Light or None
        The session's first lights (None: the spec's).
    static, tracks : lists
        Fixed lights and sun tracks of a time-lapse (:meth:`Session.use_sun_tracks`).
    time_lapse : (datetime, float) or None
    """

    spec: SceneSpec
    lights: list[Light] | None = None
    static: list[Light] = field(default_factory=list)
    tracks: list[SunTrack] = field(default_factory=list)
    time_lapse: tuple[datetime, float] | None = None

    def key(self) -> str:
        return repr((self.spec, self.lights, self.static, self.tracks, self.time_lapse))

    def build(self) -> SessionBackend:
        session = Session(self.spec, lights=self.lights)
        if self.tracks:
            session.use_sun_tracks(self.tracks, self.static)
        # a spec with a time-lapse (SceneSpec.time_lapse) gives the session its own sun tracks
        return SessionBackend(session, self.tracks or session.sun_tracks, self.time_lapse or session.time_lapse)


_BACKENDS: dict[str, SessionBackend] = {}


def backend_for(recipe: BackendRecipe, threads: int = 0) -> SessionBackend:
    """One backend per recipe per process (a worker keeps its GL context between chunks). ``threads``: the
    rasterizer threads of Mesa llvmpipe (``LP_NUM_THREADS``, set while the backend's GL context is created;
    a setting of the user's is kept; 0: Mesa's choice, one per core)."""
    key = recipe.key()
    b = _BACKENDS.get(key)
    if b is None:
        release_backends()
        b = _BACKENDS[key] = recipe.build()
        if threads and "LP_NUM_THREADS" not in os.environ:
            os.environ["LP_NUM_THREADS"] = str(int(threads))
            try:
                b.session.context  # noqa: B018 (made now, while the setting is there)
            finally:
                del os.environ["LP_NUM_THREADS"]  # the process's other contexts keep Mesa's default
    return b


def release_backends() -> None:
    """Close this process's chunk backends (their sessions and GL contexts)."""
    for old in _BACKENDS.values():
        old.session.close()
    _BACKENDS.clear()


@dataclass
class Prepared:
    """A video planned into chunks (picklable: sent with every chunk task). ``camera``: the blur and noise
    every chunk applies (``--camera-effects on``: measured on the video's first tracked frame by
    :func:`prepare_chunked`; None: off, or no frame tracked)."""

    path: str
    name: str
    index: StreamIndex
    chunks: list[Chunk]
    store: ChunkStore
    outputs: VideoOutputs
    opts: EngineOptions
    total: int | None
    rate: Fraction
    size: tuple[int, int]
    has_audio: bool
    fps_assumed: bool
    frame_count: int | None
    note: str | None = None
    camera: CameraEffects | None = None


def prepare_chunked(
    path: str | os.PathLike[str],
    outputs: VideoOutputs,
    opts: EngineOptions,
    count: int,
    outdir: str | os.PathLike[str],
    stem: str,
    recipe: BackendRecipe,
    name: str | None = None,
) -> tuple[Prepared | None, str | None]:
    """Plan one video into up to ``count`` chunks: a :class:`Prepared`, or ``(None, note)`` when it is
    processed in one piece (``note``: why, or None for an image sequence). ``recipe``: the workers' (its key
    is in the chunks' fingerprint). A scene with ``--camera-effects on`` measures them on the video's first
    tracked frame, which a chunk's own frames need not hold: they are measured here, as a run of the whole
    video measures them (:func:`arshadow.video.engine.first_camera`), and every chunk uses them
    (:attr:`Prepared.camera`)."""
    p = str(path)
    if "%" in p:
        return None, None
    if opts.layers is not None:
        return None, f"{name or p}: not cut into chunks (--layers are written in one piece)"
    index = scan_stream(p)
    if index.problem:
        return None, f"{name or p}: not cut into chunks ({index.problem})"
    probe = AvReader(p, max_frames=opts.max_frames, raw=True)
    probe.close()
    n = index.n if opts.max_frames is None else min(index.n, opts.max_frames)
    chunks, note = plan_chunks(index, n, opts, count)
    if note is not None:
        note = f"{name or p}: {note}"
    if len(chunks) < 2:
        return None, note
    total = probe.frame_count if opts.max_frames is None else min(probe.frame_count or opts.max_frames, opts.max_frames)
    camera = None
    if recipe.spec.options.camera_effects == "on":
        try:
            camera = _first_camera(p, recipe, opts)
        except ArshadowError as exc:  # e.g. a calibration that does not fit: the one-piece run reports it
            return None, f"{name or p}: not cut into chunks ({exc})"
    store = ChunkStore(outdir, stem, fingerprint(p, recipe.key(), opts, n), opts)
    return Prepared(
        p,
        name or p,
        index,
        chunks,
        store,
        outputs,
        opts,
        total,
        probe.rate,
        (probe.width, probe.height),
        probe.has_audio,
        bool(probe.fps_assumed),
        probe.frame_count,
        note,
        camera,
    ), None


def _first_camera(path: str, recipe: BackendRecipe, opts: EngineOptions) -> CameraEffects | None:
    """The video's camera effects, measured in this process with a session of its own (no GL context: the
    chunk workers may still be forked), closed after."""
    backend = recipe.build()
    reader, _ = open_reader(path, opts.max_frames)
    try:
        return first_camera(backend, reader)
    finally:
        reader.close()
        backend.session.close()


def encoder_threads(jobs: int) -> int:
    """x264 threads per chunk worker: the cores left to each when ``jobs`` workers share them (at least 1).

    >>> encoder_threads(os.cpu_count() or 1)
    1
    """
    return max(1, (os.cpu_count() or 1) // max(1, int(jobs)))


START_METHODS = ("fork", "spawn", "forkserver")


def start_method() -> str:
    """How local chunk workers start: ``$ARSHADOW_START_METHOD`` if set, else ``fork`` on Linux while this
    process has made no OpenGL context (:func:`arshadow.gl.context.contexts_made`), else ``spawn``.

    Raises
    ------
    UsageError
        ``$ARSHADOW_START_METHOD`` is not one of :data:`START_METHODS`.
    """
    env = os.environ.get("ARSHADOW_START_METHOD", "").strip().lower()
    if env:
        if env not in START_METHODS:
            raise UsageError(f"ARSHADOW_START_METHOD={env!r}: choose {', '.join(START_METHODS)}")
        return env
    return "fork" if sys.platform.startswith("linux") and contexts_made() == 0 else "spawn"


#: a chunk's work: ``task(recipe, prep, chunk) -> record`` (:func:`chunk_task`; a picklable stand-in in tests)
ChunkTask: TypeAlias = Callable[["BackendRecipe", "Prepared", Chunk], dict[str, Any]]


def chunk_task(recipe: BackendRecipe, prep: Prepared, chunk: Chunk) -> dict[str, Any]:
    """Run one chunk in this process (a pool worker or a Dask task); returns its record. (The store was
    opened, and an interrupted run's temporaries removed, before any chunk started: never here, where
    other chunks are writing.)"""
    make_folder(prep.store.dir)  # the shared parent may be removed meanwhile by another video's join
    t = time.perf_counter()
    backend = backend_for(recipe, prep.opts.encoder_threads)
    setup = time.perf_counter() - t
    rec = run_chunk(
        backend,
        prep.path,
        prep.index,
        chunk,
        prep.opts,
        prep.store,
        name=prep.name,
        final=prep.outputs,
        total=prep.total,
        camera=prep.camera,
    )
    rec["setup_s"] = round(setup, 3)  # the worker's session and GL context (0 once made)
    return rec


class ChunkPool:
    """``jobs`` processes for chunks: this one and ``jobs - 1`` local workers (:func:`start_method`),
    recreated after a worker dies."""

    def __init__(self, jobs: int) -> None:
        self.jobs = int(jobs)
        self._ex: ProcessPoolExecutor | None = None

    def _executor(self) -> ProcessPoolExecutor:
        if self._ex is None:
            workers = max(1, self.jobs - 1)
            self._ex = ProcessPoolExecutor(
                workers, mp_context=multiprocessing.get_context(start_method()), initializer=quiet_notes
            )  # the notes (a scaled calibration) are said once, by this process
        return self._ex

    def run(
        self,
        fn: ChunkTask,
        recipe: BackendRecipe,
        prep: Prepared,
        chunks: Sequence[Chunk],
        on_done: Callable[[dict[str, Any]], None] | None = None,
    ) -> dict[int, dict[str, Any]]:
        """``fn(recipe, prep, chunk)`` for every chunk; ``{k: record}``. When a worker dies every chunk in
        flight is lost with it: those are run again one at a time in a fresh pool (so that a death names
        its chunk), and a chunk whose worker dies again fails the video (ImageError naming it)."""
        records: dict[int, dict[str, Any]] = {}
        died = self._round(fn, recipe, prep, chunks, records, on_done)
        for c in died:
            self.close()
            if self._round(fn, recipe, prep, [c], records, on_done):
                self.close()
                raise ImageError(
                    f"{prep.name}: chunk {c.k} (frames {c.start}-{c.stop - 1}): its worker process "
                    f"died twice; the video is not written"
                )
        return records

    def _round(
        self,
        fn: ChunkTask,
        recipe: BackendRecipe,
        prep: Prepared,
        chunks: Sequence[Chunk],
        records: dict[int, dict[str, Any]],
        on_done: Callable[[dict[str, Any]], None] | None,
    ) -> list[Chunk]:
        """Run the chunks in parallel, the first in this process when there are several (a lone chunk, as
        a retry, goes to a worker: a death there names it); returns those lost to a dead worker."""
        ex = self._executor()
        here = chunks[0] if len(chunks) > 1 else None
        futs = {ex.submit(fn, recipe, prep, c): c for c in chunks if c is not here}
        if here is not None:
            records[here.k] = fn(recipe, prep, here)
            if on_done is not None:
                on_done(records[here.k])
        died: list[Chunk] = []
        for fut, c in futs.items():
            try:
                records[c.k] = fut.result()
            except BrokenProcessPool:
                died.append(c)
                continue
            if on_done is not None:
                on_done(records[c.k])
        return died

    def close(self) -> None:
        if self._ex is not None:
            self._ex.shutdown(wait=False, cancel_futures=True)
            self._ex = None
        release_backends()  # the chunk this process ran kept a session and GL context


def finish_chunked(
    prep: Prepared, records: dict[int, dict[str, Any]], rerun: Callable[[Chunk], dict[str, Any]]
) -> dict[str, Any]:
    """Check the chunks against each other (redoing a chunk with a longer primer via ``rerun(chunk)``
    until they agree), join them into the video's outputs, remove the store; returns the summary (with
    ``items``, every frame's report item as the sequential run makes it, when ``opts.collect_items``)."""
    chunks = list(prep.chunks)
    redone = 0
    while (bad := first_mismatch(prep.store, chunks, records, prep.opts, prep.index)) is not None:
        wider = widened(chunks[bad], prep.index, prep.opts)
        if wider is None:
            raise ImageError(f"{prep.name}: chunk {bad} differs from the run before it even from frame 0")
        chunks[bad] = wider
        records[bad] = rerun(wider)
        redone += 1
    t_join = time.perf_counter()
    joined = join_chunks(
        prep.store,
        chunks,
        prep.outputs,
        prep.opts,
        prep.rate,
        audio_from=prep.path if (prep.opts.keep_audio and prep.has_audio) else None,
        rotation=display_rotation(prep.path),
    )
    sheet = SheetThumbs(prep.opts.contact_sheet, prep.total, prep.size)
    for k in sorted(joined["thumbs"]):
        sheet.offer(k, joined["thumbs"][k])
    if (sheet_path := prep.outputs.get("sheet")) is not None and sheet.thumbs:
        write_contact_sheet(sheet_path, sheet.picked())
    summary = _summary(prep, chunks, records, sheet, joined["audio"], redone)
    summary["join_s"] = round(time.perf_counter() - t_join, 3)
    if joined["items"] is not None:  # taken out by the caller (arshadow.video.runner): not a summary key
        summary["items"] = joined["items"]
    prep.store.remove()
    return summary


def _summary(
    prep: Prepared,
    chunks: list[Chunk],
    records: dict[int, dict[str, Any]],
    sheet: SheetThumbs,
    audio: bool,
    redone: int,
) -> dict[str, Any]:
    counts = ("frames", "frames_ok", "frames_held", "frames_no_marker", "swapped")
    stats: dict[str, int] = {k: sum(records[c.k]["stats"][k] for c in chunks) for k in counts}
    gaps: dict[str, int | None] = {}  # the longest run of frames not tracked, when the records count it
    stage_ms: dict[str, list[float]] = {k: [] for k in FRAME_STAGES}
    # runs of frames not tracked, across the chunks' boundaries: (length, first frame)
    gap: tuple[int, int | None] = (0, None)
    longest: tuple[int, int | None] = (0, None)
    refs = ReferenceTally()  # the reference marker of each tracked frame (a change is warned of)
    with open(required(prep.outputs, "frames"), encoding="utf-8") as f:
        for line in f:
            d = json.loads(line)
            for k, v in d["timings_ms"].items():
                stage_ms.setdefault(k, []).append(v)
            if d["status"] == "ok":
                refs.add(d["frame"], d.get("reference_id"))
            gap = (0, None) if d["status"] == "ok" else (gap[0] + 1, d["frame"] if gap[1] is None else gap[1])
            longest = gap if gap[0] > longest[0] else longest
    if "longest_gap" in records[chunks[0].k]["stats"]:
        gaps["longest_gap"], gaps["longest_gap_start"] = longest
    warnings: list[str] = [prep.note] if prep.note else []
    flags = FlagTally()  # the flagged poses of every chunk, in frame order: the sequential run's line
    for c in chunks:
        fl = records[c.k].get("flags") or {"keys": [], "kinds": {}}
        flags.keys += fl["keys"]
        for kind, n in fl["kinds"].items():
            flags.kinds[kind] = flags.kinds.get(kind, 0) + n
    if (flagged := flags.summary(stats["frames"], "frames", prep.outputs["frames"])) is not None:
        warnings.append(f"{prep.name}: {flagged}")
    if (switched := refs.summary()) is not None:
        warnings.append(f"{prep.name}: {switched}")
    status = "ok"
    if stats["frames_ok"] == 0:
        status = "no_marker"
        warnings.append(f"{prep.name}: the marker was found in none of the {stats['frames']} frames")
    out_mask = prep.outputs.get("mask")
    fm = np.asarray(stage_ms["total"] or [0.0])
    cpu = sum(records[c.k]["cpu_s"] for c in chunks)
    return {
        "input": prep.name,
        "output": str(prep.outputs["video"]),
        "mask": None if out_mask is None else str(out_mask),
        "frames_report": str(prep.outputs["frames"]),
        "sheet": str(prep.outputs["sheet"]) if prep.outputs.get("sheet") is not None and sheet.thumbs else None,
        "status": status,
        "error": None,
        "warnings": warnings,
        **stats,
        **gaps,
        "recomputes": sum(records[c.k]["recomputes"] for c in chunks),
        "decode_errors": 0,
        "truncated": False,
        "frame_count_declared": prep.frame_count,
        "fps": float(prep.rate),
        "fps_assumed": prep.fps_assumed,
        "size": list(prep.size),
        "audio": audio,
        "codec": prep.opts.codec,
        "crf": prep.opts.crf,
        "chunks": [
            {
                "k": c.k,
                "frames": [c.start, c.stop],
                "decoded_from": c.decode_from,
                "primed_from": c.prime_from,
                "wall_s": records[c.k]["wall_s"],
                "cpu_s": records[c.k]["cpu_s"],
                "setup_s": records[c.k].get("setup_s", 0.0),
                "pid": records[c.k]["pid"],
                "max_rss_mb": records[c.k].get("max_rss_mb"),
                "frames_decoded": records[c.k].get("frames_decoded"),
                "process_cpu_s": records[c.k].get("process_cpu_s"),
            }
            for c in chunks
        ],
        "chunks_redone": redone,
        "chunk_cpu_s": round(cpu, 3),
        "stage_ms_median": {k: round(float(np.median(v)), 3) for k, v in stage_ms.items() if v},
        "frame_ms_median": float(np.median(fm)),
        "frame_ms_iqr": [float(np.percentile(fm, 25)), float(np.percentile(fm, 75))],
        "frame_ms_minmax": [float(fm.min()), float(fm.max())],
    }


def name_other_dictionaries(summary: dict[str, Any], spec: SceneSpec, path: str | os.PathLike[str]) -> None:
    """A video whose marker was found in no frame: its warning names the other dictionaries' markers the
    video shows (:func:`arshadow.video.hints.other_dictionaries_hint`; single-marker mode), as the
    one-piece run's does."""
    tracker = getattr(spec, "tracker", None)
    if summary.get("status") != "no_marker" or tracker is None or getattr(tracker, "board", None):
        return
    hint = other_dictionaries_hint(path, getattr(tracker, "dictionary", None) or DEFAULT_DICTIONARY)
    end = f"found in none of the {summary['frames']} frames"
    summary["warnings"] = [w + hint if w.endswith(end) else w for w in summary["warnings"]]


def process_video_chunked(
    recipe: BackendRecipe,
    pool: ChunkPool,
    path: str | os.PathLike[str],
    outputs: VideoOutputs,
    opts: EngineOptions,
    *,
    outdir: str | os.PathLike[str],
    stem: str,
    name: str | None = None,
    progress: Progress | None = None,
    task: ChunkTask = chunk_task,
) -> tuple[dict[str, Any] | None, str | None]:
    """One video on ``pool``'s workers in chunks; ``(summary, note)``, or ``(None, note)`` when it is to be
    processed in one piece (``note``: why, or None).

    Finished chunks found in the store (an interrupted earlier run) are kept; the others are run with
    ``task(recipe, prep, chunk)`` (:func:`chunk_task`; a picklable stand-in in tests).
    """
    t0 = time.perf_counter()
    opts = opts.check()
    prep, note = prepare_chunked(path, outputs, opts, pool.jobs, outdir, stem, recipe, name)
    if prep is not None and not opts.encoder_threads:
        prep.opts = dataclasses.replace(opts, encoder_threads=encoder_threads(pool.jobs))
    if prep is None:
        return None, note
    prep.store.open()
    records = {c.k: r for c in prep.chunks if (r := prep.store.done(c)) is not None}
    done = [0]

    def on_done(rec: dict[str, Any]) -> None:
        done[0] += rec["chunk"]["stop"] - rec["chunk"]["start"]
        if progress is not None:
            progress(done[0], prep.total)

    todo = [c for c in prep.chunks if c.k not in records]
    records.update(pool.run(task, recipe, prep, todo, on_done))
    summary = finish_chunked(prep, records, lambda c: pool.run(task, recipe, prep, [c])[c.k])
    summary["chunks_resumed"] = len(prep.chunks) - len(todo)
    name_other_dictionaries(summary, recipe.spec, prep.path)
    wall = time.perf_counter() - t0
    summary.update(wall_s=round(wall, 3), fps_processed=round(summary["frames"] / wall, 2) if wall > 0 else None)
    return summary, None
