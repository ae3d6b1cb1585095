"""The Python entry point and the engine: a :class:`Session` tracks, plans and renders photos of one scene.

::

    import arshadow

    spec = arshadow.scene_from_dict({"calib": "calib/cam.yml", "marker_length": 0.05,
                                     "model": "box:0.04,0.04,0.06", "lights": ["point:0.1,0.1,0.4"]})
    with arshadow.Session(spec) as s:
        result = s.process(image_bgr)          # FrameResult: composite, mask, pose, item, timings, plan

A frame goes through three steps, each a public method:

1. :meth:`Session.track`: marker / board detection and pose (the fast first pass of
   :mod:`arshadow.tracking.fastdetect`, the full search only if it finds nothing) -> ``MarkerPose``;
2. :meth:`Session.plan`: :func:`arshadow.plan.plan_frame` (pure, no GL): ROI and canvas, near plane,
   z-pass / z-fail per light, which cached geometry is reused; at render time also the compose path
   (:func:`arshadow.plan.decide_compose`) -> :class:`arshadow.plan.FramePlan`;
3. :meth:`Session.render` (at a pose or a plan): :func:`arshadow.execute.execute`: volumes, renderer, lens
   warp, composite -> :class:`FrameResult`.

:meth:`Session.process` is ``track`` then ``render``. A session loads the scene once
(:meth:`arshadow.scene.SceneSpec.build`: errors surface at construction), creates its OpenGL context on first
use (once: ``track`` and ``plan`` alone never create one) and keeps the caches of a run (trackers and lens
maps per photo size, silhouettes and volumes per light, the renderer). It pickles as its spec: a worker
process unpickles it into a fresh session of the same scene.

For a video engine: :meth:`Session.track` (pose only, grey images too), :meth:`Session.render` (at a given
pose), :meth:`Session.tracker_state` (the trackers' memory); what carries from frame to frame (lights over
time, the exposure match's smoothing, their saved state: ``set_lights`` / ``set_time``, ``state`` /
``restore``) is :class:`arshadow.history.History`, which ``Session`` inherits.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .camera import Intrinsics
from .compose.composite import Workspace
from .compose.lens import LensWarp
from .engine import CalibrationState, check_image, default_renderer, estimate_pose
from .errors import UsageError
from .estimate.match import ExposureMatch, marker_id_of
from .execute import LAYERS_WHY, execute
from .geometry.ground import check_camera_above, parse_ground
from .history import History
from .io import read_image
from .plan import FramePlan, SceneGeometry, decide_compose, plan_frame
from .render_api import Renderer
from .report import ReportItem, StageTimings
from .result import FrameResult
from .sanity import FrameChecks, calibration_scaled_note, say_note
from .scene import Scene, SceneSpec, load_scene, scene_from_dict
from .tracking.luma import LumaFrame
from .transforms import invert_rigid, rvec_tvec_from_matrix

__all__ = ["Session", "FrameResult", "render_photo"]

log = logging.getLogger(__name__)


class Session(History):
    """Track, plan and render photos of one :class:`arshadow.scene.SceneSpec`.

    Parameters
    ----------
    spec : arshadow.scene.SceneSpec
        The scene (or a mapping for :func:`arshadow.scene.scene_from_dict`, a job file path for
        :func:`arshadow.scene.load_scene`, or an already loaded :class:`arshadow.scene.Scene`: objects
        instead of files; such a session does not pickle).
    lights : sequence of arshadow.lights.spec.Light, optional
        Lights to start with instead of the spec's.
    context : moderngl.Context, optional
        Use this OpenGL context (not released by :meth:`close`) instead of creating one on first use.
    renderer : Renderer or callable, optional
        A renderer to share (:class:`arshadow.render_api.Renderer`, not released by :meth:`close`), or
        ``renderer(ctx, options) -> Renderer`` making this session's own: another shadow technique
        (default: the stencil :class:`arshadow.gl.stencil.ShadowRenderer` with ``options.aa`` samples).

    Attributes
    ----------
    compose_chooser : arshadow.gl.compose.PathChooser
        Measures the numpy and shader compose paths when the plan says ``"measure"``.

    Raises
    ------
    ArshadowError
        The scene does not load (calibration, board, mesh, lights, options): the first problem found.
    """

    #: what the inputs are, for the notes (``"video"``: set by arshadow.video.framejob.SessionBackend)
    input_kind = "photo"

    def __init__(
        self,
        spec: SceneSpec | Scene | Mapping[str, Any] | str | os.PathLike[str],
        *,
        lights: Sequence[Any] | None = None,
        context: Any = None,
        renderer: Any = None,
    ) -> None:
        if isinstance(spec, Scene):
            self.spec, self.scene = None, spec
        else:
            if isinstance(spec, Mapping):
                spec = scene_from_dict(spec)
            elif not isinstance(spec, SceneSpec):
                spec = load_scene(os.fspath(spec))
            self.spec = spec
            self.scene = spec.build(lights=lights)
        self.options = self.scene.options
        self.geometry = SceneGeometry(self.scene.caster, self.options, self.scene.lights)
        #: the proxy ground (``options.ground``, :mod:`arshadow.geometry.ground`): the scene's world frame
        self.ground = parse_ground(self.options.ground)
        self._marker_from_ground = None if self.ground.is_marker else self.ground.marker_from_ground
        self._ctx, self._own_ctx = context, context is None
        shared = renderer if isinstance(renderer, Renderer) else None
        self._renderer, self._own_renderer = shared, shared is None
        self._renderer_factory = None if shared is not None else renderer
        self._gpu = None
        if self.scene.sun_tracks:  # a time-lapse of the spec (SceneSpec.time_lapse)
            self.use_sun_tracks(self.scene.sun_tracks, self.scene.static_lights or ())
        self._calibs: dict = {}
        self._lenses: dict = {}
        self._work = Workspace()
        self._checks = FrameChecks(self.scene.caster, self.scene.tracker.get("marker_length"))  # O(1) per frame
        from .gl.compose import PathChooser  # deferred: no GL at import (moderngl loads on first render)

        tk = self.scene.tracker
        #: per-photo exposure / white balance match (arshadow.estimate.match); None when off, on a board or an
        #: inverted marker (its white cells are ink)
        self.exposure = (
            ExposureMatch(tk["marker_length"], tk.get("dictionary"), tk.get("marker_id"), smooth=self.options.track_roi)
            if self.options.exposure and tk.get("board") is None and tk.get("marker_length") and not tk.get("inverted")
            else None
        )
        self.compose_chooser = PathChooser(force=None if self.options.compose == "auto" else self.options.compose)

    # -- resources ------------------------------------------------------------------------------------
    @property
    def context(self) -> Any:
        """The OpenGL context (created on first use, once per session)."""
        if self._ctx is None:
            from .gl.context import create_context  # deferred: moderngl loads on first render only

            self._ctx = create_context()
        return self._ctx

    @property
    def renderer(self) -> Any:
        """The renderer (made, with the context, on first use)."""
        if self._renderer is None:
            if self._renderer_factory is not None:
                self._renderer = self._renderer_factory(self.context, self.options)
            else:
                self._renderer = default_renderer(self.context, self.options)
        return self._renderer

    def _gpu_compositor(self) -> Any:
        """The shader compose path on the renderer's context (made on first use)."""
        if self._gpu is None:
            from .gl.compose import GpuCompositor  # deferred: GL, only when the shader path runs

            self._gpu = GpuCompositor(self.renderer.ctx)
        return self._gpu

    @property
    def intrinsics(self) -> Intrinsics:
        """The calibration (:class:`arshadow.camera.Intrinsics`)."""
        return self.scene.intrinsics

    @property
    def notes(self) -> list[str]:
        """Notes on the current lights (e.g. a sun below the horizon)."""
        return self.geometry.notes

    def close(self) -> None:
        """Release the renderer (if made here) and the OpenGL context (if this session created it)."""
        if self._own_renderer and self._renderer is not None:
            self._renderer.release()
        self._renderer = None
        if self._gpu is not None:
            self._gpu.release()
            self._gpu = None
        if self._own_ctx and self._ctx is not None:
            self._ctx.release()
            self._ctx = None

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __reduce__(self) -> tuple[Any, ...]:
        # a session pickles as its spec: the receiver loads the scene and makes its own context
        if self.spec is None:
            raise UsageError("a Session made from a loaded Scene does not pickle; make it from a SceneSpec")
        return (Session, (self.spec,))

    # -- per photo size -------------------------------------------------------------------------------
    def calibration(self, width: int, height: int) -> CalibrationState:
        """Intrinsics (scaled to the size), lens warp and trackers for a photo size
        (:class:`arshadow.engine.CalibrationState`, built once per size).

        Raises
        ------
        CalibrationError
            A size whose aspect ratio differs from the calibration's.
        """
        key = (int(width), int(height))
        c = self._calibs.get(key)
        if c is None:
            intr, scaled = self.intrinsics.for_image(width, height)
            if scaled:  # once per size, on stderr (the report says it per photo)
                say_note(log, calibration_scaled_note(self.intrinsics, width, height, self.input_kind))
            tracker = self.scene.tracker
            # video: each tracker searches a window around its last detection first (the planner's tracking
            # ROI, full-frame fallback: arshadow/tracking/roi_track.py)
            roi = bool(self.options.track_roi and self.options.plan != "general" and "board" not in tracker)
            lens = self._lens_for(intr) if intr.has_distortion else None
            c = self._calibs[key] = CalibrationState(
                intr, scaled, lens, dict(tracker), roi, bool(self.options.fast_detect)
            )
        return c

    def _lens_for(self, intr: Intrinsics) -> LensWarp:
        """The cached :class:`LensWarp` of a calibration (one map per distinct calibration)."""
        lens = self._lenses.get(intr)
        if lens is None:
            lens = self._lenses[intr] = LensWarp(intr)
        return lens

    def compose_key(self, width: int, height: int, distorted: bool) -> tuple[Any, ...]:
        """The key under which the compose path is measured: (GL renderer, size, anti-aliasing, lens)."""
        ctx = getattr(self.renderer, "ctx", None)
        backend = (getattr(ctx, "info", None) or {}).get("GL_RENDERER", "?") if ctx is not None else "?"
        return (backend, int(width), int(height), int(self.options.aa), bool(distorted))

    # -- the three steps --------------------------------------------------------------------------------
    def track(self, image: np.ndarray | LumaFrame, timings: StageTimings | None = None) -> Any:
        """Marker / board pose only (no rendering, no GL): the fast pass, the full search if it finds nothing.

        Parameters
        ----------
        image : (H, W, 3) uint8 BGR or (H, W) uint8 grey, or arshadow.tracking.luma.LumaFrame
            A video frame's limited-range luma (converted to grey only where the tracker reads it).
        timings : arshadow.report.StageTimings, optional
            ``detect`` and ``pose`` are added to.

        Returns
        -------
        arshadow.tracking.pose.MarkerPose

        Raises
        ------
        MarkerNotFoundError
        """
        if not isinstance(image, LumaFrame):
            image = check_image(image, "image", grey_ok=True)
        cal = self.calibration(image.shape[1], image.shape[0])
        return estimate_pose(cal, image, timings if timings is not None else StageTimings())[0]

    def reset_tracking(self) -> None:
        """Forget the frames tracked so far, at every size (a new video: its first frame is searched
        whole, as it would be in a fresh session)."""
        for cal in self._calibs.values():
            cal.reset_trackers()

    def tracker_state(self, width: int, height: int) -> list:
        """What the next :meth:`track` of a ``width x height`` frame depends on from the frames before
        (tracking window, misses in a row), JSON-able: two runs whose states are equal track the next
        frame alike (a video's chunks compare it at their boundaries)."""
        return self.calibration(width, height).tracker_state()

    def plan(self, pose: Any, width: int, height: int, *, modes: Sequence[str] | None = None) -> FramePlan:
        """The :class:`arshadow.plan.FramePlan` for a pose and photo size, without rendering (no GL).

        Parameters
        ----------
        pose : arshadow.tracking.pose.MarkerPose or (4, 4) float64
            A tracked pose or ``cam_from_marker``; the plan's ``cam_from_world`` is the ground frame's
            camera (:meth:`ground_camera`).
        width, height : int
        modes : list of str, optional
            Force the volume mode per light (tests compare z-pass and z-fail).

        The compose path is decided when the plan is rendered (it depends on the output buffers).
        """
        cal = self.calibration(width, height)
        cfw = self.ground_camera(getattr(pose, "cam_from_world", pose))
        if self.options.plan == "general" or "reuse" in self.options.plan_off:
            self.geometry.forget()  # the reference rebuilds every light's geometry every frame
        return plan_frame(self.geometry, cal.intrinsics, cfw, int(width), int(height), lens=cal.lens, modes=modes)

    def ground_camera(self, cam_from_marker: Any) -> np.ndarray:
        """``cam_from_world`` (4, 4) float64 of the frame the scene lives in, the ground frame
        (:mod:`arshadow.geometry.ground`): ``cam_from_marker @ marker_from_ground``, the marker pose itself
        when the ground is the marker plane.

        Raises
        ------
        UsageError
            The camera sees the ground plane from below or edge-on.
        """
        m = np.asarray(cam_from_marker, np.float64).reshape(4, 4)
        if self._marker_from_ground is None:
            return m
        cam_from_ground: np.ndarray = m @ self._marker_from_ground
        check_camera_above(cam_from_ground, self.ground.text)
        return cam_from_ground

    def render(
        self,
        image: np.ndarray,
        pose: Any = None,
        *,
        plan: FramePlan | None = None,
        name: str = "",
        want_mask: bool = True,
        out: np.ndarray | None = None,
        mask_out: np.ndarray | None = None,
        timings: StageTimings | None = None,
        modes: Sequence[str] | None = None,
        layers: bool | str = False,
        marker: Any = None,
        seen: bool = True,
    ) -> FrameResult:
        """Composite at a given pose, or carry out a plan of :meth:`plan`.

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified unless it is ``out``).
        pose : arshadow.tracking.pose.MarkerPose or (4, 4) float64
            A tracked pose or ``cam_from_world`` (not with ``plan``).
        plan : arshadow.plan.FramePlan, optional
            A plan of :meth:`plan` for this image's size.
        name : str
            Used in the report item and messages.
        want_mask : bool
            Also compute the full-size mask.
        out, mask_out : arrays, optional
            Buffers for the composite ``(H, W, 3) uint8`` and the mask ``(H, W) uint8`` (reused across
            frames of one size by callers that consume each result at once; ``out`` may be ``image``).
        timings : arshadow.report.StageTimings, optional
            Stage times to add to (e.g. the ``detect``/``pose`` of :meth:`track`); ``total`` grows by this
            call's time.
        modes : list of str, optional
            Force the volume mode per light (as :meth:`plan`).
        layers : bool or "undistorted"
            Also make the compositing layers (``FrameResult.layers``; the numpy compose path); with
            ``"undistorted"`` also their pinhole version (``FrameResult.layers.undistorted``).
        marker : arshadow.tracking.pose.MarkerPose, optional
            This frame's tracked marker when ``pose`` is not it (a video's smoothed pose, or a plan): the
            exposure match reads the paper of its marker id.
        seen : bool
            False: the marker is not in this frame (a video frame rendered with a held pose). The exposure
            match then measures nothing, because the paper is not where the pose says, and keeps the
            video's last gain.

        Returns
        -------
        FrameResult

        Raises
        ------
        ImageError, CalibrationError
            Unusable image, or a size the calibration cannot be scaled to.
        """
        if (pose is None) == (plan is None):
            raise UsageError("Session.render needs a pose or a plan (one of them)")
        t0 = time.perf_counter()
        image = check_image(image, name)
        timings = timings if timings is not None else StageTimings()
        item = ReportItem(input=name)
        if plan is None:
            plan = self.plan(pose, image.shape[1], image.shape[0], modes=modes)
        elif tuple(plan.size) != (image.shape[1], image.shape[0]):
            raise UsageError(
                f"{name or 'image'}: the plan is for {plan.size[0]}x{plan.size[1]}, the image is "
                f"{image.shape[1]}x{image.shape[0]}"
            )
        tracked = pose if hasattr(pose, "cam_from_world") else None
        res = self._render(image, plan, tracked, item, timings, want_mask, out, mask_out, layers, marker, seen)
        timings.total += (time.perf_counter() - t0) * 1e3
        item.timings_ms = timings.as_dict(3)
        return res

    def process(
        self,
        image: np.ndarray,
        name: str = "",
        want_mask: bool = True,
        out: np.ndarray | None = None,
        mask_out: np.ndarray | None = None,
        layers: bool | str = False,
    ) -> FrameResult:
        """:meth:`track` then :meth:`render`: composite the object and its shadow into one photo.

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified unless it is ``out``).
        name, want_mask, out, mask_out, layers
            As :meth:`render`.

        Returns
        -------
        FrameResult

        Raises
        ------
        MarkerNotFoundError
            No marker / board found.
        ImageError, CalibrationError
            Unusable image, or a size the calibration cannot be scaled to.
        """
        t0 = time.perf_counter()
        timings = StageTimings()
        image = check_image(image, name)
        cal = self.calibration(image.shape[1], image.shape[0])
        pose, detector = estimate_pose(cal, image, timings)
        item = ReportItem(input=name, detector=detector)
        plan = self.plan(pose, image.shape[1], image.shape[0])
        res = self._render(image, plan, pose, item, timings, want_mask, out, mask_out, layers)
        note = cal.detect_note()
        if note is not None and item.plan is not None:
            item.plan["detect"] = note
        timings.total = (time.perf_counter() - t0) * 1e3
        item.timings_ms = timings.as_dict(3)
        return res

    def _render(
        self,
        image: np.ndarray,
        plan: FramePlan,
        pose: Any,
        item: ReportItem,
        timings: StageTimings,
        want_mask: bool,
        out: np.ndarray | None,
        mask_out: np.ndarray | None,
        layers: bool | str = False,
        marker: Any = None,
        seen: bool = True,
    ) -> FrameResult:
        """Execute ``plan`` on ``image`` and fill ``item`` (all but ``timings_ms``); ``pose``: the tracked
        :class:`~arshadow.tracking.pose.MarkerPose` or None; ``layers``, ``marker``, ``seen``: as
        :meth:`render`."""
        lay: dict[str, Any] | None = {"undistorted": layers == "undistorted"} if layers else None
        H, W = image.shape[:2]
        cal = self.calibration(W, H)
        cfw = plan.cam_from_world
        if cal.was_scaled:
            item.calibration_scaled = {"from": [self.intrinsics.width, self.intrinsics.height], "to": [W, H]}
        if self.notes:
            item.notes = list(self.notes)
        if pose is not None:
            item.set_pose(pose)
        else:  # the report carries the marker's pose: back from the ground frame
            cfm = cfw if self._marker_from_ground is None else cfw @ invert_rigid(self._marker_from_ground)
            rvec, tvec = rvec_tvec_from_matrix(cfm)
            item.rvec, item.tvec = rvec.tolist(), tvec.tolist()
        if self._marker_from_ground is not None:
            item.ground = self.ground.text
        cfm = cfw if self._marker_from_ground is None else cfw @ invert_rigid(self._marker_from_ground)
        for msg in self._checks.check(cfw, cfm):  # a far camera (wrong units), the camera inside: once per run
            log.warning(msg)
        gain = None  # the exposure match: the object's colour gain, measured on the marker's paper
        if self.exposure is not None and not plan.empty:
            gain, item.exposure = self.exposure.frame_gain(
                image,
                cal.intrinsics,
                cfw,
                pose if marker is None else marker,
                self.geometry,
                self._marker_from_ground,
                self.options.exposure_gain,
                seen,
            )
        renderer = key = None
        if not plan.empty:  # the renderer (and the context) is made only when there is something to draw
            renderer = self.renderer
            key = self.compose_key(W, H, cal.lens is not None)
            if lay is not None and plan.compose != "cpu":  # the layers come from the numpy path
                plan.decide("compose", "cpu", LAYERS_WHY)
            self._decide_compose(plan, renderer, key, want_mask, out, mask_out)
        out, mask = execute(
            plan,
            image,
            cal.intrinsics,
            geometry=self.geometry,
            renderer=renderer,
            lens=cal.lens,
            work=self._work,
            timings=timings,
            item=item,
            want_mask=want_mask,
            out=out,
            mask_out=mask_out,
            chooser=self.compose_chooser,
            gpu=self._gpu_compositor,
            compose_key=key,
            layers=lay,
            color_gain=gain,
        )
        return FrameResult(
            out, mask, pose, np.asarray(cfw, np.float64), item, timings, plan, None if lay is None else lay["layers"]
        )

    def exposure_region(self, cam_from_world: np.ndarray, width: int, height: int, pose: Any = None) -> tuple | None:
        """``(x0, y0, w, h)``: the pixels the exposure match reads on a ``width x height`` frame at the
        tracked pose ``cam_from_world`` (``cam_from_marker``, what :meth:`plan` takes), or None (the match is
        off, or the marker is behind the camera). A caller converting only part of a frame (the video
        engine: the plan's ROI) converts these too, or the paper is measured on pixels that are not the
        frame's."""
        if self.exposure is None:
            return None
        cal = self.calibration(width, height)
        cfm = np.asarray(getattr(cam_from_world, "cam_from_world", cam_from_world), np.float64)
        return self.exposure.region(cal.intrinsics, cfm, marker_id_of(pose))

    def _decide_compose(
        self,
        plan: FramePlan,
        renderer: Any,
        key: tuple[Any, ...],
        want_mask: bool,
        out: np.ndarray | None,
        mask_out: np.ndarray | None,
    ) -> None:
        """Record the plan's compose decision (unless it has one these buffers allow)."""
        available = (
            bool(getattr(renderer, "gpu_layers", False))
            and (out is None or out.flags.c_contiguous)
            and (not want_mask or mask_out is None or mask_out.flags.c_contiguous)
        )
        if plan.compose == "cpu" or (plan.compose is not None and available):
            return
        chooser = self.compose_chooser
        decide_compose(
            plan,
            force=chooser.force,
            shader_available=available,
            measured=None if chooser.force else chooser.decisions.get(key),
            software=bool(getattr(renderer, "software", False)) and not chooser.time_software,
        )


def render_photo(
    spec: Any, image: np.ndarray | str | os.PathLike[str], name: str = "", want_mask: bool = True
) -> FrameResult:
    """One photo, one call: ``Session(spec).process(image)`` (context created and released).

    Parameters
    ----------
    spec : SceneSpec, mapping or job file path
    image : (H, W, 3) uint8 BGR, or a path of a photo
    """
    if not isinstance(image, np.ndarray):
        name = name or str(image)
        image = read_image(image)
    with Session(spec) as s:
        return s.process(image, name=name, want_mask=want_mask)
