"""The per-photo engine: track -> plan -> execute, with the caches that make a run fast.

A :class:`Compositor` holds what stays fixed over a run (calibration per photo size, trackers, lens
warps, the scene's CPU geometry, the renderer) and runs each photo through three steps:

1. **track**: marker / board detection and pose (:mod:`arshadow.tracking.marker`; the fast first pass of
   :mod:`arshadow.tracking.fastdetect`, the full search only if it finds nothing);
2. **plan**: :func:`arshadow.plan.plan_frame` (pure, no GL): ROI and canvas, near plane, z-pass / z-fail
   per light, which cached geometry is reused;
3. **execute**: :func:`arshadow.execute.execute`: volumes, renderer, lens warp, composite.

Most users want :class:`arshadow.session.Session` (built from a declarative
:class:`arshadow.scene.SceneSpec`, owning its GL context); a Compositor is the lower-level form that is
handed a context and loaded objects::

    comp = Compositor(ctx, intrinsics, caster, lights, tracker=dict(marker_length=0.05))
    out_bgr, mask_u8, item = comp.process(image_bgr)
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from .compose.composite import Workspace
from .errors import ImageError, MarkerNotFoundError
from .execute import STAGES, execute
from .geometry.ground import check_camera_above, parse_ground
from .tracking.fastdetect import HalfResolutionDetector, fast_detector_params, make_fast_tracker
from .plan import (
    ROI_MAX_POINTS,
    SceneGeometry,
    pinhole_rect_for_scene,
    plan_frame,
    scene_hull_points,
    shadow_footprint,
)
from .report import ReportItem
from .scene import RenderOptions
from .transforms import invert_rigid, rvec_tvec_from_matrix

log = logging.getLogger(__name__)

__all__ = ["RenderOptions", "Compositor", "CalibrationState", "shadow_footprint", "scene_hull_points",
           "pinhole_rect_for_scene", "STAGES", "ROI_MAX_POINTS", "HalfResolutionDetector", "make_fast_tracker",
           "fast_detector_params"]


@dataclass
class CalibrationState:
    """Per image size: scaled intrinsics, trackers, lens warp.

    Attributes
    ----------
    intrinsics : arshadow.camera.Intrinsics
        Scaled to the size.
    was_scaled : bool
    tracker : arshadow.tracking.marker.MarkerTracker
        The full search.
    lens : arshadow.compose.lens.LensWarp or None
        None without distortion.
    fast_tracker : arshadow.tracking.marker.MarkerTracker or None
        The fast first pass (``detector="fast"``), None when off.
    """

    intrinsics: object
    was_scaled: bool
    tracker: object
    lens: object | None
    fast_tracker: object = None


def check_bgr_image(image, name: str = "") -> np.ndarray:
    """``image`` as an ``(H, W, 3) uint8`` BGR array, or an :class:`ImageError` naming ``name``."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ImageError(f"{name or 'image'}: expected an (H, W, 3) uint8 BGR image, got {image.shape} "
                         f"{image.dtype}")
    return image

class Compositor:
    """Everything that stays fixed over a run, and :meth:`process` for each photo.

    Parameters
    ----------
    ctx : moderngl.Context or None
        From :func:`arshadow.gl.context.create_context`; the default renderer is built on it (never
        creates one). None with ``make_renderer`` or ``renderer``.
    intrinsics : arshadow.camera.Intrinsics
        The calibration; photos of another size with the same aspect ratio get a scaled copy.
    caster : arshadow.geometry.mesh.ShadowCaster
        The occluder in the world (marker) frame.
    lights : sequence of arshadow.lights.spec.Light
        At least one. Area lights are split into ``options.soft_samples`` hard samples.
    options : RenderOptions, optional
    tracker : dict, optional
        Keyword arguments of :class:`arshadow.tracking.marker.MarkerTracker` (dictionary, marker_length,
        marker_id, board, ...).
    renderer : arshadow.render_api.Renderer, optional
        Share an existing renderer (not released by :meth:`close`).
    make_renderer : callable, optional
        ``make_renderer(options) -> Renderer``, called on first use (default: a
        :class:`arshadow.gl.stencil.ShadowRenderer` on ``ctx`` with ``options.aa`` samples); the
        renderer made is released by :meth:`close`.
    """

    def __init__(self, ctx, intrinsics, caster, lights, options: RenderOptions | None = None, tracker=None,
                 renderer=None, make_renderer=None):
        self.ctx = ctx
        self.intrinsics = intrinsics
        self.caster = caster
        self.options = (options or RenderOptions()).check()
        self.tracker_kwargs = dict(tracker or {})
        self.geometry = SceneGeometry(caster, self.options, lights)
        #: the proxy ground (``options.ground``): the model, lights and shadows live in its frame
        self.ground = parse_ground(self.options.ground)
        self._marker_from_ground = None if self.ground.is_marker else self.ground.marker_from_ground
        self._calibs: dict = {}
        self._lenses: dict = {}
        self._work = Workspace()
        self._warned_inside = False
        self._renderer = renderer
        self._own_renderer = renderer is None
        self._make_renderer = make_renderer
        from .gl.compose import PathChooser  # no GL at import: moderngl is imported when first used

        #: numpy vs shader compose, chosen by measurement per photo size (``options.compose``)
        self.compose_chooser = PathChooser(force=None if self.options.compose == "auto" else self.options.compose)
        self._gpu = None

    # -- cached per run ------------------------------------------------------------------------------
    @property
    def renderer(self):
        """The renderer (made on first use)."""
        if self._renderer is None:
            if self._make_renderer is not None:
                self._renderer = self._make_renderer(self.options)
            else:
                self._renderer = default_renderer(self.ctx, self.options)
        return self._renderer

    def close(self):
        """Release the renderer this compositor made."""
        if self._own_renderer and self._renderer is not None:
            self._renderer.release()
        self._renderer = None
        if self._gpu is not None:
            self._gpu.release()
            self._gpu = None

    def _gpu_compositor(self):
        """The shader compose path on the renderer's context (made on first use)."""
        if self._gpu is None:
            from .gl.compose import GpuCompositor

            self._gpu = GpuCompositor(self.renderer.ctx)
        return self._gpu

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def notes(self) -> list[str]:
        """Notes about the current lights (below the horizon...), for the report."""
        return self.geometry.notes

    @property
    def lights_in(self) -> list:
        """The lights as last given (before area-light sampling)."""
        return self.geometry.lights_in

    @property
    def _lights(self):
        # the per-(sample)-light cache; tests/benchmarks/bench_pipeline.py clears it for "cold" runs
        return self.geometry.lights

    def set_lights(self, lights) -> int:
        """Replace the lights between frames (``arshadow video --time-lapse``), keeping cached work.

        See :meth:`arshadow.plan.SceneGeometry.set_lights`. A sun track hands the direction of its last
        recompute (``TrackFrame.world_used``) until the sun has moved more than the set angle, so in
        between nothing is recomputed.

        Returns
        -------
        int
            Number of (sample) lights whose silhouette and volumes must be recomputed.
        """
        return self.geometry.set_lights(lights)

    def calib_for(self, width: int, height: int) -> CalibrationState:
        """Intrinsics, trackers and lens warp for a photo size (built once per size)."""
        key = (int(width), int(height))
        c = self._calibs.get(key)
        if c is None:
            from .tracking.marker import MarkerTracker

            intr, scaled = self.intrinsics.for_image(width, height)
            # video: each tracker searches a window around its last detection first (the planner's tracking
            # ROI, full-frame fallback: arshadow/tracking/roi_track.py)
            roi = bool(self.options.track_roi and self.options.plan != "general"
                       and "board" not in self.tracker_kwargs)
            tracker = MarkerTracker(intr, **self.tracker_kwargs, track_roi=roi)
            fast = None
            if self.options.fast_detect and "detector_params" not in self.tracker_kwargs:
                fast = MarkerTracker(intr, **self.tracker_kwargs, detector="fast", track_roi=roi)
            lens = self._lens_for(intr) if intr.has_distortion else None
            c = self._calibs[key] = CalibrationState(intr, scaled, tracker, lens, fast)
        return c

    def znear_for(self, cam_from_world) -> float:
        """A near plane that clips nothing visible (:meth:`arshadow.plan.SceneGeometry.znear_for`)."""
        return self.geometry.znear_for(cam_from_world)

    def modes_for(self, cam_from_world, znear, intr=None, canvas=None):
        """Per light: ``"zpass"`` or ``"zfail"`` (:meth:`arshadow.plan.SceneGeometry.modes_for`)."""
        return self.geometry.modes_for(cam_from_world, znear, intr, canvas)

    # -- per photo ------------------------------------------------------------------------------------
    def track(self, image, cal: CalibrationState, timings=None, extra=None):
        """Marker pose of one photo: the fast pass, then the full search if it finds nothing.

        Parameters
        ----------
        image : (H, W, 3) uint8
        cal : CalibrationState
            :meth:`calib_for` of the photo's size.
        timings : dict, optional
            ``detect`` and ``pose`` are added to.
        extra : dict, optional
            Gets ``"detector"`` when the fallback ran (the report item's ``extra``).

        Returns
        -------
        arshadow.tracking.marker.MarkerPose

        Raises
        ------
        MarkerNotFoundError
        """
        timings = timings if timings is not None else dict.fromkeys(STAGES, 0.0)
        pose = None
        if cal.fast_tracker is not None:
            try:
                pose = self._estimate(cal.fast_tracker, image, timings)
            except MarkerNotFoundError:
                if extra is not None:
                    extra["detector"] = "full (fast pass found nothing)"
        if pose is None:
            pose = self._estimate(cal.tracker, image, timings)
        return pose

    def process(self, image, name: str = "", want_mask: bool = True, out=None, mask_out=None):
        """Composite the occluder and its shadow into one photo.

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified).
        name : str
            Used in the report item and messages.
        want_mask : bool
            Also return the full-size mask (else None).
        out : (H, W, 3) uint8, optional
            Buffer for the result (reused across frames by callers that consume each result at once,
            e.g. encode it: saves allocating and page-faulting a photo-sized array per frame).
        mask_out : (H, W) uint8, optional
            Buffer for the mask, likewise.

        Returns
        -------
        out : (H, W, 3) uint8
            The composited photo (a new array).
        mask : (H, W) uint8 or None
            The shadow mask of CONVENTIONS.md.
        item : arshadow.report.ReportItem
            Pose, mode, silhouette edges, per-stage timings (``output``/``mask`` left for the caller).

        Raises
        ------
        MarkerNotFoundError
            No marker / board found.
        ImageError, CalibrationError
            Unusable image, or a size the calibration cannot be scaled to.
        """
        out, mask, item, _pose, _plan = self.process_full(image, name, want_mask, out, mask_out)
        return out, mask, item

    def process_full(self, image, name: str = "", want_mask: bool = True, out=None, mask_out=None):
        """:meth:`process`, also returning the pose and the frame plan: ``(out, mask, item, pose, plan)``."""
        t_start = time.perf_counter()
        timings = dict.fromkeys(STAGES, 0.0)
        image = check_bgr_image(image, name)
        cal = self.calib_for(image.shape[1], image.shape[0])
        extra = {}
        pose = self.track(image, cal, timings, extra)
        out, mask, item, plan = self.render_item(image, pose, cal, name=name, timings=timings, want_mask=want_mask,
                                                 out=out, mask_out=mask_out, extra=extra)
        det = [t.last_search for t in (cal.fast_tracker, cal.tracker) if t is not None]
        if any(isinstance(d, str) for d in det):
            item.extra["plan"]["detect"] = ("window around the last detection" if "window" in det
                                            else "whole frame (no window yet, or nothing found in it)")
        timings["total"] = (time.perf_counter() - t_start) * 1e3
        item.timings_ms = {k: round(v, 3) for k, v in timings.items()}
        return out, mask, item, pose, plan

    def render_item(self, image, pose, cal: CalibrationState, *, name: str = "", timings=None, want_mask=True,
                    out=None, mask_out=None, extra=None):
        """Render and composite at a pose and fill the photo's report item (everything but ``timings_ms``).

        Parameters
        ----------
        image : (H, W, 3) uint8
        pose : arshadow.tracking.marker.MarkerPose or (4, 4) float64
            A tracked pose or ``cam_from_marker`` (turned into the ground frame's camera by
            :meth:`ground_camera`).
        cal : CalibrationState
            :meth:`calib_for` of the photo's size.
        name, timings, want_mask, out, mask_out
            As :meth:`process` (``timings``: stage times are added to it).
        extra : dict, optional
            Entries for the item's ``extra`` before the render's (e.g. :meth:`track`'s ``detector``).

        Returns
        -------
        out, mask, item (arshadow.report.ReportItem), plan (arshadow.plan.FramePlan)
        """
        item = ReportItem(input=name)
        if cal.was_scaled:
            item.extra["calibration_scaled"] = {"from": [self.intrinsics.width, self.intrinsics.height],
                                                "to": [int(image.shape[1]), int(image.shape[0])]}
        if self.notes:
            item.extra["notes"] = list(self.notes)
        item.extra.update(extra or {})
        if hasattr(pose, "cam_from_world"):
            item.set_pose(pose)
            cam_from_world = np.asarray(pose.cam_from_world, np.float64)
        else:
            cam_from_world = np.asarray(pose, np.float64).reshape(4, 4)
            rvec, tvec = rvec_tvec_from_matrix(cam_from_world)
            item.rvec, item.tvec = rvec.tolist(), tvec.tolist()
        if not self.ground.is_marker:  # the report keeps the marker's pose; the scene is in the ground frame
            item.extra["ground"] = self.ground.text
        cam_from_world = self.ground_camera(cam_from_world)
        out, mask, info, plan = self.render_planned(image, cal.intrinsics, cam_from_world, lens=cal.lens,
                                                    timings=timings, want_mask=want_mask, out=out, mask_out=mask_out)
        item.mode = info["mode"]
        item.silhouette_edges = info["silhouette_edges"]
        item.extra.update({k: v for k, v in info.items() if k not in ("mode", "silhouette_edges")})
        return out, mask, item, plan

    def ground_camera(self, cam_from_marker) -> np.ndarray:
        """``cam_from_world`` (4, 4) float64 of the world the scene lives in, the ground frame
        (:mod:`arshadow.geometry.ground`): ``cam_from_marker @ marker_from_ground``, the marker pose itself when
        the ground is the marker plane. Raises UsageError when the camera sees the ground from below or
        edge-on."""
        m = np.asarray(cam_from_marker, np.float64).reshape(4, 4)
        if self._marker_from_ground is None:
            return m
        cam_from_ground = m @ self._marker_from_ground
        check_camera_above(cam_from_ground, self.ground.text)
        return cam_from_ground

    def _estimate(self, tracker, image, timings):
        t = time.perf_counter()
        pose = tracker.estimate(image)
        total = (time.perf_counter() - t) * 1e3
        # the tracker splits its own time into marker search and pose (MarkerPose.timings_ms)
        pose_ms = float((getattr(pose, "timings_ms", None) or {}).get("pose", 0.0))
        timings["detect"] += total - pose_ms
        timings["pose"] += pose_ms
        return pose

    def plan(self, intr, cam_from_world, width: int, height: int, *, lens=None, modes=None):
        """The :class:`arshadow.plan.FramePlan` of a pose (no GL; see :func:`arshadow.plan.plan_frame`)."""
        if intr.has_distortion and lens is None:
            lens = self._lens_for(intr)
        return plan_frame(self.geometry, intr, cam_from_world, width, height, lens=lens, modes=modes)

    def render_pose(self, image, intr, cam_from_world, *, lens=None, timings=None, want_mask=True,
                    modes=None, out=None, mask_out=None):
        """Render and composite for a known pose (the part of :meth:`process` after the tracker).

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified).
        intr : arshadow.camera.Intrinsics
            Calibration for this photo size.
        cam_from_world : (4, 4) float64
            Pose.
        lens : arshadow.compose.lens.LensWarp or None
            Needed when ``intr`` has distortion (built from ``intr`` if missing).
        modes : list of str, optional
            Force the volume mode per light (tests compare z-pass and z-fail); default: decided per
            light by :func:`arshadow.geometry.volume.camera_may_be_in_shadow`.

        Returns
        -------
        out, mask, info
            As :meth:`process`; ``info`` has ``mode``, ``modes``, ``silhouette_edges``, ``roi``, ``canvas``.
        """
        out, mask, info, _ = self.render_planned(image, intr, cam_from_world, lens=lens, timings=timings,
                                                 want_mask=want_mask, modes=modes, out=out, mask_out=mask_out)
        return out, mask, info

    def render_planned(self, image, intr, cam_from_world, *, lens=None, timings=None, want_mask=True, modes=None,
                       out=None, mask_out=None):
        """:meth:`render_pose`, also returning the plan: ``(out, mask, info, plan)``."""
        timings = timings if timings is not None else dict.fromkeys(STAGES, 0.0)
        H, W = image.shape[:2]
        if intr.has_distortion and lens is None:
            lens = self._lens_for(intr)
        if self.options.plan == "general" or "reuse" in self.options.plan_off:
            self.geometry.forget()  # the reference rebuilds every light's geometry every frame
        plan = plan_frame(self.geometry, intr, cam_from_world, W, H, lens=lens, modes=modes)
        if not self._warned_inside:
            from .geometry.mesh import placement_warnings

            for msg in placement_warnings(self.caster, eye_world=invert_rigid(cam_from_world)[:3, 3]):
                log.warning(msg)
                self._warned_inside = True  # once per run, not per frame
        # the renderer is made only when there is something to draw
        renderer = None if plan.empty else self.renderer
        out, mask, info = execute(plan, image, intr, geometry=self.geometry, renderer=renderer, lens=lens,
                                  work=self._work, timings=timings, want_mask=want_mask, out=out, mask_out=mask_out,
                                  chooser=self.compose_chooser, gpu=self._gpu_compositor)
        return out, mask, info, plan

    def _lens_for(self, intr):
        """The cached :class:`LensWarp` of a calibration (one map per distinct calibration)."""
        lens = self._lenses.get(intr)
        if lens is None:
            from .compose.lens import LensWarp

            lens = self._lenses[intr] = LensWarp(intr)
        return lens


def default_renderer(ctx, options: RenderOptions):
    """The renderer ``options`` ask for, on ``ctx``: the stencil :class:`arshadow.gl.stencil.ShadowRenderer`
    (volumes and planar shadows), or the :class:`arshadow.gl.shadowmap.ShadowMapRenderer` baseline."""
    if options.shadow_method == "shadowmap":
        from .gl.shadowmap import ShadowMapRenderer

        return ShadowMapRenderer(ctx, map_size=int(options.shadowmap_size), samples=int(options.aa))
    from .gl.stencil import ShadowRenderer

    return ShadowRenderer(ctx, samples=int(options.aa))
