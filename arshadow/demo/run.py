"""The bundled demo: the sample photos of ``samples/`` (``scenes.json``) through the photo loop, a contact
sheet and a JSON report (``arshadow demo``; the API behind it)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import ArshadowError, UsageError
from ..frame.report import ReportItem, make_report
from ..frame.session import Session
from ..io import read_image, write_image, write_json
from ..photos import OnDone, PhotoJob, caption_panel, contact_sheet, render_photos
from ..scene.options import DEFAULT_AA
from ..scene.spec import scene_from_dict
from .data import samples_dir

if TYPE_CHECKING:
    import numpy as np

    from ..frame.result import FrameResult
    from ..gl.stencil import ShadowRenderer
    from ..scene.spec import SceneSpec

__all__ = ["find_samples", "scene_spec", "run_demo", "SCENE_JSON_KEYS"]

#: the keys of a samples/scenes.json entry that describe the scene (the rest: photo, title)
SCENE_JSON_KEYS = (
    "calib",
    "model",
    "scale",
    "rotate",
    "place",
    "color",
    "lights",
    "soft_samples",
    "marker_length",
    "dictionary",
    "marker_id",
)


def find_samples(explicit: Path | str | None = None) -> Path:
    """The samples folder: ``explicit``, else the bundled ``samples/`` (the repository's in a checkout, the
    installed copy otherwise: :func:`arshadow.demo.data.samples_dir`), else ``./samples``."""
    cands = [Path(explicit)] if explicit else [samples_dir(), Path("samples")]
    for c in cands:
        if (c / "scenes.json").is_file():
            return c
    raise UsageError(
        f"no samples found ({', '.join(str(c / 'scenes.json') for c in cands)} missing); "
        "run from the repository root or pass --samples DIR"
    )


def scene_spec(sc: dict[str, Any], root: Path, aa: int) -> SceneSpec:
    """The :class:`arshadow.scene.SceneSpec` of one ``scenes.json`` entry (paths relative to ``root``)."""
    d = {k: sc[k] for k in SCENE_JSON_KEYS if sc.get(k) is not None}
    d["soft_samples"] = int(sc.get("soft_samples", 1))
    d["aa"] = int(aa)
    return scene_from_dict(d, base_dir=root)


def run_demo(
    samples: Path, outdir: Path | str, *, aa: int = DEFAULT_AA, debug: bool = False, on_done: OnDone | None = None
) -> tuple[list[ReportItem], Path | None, list[str] | ArshadowError]:
    """Render every sample scene into ``outdir``: ``<stem>.png``, ``<stem>.shadow.png``, ``report.json`` and
    ``contact_sheet.png`` (the composites, then the first input photo).

    Parameters
    ----------
    samples : Path
        A folder with ``scenes.json`` (:func:`find_samples`).
    outdir : str or Path
    aa : int
        MSAA samples (default :data:`arshadow.scene.options.DEFAULT_AA`, as ``arshadow render``).
    debug : bool
        Re-raise errors (tracebacks).
    on_done : callable, optional
        As :func:`arshadow.photos.render_photos` (also for a scene that does not load: result None).

    Returns
    -------
    items : list of arshadow.frame.report.ReportItem
    sheet : Path or None
        The contact sheet (None when nothing was rendered).
    light : list of str or ArshadowError
        The measured-light item's lines (:func:`arshadow.demo.light.light_demo`: extra outputs), or its
        error.
    """
    # deferred: the GL context and renderer load only when the demo runs (the CLI imports this module)
    from ..gl.context import create_context
    from ..gl.stencil import ShadowRenderer
    from .light import light_demo

    root, outdir = samples.parent, Path(outdir)
    scenes = json.loads((samples / "scenes.json").read_text())["scenes"]
    items: list[ReportItem] = []
    panels: list[np.ndarray] = []
    ctx = create_context()
    try:
        with ShadowRenderer(ctx, samples=int(aa)) as renderer:
            for sc in scenes:
                items.append(_demo_scene(sc, samples, root, outdir, aa, ctx, renderer, panels, debug, on_done))
            first = samples / scenes[0]["photo"] if scenes else None
            if panels and first is not None and first.is_file():
                panels.append(caption_panel(read_image(first), f"input photo: {first.name} (before)"))
            light: list[str] | ArshadowError
            try:  # the measured-look item (the light estimate): extra outputs, the rest is unchanged
                light = light_demo(samples, outdir, context=ctx, renderer=renderer, aa=aa)
            except ArshadowError as exc:
                if debug:
                    raise
                light = exc
    finally:
        ctx.release()
    sheet = None
    if panels:
        sheet = write_image(outdir / "contact_sheet.png", contact_sheet(panels, columns=2, gap=6, background=16))
    write_json(outdir / "report.json", make_report(items))
    return items, sheet, light


def _demo_scene(
    sc: dict[str, Any],
    samples: Path,
    root: Path,
    outdir: Path,
    aa: int,
    ctx: Any,  # a moderngl.Context (only arshadow.gl imports moderngl)
    renderer: ShadowRenderer,
    panels: list[np.ndarray],
    debug: bool,
    on_done: OnDone | None,
) -> ReportItem:
    """One sample scene through the photo loop (its session sharing the context and renderer)."""
    stem = Path(sc["photo"]).stem
    title = sc.get("title", stem)
    job = PhotoJob(str(samples / sc["photo"]), outdir / f"{stem}.png", outdir / f"{stem}.shadow.png")

    def done(job: PhotoJob, item: ReportItem, res: FrameResult | None, err: BaseException | None) -> None:
        if res is not None:
            item.title = title
            panels.append(
                caption_panel(res.composite, f"{title}  |  {item.mode}, {item.silhouette_edges} silhouette edges")
            )
        if on_done is not None:
            on_done(job, item, res, err)

    try:
        session = Session(scene_spec(sc, root, aa), context=ctx, renderer=renderer)
    except ArshadowError as exc:
        if debug:
            raise
        item = ReportItem(input=job.input, status="error", error=str(exc))
        done(job, item, None, exc)
        return item
    with session:
        return render_photos(session, [job], debug=debug, on_done=done)[0]
