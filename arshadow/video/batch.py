"""Batches of photos and videos under one scene, resumable, locally or on a Dask cluster.

:func:`run_batch` processes every input of a batch with one :class:`arshadow.scene.SceneSpec` and writes,
per input, its outputs into ``OUT_DIR`` (photos: ``<stem>.png`` and ``<stem>.shadow.png``; videos: the
outputs of :func:`arshadow.video.engine.process_video`), then a **done record**
``OUT_DIR/.arshadow-batch/<stem>.json`` (the item's summary and the fingerprint of its input and settings),
and at the end the summary ``OUT_DIR/batch.json``.

Resuming: every output is written to a temporary name and renamed into place when complete, and the done
record is written last. A rerun after an interruption (``kill -9`` included) therefore skips every item
whose done record matches (same input file size and modification time, same scene and options, outputs
present) and redoes the others from scratch; temporary files an interrupted run left behind are removed
first. No output is ever half-written.

Dask (``pip install arshadow[dask]``): ``run_batch(..., client=distributed.Client(...))`` runs one task
per item; each worker builds its own :class:`arshadow.frame.session.Session` (and OpenGL context) from the
picklable spec once and reuses it for its later items. Workers write into ``OUT_DIR`` directly, so it must
be a folder every worker sees (a shared file system); the outputs and records are the same as a local run.

About 600 lines: one batch's resumable bookkeeping (fingerprints, done records, temporary outputs) and
its local and Dask drivers, which share it; a photo's work is :func:`arshadow.photos.render_photo_file`'s, a
video's :func:`arshadow.video.engine.process_video`'s.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import hashlib
import json
import os
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

import cv2

from .. import __version__
from ..errors import ArshadowError, BatchStoppedError, MarkerNotFoundError, OutputSpaceError, UsageError
from ..export.layerfiles import layer_paths
from ..frame.session import Session
from ..io import IMAGE_EXTENSIONS, InputGuard, check_output_folder, make_folder, unique_stems, write_json
from ..io import clean_temporaries as clean_io_temporaries
from ..photos import PhotoJob, render_photo_file
from .decode import looks_like_sequence
from .encode import VideoOutputs
from .engine import EngineOptions, SessionBackend, process_video, video_outputs
from .parallel import (
    BackendRecipe,
    ChunkPool,
    Prepared,
    chunk_task,
    finish_chunked,
    name_other_dictionaries,
    prepare_chunked,
    process_video_chunked,
)

if TYPE_CHECKING:
    from distributed import Client, Future

    from ..scene.spec import SceneSpec

__all__ = ["VIDEO_EXTENSIONS", "BatchItem", "clean_temporaries", "plan_batch", "process_item", "run_batch"]

#: an item's summary (JSON: ``input``, ``kind``, ``stem``, ``status``, ``error``, ``outputs``, ``warnings``, ...)
Summary: TypeAlias = dict[str, Any]
#: ``(index in the batch, item, fingerprint)`` of an item to process
Todo: TypeAlias = tuple[int, "BatchItem", str]

VIDEO_EXTENSIONS = {".mp4", ".m4v", ".mov", ".mkv", ".avi", ".webm", ".mpg", ".mpeg", ".ts", ".mts", ".wmv", ".flv"}
RECORDS = ".arshadow-batch"


@dataclasses.dataclass(frozen=True)
class BatchItem:
    """One input of a batch: ``kind`` ``"photo"`` or ``"video"``, its output ``stem``."""

    input: str
    kind: str
    stem: str


def plan_batch(inputs: Iterable[str | os.PathLike[str]]) -> list[BatchItem]:
    """Classify inputs by extension (videos: :data:`VIDEO_EXTENSIONS`) and give each a unique stem."""
    names = [str(i) for i in inputs]
    if not names:
        raise UsageError("no input given")
    return [BatchItem(i, _kind(i), s) for i, s in zip(names, unique_stems(names), strict=True)]


def _kind(path: str) -> str:
    """``"video"`` for a video extension or an image-sequence pattern; ``"photo"`` for an image extension;
    otherwise by content (what OpenCV's image readers recognise is a photo, anything else is tried as a
    video)."""
    ext = Path(path).suffix.lower()
    if ext in VIDEO_EXTENSIONS or looks_like_sequence(path):
        return "video"
    if ext in IMAGE_EXTENSIONS or not Path(path).is_file():
        return "photo"
    try:
        return "photo" if cv2.haveImageReader(path) else "video"
    except cv2.error:
        return "photo"


def _outputs(item: BatchItem, outdir: Path, opts: EngineOptions, save_mask: bool) -> list[Path]:
    """The files an item writes (before its done record)."""
    if item.kind == "video":
        return [p for p in video_outputs(outdir, item.stem, opts).values() if p is not None]
    outs = [outdir / f"{item.stem}.png", *([outdir / f"{item.stem}.shadow.png"] if save_mask else [])]
    if opts.layers is not None:
        outs += list(layer_paths(outdir, item.stem, _photo_layers(opts), opts.layers_undistorted).values())
    return outs


def _photo_layers(opts: EngineOptions) -> str:
    """The layer format of a batch's photos: EXR with ``--layers-format exr``, else 16-bit PNG."""
    return "exr" if opts.layers == "exr" else "png"


def _fingerprint(item: BatchItem, spec: SceneSpec, opts: EngineOptions, save_mask: bool) -> str:
    """Input file identity (size, mtime) + scene + options: a changed input or setting redoes the item."""
    try:
        st = os.stat(item.input)
        ident: list[int] | None = [st.st_size, st.st_mtime_ns]
    except OSError:
        ident = None
    blob = json.dumps(
        [str(Path(item.input).resolve()), ident, repr(spec), repr(opts), save_mask, item.kind], default=str
    )
    return hashlib.sha256(blob.encode()).hexdigest()


def _record_path(outdir: Path, item: BatchItem) -> Path:
    return outdir / RECORDS / f"{item.stem}.json"


def clean_temporaries(outdir: str | os.PathLike[str]) -> int:
    """Remove the temporary files and folders an interrupted run left in ``outdir`` (``.NAME.*.tmp*``)."""
    d = Path(outdir)
    return clean_io_temporaries(d) + clean_io_temporaries(d / RECORDS)


def _done(outdir: Path, item: BatchItem, fp: str) -> Summary | None:
    """The item's done record when it matches and its outputs exist, else None."""
    p = _record_path(outdir, item)
    try:
        rec: Summary = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if rec.get("fingerprint") != fp:
        return None
    if not all(Path(o).exists() for o in rec.get("outputs", [])):
        return None
    return rec


# --------------------------------------------------------------------------------------------------
# one item (local or on a worker)
# --------------------------------------------------------------------------------------------------
_WORKER_SESSIONS: dict[str, Session] = {}


def _session_for(spec: SceneSpec) -> Session:
    """One Session per spec per process (a Dask worker keeps its GL context between items)."""
    key = repr(spec)
    s = _WORKER_SESSIONS.get(key)
    if s is None:
        for old in _WORKER_SESSIONS.values():
            old.close()
        _WORKER_SESSIONS.clear()
        s = _WORKER_SESSIONS[key] = Session(spec)
    return s


def process_item(
    spec: SceneSpec,
    item: BatchItem,
    outdir: str | os.PathLike[str],
    opts: EngineOptions,
    save_mask: bool,
    fingerprint: str,
    session: Session | None = None,
    pool: ChunkPool | None = None,
) -> Summary:
    """Process one input and write its outputs and done record; returns the item's summary.

    ``pool`` (:class:`arshadow.video.parallel.ChunkPool`): a video is cut into chunks run on its workers.
    Never raises for a bad input: the summary has ``status: "error"`` and ``error`` (nothing is recorded
    as done, so a rerun tries it again).
    """
    out_dir = Path(outdir)

    def work(summary: Summary) -> None:
        outs = video_outputs(out_dir, item.stem, opts) if item.kind == "video" else None
        if outs is not None and pool is not None:  # a video
            vs, note = process_video_chunked(
                BackendRecipe(spec), pool, item.input, outs, opts, outdir=out_dir, stem=item.stem, name=item.input
            )
            if vs is not None:
                _video_fields(summary, vs, outs)
                return
            summary["warnings"] = [note] if note else []
        sess = session if session is not None else _session_for(spec)
        if outs is not None:  # a video
            vs1, _ = process_video(
                SessionBackend(sess, sess.sun_tracks, sess.time_lapse), item.input, outs, opts, name=item.input
            )
            vs1["warnings"] = summary["warnings"] + vs1["warnings"]
            _video_fields(summary, vs1, outs)
            return
        # the photo loop's one photo (EXIF orientation, upright outputs and layers), as arshadow render
        fmt = _photo_layers(opts)
        lay = None if opts.layers is None else layer_paths(out_dir, item.stem, fmt, opts.layers_undistorted)
        job = PhotoJob(
            item.input,
            out_dir / f"{item.stem}.png",
            out_dir / f"{item.stem}.shadow.png" if save_mask else None,
            lay,
            fmt,
        )
        res = render_photo_file(sess, job)
        summary["outputs"] = [str(p) for p in job.outputs]
        summary["status"] = "ok"
        if res.item.flag_reasons:  # the sanity gates: a flagged pose is said (its reasons also in the item)
            summary["warnings"].append(f"{item.input}: flagged pose: {'; '.join(res.item.flag_reasons)}")
        summary["item"] = res.item.to_dict()

    return _guarded(item, out_dir, fingerprint, work)


def _video_fields(summary: Summary, vs: dict[str, Any], outs: VideoOutputs) -> None:
    summary.update(
        {
            k: vs.get(k)
            for k in (
                "status",
                "warnings",
                "frames",
                "frames_ok",
                "frames_held",
                "frames_no_marker",
                "truncated",
                "decode_errors",
                "fps_processed",
            )
        }
    )
    if "chunks" in vs:
        summary.update(chunks=len(vs["chunks"]), chunks_resumed=vs.get("chunks_resumed", 0))
    summary["outputs"] = [str(p) for p in outs.values() if p is not None and Path(p).exists()]


def _guarded(item: BatchItem, outdir: Path, fingerprint: str, work: Callable[[Summary], None]) -> Summary:
    """``work(summary)`` fills the item's summary; a bad input becomes ``status: "error"``; the done record
    is written last, once every output is in place."""
    t0 = time.perf_counter()
    summary: Summary = {
        "input": item.input,
        "kind": item.kind,
        "stem": item.stem,
        "status": "error",
        "error": None,
        "outputs": [],
        "warnings": [],
    }
    try:
        work(summary)
    except OutputSpaceError as exc:  # the next items would fail the same way: stop
        raise disk_full(outdir, exc) from None
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise disk_full(outdir, exc) from None
        summary["error"] = f"{type(exc).__name__}: {exc}"
        if item.input not in summary["error"]:
            summary["error"] = f"{item.input}: {summary['error']}"
    except MarkerNotFoundError as exc:  # a photo without the marker: done (a rerun would find none either)
        summary["status"] = "no_marker"
        summary["error"] = f"{item.input}: {exc}"
    except (ArshadowError, MemoryError) as exc:
        summary["status"] = "error"
        summary["error"] = str(exc) if isinstance(exc, ArshadowError) else f"{type(exc).__name__}: {exc}"
        if item.input not in summary["error"]:
            summary["error"] = f"{item.input}: {summary['error']}"
    summary["seconds"] = round(time.perf_counter() - t0, 3)
    if summary["status"] in ("ok", "no_marker", "damaged"):
        write_json(_record_path(outdir, item), {"fingerprint": fingerprint, **summary})
    return summary


RESUME = "rerun the same command to resume (finished items and video chunks are kept)"


def disk_full(outdir: str | os.PathLike[str], exc: Exception) -> BatchStoppedError:
    """The one-line error of a full output disk (``ENOSPC``/``EDQUOT`` while writing under ``outdir``)."""
    return BatchStoppedError(
        f"{outdir}: no space left on the output disk ({exc}); no half-written output was kept: free some "
        f"space and {RESUME}"
    )


def _dask_task(
    spec: SceneSpec, item: BatchItem, outdir: str, opts: EngineOptions, save_mask: bool, fingerprint: str
) -> Summary:
    return process_item(spec, item, outdir, opts, save_mask, fingerprint)


def _dask_join(
    spec: SceneSpec,
    item: BatchItem,
    outdir: str,
    opts: EngineOptions,
    fingerprint: str,
    prep: Prepared,
    done: dict[int, dict[str, Any]],
    *records: dict[str, Any],
) -> Summary:
    """The join task of a chunked video on Dask: its chunk tasks' records are the arguments."""
    recs = {**{int(k): r for k, r in done.items()}, **{r["chunk"]["k"]: r for r in records}}
    recipe = BackendRecipe(spec)

    def work(summary: Summary) -> None:
        vs = finish_chunked(prep, recs, lambda c: chunk_task(recipe, prep, c))
        vs["chunks_resumed"] = len(done)
        name_other_dictionaries(vs, spec, prep.path)
        _video_fields(summary, vs, prep.outputs)

    return _guarded(item, Path(outdir), fingerprint, work)


def _submit_dask(
    client: Client,
    spec: SceneSpec,
    it: BatchItem,
    outdir: Path,
    opts: EngineOptions,
    save_mask: bool,
    fp: str,
    chunks: int,
) -> Future[Summary]:
    """One item's tasks: a chunked video is one task per unfinished chunk and a join task depending on
    them; anything else is one task. Returns the future of the item's summary."""
    if it.kind == "video" and chunks > 1:
        recipe = BackendRecipe(spec)
        try:
            prep, _note = prepare_chunked(
                it.input, video_outputs(outdir, it.stem, opts), opts.check(), chunks, outdir, it.stem, recipe, it.input
            )
        except ArshadowError:
            prep = None  # the item's own task reports the problem
        if prep is not None:
            prep.store.open()
            done = {c.k: r for c in prep.chunks if (r := prep.store.done(c)) is not None}
            futs = [
                client.submit(
                    chunk_task, recipe, prep, c, pure=False, retries=1, key=f"arshadow-{it.stem}-{fp[:12]}-c{c.k}"
                )
                for c in prep.chunks
                if c.k not in done
            ]
            return client.submit(
                _dask_join,
                spec,
                it,
                str(outdir),
                opts,
                fp,
                prep,
                done,
                *futs,
                pure=False,
                key=f"arshadow-{it.stem}-{fp[:12]}-join",
            )
    return client.submit(
        _dask_task, spec, it, str(outdir), opts, save_mask, fp, pure=False, key=f"arshadow-{it.stem}-{fp[:12]}"
    )


def _stop_if_lost(client: Client, exc: Exception, outdir: str | os.PathLike[str]) -> None:
    """Raise the batch's one-line error when ``exc`` (a task's) means the batch cannot go on: the
    scheduler lost (every other task is cancelled with it), the output disk full."""
    if isinstance(exc, OutputSpaceError) or (isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)):
        raise disk_full(outdir, exc) from None
    lost = "scheduler-connection-lost" in str(exc) or getattr(client, "status", "running") != "running"
    if lost:
        addr = getattr(getattr(client, "scheduler", None), "address", None) or "of the batch"
        raise BatchStoppedError(f"the Dask scheduler {addr} was lost; {RESUME}") from None


# --------------------------------------------------------------------------------------------------
# the batch
# --------------------------------------------------------------------------------------------------
def run_batch(
    spec: SceneSpec,
    inputs: Sequence[str | Path],
    outdir: Path | str,
    opts: EngineOptions,
    *,
    save_mask: bool = False,
    client: Client | None = None,
    progress: Callable[[int, int, Summary | None], object] | None = None,
    session: Session | None = None,
    jobs: int = 1,
) -> dict[str, Any]:
    """Process a batch (see the module); returns the summary also written to ``OUT_DIR/batch.json``.

    Parameters
    ----------
    spec : arshadow.scene.SceneSpec
    inputs : list of str
        Photos and videos (by extension, :data:`VIDEO_EXTENSIONS`).
    outdir : str or Path
    opts : arshadow.video.engine.EngineOptions
        How videos are written (``opts.mask`` also decides photo masks: ``save_mask``).
    save_mask : bool
        Write photo masks (``<stem>.shadow.png``).
    client : distributed.Client, optional
        Run the items on this Dask cluster instead of in this process: one task per photo, one per chunk
        of a video (chunks per video: ``jobs``, or the cluster's worker count when ``jobs`` is 1) and a join
        task per video, all scheduled together.
    progress : callable, optional
        ``progress(done, total, summary)`` after each item.
    session : arshadow.frame.session.Session, optional
        Local runs: use this session (else one is made).
    jobs : int
        Local runs: worker processes per video (chunks, :mod:`arshadow.video.chunks`); 1: in this process.

    Returns
    -------
    dict
        ``{"arshadow": VERSION, "items": [...], "counts": {...}}``; each item has ``status`` (``ok``,
        ``no_marker``, ``damaged``, ``error``) and ``skipped`` (done by an earlier run).
    """
    if int(jobs) < 1:
        raise UsageError(f"--jobs {jobs}: must be >= 1")
    out_dir = check_output_folder(outdir, "-o")
    make_folder(out_dir / RECORDS)
    clean_temporaries(out_dir)
    items = plan_batch(inputs)
    results, todo = _plan_todo(items, inputs, spec, out_dir, opts, save_mask)
    done = len(items) - len(todo)
    if progress is not None:
        for r in results:
            if r is not None and r["status"] == "error":
                progress(done, len(items), r)
        if done:
            progress(done, len(items), None)

    def finished(k: int, res: Summary) -> None:
        nonlocal done
        results[k] = {**res, "skipped": False}
        done += 1
        if progress is not None:
            progress(done, len(items), results[k])

    try:
        if client is None:
            _run_local(spec, todo, out_dir, opts, save_mask, session, int(jobs), finished)
        else:
            _run_dask(client, spec, items, todo, out_dir, opts, save_mask, int(jobs), finished)
    except KeyboardInterrupt:  # Ctrl-C / SIGTERM: batch.json still says what is done and what is not
        _write_summary(out_dir, items, results, interrupted=True)
        raise
    except BatchStoppedError:  # the scheduler lost, the disk full: batch.json says so if it can be written
        with contextlib.suppress(OSError):
            _write_summary(out_dir, items, results, interrupted=True)
        raise
    return _write_summary(out_dir, items, results)


def _write_summary(
    outdir: Path, items: list[BatchItem], results: list[Summary | None], interrupted: bool = False
) -> dict[str, Any]:
    """``OUT_DIR/batch.json``; after an interruption the items not finished are ``status: "pending"``."""
    filled: list[Summary] = [
        r
        if r is not None
        else {
            "input": it.input,
            "kind": it.kind,
            "stem": it.stem,
            "status": "pending",
            "skipped": False,
            "error": None,
            "outputs": [],
            "warnings": [],
        }
        for it, r in zip(items, results, strict=True)
    ]
    counts: dict[str, int] = {}
    for r in filled:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    counts["skipped"] = sum(bool(r.get("skipped")) for r in filled)
    summary: dict[str, Any] = {"arshadow": __version__, "items": filled, "counts": counts}
    if interrupted:
        summary["interrupted"] = True  # rerun the same command to finish the pending items
    write_json(outdir / "batch.json", summary)
    return summary


def _plan_todo(
    items: list[BatchItem],
    inputs: Sequence[str | Path],
    spec: SceneSpec,
    outdir: Path,
    opts: EngineOptions,
    save_mask: bool,
) -> tuple[list[Summary | None], list[Todo]]:
    """``(results, todo)``: results of items refused (an output onto an input) or done by an earlier run,
    and ``(index, item, fingerprint)`` of the others."""
    results: list[Summary | None] = [None] * len(items)
    todo: list[Todo] = []
    guard = InputGuard(inputs)
    for k, it in enumerate(items):
        try:  # inputs are never modified
            guard.check(_outputs(it, outdir, opts, save_mask))
        except ArshadowError as exc:
            results[k] = {
                "input": it.input,
                "kind": it.kind,
                "stem": it.stem,
                "status": "error",
                "skipped": False,
                "error": str(exc),
                "outputs": [],
                "warnings": [],
            }
            continue
        fp = _fingerprint(it, spec, opts, save_mask)
        rec = _done(outdir, it, fp)
        if rec is not None:
            rec.pop("fingerprint", None)
            results[k] = {**rec, "skipped": True}
        else:
            todo.append((k, it, fp))
    return results, todo


def _run_local(
    spec: SceneSpec,
    todo: list[Todo],
    outdir: Path,
    opts: EngineOptions,
    save_mask: bool,
    session: Session | None,
    jobs: int,
    finished: Callable[[int, Summary], None],
) -> None:
    own = Session(spec) if session is None and todo else None
    if own is not None:
        session = own
    pool = ChunkPool(jobs) if jobs > 1 and any(it.kind == "video" for _, it, _ in todo) else None
    try:
        for k, it, fp in todo:
            finished(k, process_item(spec, it, outdir, opts, save_mask, fp, session=session, pool=pool))
    finally:
        if pool is not None:
            pool.close()
        if own is not None:
            own.close()


def _run_dask(
    client: Client,
    spec: SceneSpec,
    items: list[BatchItem],
    todo: list[Todo],
    outdir: Path,
    opts: EngineOptions,
    save_mask: bool,
    jobs: int,
    finished: Callable[[int, Summary], None],
) -> None:
    from distributed import (
        as_completed,  # deferred: Dask is an optional extra (arshadow[dask])
    )

    chunks = jobs if jobs > 1 else max(1, len(client.scheduler_info().get("workers", {})))
    futs = {_submit_dask(client, spec, it, outdir, opts, save_mask, fp, chunks): k for k, it, fp in todo}
    for fut in as_completed(futs):
        k = futs[fut]
        try:
            res: Summary = fut.result()
        except BatchStoppedError:
            raise
        except Exception as exc:  # noqa: BLE001 (a worker died or the task failed outside process_item)
            _stop_if_lost(client, exc, outdir)
            it = items[k]
            res = {
                "input": it.input,
                "kind": it.kind,
                "stem": it.stem,
                "status": "error",
                "error": f"{it.input}: task failed on the cluster ({type(exc).__name__}: {exc})",
                "outputs": [],
                "warnings": [],
            }
        finished(k, res)
