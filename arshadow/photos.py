"""The photo loop: inputs -> a session -> upright outputs and report items, one photo's failure not stopping
the others. ``arshadow render``, ``arshadow batch`` (its photos) and ``arshadow demo`` all go through it.

::

    from arshadow.photos import expand_inputs, photo_jobs, render_photos

    jobs = photo_jobs(expand_inputs(["shots/"]), Path("out"), save_mask=True)
    with Session(spec) as session:
        items = render_photos(session, jobs)          # ReportItem per photo (status ok / no_marker / error)

Per photo (:func:`render_photo_file`): the overwrite guard (an output never replaces an input), the photo
read as stored with its EXIF orientation noted (it is processed in the calibration's frame), one output
buffer per photo size reused (the result is encoded at once), the composite and mask turned upright as a
viewer shows the input (the outputs carry no EXIF), JPEG / WebP written at quality 95.
"""

from __future__ import annotations

import functools
import glob
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from .errors import ArshadowError, MarkerNotFoundError
from .export.layerfiles import check_layer_format, layer_paths, write_layers
from .export.stmap import stmap, write_stmap
from .frame.report import ReportItem
from .io import (
    IMAGE_EXTENSIONS,
    InputGuard,
    apply_orientation,
    exif_orientation,
    read_image,
    unique_stems,
    write_image,
)

if TYPE_CHECKING:
    from .frame.result import FrameResult
    from .frame.session import Session
    from .tracking.pose import MarkerPose
    from .tracking.tracker import MarkerTracker

__all__ = [
    "PhotoJob",
    "expand_inputs",
    "photo_jobs",
    "render_photo_file",
    "render_photos",
    "write_params",
    "track_photos",
    "pose_overlay",
    "contact_sheet",
    "caption_panel",
]


@dataclass(frozen=True)
class PhotoJob:
    """One photo and where its outputs go (``mask`` None: no mask written).

    ``layers``: ``{name: Path}`` of the compositing layer files (:func:`arshadow.export.layerfiles.layer_paths`,
    in ``layers_format``; with ``undistorted.*`` names and ``stmap`` also the pinhole versions), or None.
    """

    input: str
    output: Path
    mask: Path | None = None
    layers: dict | None = None
    layers_format: str = "png"

    @property
    def outputs(self) -> list[Path]:
        """Every file the job writes."""
        return [self.output, *([self.mask] if self.mask is not None else []), *(self.layers or {}).values()]


#: the middle of the name of arshadow's own per-photo outputs other than the composite: the shadow mask
#: ``<stem>.shadow.png`` and the layer files ``<stem>.<layer>.<png|exr>`` (arshadow.export.layerfiles)
OWN_OUTPUT_PARTS = ("shadow", "object", "shadow.mult", "shadow.only", "stmap", "undistorted")


def own_outputs(files: Sequence[str | Path]) -> set[str]:
    """Those of ``files`` (one folder's images) that are arshadow's own outputs: shadow masks and layer
    files (:data:`OWN_OUTPUT_PARTS`), and the composites ``<stem>.png`` / ``<stem>_N.png`` of a photo
    ``<stem>.<other extension>`` in the same list.

    >>> sorted(own_outputs(["d/a.jpg", "d/a.png", "d/a_2.png", "d/a.shadow.png", "d/b.png", "d/c.object.exr"]))
    ['d/a.png', 'd/a.shadow.png', 'd/a_2.png', 'd/c.object.exr']
    """
    paths = [Path(f) for f in files]
    sources = {p.stem for p in paths if p.suffix.lower() != ".png"}
    out: set[str] = set()
    for f, p in zip(files, paths, strict=True):
        middle = p.stem.split(".", 1)[1] if "." in p.stem else ""
        base = p.stem.rsplit("_", 1)[0] if p.stem.rsplit("_", 1)[-1].isdigit() else p.stem
        if any(middle == m or middle.startswith(m + ".") for m in OWN_OUTPUT_PARTS):
            out.add(str(f))
        elif p.suffix.lower() == ".png" and (p.stem in sources or base in sources):
            out.add(str(f))
    return out


def expand_inputs(items: Iterable[str], skipped: list[str] | None = None) -> list[str]:
    """Files as given; folders -> their image files (sorted, :data:`arshadow.io.IMAGE_EXTENSIONS`), less
    arshadow's own outputs (:func:`own_outputs`, appended to ``skipped`` when given: an earlier run's
    masks and composites are not photos); glob patterns -> matches (sorted). Anything that matches nothing
    is kept as given, so that reading it reports the problem."""
    out: list[str] = []
    for it in items:
        p = Path(it)
        if p.is_dir():
            files = sorted(str(f) for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_EXTENSIONS)
            own = own_outputs(files)
            if skipped is not None:
                skipped.extend(f for f in files if f in own)
            files = [f for f in files if f not in own]
            out.extend(files if files else [it])
        elif not p.exists() and any(c in it for c in "*?["):
            matches = sorted(m for m in glob.glob(it) if Path(m).is_file())
            out.extend(matches if matches else [it])
        else:
            out.append(it)
    return out


def photo_jobs(
    inputs: Sequence[Path | str],
    outdir: Path | str,
    *,
    save_mask: bool = False,
    keep_format: bool = False,
    layers_format: str | None = None,
    layers_undistorted: bool = False,
) -> list[PhotoJob]:
    """A :class:`PhotoJob` per input: ``DIR/<stem>.png`` (the input's format with ``keep_format``),
    ``DIR/<stem>.shadow.png`` and with ``layers_format`` (``png`` / ``exr``) the layer files; stems that
    collide get ``_2``, ``_3``... (:func:`arshadow.io.unique_stems`).

    Raises
    ------
    UsageError
        ``layers_format`` exr without an OpenEXR writer.
    """
    outdir = Path(outdir)
    if layers_format is not None:
        check_layer_format(layers_format)
    jobs = []
    for inp, stem in zip(inputs, unique_stems(inputs), strict=True):
        suffix = Path(inp).suffix.lower()
        ext = suffix if keep_format and suffix in IMAGE_EXTENSIONS else ".png"
        lay = None if layers_format is None else layer_paths(outdir, stem, layers_format, layers_undistorted)
        jobs.append(
            PhotoJob(
                str(inp),
                outdir / f"{stem}{ext}",
                outdir / f"{stem}.shadow.png" if save_mask else None,
                lay,
                layers_format or "png",
            )
        )
    return jobs


def write_params(path: Path | str) -> list[int] | None:
    """``cv2.imwrite`` parameters for an output: quality 95 for JPEG and WebP, else None."""
    ext = Path(path).suffix.lower()
    if ext in (".jpg", ".jpeg", ".jpe"):
        return [int(cv2.IMWRITE_JPEG_QUALITY), 95]
    if ext == ".webp":
        return [int(cv2.IMWRITE_WEBP_QUALITY), 95]
    return None


def render_photo_file(
    session: Session, job: PhotoJob, *, buffers: dict[tuple[int, int], Any] | None = None
) -> FrameResult:
    """Render one photo file and write its outputs (atomically, upright).

    Parameters
    ----------
    session : arshadow.frame.session.Session
    job : PhotoJob
    buffers : dict, optional
        ``{(H, W): (composite, mask)}`` output buffers reused per photo size (filled as needed).

    Returns
    -------
    arshadow.frame.session.FrameResult
        Its ``item`` has ``output`` (and ``mask``) set; ``composite`` / ``mask`` are in the stored
        orientation (and are the reused buffers).

    Raises
    ------
    MarkerNotFoundError, ArshadowError, OSError, cv2.error
        As :meth:`arshadow.frame.session.Session.process` and the reading / writing.
    """
    image = read_image(job.input)
    orientation = exif_orientation(job.input)  # processed as stored (the calibration's frame)
    out = mask_out = None
    if buffers is not None:
        out, mask_out = buffers.setdefault(
            image.shape[:2], (np.empty(image.shape, np.uint8), np.empty(image.shape[:2], np.uint8))
        )
    want_layers = False if job.layers is None else "undistorted" if "stmap" in job.layers else True
    res = session.process(
        image, name=job.input, want_mask=job.mask is not None, out=out, mask_out=mask_out, layers=want_layers
    )
    # outputs upright as a viewer shows the input (EXIF orientation; they carry no EXIF)
    res.item.output = str(
        write_image(job.output, apply_orientation(res.composite, orientation), write_params(job.output))
    )
    if job.mask is not None:
        assert res.mask is not None  # asked for (want_mask)
        res.item.mask = str(write_image(job.mask, apply_orientation(res.mask, orientation)))
    if job.layers is not None:
        assert res.layers is not None  # asked for (layers=)
        write_layers(
            job.layers,
            res.layers,
            job.layers_format,
            orient=functools.partial(apply_orientation, orientation=orientation),
        )
        if "stmap" in job.layers:  # the pinhole layers' distortion map (stored frame, as they are)
            cal = session.hooks.calibration(image.shape[1], image.shape[0])
            write_stmap(job.layers["stmap"], stmap(cal.intrinsics, None if cal.lens is None else cal.lens.maps))
        res.item.layers = {n: str(p) for n, p in job.layers.items()}
    return res


#: ``on_done(job, item, result or None, error or None)`` after each photo (printing, thumbnails)
OnDone = Callable[[PhotoJob, ReportItem, "FrameResult | None", BaseException | None], None]


def render_photos(
    session: Session,
    jobs: Sequence[PhotoJob],
    *,
    debug: bool = False,
    on_done: OnDone | None = None,
    guard: InputGuard | None = None,
) -> list[ReportItem]:
    """Render every photo; a photo that fails is recorded (``status`` ``no_marker`` or ``error``, with
    ``error``) and the others go on.

    Parameters
    ----------
    session : arshadow.frame.session.Session
    jobs : list of PhotoJob
    debug : bool
        Re-raise errors other than a missing marker (tracebacks).
    on_done : callable, optional
        Called after each photo (:data:`OnDone`).
    guard : arshadow.io.InputGuard, optional
        Default: the jobs' inputs (an output that would replace one is an error of that photo).

    Returns
    -------
    list of ReportItem
        One per job, in order.
    """
    guard = guard if guard is not None else InputGuard([j.input for j in jobs])
    buffers: dict[tuple[int, int], Any] = {}
    items: list[ReportItem] = []
    for job in jobs:
        t0 = time.perf_counter()
        res = None
        err: BaseException | None = None
        try:
            guard.check(job.outputs)
            res = render_photo_file(session, job, buffers=buffers)
            item = res.item
        except MarkerNotFoundError as exc:
            err, item = exc, ReportItem(input=job.input, status="no_marker", error=str(exc))
        except (ArshadowError, OSError, MemoryError, cv2.error) as exc:  # cv2.error: a decoder the checks missed
            if debug:
                raise
            msg = str(exc) if isinstance(exc, ArshadowError) else f"{type(exc).__name__}: {exc}"
            err, item = exc, ReportItem(input=job.input, status="error", error=msg)
        if err is not None:
            item.timings_ms = {"total": round((time.perf_counter() - t0) * 1e3, 3)}
        items.append(item)
        if on_done is not None:
            on_done(job, item, res, err)
    return items


def track_photos(
    tracker: MarkerTracker,
    inputs: Sequence[Path | str],
    *,
    overlay_dir: Path | str | None = None,
    on_done: Callable[[str, ReportItem, Any, np.ndarray | None, BaseException | None], None] | None = None,
) -> list[ReportItem]:
    """The pose of the marker / board in each photo (``arshadow pose``): a report item per photo with the
    pose keys, ``n_points``, ``kind``, ``calibration_scaled`` and ``timings_ms`` (``read``, ``detect``,
    ``pose``, ``total``); a photo that fails is recorded (``no_marker`` / ``error``) and the others go on.

    Parameters
    ----------
    tracker : arshadow.tracking.tracker.MarkerTracker
    inputs : list of str
    overlay_dir : str or Path, optional
        Write ``<stem>.png`` (:func:`pose_overlay`) there; the item's ``output`` names it.
    on_done : callable, optional
        ``on_done(input, item, pose or None, image or None, error or None)`` after each photo.
    """
    items = []
    stems = unique_stems(inputs)
    for name, stem in zip(inputs, stems, strict=True):
        item = ReportItem(input=str(name))
        t0 = time.perf_counter()
        pose = image = err = None
        try:
            image = read_image(name)
            t1 = time.perf_counter()
            pose = tracker.estimate(image)
            t2 = time.perf_counter()
            item.set_pose(pose)
            item.n_points, item.kind, item.calibration_scaled = int(pose.n_points), pose.kind, bool(pose.scaled)
            if overlay_dir is not None:
                item.output = str(write_image(Path(overlay_dir) / f"{stem}.png", pose_overlay(image, pose, tracker)))
            item.timings_ms = {
                "read": 1e3 * (t1 - t0),
                "detect": pose.timings_ms.get("detect", 1e3 * (t2 - t1)),
                "pose": pose.timings_ms.get("pose", 0.0),
                "total": 1e3 * (time.perf_counter() - t0),
            }
        except ArshadowError as exc:
            err = exc
            item.status = "no_marker" if isinstance(exc, MarkerNotFoundError) else "error"
            item.error = str(exc)
            item.timings_ms = {"total": 1e3 * (time.perf_counter() - t0)}
        items.append(item)
        if on_done is not None:
            on_done(str(name), item, pose, image, err)
    return items


def pose_overlay(image: np.ndarray, pose: MarkerPose, tracker: MarkerTracker) -> np.ndarray:
    """A copy of ``image`` with the detected markers and the world axes drawn (``arshadow pose --overlay``)."""
    img = image.copy()
    ids = list(pose.all_corners)
    if ids:
        cv2.aruco.drawDetectedMarkers(
            img,
            [c.reshape(1, 4, 2).astype(np.float32) for c in pose.all_corners.values()],
            np.asarray(ids, np.int32).reshape(-1, 1),
        )
    intr = pose.intrinsics
    assert intr is not None  # a pose the tracker estimated has its camera
    if tracker.board is not None:
        length = 0.5 * min(tracker.board.extent)
    else:
        length = 0.75 * tracker.marker_length
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)  # "axes out of frame" is not an error
    try:
        cv2.drawFrameAxes(img, intr.K, intr.dist_cv, pose.rvec.reshape(3, 1), pose.tvec.reshape(3, 1), length, 2)
    finally:
        cv2.utils.logging.setLogLevel(level)
    return img


def contact_sheet(tiles: Sequence[np.ndarray], columns: int, gap: int, background: int) -> np.ndarray:
    """Tile equally sized ``(h, w, 3) uint8`` images row by row, ``gap`` pixels apart and around, on a
    grey ``background``; the one contact sheet of the package (the demo's, a video's).

    >>> contact_sheet([np.zeros((2, 3, 3), np.uint8)] * 3, columns=2, gap=1, background=9).shape
    (7, 9, 3)
    """
    th, tw = tiles[0].shape[:2]
    rows = (len(tiles) + columns - 1) // columns
    sheet = np.full((rows * th + (rows + 1) * gap, columns * tw + (columns + 1) * gap, 3), background, np.uint8)
    for i, t in enumerate(tiles):
        r, c = divmod(i, columns)
        y, x = gap + r * (th + gap), gap + c * (tw + gap)
        sheet[y : y + th, x : x + tw] = t
    return sheet


def caption_panel(image: np.ndarray, caption: str, width: int = 640, height: int = 360, bar: int = 30) -> np.ndarray:
    """A ``width x height`` thumbnail of ``image`` with a dark caption bar of ``bar`` pixels below it."""
    th = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    strip = np.full((bar, width, 3), 32, np.uint8)
    cv2.putText(strip, caption, (8, bar - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (235, 235, 235), 1, cv2.LINE_AA)
    return np.vstack([th, strip])
