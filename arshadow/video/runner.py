"""Several videos, one after another, each in one piece (:func:`arshadow.video.engine.process_video`) or, with
``jobs > 1``, in chunks on local worker processes (:mod:`arshadow.video.parallel`)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..errors import ArshadowError, ImageError
from ..frame.report import ReportItem
from ..io import InputGuard, clean_temporaries
from .encode import Progress, ProgressFactory
from .engine import EngineOptions, SessionBackend, process_video, unique_stems, video_outputs
from .parallel import BackendRecipe, ChunkPool, process_video_chunked

__all__ = ["run_videos"]


def run_videos(
    backend: SessionBackend,
    inputs: Sequence[str],
    outdir: Path,
    opts: EngineOptions,
    *,
    progress_factory: ProgressFactory | None = None,
    on_error: Callable[[BaseException], None] | None = None,
    jobs: int = 1,
    recipe: BackendRecipe | None = None,
) -> tuple[list[dict[str, Any]], list[ReportItem | dict[str, Any]]]:
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
    jobs : int
        Worker processes per video (``--jobs``): a video is cut at keyframes into ``jobs`` chunks
        (:mod:`arshadow.video.chunks`); 1: in this process, in one piece.
    recipe : arshadow.video.parallel.BackendRecipe, optional
        How a worker builds ``backend`` (needed with ``jobs > 1``).

    Returns
    -------
    summaries : list of dict
        One per input (:func:`process_video`'s, or ``status: "error"`` with ``error``).
    items : list of ReportItem or dict
        Per-frame items when ``opts.collect_items`` (a video run in chunks: their dicts); an unreadable video
        has one item with ``frame: None``.
    """
    summaries: list[dict[str, Any]] = []
    items: list[ReportItem | dict[str, Any]] = []
    given = InputGuard(inputs)  # outputs never replace an input
    pool = ChunkPool(jobs) if jobs > 1 and recipe is not None else None
    try:
        for inp, stem in zip(inputs, unique_stems(inputs), strict=True):
            summary, its = _one_video(backend, pool, recipe, inp, stem, outdir, opts, given, progress_factory, on_error)
            summaries.append(summary)
            items.extend(its)
    finally:
        if pool is not None:
            pool.close()
    return summaries, items


def _one_video(
    backend: SessionBackend,
    pool: ChunkPool | None,
    recipe: BackendRecipe | None,
    inp: str | os.PathLike[str],
    stem: str,
    outdir: Path,
    opts: EngineOptions,
    given: InputGuard,
    progress_factory: ProgressFactory | None,
    on_error: Callable[[BaseException], None] | None,
) -> tuple[dict[str, Any], Sequence[ReportItem | dict[str, Any]]]:
    outs = video_outputs(outdir, stem, opts)
    close: Callable[[], object] | None = None
    try:
        given.check(outs.values())
        clean_temporaries(outdir, stem)  # left by a run killed while writing this video
        update: Progress | None = None
        if progress_factory is not None:
            update, close = progress_factory(str(inp))
        summary: dict[str, Any] | None = None
        note: str | None = None
        if pool is not None:
            assert recipe is not None  # the pool is made with a recipe (run_videos)
            try:
                summary, note = process_video_chunked(
                    recipe, pool, inp, outs, opts, outdir=outdir, stem=stem, name=str(inp), progress=update
                )
            except ImageError as exc:  # e.g. a damaged packet: the one-piece run reports and skips it
                summary, note = None, f"not cut into chunks ({exc})"
        its: Sequence[ReportItem | dict[str, Any]]
        if summary is None:
            summary, its = process_video(backend, inp, outs, opts, progress=update, name=str(inp))
            if note:
                summary["warnings"].insert(0, note)
        else:
            its = summary.pop("items", None) or []  # the chunks' own items (opts.collect_items), in order
        return summary, its
    except (ArshadowError, OSError, MemoryError) as exc:
        if on_error is not None:
            on_error(exc)
        msg = str(exc) if isinstance(exc, ArshadowError) else f"{type(exc).__name__}: {exc}"
        if str(inp) not in msg:
            msg = f"{inp}: {msg}"
        summary = {"input": str(inp), "output": None, "mask": None, "status": "error", "error": msg, "warnings": []}
        return summary, [ReportItem(input=str(inp), status="error", error=msg)]
    finally:
        if close is not None:
            close()
