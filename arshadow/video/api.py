"""The video entry point of the API: :func:`process_video` composites a scene into videos (what
``arshadow video`` runs; the CLI only parses its arguments, calls this and prints).

A video run is one :class:`arshadow.frame.session.Session` of the scene (tracking near the last detection first:
``RenderOptions.track_roi``), the engine's backend over it
(:class:`arshadow.video.framejob.SessionBackend`), and :func:`arshadow.video.runner.run_videos` over the
inputs: one after another, each in one piece or cut at keyframes into ``jobs`` chunks processed by worker
processes (:mod:`arshadow.video.chunks`). A failed video is recorded in its summary and the others go on.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import UsageError
from ..frame.report import ReportItem, jsonable, make_report
from ..io import check_output_folder
from ..scene.spec import SceneSpec, load_scene, scene_from_dict
from .encode import ProgressFactory as EncodeProgressFactory
from .engine import EngineOptions, SessionBackend, video_outputs
from .scan import time_lapse_warnings

__all__ = ["VideoRun", "process_video"]

log = logging.getLogger("arshadow.video")

#: ``progress(input) -> (update(done, total), close())`` per video (a progress bar), or None
ProgressFactory = EncodeProgressFactory


@dataclass
class VideoRun:
    """What :func:`process_video` returns.

    Attributes
    ----------
    summaries : list of dict
        One per input, in order: ``status`` (``"ok"``, ``"error"`` with ``error``, ...), ``input``,
        ``output``, ``frames``, ``frames_ok`` / ``frames_held`` / ``frames_no_marker``, ``fps_processed``,
        ``warnings`` (the sun-set warning of a time-lapse first), ... (docs/video.md).
    items : list of arshadow.frame.report.ReportItem or dict
        Every frame's report item when ``EngineOptions.collect_items`` (else empty); a video run in chunks
        (``jobs > 1``) gives its items as their dicts (:meth:`ReportItem.to_dict`, read back from the chunks).
    warnings : dict
        ``{input: message}``: a sun that sets during the input's time-lapse, found before any frame.
    """

    summaries: list[dict[str, Any]]
    items: list[ReportItem | dict[str, Any]] = field(default_factory=list)
    warnings: dict[str, str] = field(default_factory=dict)

    @property
    def failed(self) -> int:
        """Inputs whose status is not ``"ok"``."""
        return sum(1 for s in self.summaries if s["status"] != "ok")

    def report(self) -> dict[str, Any]:
        """The JSON report (``arshadow video --report``): the frames' items and the ``videos`` summaries."""
        rep: dict[str, Any] = make_report(self.items)
        rep["videos"] = jsonable(self.summaries)
        return rep


def process_video(
    spec: SceneSpec | Mapping[str, Any] | str | os.PathLike[str],
    videos: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    output: str | os.PathLike[str],
    *,
    options: EngineOptions | None = None,
    jobs: int = 1,
    progress: ProgressFactory | None = None,
    warn: Callable[[str], None] | None = None,
    raise_errors: bool = False,
) -> VideoRun:
    """Composite the scene's object and its shadow into each video; write ``output/<stem>.<format>`` (and the
    mask, layers, contact sheet ``options`` ask for).

    Parameters
    ----------
    spec : arshadow.scene.SceneSpec, mapping or job file path
        The scene (:func:`arshadow.scene.scene_from_dict`, :func:`arshadow.scene.load_scene`). Videos are
        tracked near the last detection first (its options' ``track_roi`` is set, as ``arshadow video``
        does).
    videos : path or list of paths
    output : path
        Output folder (created if missing).
    options : arshadow.video.engine.EngineOptions, optional
        Format, codec, mask, temporal pose choice, frames, layers... (default: ``EngineOptions()``).
    jobs : int
        Worker processes per video (a video is cut at keyframes into ``jobs`` chunks); 1: in this process.
    progress : callable, optional
        ``progress(input) -> (update(done, total), close())`` per video (a progress bar).
    warn : callable, optional
        ``warn(message)`` for each warning found before any frame is processed (a sun that sets during a
        time-lapse); default: the ``arshadow.video`` logger.
    raise_errors : bool
        Re-raise a video's error instead of recording it and going on.

    Returns
    -------
    VideoRun

    Raises
    ------
    ArshadowError
        The scene does not load, or a bad output folder / ``jobs`` / layer file over an input (before any
        work).

    Examples
    --------
    >>> import tempfile, arshadow
    >>> from arshadow.demo.data import data_root
    >>> root = data_root()
    >>> spec = arshadow.scene_from_dict({"calib": str(root / "calib" / "synth_640x360.yml"), "marker_length": 0.05,
    ...                                  "model": "box:0.04,0.04,0.06", "lights": ["point:0.1,0.1,0.4"]})
    >>> run = arshadow.process_video(spec, root / "samples" / "video" / "orbit.mp4", tempfile.mkdtemp(),
    ...                              options=arshadow.EngineOptions(max_frames=5, contact_sheet=0))
    >>> s = run.summaries[0]
    >>> s["status"], s["frames"], s["frames_ok"], run.failed
    ('ok', 5, 5, 0)
    """
    from ..frame.session import Session  # deferred: the session loads the GL side on first render
    from .parallel import BackendRecipe
    from .runner import run_videos

    spec = _video_spec(spec)
    inputs = [os.fspath(videos)] if isinstance(videos, str | os.PathLike) else [os.fspath(v) for v in videos]
    opts = (options if options is not None else EngineOptions()).check()
    outdir = check_output_folder(os.fspath(output), "output")
    if int(jobs) < 1:
        raise UsageError(f"jobs {jobs}: must be >= 1")
    if opts.layers is not None:  # a layer file over an input: a usage error before any work
        _refuse_layer_overwrite(inputs, outdir, opts)
    say = warn if warn is not None else log.warning
    with Session(spec) as session:
        # before any frame is processed: a sun that sets during a time-lapse (the tracks are reset per video)
        sun_set = time_lapse_warnings(inputs, session.sun_tracks, session.time_lapse, opts.max_frames)
        for msg in sun_set.values():
            say(msg)
        backend = SessionBackend(session, session.sun_tracks, session.time_lapse)
        recipe = BackendRecipe(spec) if jobs > 1 else None  # workers rebuild the session from the spec

        def on_error(exc: BaseException) -> None:
            if raise_errors:
                raise exc

        summaries, items = run_videos(
            backend, inputs, outdir, opts, progress_factory=progress, on_error=on_error, jobs=int(jobs), recipe=recipe
        )
    for s in summaries:  # the summary says it too
        if s.get("input") in sun_set:
            s.setdefault("warnings", []).insert(0, sun_set[s["input"]])
    return VideoRun(summaries, items, sun_set)


def _video_spec(spec: SceneSpec | Mapping[str, Any] | str | os.PathLike[str]) -> SceneSpec:
    """The scene as a :class:`SceneSpec`, tracking near the last detection first (``track_roi``)."""
    if isinstance(spec, Mapping):
        spec = scene_from_dict(spec)
    elif not isinstance(spec, SceneSpec):
        spec = load_scene(os.fspath(spec))
    if spec.options.track_roi:
        return spec
    return dataclasses.replace(spec, options=dataclasses.replace(spec.options, track_roi=True))


def _refuse_layer_overwrite(inputs: list[str], outdir: Path, opts: EngineOptions) -> None:
    """A layer file that would replace an input: one usage error before any work."""
    from ..export.layerfiles import refuse_overwrite
    from ..io import unique_stems

    paths = [
        p
        for stem in unique_stems(inputs)
        for k, p in video_outputs(outdir, stem, opts).items()
        if k.startswith("layers:") and p is not None
    ]
    refuse_overwrite(paths, inputs)
