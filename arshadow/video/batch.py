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
per item; each worker builds its own :class:`arshadow.session.Session` (and OpenGL context) from the
picklable spec once and reuses it for its later items. Workers write into ``OUT_DIR`` directly, so it must
be a folder every worker sees (a shared file system); the outputs and records are the same as a local run.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import time
from pathlib import Path

import cv2

from .. import __version__
from ..errors import ArshadowError, MarkerNotFoundError, UsageError
from ..io import check_output_folder, read_image, resolved_path, write_image, write_json
from ..io import clean_temporaries as clean_io_temporaries
from ..session import Session
from .decode import looks_like_sequence
from .engine import SessionBackend, process_video, unique_stems, video_outputs

__all__ = ["VIDEO_EXTENSIONS", "BatchItem", "clean_temporaries", "plan_batch", "process_item", "run_batch"]

PHOTO_EXTENSIONS = {".jpg", ".jpeg", ".jpe", ".png", ".bmp", ".dib", ".tif", ".tiff", ".webp", ".jp2", ".pbm", ".pgm",
                    ".ppm", ".pnm", ".pxm", ".sr", ".ras", ".exr", ".hdr", ".pic", ".avif"}
VIDEO_EXTENSIONS = {".mp4", ".m4v", ".mov", ".mkv", ".avi", ".webm", ".mpg", ".mpeg", ".ts", ".mts", ".wmv", ".flv"}
RECORDS = ".arshadow-batch"


@dataclasses.dataclass(frozen=True)
class BatchItem:
    """One input of a batch: ``kind`` ``"photo"`` or ``"video"``, its output ``stem``."""

    input: str
    kind: str
    stem: str


def plan_batch(inputs) -> list[BatchItem]:
    """Classify inputs by extension (videos: :data:`VIDEO_EXTENSIONS`) and give each a unique stem."""
    inputs = [str(i) for i in inputs]
    if not inputs:
        raise UsageError("no input given")
    return [BatchItem(i, _kind(i), s) for i, s in zip(inputs, unique_stems(inputs))]


def _kind(path: str) -> str:
    """``"video"`` for a video extension or an image-sequence pattern; ``"photo"`` for an image extension;
    otherwise by content (what OpenCV's image readers recognise is a photo, anything else is tried as a
    video)."""
    ext = Path(path).suffix.lower()
    if ext in VIDEO_EXTENSIONS or looks_like_sequence(path):
        return "video"
    if ext in PHOTO_EXTENSIONS or not Path(path).is_file():
        return "photo"
    try:
        return "photo" if cv2.haveImageReader(path) else "video"
    except cv2.error:
        return "photo"


def _outputs(item: BatchItem, outdir: Path, opts, save_mask: bool) -> list:
    """The files an item writes (before its done record)."""
    if item.kind == "video":
        return [p for p in video_outputs(outdir, item.stem, opts).values() if p is not None]
    outs = [outdir / f"{item.stem}.png", *([outdir / f"{item.stem}.shadow.png"] if save_mask else [])]
    if opts.layers is not None:
        from ..export.layerfiles import layer_paths

        outs += list(layer_paths(outdir, item.stem, _photo_layers(opts), opts.layers_undistorted).values())
    return outs


def _photo_layers(opts) -> str:
    """The layer format of a batch's photos: EXR with ``--layers-format exr``, else 16-bit PNG."""
    return "exr" if opts.layers == "exr" else "png"


def _fingerprint(item: BatchItem, spec, opts, save_mask) -> str:
    """Input file identity (size, mtime) + scene + options: a changed input or setting redoes the item."""
    try:
        st = os.stat(item.input)
        ident = [st.st_size, st.st_mtime_ns]
    except OSError:
        ident = None
    blob = json.dumps([str(Path(item.input).resolve()), ident, repr(spec), repr(opts), save_mask, item.kind],
                      default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


def _record_path(outdir: Path, item: BatchItem) -> Path:
    return outdir / RECORDS / f"{item.stem}.json"


def clean_temporaries(outdir) -> int:
    """Remove the temporary files and folders an interrupted run left in ``outdir`` (``.NAME.*.tmp*``)."""
    d = Path(outdir)
    return clean_io_temporaries(d) + clean_io_temporaries(d / RECORDS)


def _done(outdir: Path, item: BatchItem, fp: str):
    """The item's done record when it matches and its outputs exist, else None."""
    p = _record_path(outdir, item)
    try:
        rec = json.loads(p.read_text(encoding="utf-8"))
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
_WORKER_SESSIONS: dict = {}


def _session_for(spec):
    """One Session per spec per process (a Dask worker keeps its GL context between items)."""
    key = repr(spec)
    s = _WORKER_SESSIONS.get(key)
    if s is None:
        for old in _WORKER_SESSIONS.values():
            old.close()
        _WORKER_SESSIONS.clear()
        s = _WORKER_SESSIONS[key] = Session(spec)
    return s


def process_item(spec, item: BatchItem, outdir, opts, save_mask: bool, fingerprint: str, session=None) -> dict:
    """Process one input and write its outputs and done record; returns the item's summary.

    Never raises for a bad input: the summary has ``status: "error"`` and ``error`` (nothing is recorded
    as done, so a rerun tries it again).
    """
    outdir = Path(outdir)
    t0 = time.perf_counter()
    summary = {"input": item.input, "kind": item.kind, "stem": item.stem, "status": "error", "error": None,
               "outputs": [], "warnings": []}
    try:
        session = session if session is not None else _session_for(spec)
        if item.kind == "video":
            outs = video_outputs(outdir, item.stem, opts)
            vs, _ = process_video(SessionBackend(session), item.input, outs, opts, name=item.input)
            summary.update({k: vs[k] for k in ("status", "warnings", "frames", "frames_ok", "frames_held",
                                               "frames_no_marker", "truncated", "decode_errors", "fps_processed")})
            summary["outputs"] = [str(p) for p in outs.values() if p is not None and Path(p).exists()]
        else:
            img = read_image(item.input)
            want = ("undistorted" if opts.layers_undistorted else True) if opts.layers is not None else False
            res = session.process(img, name=item.input, want_mask=save_mask, layers=want)
            out = write_image(outdir / f"{item.stem}.png", res.composite)
            summary["outputs"] = [str(out)]
            if opts.layers is not None:
                from ..export.layerfiles import layer_paths, write_layers
                from ..export.stmap import stmap, write_stmap

                fmt = _photo_layers(opts)
                paths = write_layers(layer_paths(outdir, item.stem, fmt, opts.layers_undistorted), res.layers, fmt)
                if "stmap" in paths:
                    cal = session.calibration(img.shape[1], img.shape[0])
                    write_stmap(paths["stmap"], stmap(cal.intrinsics, None if cal.lens is None else cal.lens.maps))
                summary["outputs"] += [str(p) for p in paths.values()]
            if save_mask:
                summary["outputs"].append(str(write_image(outdir / f"{item.stem}.shadow.png", res.mask)))
            summary["status"] = "ok"
            res.item.output = str(out)  # the report item names the files too (it said output: null)
            res.item.mask = summary["outputs"][1] if save_mask else None
            if res.item.flag_reasons:  # issue 20: a flagged pose is said (its reasons also in the item)
                summary["warnings"].append(f"{item.input}: flagged pose: {'; '.join(res.item.flag_reasons)}")
            summary["item"] = res.item.to_dict()
    except MarkerNotFoundError as exc:  # a photo without the marker: done (a rerun would find none either)
        summary["status"] = "no_marker"
        summary["error"] = f"{item.input}: {exc}"
    except (ArshadowError, OSError, MemoryError) as exc:
        summary["status"] = "error"
        summary["error"] = str(exc) if isinstance(exc, ArshadowError) else f"{type(exc).__name__}: {exc}"
        if item.input not in summary["error"]:
            summary["error"] = f"{item.input}: {summary['error']}"
    summary["seconds"] = round(time.perf_counter() - t0, 3)
    if summary["status"] in ("ok", "no_marker", "damaged"):
        # written last: the item counts as done only once every output is in place
        write_json(_record_path(outdir, item), {"fingerprint": fingerprint, **summary})
    return summary


def _dask_task(spec, item, outdir, opts, save_mask, fingerprint):
    return process_item(spec, item, outdir, opts, save_mask, fingerprint)


# --------------------------------------------------------------------------------------------------
# the batch
# --------------------------------------------------------------------------------------------------
def run_batch(spec, inputs, outdir, opts, *, save_mask: bool = False, client=None, progress=None,
              session=None) -> dict:
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
        Run the items on this Dask cluster (one task per item) instead of in this process.
    progress : callable, optional
        ``progress(done, total, summary)`` after each item.
    session : arshadow.session.Session, optional
        Local runs: use this session (else one is made).

    Returns
    -------
    dict
        ``{"arshadow": VERSION, "items": [...], "counts": {...}}``; each item has ``status`` (``ok``,
        ``no_marker``, ``damaged``, ``error``) and ``skipped`` (done by an earlier run).
    """
    outdir = check_output_folder(outdir, "-o")
    (outdir / RECORDS).mkdir(parents=True, exist_ok=True)
    clean_temporaries(outdir)
    items = plan_batch(inputs)
    results: list = [None] * len(items)
    todo = []
    given = {resolved_path(i) for i in inputs}
    for k, it in enumerate(items):
        clash = [p for p in _outputs(it, outdir, opts, save_mask) if resolved_path(p) in given]
        if clash:  # inputs are never modified
            results[k] = {"input": it.input, "kind": it.kind, "stem": it.stem, "status": "error", "skipped": False,
                          "error": f"{clash[0]}: output would overwrite an input; choose another -o folder",
                          "outputs": [], "warnings": []}
            continue
        fp = _fingerprint(it, spec, opts, save_mask)
        rec = _done(outdir, it, fp)
        if rec is not None:
            rec.pop("fingerprint", None)
            results[k] = {**rec, "skipped": True}
        else:
            todo.append((k, it, fp))
    done = len(items) - len(todo)
    if progress is not None:
        for r in results:
            if r is not None and r["status"] == "error":
                progress(done, len(items), r)
        if done:
            progress(done, len(items), None)
    try:
        _run_todo(spec, items, todo, results, done, outdir, opts, save_mask, client, progress, session)
    except KeyboardInterrupt:  # Ctrl-C / SIGTERM: batch.json still says what is done and what is not
        _write_summary(outdir, items, results, interrupted=True)
        raise
    return _write_summary(outdir, items, results)


def _write_summary(outdir: Path, items, results, interrupted: bool = False) -> dict:
    """``OUT_DIR/batch.json``; after an interruption the items not finished are ``status: "pending"``."""
    results = [r if r is not None else {"input": it.input, "kind": it.kind, "stem": it.stem, "status": "pending",
                                        "skipped": False, "error": None, "outputs": [], "warnings": []}
               for it, r in zip(items, results)]
    counts: dict = {}
    for r in results:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    counts["skipped"] = sum(bool(r.get("skipped")) for r in results)
    summary = {"arshadow": __version__, "items": results, "counts": counts}
    if interrupted:
        summary["interrupted"] = True  # rerun the same command to finish the pending items
    write_json(outdir / "batch.json", summary)
    return summary


def _run_todo(spec, items, todo, results, done, outdir, opts, save_mask, client, progress, session) -> None:
    """Process the items not done yet, filling ``results`` in place (locally or on a Dask cluster)."""
    if client is None:
        own = session is None and todo
        if own:
            session = Session(spec)
        try:
            for k, it, fp in todo:
                results[k] = {**process_item(spec, it, outdir, opts, save_mask, fp, session=session),
                              "skipped": False}
                done += 1
                if progress is not None:
                    progress(done, len(items), results[k])
        finally:
            if own:
                session.close()
    else:
        from distributed import (
            as_completed,  # deferred: Dask is an optional extra (arshadow[dask])
        )

        futs = {client.submit(_dask_task, spec, it, str(outdir), opts, save_mask, fp, pure=False,
                              key=f"arshadow-{it.stem}-{fp[:12]}"): k for k, it, fp in todo}
        for fut in as_completed(futs):
            k = futs[fut]
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 (a worker died or the task failed outside process_item)
                it = items[k]
                res = {"input": it.input, "kind": it.kind, "stem": it.stem, "status": "error",
                       "error": f"{it.input}: task failed on the cluster ({type(exc).__name__}: {exc})",
                       "outputs": [], "warnings": []}
            results[k] = {**res, "skipped": False}
            done += 1
            if progress is not None:
                progress(done, len(items), results[k])
