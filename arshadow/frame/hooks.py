"""The parts of a :class:`arshadow.frame.session.Session` that are per photo size or per tracker, and what a frame
engine reaches into a session for: public names the session uses, kept apart so that the session module stays
the façade.

- :class:`EngineHooks` (``Session.hooks``): what the video engine (and the photo loop) needs of a session
  beyond its public face: per-size calibrations and trackers (their state, their reset), the compose path's
  chooser and key, the exposure match over frames, a render into the engine's buffers;
- :class:`CalibrationState`: per photo size, the scaled intrinsics, the lens warp, and the trackers (made on
  first use: a session that only renders at given poses never builds one);
- :func:`estimate_pose`: the fast detection pass, then the full search if it finds nothing, with stage times;
- :func:`check_image`: the one image check of the API;
- :func:`default_renderer`: the renderer :class:`arshadow.scene.RenderOptions` ask for.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..compose.lens import LensWarp
from ..errors import ImageError, MarkerNotFoundError
from ..estimate.match import ExposureMatch, marker_id_of
from ..scene.sanity import calibration_scaled_note, say_note
from ..scene.spec import RenderOptions
from ..tracking.detect import VIDEO_REFINE
from ..tracking.edgelock import EdgeSpaceLock
from ..tracking.pose import MarkerPose
from ..tracking.reference import ReferenceLock
from ..tracking.tracker import MarkerTracker
from .effects import CameraEffects, measure_camera
from .report import StageTimings

if TYPE_CHECKING:  # annotations only
    from ..camera.model import Intrinsics
    from ..gl.gpu_compose import PathChooser
    from ..plan.planner import FramePlan
    from ..renderer.request import Renderer
    from .execute import FrameOutputs
    from .motion import MotionBlur
    from .result import FrameResult
    from .session import Session

__all__ = [
    "CalibrationState",
    "EngineFrame",
    "EngineHooks",
    "PHOTO_FRAME",
    "estimate_pose",
    "check_image",
    "default_renderer",
    "DETECT_NOTES",
]

log = logging.getLogger("arshadow.frame.session")


@dataclass(frozen=True)
class EngineFrame:
    """What a video engine knows of a frame beyond the pose it is rendered at (:meth:`EngineHooks.render`).

    Attributes
    ----------
    marker : arshadow.tracking.pose.MarkerPose or None
        This frame's tracked marker when the pose rendered at is not it (a video's smoothed pose, or a
        plan): the exposure match reads the paper of its marker id.
    seen : bool
        False: the marker is not in this frame (a video frame rendered with a held pose). The exposure
        match then measures nothing, because the paper is not where the pose says, and keeps the video's
        last gain.
    motion : arshadow.frame.motion.MotionBlur or None
        The frame's motion blur (a video's, from its neighbouring frames' poses:
        :meth:`arshadow.video.framejob.SessionBackend.motion`); None: none.
    """

    marker: MarkerPose | None = None
    seen: bool = True
    motion: MotionBlur | None = None


#: a photo: its own marker, seen, no motion
PHOTO_FRAME = EngineFrame()

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
    video : bool
        The frames are a video's: the trackers share one :class:`~arshadow.tracking.edgelock.EdgeSpaceLock`
        (the edge fit's space decided once per marker and video).
    """

    intrinsics: Intrinsics
    was_scaled: bool
    lens: LensWarp | None
    tracker_kwargs: dict
    track_roi: bool = False
    fast_detect: bool = False
    video: bool = False
    _trackers: tuple | None = None

    def trackers(self) -> tuple:
        """``(fast or None, full)`` :class:`~arshadow.tracking.tracker.MarkerTracker` (made on first use)."""
        if self._trackers is None:
            kw, roi = self.tracker_kwargs, self.track_roi
            # video: one reference marker for the whole video (the trust fixes), shared by both trackers
            ref = ReferenceLock() if roi else None
            shared: dict[str, Any] = {
                "track_roi": roi,
                "reference": ref,
                "edge_lock": EdgeSpaceLock() if self.video else None,
            }
            full = MarkerTracker(self.intrinsics, **kw, **shared)
            fast = None
            if self.fast_detect and "detector_params" not in kw:
                fast = MarkerTracker(self.intrinsics, **kw, detector="fast", **shared)
            self._trackers = (fast, full)
        return self._trackers

    def reset_trackers(self) -> None:
        """Forget the frames tracked so far (a new video)."""
        for t in self._trackers or ():
            if t is not None:
                t.reset()
                for shared in (t.reference, t.edge_lock):
                    if shared is not None:
                        shared.reset()

    def tracker_state(self) -> list:
        """:meth:`~arshadow.tracking.tracker.MarkerTracker.state` of the trackers made so far (fast, full)."""
        return [None if t is None else t.state() for t in (self._trackers or ())]

    def detect_note(self) -> str | None:
        """Where the last search looked (:data:`DETECT_NOTES`), None without a tracking window."""
        det = [t.last_search for t in (self._trackers or ()) if t is not None]
        if not any(isinstance(d, str) for d in det):
            return None
        return DETECT_NOTES["window" if "window" in det else "full"]


def estimate_pose(cal: CalibrationState, image: Any, timings: StageTimings) -> tuple[MarkerPose, str | None]:
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


def _timed_estimate(tracker: MarkerTracker, image: Any, timings: StageTimings) -> MarkerPose:
    t = time.perf_counter()
    pose: MarkerPose = tracker.estimate(image)
    total = (time.perf_counter() - t) * 1e3
    # the tracker splits its own time into marker search and pose (MarkerPose.timings_ms)
    pose_ms = float((getattr(pose, "timings_ms", None) or {}).get("pose", 0.0))
    timings.detect += total - pose_ms
    timings.pose += pose_ms
    return pose


def check_image(image: Any, name: str = "", grey_ok: bool = False) -> np.ndarray:
    """``image`` as an ``(H, W, 3) uint8`` BGR array (or ``(H, W) uint8`` grey with ``grey_ok``), or an
    :class:`ImageError` naming ``name``.

    >>> check_image(np.zeros((2, 3, 3), np.uint8)).shape
    (2, 3, 3)
    """
    image = np.asarray(image)
    arr: np.ndarray = image
    ok = image.dtype == np.uint8 and ((image.ndim == 3 and image.shape[2] == 3) or (grey_ok and image.ndim == 2))
    if not ok:
        want = "an (H, W, 3) uint8 BGR" + (" or (H, W) uint8 grey" if grey_ok else "")
        raise ImageError(f"{name or 'image'}: expected {want} image, got {image.shape} {image.dtype}")
    return arr


def default_renderer(ctx: Any, options: RenderOptions) -> Renderer:
    """The renderer ``options`` ask for, on ``ctx``: the stencil :class:`arshadow.gl.stencil.ShadowRenderer`
    (volumes and planar shadows), or the :class:`arshadow.gl.shadowmap.ShadowMapRenderer` baseline."""
    # deferred: moderngl loads only when a session first renders (``import arshadow`` stays light)
    if options.shadow_method == "shadowmap":
        from ..gl.shadowmap import ShadowMapRenderer

        shadowmap: Renderer = ShadowMapRenderer(ctx, map_size=int(options.shadowmap_size), samples=int(options.aa))
        return shadowmap
    from ..gl.stencil import ShadowRenderer

    stencil: Renderer = ShadowRenderer(ctx, samples=int(options.aa))
    return stencil


class EngineHooks:
    """What a frame engine reaches into a :class:`arshadow.frame.session.Session` for (``session.hooks``), kept off
    the session's public face (``track``, ``plan``, ``render``, ``process``, ``state`` / ``restore``, ...).

    The video engine (:class:`arshadow.video.framejob.SessionBackend`) and the photo loop
    (:func:`arshadow.photos.render_photos`) use it. Names: ``cam_from_marker`` is the marker's pose (what
    :meth:`Session.track` measures, what :meth:`Session.plan` takes); ``cam_from_world`` is always the
    scene's world frame, the ground's (:meth:`Session.ground_camera`).

    Attributes
    ----------
    compose_chooser : arshadow.gl.gpu_compose.PathChooser
        Measures the numpy and shader compose paths when the plan says ``"measure"``.
    exposure : arshadow.estimate.match.ExposureMatch or None
        The per-frame exposure / white balance match (:mod:`arshadow.estimate.match`); None when off, on a
        board or an inverted marker (its white cells are ink).
    input_kind : str
        What the inputs are, for the notes: ``"photo"``, or ``"video"`` (set by the video engine).
    """

    #: what the inputs are, for the notes ("video": set by arshadow.video.framejob.SessionBackend)
    input_kind = "photo"

    def __init__(self, session: Session, render: Callable[..., FrameResult]) -> None:
        from ..gl.gpu_compose import PathChooser  # deferred: no GL at import (moderngl loads on first render)

        self._session, self._render = session, render
        self._calibs: dict[tuple[int, int], CalibrationState] = {}
        self._lenses: dict[Any, LensWarp] = {}
        #: the photo's blur and noise (--camera-effects on): measured on the first frame with a marker
        self.measured_camera: CameraEffects | None = None
        opts, tk = session.options, session.scene.tracker
        self.compose_chooser: PathChooser = PathChooser(force=None if opts.compose == "auto" else opts.compose)
        self.exposure: ExposureMatch | None = (
            ExposureMatch(tk["marker_length"], tk.get("dictionary"), tk.get("marker_id"), smooth=opts.track_roi)
            if opts.exposure and tk.get("board") is None and tk.get("marker_length") and not tk.get("inverted")
            else None
        )

    # -- per photo size ---------------------------------------------------------------------------------
    def calibration(self, width: int, height: int) -> CalibrationState:
        """Intrinsics (scaled to the size), lens warp and trackers for a photo size (built once per size).

        Raises
        ------
        CalibrationError
            A size whose aspect ratio differs from the calibration's.
        """
        key = (int(width), int(height))
        c = self._calibs.get(key)
        if c is None:
            s = self._session
            intr, scaled = s.intrinsics.for_image(width, height)
            if scaled:  # once per size, on stderr (the report says it per photo)
                say_note(log, calibration_scaled_note(s.intrinsics, width, height, self.input_kind))
            tracker, opts = s.scene.tracker, s.options
            # video: each tracker searches a window around its last detection first (the planner's tracking
            # ROI, full-frame fallback: arshadow/tracking/roi_track.py)
            roi = bool(opts.track_roi and opts.plan != "general" and "board" not in tracker)
            if opts.track_roi and "refine" not in tracker:  # a video: its own default refinement
                tracker = {**tracker, "refine": VIDEO_REFINE}
            lens = None
            if intr.has_distortion:  # one map per distinct calibration
                lens = self._lenses.get(intr)
                if lens is None:
                    lens = self._lenses[intr] = LensWarp(intr)
            video = bool(opts.track_roi)
            c = self._calibs[key] = CalibrationState(
                intr, scaled, lens, dict(tracker), roi, bool(opts.fast_detect), video
            )
        return c

    def tracker_state(self, width: int, height: int) -> list:
        """What the next :meth:`Session.track` of a ``width x height`` frame depends on from the frames before
        (tracking window, misses in a row), JSON-able: two runs whose states are equal track the next frame
        alike (a video's chunks compare it at their boundaries)."""
        return self.calibration(width, height).tracker_state()

    def reset_tracking(self) -> None:
        """Forget the frames tracked so far, at every size (a new video: its first frame is searched whole,
        as it would be in a fresh session)."""
        for cal in self._calibs.values():
            cal.reset_trackers()

    def camera_effects(self, image: np.ndarray, pose: MarkerPose | None) -> CameraEffects | None:
        """The photo's blur and noise (``--camera-effects on``), measured on the first frame whose marker is
        tracked and kept for the session (:func:`arshadow.frame.effects.measure_camera`, then
        :attr:`measured_camera`; the video engine forgets it at each new video); None when off or not
        measured yet.

        ``image`` (H, W, 3) uint8 BGR: the whole frame (the marker's edges, its paper and the floor round it
        are read); ``pose``: its tracked marker (None: nothing measured)."""
        if self._session.options.camera_effects != "on":
            return None
        if self.measured_camera is None and pose is not None and pose.all_corners:
            corners = pose.all_corners
            ref = pose.marker_ids[0] if pose.marker_ids else next(iter(corners))
            self.measured_camera = measure_camera(image, np.asarray(corners.get(ref, next(iter(corners.values())))))
        return self.measured_camera

    def compose_key(self, width: int, height: int, distorted: bool) -> tuple[Any, ...]:
        """The key under which the compose path is measured: (renderer backend, size, anti-aliasing, lens, sky
        occlusion, camera effects: the numpy path pays for the sky channel and the effects per pixel, the
        shader path hardly)."""
        s = self._session
        effects = s.options.camera_effects == "on"
        return (
            s.renderer.backend,
            int(width),
            int(height),
            int(s.options.aa),
            bool(distorted),
            s.geometry.sky_on,
            effects,
        )

    # -- the exposure match over frames -----------------------------------------------------------------
    def exposure_region(
        self, cam_from_marker: np.ndarray | MarkerPose, width: int, height: int, marker: MarkerPose | None = None
    ) -> tuple | None:
        """``(x0, y0, w, h)``: the pixels the exposure match reads on a ``width x height`` frame at the marker
        pose ``cam_from_marker``, or None (the match is off, or the marker is behind the camera). A caller
        converting only part of a frame (the video engine: the plan's ROI) converts these too, or the paper
        is measured on pixels that are not the frame's. ``marker``: the frame's tracked pose (its id)."""
        if self.exposure is None:
            return None
        cal = self.calibration(width, height)
        cfm = cam_from_marker.cam_from_world if isinstance(cam_from_marker, MarkerPose) else cam_from_marker
        return self.exposure.region(cal.intrinsics, np.asarray(cfm, np.float64), marker_id_of(marker))

    def observe_exposure(
        self, image: np.ndarray, cam_from_marker: np.ndarray, marker: MarkerPose | None = None
    ) -> None:
        """Measure the marker's paper on a frame that is not rendered (a video chunk's primer: the frames
        before it, decided but not composited), so that the exposure match's smoothing over frames starts
        where the run over those frames would be. No-op when the match is off.

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR frame (at least the paper's pixels, :meth:`exposure_region`).
        cam_from_marker : (4, 4) float64
            The frame's decided marker pose.
        marker : arshadow.tracking.pose.MarkerPose, optional
            The frame's tracked pose (its marker id).
        """
        if self.exposure is None:
            return
        s = self._session
        cal = self.calibration(image.shape[1], image.shape[0])
        cfw = s.ground_camera(cam_from_marker)
        mfg = None if s.ground.is_marker else s.ground.marker_from_ground
        self.exposure.frame_gain(image, cal.intrinsics, cfw, marker, s.geometry, mfg)

    def exposure_gap(self) -> None:
        """A video frame without the marker, not rendered: the exposure match's smoothing counts it (a long
        loss restarts it, :data:`arshadow.estimate.exposure.RESTART_AFTER`). No-op when the match is off."""
        if self.exposure is not None:
            self.exposure.missing()

    # -- a frame into the engine's buffers -----------------------------------------------------------------
    def render(
        self,
        image: np.ndarray,
        pose: MarkerPose | np.ndarray | None = None,
        *,
        plan: FramePlan | None = None,
        outputs: FrameOutputs | None = None,
        layers: bool | str = False,
        frame: EngineFrame = PHOTO_FRAME,
    ) -> FrameResult:
        """:meth:`Session.render` with the engine's buffers and history.

        Parameters
        ----------
        image, pose, plan, layers
            As :meth:`Session.render` (``pose``: a tracked pose or ``cam_from_marker``).
        outputs : arshadow.frame.execute.FrameOutputs, optional
            Buffers (``out`` may be ``image``: composited in place), ``want_mask``, the report item and the
            stage times to add to (e.g. the ``detect`` / ``pose`` of :meth:`Session.track`; ``total`` grows by
            this call's time).
        frame : EngineFrame
            The frame's tracked marker, whether it is in view, and its motion blur (default: a photo's).
        """
        return self._render(image, pose, plan, outputs, layers, frame)
