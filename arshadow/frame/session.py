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
3. :meth:`Session.render` (at a pose or a plan): :func:`arshadow.frame.execute.execute`: volumes, renderer, lens
   warp, composite -> :class:`FrameResult`.

:meth:`Session.process` is ``track`` then ``render``. A session loads the scene once
(:meth:`arshadow.scene.SceneSpec.build`: errors surface at construction), creates its OpenGL context on first
use (once: ``track`` and ``plan`` alone never create one) and keeps the caches of a run (trackers and lens
maps per photo size, silhouettes and volumes per light, the renderer). It pickles as its spec: a worker
process unpickles it into a fresh session of the same scene.

For a video engine: :meth:`Session.track` (pose only, grey images too), :meth:`Session.render` (at a given
pose); what carries from frame to frame (lights over time and their saved state: ``set_lights`` /
``set_time``, ``state`` / ``restore``) is :class:`arshadow.frame.history.History`, which ``Session`` inherits;
what an engine reaches into (per-size calibrations and trackers, the compose path's chooser, the exposure
match over frames, a render into its buffers) is ``session.hooks`` (:class:`arshadow.frame.hooks.EngineHooks`).

Poses: ``cam_from_marker`` is the marker's pose (what :meth:`Session.track` measures:
:class:`arshadow.tracking.pose.MarkerPose`, whose ``cam_from_world`` is it, the tracker's world being the
marker); ``cam_from_world`` in the session, the plan and the result is always the scene's world frame, the
ground's (:meth:`Session.ground_camera`; the marker's own unless ``--ground`` moves the ground).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..camera.model import Intrinsics
from ..compose.composite import Workspace
from ..errors import UsageError
from ..geometry.ground import check_camera_above, parse_ground
from ..io import read_image
from ..lights.spec import Light
from ..plan.planner import FramePlan, SceneGeometry, decide_compose, plan_frame
from ..renderer.request import Renderer
from ..scene.options import RenderOptions
from ..scene.sanity import FrameChecks
from ..scene.spec import ModelSpec, Scene, SceneSpec, load_scene, scene_from_dict
from ..tracking.luma import LumaFrame
from ..tracking.pose import MarkerPose
from ..transforms import invert_rigid, rvec_tvec_from_matrix
from .execute import LAYERS_WHY, FrameContext, FrameOutputs, LayerRequest, execute
from .history import History
from .hooks import PHOTO_FRAME, CalibrationState, EngineFrame, EngineHooks, check_image, default_renderer, estimate_pose
from .report import ReportItem, StageTimings
from .result import FrameResult

if TYPE_CHECKING:
    from ..geometry.caster import ShadowCaster
    from ..gl.gpu_compose import GpuCompositor
    from ..shading.sky import GroundRaster
    from .effects import CameraEffects

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
        A renderer to share (:class:`arshadow.renderer.request.Renderer`, not released by :meth:`close`), or
        ``renderer(ctx, options) -> Renderer`` making this session's own: another shadow technique
        (default: the stencil :class:`arshadow.gl.stencil.ShadowRenderer` with ``options.aa`` samples).

    Attributes
    ----------
    spec, scene, options, geometry, ground
        The scene as given and as loaded, its render options, its lights' cached geometry, its ground.
    hooks : arshadow.frame.hooks.EngineHooks
        What a frame engine reaches into (the video engine's calibrations, trackers, compose chooser,
        exposure match over frames, render into its buffers).

    Raises
    ------
    ArshadowError
        The scene does not load (calibration, board, mesh, lights, options): the first problem found.
    """

    def __init__(
        self,
        spec: SceneSpec | Scene | Mapping[str, Any] | str | os.PathLike[str],
        *,
        lights: Sequence[Light] | None = None,
        context: Any = None,
        renderer: Renderer | Callable[[Any, RenderOptions], Renderer] | None = None,
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
        self.geometry = SceneGeometry(self.scene.caster, self.options, self.scene.lights, self._ground_raster)
        #: the proxy ground (``options.ground``, :mod:`arshadow.geometry.ground`): the scene's world frame
        self.ground = parse_ground(self.options.ground)
        self._marker_from_ground = None if self.ground.is_marker else self.ground.marker_from_ground
        self._ctx, self._own_ctx = context, context is None
        self._renderer_factory: Callable[[Any, RenderOptions], Renderer] | None = None
        self._renderer: Renderer | None
        if isinstance(renderer, Renderer):  # shared: not released here
            self._renderer, self._own_renderer = renderer, False
        else:
            self._renderer, self._own_renderer, self._renderer_factory = None, True, renderer
        self._gpu: GpuCompositor | None = None
        if self.scene.sun_tracks:  # a time-lapse of the spec (SceneSpec.time_lapse)
            self.use_sun_tracks(self.scene.sun_tracks, self.scene.static_lights or ())
        self._work = Workspace()
        self._checks = FrameChecks(self.scene.caster, self.scene.tracker.get("marker_length"))  # O(1) per frame
        self.hooks = EngineHooks(self, self._render_at)

    # -- resources ------------------------------------------------------------------------------------
    @property
    def context(self) -> Any:
        """The OpenGL context (created on first use, once per session)."""
        if self._ctx is None:
            from ..gl.context import create_context  # deferred: moderngl loads on first render only

            self._ctx = create_context()
        return self._ctx

    @property
    def renderer(self) -> Renderer:
        """The renderer (made, with the context, on first use)."""
        if self._renderer is None:
            if self._renderer_factory is not None:
                self._renderer = self._renderer_factory(self.context, self.options)
            else:
                self._renderer = default_renderer(self.context, self.options)
        return self._renderer

    def _ground_raster(self) -> GroundRaster | None:
        """The renderer's rasteriser of the ground occlusion map (:attr:`SceneGeometry.raster_source`)."""
        return self.renderer.ground_raster

    def _gpu_compositor(self) -> GpuCompositor:
        """The shader compose path on the renderer's context (made on first use)."""
        if self._gpu is None:
            from ..gl.gpu_compose import GpuCompositor  # deferred: GL, only when the shader path runs

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

    def __reduce__(self) -> tuple[type[Session], tuple[SceneSpec]]:
        # a session pickles as its spec: the receiver loads the scene and makes its own context
        if self.spec is None:
            raise UsageError("a Session made from a loaded Scene does not pickle; make it from a SceneSpec")
        return (Session, (self.spec,))

    def set_model(self, model: ModelSpec | ShadowCaster) -> None:
        """Replace the object, keeping the rest of the session: calibrations and lens maps, the renderer and
        its context, the lights (their silhouettes and volumes are rebuilt for the new mesh on first use).
        The next render equals a fresh session's of the changed scene (``arshadow preview``'s drag).

        Parameters
        ----------
        model : arshadow.scene.ModelSpec or arshadow.geometry.mesh.ShadowCaster
            A spec (built here; the session's spec follows it) or an already placed caster (the session
            then no longer pickles).
        """
        if isinstance(model, ModelSpec):
            caster = model.build()
            self.spec = None if self.spec is None else self.spec.replace(model=model)
        else:
            caster, self.spec = model, None
        self.scene.caster = caster
        self.geometry = SceneGeometry(caster, self.options, self.geometry.lights_in, self._ground_raster)
        self._checks = FrameChecks(caster, self.scene.tracker.get("marker_length"))

    # -- the three steps --------------------------------------------------------------------------------
    def track(self, image: np.ndarray | LumaFrame, timings: StageTimings | None = None) -> MarkerPose:
        """Marker / board pose only (no rendering, no GL): the fast pass, the full search if it finds nothing.

        Parameters
        ----------
        image : (H, W, 3) uint8 BGR or (H, W) uint8 grey, or arshadow.tracking.luma.LumaFrame
            A video frame's limited-range luma (converted to grey only where the tracker reads it).
        timings : arshadow.frame.report.StageTimings, optional
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
        cal = self.hooks.calibration(image.shape[1], image.shape[0])
        pose: MarkerPose = estimate_pose(cal, image, timings if timings is not None else StageTimings())[0]
        return pose

    def plan(
        self, pose: MarkerPose | np.ndarray, width: int, height: int, *, modes: Sequence[str] | None = None
    ) -> FramePlan:
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
        cal = self.hooks.calibration(width, height)
        cfw = self.ground_camera(pose)
        if self.options.plan == "general" or "reuse" in self.options.plan_off:
            self.geometry.forget()  # the reference rebuilds every light's geometry every frame
        return plan_frame(self.geometry, cal.intrinsics, cfw, int(width), int(height), lens=cal.lens, modes=modes)

    def ground_camera(self, cam_from_marker: MarkerPose | np.ndarray) -> np.ndarray:
        """``cam_from_world`` (4, 4) float64 of the frame the scene lives in, the ground frame
        (:mod:`arshadow.geometry.ground`): ``cam_from_marker @ marker_from_ground``, the marker pose itself
        when the ground is the marker plane.

        Raises
        ------
        UsageError
            The camera sees the ground plane from below or edge-on.
        """
        if isinstance(cam_from_marker, MarkerPose):
            cam_from_marker = cam_from_marker.cam_from_world  # the tracker's world: the marker
        m = np.asarray(cam_from_marker, np.float64).reshape(4, 4)
        if self._marker_from_ground is None:
            return m
        cam_from_ground: np.ndarray = m @ self._marker_from_ground
        check_camera_above(cam_from_ground, self.ground.text)
        return cam_from_ground

    def render(
        self,
        image: np.ndarray,
        pose: MarkerPose | np.ndarray | None = None,
        *,
        plan: FramePlan | None = None,
        name: str = "",
        want_mask: bool = True,
        out: np.ndarray | None = None,
        mask_out: np.ndarray | None = None,
        layers: bool | str = False,
    ) -> FrameResult:
        """Composite at a given pose, or carry out a plan of :meth:`plan`.

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified unless it is ``out``).
        pose : arshadow.tracking.pose.MarkerPose or (4, 4) float64
            A tracked pose or ``cam_from_marker`` (not with ``plan``).
        plan : arshadow.plan.FramePlan, optional
            A plan of :meth:`plan` for this image's size (e.g. with ``modes`` forced).
        name : str
            Used in the report item and messages.
        want_mask : bool
            Also compute the full-size mask.
        out, mask_out : arrays, optional
            Buffers for the composite ``(H, W, 3) uint8`` and the mask ``(H, W) uint8`` (reused across
            frames of one size by callers that consume each result at once; ``out`` may be ``image``).
        layers : bool or "undistorted"
            Also make the compositing layers (``FrameResult.layers``; the numpy compose path); with
            ``"undistorted"`` also their pinhole version (``FrameResult.layers.undistorted``).

        Returns
        -------
        FrameResult

        Raises
        ------
        ImageError, CalibrationError
            Unusable image, or a size the calibration cannot be scaled to.

        A video engine's render (stage times to add to, the tracked marker of a smoothed pose, a frame
        without the marker) is :meth:`arshadow.frame.hooks.EngineHooks.render`.
        """
        outputs = FrameOutputs(want_mask, out, mask_out, StageTimings(), ReportItem(input=name))
        return self._render_at(image, pose, plan, outputs, layers)

    def _render_at(
        self,
        image: np.ndarray,
        pose: MarkerPose | np.ndarray | None,
        plan: FramePlan | None,
        outputs: FrameOutputs | None,
        layers: bool | str = False,
        frame: EngineFrame = PHOTO_FRAME,
    ) -> FrameResult:
        """:meth:`render` (and :meth:`arshadow.frame.hooks.EngineHooks.render`): ``outputs`` holds the buffers, item
        and timings (``total`` grows by this call's time); ``frame``: as the hook's."""
        if (pose is None) == (plan is None):
            raise UsageError("Session.render needs a pose or a plan (one of them)")
        t0 = time.perf_counter()
        outputs = outputs if outputs is not None else FrameOutputs()
        name = outputs.item.input
        image = check_image(image, name)
        if plan is None:
            assert pose is not None  # one of them (checked above)
            plan = self.plan(pose, image.shape[1], image.shape[0])
        elif tuple(plan.size) != (image.shape[1], image.shape[0]):
            raise UsageError(
                f"{name or 'image'}: the plan is for {plan.size[0]}x{plan.size[1]}, the image is "
                f"{image.shape[1]}x{image.shape[0]}"
            )
        tracked = pose if isinstance(pose, MarkerPose) else None
        outputs.layers = _layer_request(layers)
        res = self._render(image, plan, tracked, outputs, frame)
        outputs.timings.total += (time.perf_counter() - t0) * 1e3
        outputs.item.timings_ms = outputs.timings.as_dict(3)
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
        cal = self.hooks.calibration(image.shape[1], image.shape[0])
        pose, detector = estimate_pose(cal, image, timings)
        item = ReportItem(input=name, detector=detector)
        plan = self.plan(pose, image.shape[1], image.shape[0])
        res = self._render(
            image, plan, pose, FrameOutputs(want_mask, out, mask_out, timings, item, _layer_request(layers))
        )
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
        pose: MarkerPose | None,
        outputs: FrameOutputs,
        frame: EngineFrame = PHOTO_FRAME,
    ) -> FrameResult:
        """Execute ``plan`` on ``image`` into ``outputs`` and fill its item (all but ``timings_ms``); ``pose``:
        the tracked :class:`~arshadow.tracking.pose.MarkerPose` or None; ``frame``: as
        :meth:`arshadow.frame.hooks.EngineHooks.render`."""
        H, W = image.shape[:2]
        cal, hooks = self.hooks.calibration(W, H), self.hooks
        cfw = plan.cam_from_world
        self._report_frame(outputs.item, plan, pose, cal)
        gain = None  # the exposure match: the object's colour gain, measured on the marker's paper
        if hooks.exposure is not None and not plan.empty:
            gain, outputs.item.exposure = hooks.exposure.frame_gain(
                image,
                cal.intrinsics,
                cfw,
                pose if frame.marker is None else frame.marker,
                self.geometry,
                self._marker_from_ground,
                self.options.exposure_gain,
                frame.seen,
            )
        if not plan.empty:  # the renderer (and the context) is made only when there is something to draw
            key = hooks.compose_key(W, H, cal.lens is not None)
            if outputs.layers is not None and plan.compose != "cpu":  # the layers come from the numpy path
                plan.decide("compose", "cpu", LAYERS_WHY)
            self._decide_compose(plan, self.renderer, key, outputs)
        context = FrameContext(
            geometry=self.geometry,
            renderer=lambda: self.renderer,
            work=self._work,
            calibration=hooks.calibration,
            compose_key=hooks.compose_key,
            chooser=hooks.compose_chooser,
            gpu=self._gpu_compositor,
        )
        # the photo's optics, measured on the first frame whose marker is tracked (a video renders a smoothed
        # pose: its tracked marker comes in ``frame``)
        camera = hooks.camera_effects(image, pose if pose is not None else frame.marker)
        out, mask = execute(plan, image, context, outputs, color_gain=gain, camera=camera, motion=frame.motion)
        lay = None if outputs.layers is None else outputs.layers["layers"]
        return FrameResult(out, mask, pose, np.asarray(cfw, np.float64), outputs.item, outputs.timings, plan, lay)

    @property
    def camera_effects(self) -> CameraEffects | None:
        """The photo's measured blur and noise (``--camera-effects on``; None before the first frame with the
        marker, or off)."""
        return self.hooks.measured_camera

    def _report_frame(self, item: ReportItem, plan: FramePlan, pose: MarkerPose | None, cal: CalibrationState) -> None:
        """The report item's pose, calibration, notes and ground; warnings on a far or inside camera."""
        cfw = plan.cam_from_world
        if cal.was_scaled:
            item.calibration_scaled = {"from": [self.intrinsics.width, self.intrinsics.height], "to": list(plan.size)}
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

    def _decide_compose(
        self, plan: FramePlan, renderer: Renderer, key: tuple[object, ...], outputs: FrameOutputs
    ) -> None:
        """Record the plan's compose decision (unless it has one these buffers allow)."""
        out, mask_out, want_mask = outputs.out, outputs.mask_out, outputs.want_mask
        available = (
            renderer.gpu_layers
            and (out is None or out.flags.c_contiguous)
            and (not want_mask or mask_out is None or mask_out.flags.c_contiguous)
        )
        if plan.compose == "cpu" or (plan.compose is not None and available):
            return
        chooser = self.hooks.compose_chooser
        decide_compose(
            plan,
            force=chooser.force,
            shader_available=available,
            measured=None if chooser.force else chooser.decisions.get(key),
            software=renderer.software and not chooser.time_software,
        )


def _layer_request(layers: bool | str) -> LayerRequest | None:
    """:func:`arshadow.frame.execute.execute`'s ``layers`` request of :meth:`Session.render`'s ``layers``."""
    return {"undistorted": layers == "undistorted"} if layers else None


def render_photo(
    spec: SceneSpec | Mapping[str, Any] | str | os.PathLike[str],
    image: np.ndarray | str | os.PathLike[str],
    name: str = "",
    want_mask: bool = True,
) -> FrameResult:
    """One photo, one call: ``Session(spec).process(image)`` (context created and released).

    Parameters
    ----------
    spec : SceneSpec, mapping or job file path
    image : (H, W, 3) uint8 BGR, or a path of a photo
    """
    if not isinstance(image, np.ndarray):
        name = name or str(image)
        image = read_image(os.fspath(image))
    with Session(spec) as s:
        return s.process(image, name=name, want_mask=want_mask)
