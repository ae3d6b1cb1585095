"""The Python entry point: a :class:`Session` renders photos of one scene.

::

    import arshadow

    spec = arshadow.scene_from_dict({"calib": "calib/cam.yml", "marker_length": 0.05,
                                     "model": "box:0.04,0.04,0.06", "lights": ["point:0.1,0.1,0.4"]})
    with arshadow.Session(spec) as s:
        result = s.process(image_bgr)          # FrameResult: composite, mask, pose, item, timings, plan

A session loads the scene once (:meth:`arshadow.scene.SceneSpec.build`: errors surface at construction),
creates its OpenGL context on first use (once: ``track`` alone never creates one) and keeps the caches of
a run (trackers per photo size, silhouettes and volumes per light, lens maps, the renderer). It pickles
as its spec: a worker process unpickles it into a fresh session of the same scene.

For a video engine: :meth:`Session.track` (pose only), :meth:`Session.render` (at a given pose),
:meth:`Session.set_lights` / :meth:`Session.set_time` (time-lapse), :meth:`Session.state` /
:meth:`Session.restore` (resume a run or start a chunk of it with the same history).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .execute import STAGES
from .report import ReportItem

__all__ = ["Session", "FrameResult", "render_photo"]


@dataclass
class FrameResult:
    """One photo's result.

    Attributes
    ----------
    composite : (H, W, 3) uint8
        The photo with the object and its shadow (BGR).
    mask : (H, W) uint8 or None
        The shadow mask of CONVENTIONS.md (None when not asked for).
    pose : arshadow.tracking.marker.MarkerPose or None
        The tracked pose (None when rendering at a given ``cam_from_world``).
    cam_from_world : (4, 4) float64
        The pose rendered.
    item : arshadow.report.ReportItem
        The report entry (``output``/``mask`` paths left for the caller).
    timings_ms : dict
        Per stage (:data:`arshadow.execute.STAGES`), milliseconds.
    plan : arshadow.plan.FramePlan
        What was decided for the frame, with reasons (``plan.decisions``).
    """

    composite: np.ndarray
    mask: np.ndarray | None
    pose: object
    cam_from_world: np.ndarray
    item: ReportItem
    timings_ms: dict = field(default_factory=dict)
    plan: object = None


class Session:
    """Render photos of one :class:`arshadow.scene.SceneSpec`.

    Parameters
    ----------
    spec : arshadow.scene.SceneSpec
        The scene (or a mapping for :func:`arshadow.scene.scene_from_dict`, or a job file path for
        :func:`arshadow.scene.load_scene`).
    lights : sequence of arshadow.lights.spec.Light, optional
        Lights to start with instead of the spec's (a time-lapse's static lights plus its sun's first
        position).
    context : moderngl.Context, optional
        Use this OpenGL context (not released by :meth:`close`) instead of creating one on first use.
    renderer : Renderer or callable, optional
        A renderer to share (:class:`arshadow.render_api.Renderer`, not released by :meth:`close`), or
        ``renderer(ctx, options) -> Renderer`` making this session's own: another shadow technique
        (default: the stencil :class:`arshadow.gl.stencil.ShadowRenderer` with ``options.aa`` samples).

    Raises
    ------
    ArshadowError
        The scene does not load (calibration, board, mesh, lights, options): the first problem found.
    """

    def __init__(self, spec, *, lights=None, context=None, renderer=None):
        from .pipeline import Compositor
        from .scene import SceneSpec, load_scene, scene_from_dict

        if isinstance(spec, dict):
            spec = scene_from_dict(spec)
        elif not isinstance(spec, SceneSpec):
            spec = load_scene(spec)
        self.spec = spec
        self.scene = spec.build(lights=lights)
        self._ctx = context
        self._own_ctx = context is None
        self._renderer_factory = renderer
        self._sun = None  # (static lights, sun tracks) of set_time
        from .render_api import Renderer

        shared = renderer if isinstance(renderer, Renderer) else None
        if shared is not None:
            self._renderer_factory = None
        self._compositor = Compositor(None, self.scene.intrinsics, self.scene.caster, self.scene.lights,
                                      self.scene.options, tracker=self.scene.tracker, renderer=shared,
                                      make_renderer=self._make_renderer)

    # -- resources ------------------------------------------------------------------------------------
    @property
    def context(self):
        """The OpenGL context (created on first use, once per session)."""
        if self._ctx is None:
            from .gl.context import create_context

            self._ctx = create_context()
        return self._ctx

    def _make_renderer(self, options):
        if self._renderer_factory is not None:
            return self._renderer_factory(self.context, options)
        from .pipeline import default_renderer

        return default_renderer(self.context, options)

    @property
    def renderer(self):
        """The renderer (made, with the context, on first use)."""
        return self._compositor.renderer

    @property
    def compositor(self):
        """The :class:`arshadow.pipeline.Compositor` doing the work (caches per photo size)."""
        return self._compositor

    @property
    def intrinsics(self):
        """The calibration (:class:`arshadow.camera.Intrinsics`)."""
        return self.scene.intrinsics

    @property
    def notes(self) -> list[str]:
        """Notes on the current lights (e.g. a sun below the horizon)."""
        return self._compositor.notes

    def close(self) -> None:
        """Release the renderer and (if this session created it) the OpenGL context."""
        self._compositor.close()
        if self._own_ctx and self._ctx is not None:
            self._ctx.release()
            self._ctx = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __reduce__(self):
        # a session pickles as its spec: the receiver loads the scene and makes its own context
        return (Session, (self.spec,))

    # -- per photo ------------------------------------------------------------------------------------
    def process(self, image, name: str = "", want_mask: bool = True, out=None, mask_out=None) -> FrameResult:
        """Track the marker and composite the object and its shadow into one photo.

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified).
        name : str
            Used in the report item and messages.
        want_mask : bool
            Also compute the full-size mask.
        out, mask_out : arrays, optional
            Buffers for the composite and the mask (reused across photos of one size).

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
        comp, mask, item, pose, plan = self._compositor.process_full(image, name, want_mask, out, mask_out)
        return FrameResult(comp, mask, pose, np.asarray(pose.cam_from_world, np.float64), item,
                           dict(item.timings_ms), plan)

    def track(self, image, timings=None, extra=None):
        """Marker / board pose only (no rendering, no GL): the fast pass, the full search if it finds nothing.

        Parameters
        ----------
        image : (H, W, 3) uint8
        timings : dict, optional
            ``detect`` and ``pose`` (milliseconds) are added to.
        extra : dict, optional
            Gets ``"detector"`` when the full search had to run.

        Returns
        -------
        arshadow.tracking.marker.MarkerPose

        Raises
        ------
        MarkerNotFoundError
        """
        from .pipeline import check_bgr_image

        image = check_bgr_image(image, "image")
        cal = self._compositor.calib_for(image.shape[1], image.shape[0])
        return self._compositor.track(image, cal, timings, extra)

    def render(self, image, pose, name: str = "", want_mask: bool = True, out=None, mask_out=None,
               timings=None) -> FrameResult:
        """Composite at a given pose (a video engine's second half; tests with a known pose).

        Parameters
        ----------
        image : (H, W, 3) uint8
        pose : arshadow.tracking.marker.MarkerPose or (4, 4) float64
            A tracked pose or ``cam_from_world``.
        name, want_mask, out, mask_out
            As :meth:`process`.
        timings : dict, optional
            Stage timings to add to (e.g. the ``detect``/``pose`` of :meth:`track`); ``total`` is set to
            their sum.

        Returns
        -------
        FrameResult
        """
        from .pipeline import check_bgr_image

        t0 = time.perf_counter()
        image = check_bgr_image(image, name)
        timings = timings if timings is not None else dict.fromkeys(STAGES, 0.0)
        for k in STAGES:
            timings.setdefault(k, 0.0)
        comp = self._compositor
        cal = comp.calib_for(image.shape[1], image.shape[0])
        res, mask, item, plan = comp.render_item(image, pose, cal, name=name, timings=timings, want_mask=want_mask,
                                                 out=out, mask_out=mask_out)
        timings["total"] = timings.get("total", 0.0) + (time.perf_counter() - t0) * 1e3
        item.timings_ms = {k: round(v, 3) for k, v in timings.items()}
        marker_pose = pose if hasattr(pose, "cam_from_world") else None
        cam_from_world = np.asarray(getattr(pose, "cam_from_world", pose), np.float64).reshape(4, 4)
        return FrameResult(res, mask, marker_pose, cam_from_world, item, dict(item.timings_ms), plan)

    def calibration(self, width: int, height: int):
        """Intrinsics (scaled to the size), trackers and lens warp for a photo size
        (:class:`arshadow.pipeline.CalibrationState`, built once per size).

        Raises
        ------
        CalibrationError
            A size whose aspect ratio differs from the calibration's.
        """
        return self._compositor.calib_for(width, height)

    def plan(self, pose, width: int, height: int):
        """The :class:`arshadow.plan.FramePlan` for a pose and photo size, without rendering (no GL)."""
        cal = self._compositor.calib_for(width, height)
        cfw = np.asarray(getattr(pose, "cam_from_world", pose), np.float64)
        return self._compositor.plan(cal.intrinsics, self._compositor.ground_camera(cfw), width, height, lens=cal.lens)

    # -- lights and history ---------------------------------------------------------------------------
    def set_lights(self, lights) -> int:
        """Replace the lights (spec strings or :class:`arshadow.lights.spec.Light`), keeping the cached geometry
        of the lights that stay; returns the number of (sample) lights to recompute."""
        from .lights.spec import parse_light

        return self._compositor.set_lights([parse_light(s) if isinstance(s, str) else s for s in lights])

    def use_sun_tracks(self, tracks, static=()) -> None:
        """Let :meth:`set_time` move the sun: ``tracks`` (:func:`arshadow.lights.spec.parse_sun_track`) plus fixed
        ``static`` lights."""
        self._sun = (list(static), list(tracks))

    def set_time(self, when):
        """Move the sun tracks of :meth:`use_sun_tracks` to ``when`` (aware datetime) and set the lights.

        Returns
        -------
        list of arshadow.lights.sun.TrackFrame
            One per track (``recompute``, ``stale_deg``... for the report).
        """
        if self._sun is None:
            from .errors import UsageError

            raise UsageError("set_time needs sun tracks (Session.use_sun_tracks)")
        static, tracks = self._sun
        frames = [tr.update(when) for tr in tracks]
        self._compositor.set_lights(list(static) + [tr.light(f) for tr, f in zip(tracks, frames)])
        return frames

    def state(self) -> dict:
        """The history later frames depend on, picklable: the current lights with their cached silhouettes
        and volumes, and the sun tracks' recompute schedule. :meth:`restore` it (here or in another
        process's session of the same spec) to go on exactly as this session would."""
        return {"geometry": self._compositor.geometry.state(),
                "sun_tracks": None if self._sun is None else [tr.state() for tr in self._sun[1]]}

    def restore(self, state: dict) -> None:
        """Set the history saved by :meth:`state`."""
        self._compositor.geometry.restore(state["geometry"])
        if state.get("sun_tracks") is not None and self._sun is not None:
            for tr, st in zip(self._sun[1], state["sun_tracks"]):
                tr.restore(st)


def render_photo(spec, image, name: str = "", want_mask: bool = True) -> FrameResult:
    """One photo, one call: ``Session(spec).process(image)`` (context created and released).

    Parameters
    ----------
    spec : SceneSpec, mapping or job file path
    image : (H, W, 3) uint8 BGR, or a path of a photo
    """
    if not isinstance(image, np.ndarray):
        from .io import read_image

        name = name or str(image)
        image = read_image(image)
    with Session(spec) as s:
        return s.process(image, name=name, want_mask=want_mask)
