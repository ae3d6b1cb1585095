"""The parts of a :class:`arshadow.session.Session` that are per photo size or per tracker: public names the
session uses, kept apart so that the session module stays the façade.

- :class:`CalibrationState`: per photo size, the scaled intrinsics, the lens warp, and the trackers (made on
  first use: a session that only renders at given poses never builds one);
- :func:`estimate_pose`: the fast detection pass, then the full search if it finds nothing, with stage times;
- :func:`check_image`: the one image check of the API;
- :func:`default_renderer`: the renderer :class:`arshadow.scene.RenderOptions` ask for.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .errors import ImageError, MarkerNotFoundError
from .report import StageTimings
from .scene import RenderOptions
from .tracking.reference import ReferenceLock
from .tracking.tracker import MarkerTracker

if TYPE_CHECKING:  # annotations only
    from .camera import Intrinsics
    from .compose.lens import LensWarp

__all__ = ["CalibrationState", "estimate_pose", "check_image", "default_renderer", "DETECT_NOTES"]

#: the report's ``plan.detect``: where the tracker searched (``MarkerTracker.last_search``)
DETECT_NOTES = {
    "window": "window around the last detection",
    "full": "whole frame (no window yet, or nothing found in it)",
}


@dataclass
class CalibrationState:
    """Per photo size: scaled intrinsics, lens warp, trackers.

    Attributes
    ----------
    intrinsics : arshadow.camera.Intrinsics
        Scaled to the size.
    was_scaled : bool
    lens : arshadow.compose.lens.LensWarp or None
        None without distortion.
    tracker_kwargs : dict
        Keyword arguments of :class:`arshadow.tracking.tracker.MarkerTracker` (the scene's).
    track_roi : bool
        Trackers search a window around their last detection first (video).
    fast_detect : bool
        A fast first pass (``detector="fast"``) before the full search.
    """

    intrinsics: Intrinsics
    was_scaled: bool
    lens: LensWarp | None
    tracker_kwargs: dict
    track_roi: bool = False
    fast_detect: bool = False
    _trackers: tuple | None = None

    def trackers(self) -> tuple:
        """``(fast or None, full)`` :class:`~arshadow.tracking.tracker.MarkerTracker` (made on first use)."""
        if self._trackers is None:
            kw, roi = self.tracker_kwargs, self.track_roi
            # video: one reference marker for the whole video (issue 26), shared by both trackers
            ref = ReferenceLock() if roi else None
            full = MarkerTracker(self.intrinsics, **kw, track_roi=roi, reference=ref)
            fast = None
            if self.fast_detect and "detector_params" not in kw:
                fast = MarkerTracker(self.intrinsics, **kw, detector="fast", track_roi=roi, reference=ref)
            self._trackers = (fast, full)
        return self._trackers

    def reset_trackers(self) -> None:
        """Forget the frames tracked so far (a new video)."""
        for t in self._trackers or ():
            if t is not None:
                t.reset()
                if t.reference is not None:
                    t.reference.reset()

    def tracker_state(self) -> list:
        """:meth:`~arshadow.tracking.tracker.MarkerTracker.state` of the trackers made so far (fast, full)."""
        return [None if t is None else t.state() for t in (self._trackers or ())]

    def detect_note(self) -> str | None:
        """Where the last search looked (:data:`DETECT_NOTES`), None without a tracking window."""
        det = [t.last_search for t in (self._trackers or ()) if t is not None]
        if not any(isinstance(d, str) for d in det):
            return None
        return DETECT_NOTES["window" if "window" in det else "full"]


def estimate_pose(cal: CalibrationState, image, timings: StageTimings):
    """Marker / board pose of one image: the fast pass, then the full search if it finds nothing.

    Parameters
    ----------
    cal : CalibrationState
        Of the image's size.
    image : (H, W, 3) or (H, W) uint8
        BGR or grey.
    timings : StageTimings
        ``detect`` and ``pose`` are added to.

    Returns
    -------
    pose : arshadow.tracking.pose.MarkerPose
    detector : str or None
        ``"full (fast pass found nothing)"`` when the fallback ran (the report's ``detector``).

    Raises
    ------
    MarkerNotFoundError
    """
    fast, full = cal.trackers()
    note = None
    if fast is not None:
        try:
            pose = _timed_estimate(fast, image, timings)
        except MarkerNotFoundError:
            note = "full (fast pass found nothing)"
        else:
            # found: the full search's memory (its last window, its misses in a row) is stale; forgotten, so
            # that its next search depends on no frame before this one (a video's chunks compare this state)
            full.reset()
            return pose, None
    return _timed_estimate(full, image, timings), note


def _timed_estimate(tracker, image, timings: StageTimings):
    t = time.perf_counter()
    pose = tracker.estimate(image)
    total = (time.perf_counter() - t) * 1e3
    # the tracker splits its own time into marker search and pose (MarkerPose.timings_ms)
    pose_ms = float((getattr(pose, "timings_ms", None) or {}).get("pose", 0.0))
    timings.detect += total - pose_ms
    timings.pose += pose_ms
    return pose


def check_image(image, name: str = "", grey_ok: bool = False) -> np.ndarray:
    """``image`` as an ``(H, W, 3) uint8`` BGR array (or ``(H, W) uint8`` grey with ``grey_ok``), or an
    :class:`ImageError` naming ``name``.

    >>> check_image(np.zeros((2, 3, 3), np.uint8)).shape
    (2, 3, 3)
    """
    image = np.asarray(image)
    ok = image.dtype == np.uint8 and ((image.ndim == 3 and image.shape[2] == 3) or (grey_ok and image.ndim == 2))
    if not ok:
        want = "an (H, W, 3) uint8 BGR" + (" or (H, W) uint8 grey" if grey_ok else "")
        raise ImageError(f"{name or 'image'}: expected {want} image, got {image.shape} {image.dtype}")
    return image


def default_renderer(ctx, options: RenderOptions):
    """The renderer ``options`` ask for, on ``ctx``: the stencil :class:`arshadow.gl.stencil.ShadowRenderer`
    (volumes and planar shadows), or the :class:`arshadow.gl.shadowmap.ShadowMapRenderer` baseline."""
    # deferred: moderngl loads only when a session first renders (``import arshadow`` stays light)
    if options.shadow_method == "shadowmap":
        from .gl.shadowmap import ShadowMapRenderer

        return ShadowMapRenderer(ctx, map_size=int(options.shadowmap_size), samples=int(options.aa))
    from .gl.stencil import ShadowRenderer

    return ShadowRenderer(ctx, samples=int(options.aa))
