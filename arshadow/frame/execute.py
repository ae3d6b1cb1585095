"""Carrying out a :class:`arshadow.plan.FramePlan`: CPU geometry -> renderer -> lens warp -> composite.

:func:`execute` builds (or reuses) each light's shadow volume as the plan says, hands the renderer (any
:class:`arshadow.renderer.request.Renderer`) the canvas's projection and one :class:`~arshadow.renderer.request.LightPass`
per light, warps the result's layers into the photo's ROI (:class:`arshadow.compose.lens.LensWarp`, or a flip
without distortion) and composites them by the path the plan names: numpy
(:func:`arshadow.frame.numpy_compose.compose_cpu`: :func:`arshadow.compose.composite.composite`, camera effects,
the frame's layers) or shaders (:class:`arshadow.gl.gpu_compose.GpuCompositor`: the composite with the sky
occlusion and the camera effects; not the frame's layers).

Mask (CONVENTIONS.md)
    ``(H, W) uint8``: ``round(255 * blocked weight / total weight)`` at pixels that see the ground and are
    not covered by the object, 0 elsewhere.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from .._check import check_shape
from ..compose.layers import layers_from_warped
from ..compose.look import Look
from ..errors import UsageError
from ..plan.planner import MEASURED
from ..renderer.request import LightPass, RenderRequest, Shading
from ..transforms import CV_TO_GL
from .effects import touched_roi
from .numpy_compose import compose_cpu
from .report import STAGES, ReportItem, StageTimings

if TYPE_CHECKING:
    from ..camera.model import Intrinsics
    from ..compose.composite import Workspace
    from ..compose.layers import Layers
    from ..compose.lens import LensWarp
    from ..geometry.caster import ShadowCaster
    from ..gl.gpu_compose import GpuCompositor, PathChooser
    from ..plan.planner import FramePlan, SceneGeometry
    from ..renderer.request import Renderer
    from ..scene.options import RenderOptions
    from ..shading.decide import GroundLight
    from ..shading.sky import SkyShading
    from .effects import CameraEffects
    from .hooks import CalibrationState
    from .motion import MotionBlur

__all__ = [
    "LAYERS_WHY",
    "MOTION_WHY",
    "OUTLINE_WHY",
    "STAGES",
    "FrameContext",
    "FrameOutputs",
    "LayerRequest",
    "execute",
    "frame_shading",
    "render_request",
]

#: the compose decision's reason when the layers are asked for
LAYERS_WHY = "numpy (layers asked for: the composite and its layers come from the numpy path)"
#: the compose decision's reason when a frame's motion blur is applied (the numpy path's alone)
MOTION_WHY = "numpy (motion blur applied: the shader path does not motion-blur the layers)"
#: the compose decision's reason when the object's outline is anti-aliased (the planner's ``outline_aa``)
OUTLINE_WHY = "numpy (outline anti-aliasing: the shader path composites the render's layers as they are)"
#: the object's own sky visibility and ground bounce (SkyShading.object_sky) with sky occlusion on: the
#: uniform sky. Off until the ground bounce's units were fixed (it lacked the paper's albedo, 1.25 x too
#: much, so vertical faces took too much of the floor's colour); with them right it halves the object's
#: residual on the path-traced reference (own set, tracked pose: median 0.108 -> 0.065; docs/reference.md)
OBJECT_SKY: str | None = "uniform"
#: texels per side of the photo's ground light read for the object's lower faces
#: (:func:`arshadow.shading.decide.ground_light`, over the sky occlusion map's square: 6-8 mm texels for a
#: 7 cm object)
GROUND_LIGHT_RES = 64


class LayerRequest(TypedDict, total=False):
    """:attr:`FrameOutputs.layers`: what the caller asks for (``undistorted``: also the pinhole layers) and
    where :func:`execute` puts the frame's layers (``layers``)."""

    undistorted: bool
    layers: Layers


@dataclass(frozen=True)
class FrameContext:
    """What :func:`execute` needs that lasts a session (a :class:`arshadow.frame.session.Session` makes it).

    Attributes
    ----------
    geometry : arshadow.plan.SceneGeometry
        Lights and cached silhouettes / volumes (volumes the plan needs are built into it).
    renderer : callable
        ``renderer() -> arshadow.renderer.request.Renderer`` (made, with the context, on first use: only frames
        with something to draw ask for it).
    work : arshadow.compose.composite.Workspace
        Scratch buffers reused across frames.
    calibration : callable
        ``calibration(width, height)`` -> :class:`arshadow.frame.hooks.CalibrationState` (``intrinsics``: the
        calibration for this photo size, the one planned with; ``lens``: the plan's lens warp or None).
    compose_key : callable, optional
        ``compose_key(width, height, distorted)``: the chooser's key of a frame.
    chooser : arshadow.gl.gpu_compose.PathChooser, optional
        Times the numpy (``"cpu"``) and the shader (``"gpu"``) lens warp + composite when the plan's
        ``compose`` decision is ``"measure"``, and records the faster under the frame's ``compose_key``.
    gpu : callable, optional
        ``gpu() -> arshadow.gl.gpu_compose.GpuCompositor`` (made on first use by the caller); the shader path
        needs a renderer whose ``gpu_layers`` is True.
    """

    geometry: SceneGeometry
    renderer: Callable[[], Renderer]
    work: Workspace
    calibration: Callable[[int, int], CalibrationState]
    compose_key: Callable[[int, int, bool], Hashable] | None = None
    chooser: PathChooser | None = None
    gpu: Callable[[], GpuCompositor] | None = None


@dataclass
class FrameOutputs:
    """Where :func:`execute` writes one frame, and what it reports.

    Attributes
    ----------
    want_mask : bool
        Also make the full-size mask.
    out, mask_out : arrays, optional
        Buffers for the composite ``(H, W, 3) uint8`` and the mask ``(H, W) uint8`` (``out`` may be the
        image: the video engine composites in place).
    timings : arshadow.frame.report.StageTimings
        Stage times are added to it.
    item : arshadow.frame.report.ReportItem
        Gets the frame's keys: ``mode``, ``modes``, ``silhouette_edges``, ``roi``, ``canvas``, ``znear``,
        ``plan`` (the planner's decisions with their reasons) and, when something was drawn, ``compose``
        (the path taken), ``content`` (canvas pixels with content) and ``composited`` (photo pixels
        composited).
    layers : LayerRequest, optional
        Asks for the frame's compositing layers: ``layers["layers"]`` receives them
        (:class:`arshadow.compose.layers.Layers`; with ``layers["undistorted"]`` true also their pinhole
        version, ``.undistorted``). They come from the numpy path only: with layers asked for, the numpy path
        makes the composite too (the plan's compose decision becomes ``"cpu"``), so the composite and its
        layers are one computation.
    """

    want_mask: bool = True
    out: np.ndarray | None = None
    mask_out: np.ndarray | None = None
    timings: StageTimings = field(default_factory=StageTimings)
    item: ReportItem = field(default_factory=lambda: ReportItem(input=""))
    layers: LayerRequest | None = None


@dataclass
class FrameJob:
    """One frame's compose job, made once by :func:`execute` for whichever path (or both) runs (the numpy
    path: :func:`arshadow.frame.numpy_compose.compose_cpu`; the shader path: :func:`_compose_gpu`)."""

    plan: FramePlan
    image: np.ndarray
    request: RenderRequest
    renderer: Renderer
    lens: LensWarp | None
    work: Workspace
    out: np.ndarray
    mask_full: np.ndarray | None
    outputs: FrameOutputs
    look: Look


def render_request(
    plan: FramePlan,
    intr: Intrinsics,
    geometry: SceneGeometry,
    passes: Sequence[LightPass],
    sky: SkyShading | None = None,
) -> RenderRequest:
    """The frame's :class:`arshadow.renderer.request.RenderRequest`: the plan's canvas, znear and
    ``cam_from_world`` (the ground frame's camera), the scene's caster, the light passes, and the options'
    ground, what to draw and :class:`~arshadow.renderer.request.Shading`."""
    opts, canvas = geometry.options, plan.canvas
    return RenderRequest(
        projection=intr.gl_projection(plan.znear, None, canvas=canvas),
        view=CV_TO_GL @ plan.cam_from_world,
        width=int(canvas[2]),
        height=int(canvas[3]),
        caster=geometry.caster,
        passes=tuple(passes),
        ground_size=opts.ground_size,
        draw_occluder=opts.draw_occluder,
        shading=frame_shading(opts, geometry.caster, sky),
    )


def frame_shading(opts: RenderOptions, caster: ShadowCaster, sky: SkyShading | None) -> Shading:
    """:meth:`Shading.from_options` with the frame's sky; a mesh with its own colours or texture under a
    measured light keeps them, times the exposure gain (``material_gain``), instead of the grey default.

    The mesh's colours are reflectances (glTF's base colour is the surface's albedo, MTL's ``Kd`` its
    diffuse reflectance), while the exposure gain makes a colour of 1 as bright as the marker's paper: they
    are divided by the paper's reflectance (``opts.paper_albedo``, :data:`arshadow.shading.decide.PAPER_ALBEDO`
    by default), so a material as reflective as the paper renders as bright as the paper (it rendered 0.8 x
    as bright before)."""
    sh = Shading.from_options(opts) if sky is None else replace(Shading.from_options(opts), sky=sky)
    if opts.material_gain is not None and (
        getattr(caster, "material", None) is not None or getattr(caster, "colors", None) is not None
    ):
        g = [float(v) / float(opts.paper_albedo) for v in opts.material_gain]
        sh = replace(sh, color=None, albedo_gain=(g[0], g[1], g[2]))
    return sh


def execute(
    plan: FramePlan,
    image: np.ndarray,
    context: FrameContext,
    outputs: FrameOutputs,
    *,
    color_gain: Sequence[float] | np.ndarray | None = None,
    camera: CameraEffects | None = None,
    motion: MotionBlur | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Render and composite one planned frame.

    Parameters
    ----------
    plan : arshadow.plan.FramePlan
        With its ``compose`` decision (:func:`arshadow.plan.decide_compose`) unless empty.
    image : (H, W, 3) uint8
        BGR photo (not modified unless it is ``outputs.out``).
    context : FrameContext
        The session's geometry, renderer, calibrations, scratch buffers and compose-path chooser.
    outputs : FrameOutputs
        Buffers, what to make (mask, layers), timings and report item of this frame (filled in).
    color_gain : (3,) float, optional
        Per-channel gain on the object's rendered linear colour (the marker paper's exposure match,
        :mod:`arshadow.estimate.match`), measured on this frame.
    camera : arshadow.frame.effects.CameraEffects, optional
        The photo's blur and noise, applied to the inserted layers (``--camera-effects on``).
    motion : arshadow.frame.motion.MotionBlur, optional
        A video frame's motion blur of the inserted layers (``--motion-blur on``): its values go to the
        report's ``plan.motion_blur``; applied (by the numpy compose path: the plan's compose decision becomes
        ``"cpu"``) when :attr:`~arshadow.frame.motion.MotionBlur.active`.

    Returns
    -------
    out : (H, W, 3) uint8
    mask : (H, W) uint8 or None
    """
    timings, item, geometry = outputs.timings, outputs.item, context.geometry
    H, W = image.shape[:2]
    passes, plan_lights = _light_passes(plan, geometry, timings, item)
    _report_plan(plan, geometry, item, plan_lights)
    out, mask_full = _output_buffers(image, outputs)
    if outputs.layers is not None:  # nothing drawn until the numpy path says otherwise
        _no_layers(outputs.layers, (H, W))
    outline = next((d for d in reversed(plan.decisions) if d.name == "outline_aa"), None)
    if outline is not None:
        item.plan["outline_aa"] = outline.reason  # type: ignore[index]  # a dict: _report_plan made it
    # what only the numpy path does: the first reason decides the compose path
    numpy_only = (
        (outputs.layers is not None, LAYERS_WHY),
        (motion is not None and motion.active, MOTION_WHY),
        (outline is not None and bool(outline.value), OUTLINE_WHY),
    )
    why = next((w for needed, w in numpy_only if needed), None)
    if why is not None and not plan.empty and plan.compose != "cpu":
        plan.decide("compose", "cpu", why)
    if plan.empty:
        return out, mask_full  # nothing of the scene is in view
    cal = context.calibration(W, H)
    sky = _sky_shading(plan, image, cal.intrinsics, geometry, outputs, color_gain)
    frame = FrameJob(
        plan=plan,
        image=image,
        request=render_request(plan, cal.intrinsics, geometry, passes, sky),
        renderer=context.renderer(),
        lens=cal.lens,
        work=context.work,
        out=out,
        mask_full=mask_full,
        outputs=outputs,
        look=replace(Look.from_options(geometry.options, color_gain), camera=camera, motion=motion),
    )
    if camera is not None:
        outputs.item.plan["camera_effects"] = camera.report()  # type: ignore[index]  # _report_plan's dict
    if motion is not None:
        outputs.item.plan["motion_blur"] = motion.report()  # type: ignore[index]  # _report_plan's dict
    _run_compose(frame, context)
    return out, mask_full


def _sky_shading(
    plan: FramePlan,
    image: np.ndarray,
    intr: Intrinsics,
    geometry: SceneGeometry,
    outputs: FrameOutputs,
    color_gain: Sequence[float] | np.ndarray | None,
) -> SkyShading | None:
    """The frame's :class:`arshadow.shading.sky.SkyShading` (None when the planner's ``ambient_occlusion``
    decision is off): the scene's ground occlusion map (made on first use, by the geometry's
    ``raster_source``), the object's sky visibility and the ground bounce
    measured on this photo round the object (with a measured exposure; 0 otherwise)."""
    from ..shading.decide import decide_ambient_occlusion, ground_bounce, ground_light
    from ..shading.sky import SkyShading, ground_grid

    opts = geometry.options
    made = next((d for d in plan.decisions if d.name == "ambient_occlusion"), None)
    on, why = (bool(made.value), made.reason) if made is not None else decide_ambient_occlusion(opts)
    outputs.item.plan["ambient_occlusion"] = why  # type: ignore[index]  # a dict: _report_plan made it
    if not on:
        return None
    bounce: tuple[float, ...] = (0.0, 0.0, 0.0)
    if opts.exposure_gain is not None and opts.draw_occluder:
        b = geometry.bounds
        c, r = 0.5 * (b[0, :2] + b[1, :2]), 0.5 * float(np.linalg.norm(b[1, :2] - b[0, :2])) + 0.01
        a = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
        ring = np.c_[c[0] + r * np.cos(a), c[1] + r * np.sin(a), np.zeros(32)]
        gain = np.asarray(opts.exposure_gain, np.float64) * (1.0 if color_gain is None else np.asarray(color_gain))
        paper = float(opts.paper_albedo)
        m = ground_bounce(image, intr.project(ring, plan.cam_from_world), gain, paper)
        if m is not None:
            bounce = tuple(float(v) for v in m)

            def field() -> GroundLight:  # the ground round the object as the photo shows it (the paper too)
                x0, y0, t = ground_grid(geometry.caster, GROUND_LIGHT_RES)
                cam = plan.cam_from_world
                grid = (x0, y0, GROUND_LIGHT_RES * t)
                return ground_light(image, lambda p: intr.project(p, cam), gain, grid, paper_albedo=paper)

            geometry.set_ground_light(m, field)  # lights the object's lower faces, reflected back to the ground
            outputs.item.plan["ground_bounce"] = [round(v, 4) for v in bounce]  # type: ignore[index]
    ground = geometry.sky_ground(outputs.timings)
    bleed = geometry.object_bleed
    albedo = tuple(float(v) for v in geometry.object_reflectance()) if any(bounce) else None
    sky = SkyShading(
        ground=ground,
        object_sky=OBJECT_SKY,
        bounce=bounce,
        bleed=bleed,
        albedo=albedo,
        object_ground=geometry.ground_field if any(bounce) else None,
    )
    if sky.colored and bleed is not None:
        outputs.item.plan["colour_bleeding"] = [round(v, 3) for v in bleed]  # type: ignore[index]
    return sky


def _report_plan(plan: FramePlan, geometry: SceneGeometry, item: ReportItem, lights: list[dict[str, Any]]) -> None:
    """The plan's part of the report item (``lights``: the per-light part, of :func:`_light_passes`)."""
    which = (
        "planar"
        if geometry.options.shadow_method == "planar" and geometry.options.plan == "auto"
        else geometry.options.plan
    )
    roi_why = next((d.reason for d in plan.decisions if d.name == "roi"), "")
    item.mode, item.modes, item.roi, item.canvas, item.znear = (
        plan.mode,
        plan.modes,
        list(plan.roi),
        list(plan.canvas),
        plan.znear,
    )
    item.plan = {"plan": which, "roi": roi_why, "lights": lights}


def _output_buffers(image: np.ndarray, outputs: FrameOutputs) -> tuple[np.ndarray, np.ndarray | None]:
    """``(out, mask)``: the composite's buffer holding the photo, and the mask's zeroed (None when the mask
    is not wanted), ``outputs.out`` / ``outputs.mask_out`` when given."""
    H, W = image.shape[:2]
    out = outputs.out
    if out is None:
        out = image.copy()
    else:
        check_shape(out, f"{H},{W},3", "out")
        np.copyto(out, image)
    mask_full = None
    if outputs.want_mask:
        if outputs.mask_out is None:
            mask_full = np.zeros((H, W), np.uint8)
        else:
            mask_full = check_shape(outputs.mask_out, f"{H},{W}", "mask_out")
            mask_full.fill(0)
    return out, mask_full


def _no_layers(request: LayerRequest, shape: tuple[int, int]) -> None:
    """The layers of a frame with nothing drawn (the numpy path replaces them when it draws)."""
    empty = layers_from_warped(None, None, (0, 0, 0, 0), shape, opacity=0.0)
    request["layers"] = empty
    if request.get("undistorted"):
        empty.undistorted = layers_from_warped(None, None, (0, 0, 0, 0), shape, opacity=0.0)


def _light_passes(
    plan: FramePlan, geometry: SceneGeometry, timings: StageTimings, item: ReportItem
) -> tuple[list[LightPass], list[dict[str, Any]]]:
    """The renderer's passes, building the volumes the plan needs, and the per-light part of the report's
    ``plan``; ``item.silhouette_edges`` is set."""
    passes, n_edges, plan_lights = [], 0, []
    for lp in plan.lights:
        ls = geometry.lights[lp.index]
        entry = {"mode": lp.mode, "why": dict(lp.why)}
        if lp.mode in ("planar", "none", "shadowmap"):  # no volume (the shadow-map renderer ignores it)
            vol = sil = None
        else:
            vol = geometry.volume(ls, caps=lp.caps, timings=timings, truncate=lp.truncate)
            sil = ls.sil
            entry["truncated"] = bool(vol.truncated)
        if sil is not None:
            n_edges += int(len(sil.edges))
        plan_lights.append(entry)
        if plan.empty:
            continue
        # a culled light ("none"): no shadow pass, the renderer still shades the occluder with it
        passes.append(
            LightPass(
                light_h=ls.light_h,
                weight=ls.weight,
                volume=vol,
                mode="zpass" if lp.mode == "none" else lp.mode,
                direct=lp.mode == "planar" and geometry.caster.is_convex,
            )
        )
    item.silhouette_edges = n_edges
    return passes, plan_lights


def _run_compose(frame: FrameJob, context: FrameContext) -> None:
    """Render, lens warp, composite by the path the plan's ``compose`` decision names (``"measure"``: the
    chooser times both on this frame and keeps the faster for its key)."""
    plan, image, out, mask_full = frame.plan, frame.image, frame.out, frame.mask_full
    timings, item = frame.outputs.timings, frame.outputs.item
    x0, y0, w, h = _touched(frame)
    choice = plan.compose or "cpu"
    why = next((d.reason for d in reversed(plan.decisions) if d.name == "compose"), "")  # as plan.compose
    clean = None  # the photo's ROI each timed run starts from (below)

    def run(fn: Callable[[FrameJob, StageTimings], None]) -> Callable[[], StageTimings]:
        def go() -> StageTimings:
            if clean is not None:
                np.copyto(out[y0 : y0 + h, x0 : x0 + w], clean)
                if mask_full is not None:
                    mask_full[y0 : y0 + h, x0 : x0 + w] = 0
            t = StageTimings()
            fn(frame, t)
            return t

        return go

    paths = {"cpu": run(compose_cpu)}
    if choice != "cpu":
        gpu = context.gpu
        assert gpu is not None, "the shader compose path needs FrameContext.gpu"
        paths["gpu"] = run(lambda fr, t: _compose_gpu(fr, gpu(), t))
    if choice == "measure":
        chooser, key_of = context.chooser, context.compose_key
        assert chooser is not None and key_of is not None, "measuring needs FrameContext.chooser and compose_key"
        # the chooser times every path, one run after the other: each must start from the untouched photo
        # ROI (a copy of it when the caller composites in place, out is image: the video engine)
        clean = image[y0 : y0 + h, x0 : x0 + w]
        if np.shares_memory(out, image):
            clean = clean.copy()
        key = key_of(image.shape[1], image.shape[0], frame.lens is not None)
        choice, used = chooser.run(key, paths)
        why = MEASURED.format(ms=chooser.decisions[key]["ms"])
    else:
        used = paths[choice]()
    timings.add(used)
    item.compose = choice
    item.plan["compose"] = why  # type: ignore[index]  # a dict: _report_plan made it


def _touched(frame: FrameJob) -> tuple[int, int, int, int]:
    """The photo pixels either compose path may write: the plan's ROI, grown by the blurs' reach."""
    H, W = frame.image.shape[:2]
    return touched_roi(frame.plan.roi, frame.look.camera, frame.look.motion, W, H)


def _compose_gpu(frame: FrameJob, gpu: GpuCompositor, timings: StageTimings) -> None:
    """Render with the layers kept on the GPU; lens warp + composite in a shader; one 8-bit readback."""
    roi = frame.plan.roi
    t = time.perf_counter()
    lay = frame.renderer.render_gpu(frame.request)
    timings.render += (time.perf_counter() - t) * 1e3
    sky = frame.request.shading.sky
    if sky is not None and sky.ground is not None and not lay.sky:
        raise UsageError(
            f"{type(frame.renderer).__name__}.render_gpu left out the sky occlusion the frame asks for "
            "(GpuLayers.sky is False): the shader compose path cannot composite it"
        )
    ct: dict[str, float] = {}
    t = time.perf_counter()
    gpu.compose(
        frame.image,
        lay,
        frame.plan,
        frame.look,
        lens=frame.lens,
        out=frame.out,
        mask_out=frame.mask_full if frame.outputs.want_mask else None,
        timings=ct,
    )
    # the readback waits for the render and the shader to finish: it holds the GPU time of both
    timings.readback += ct.get("readback", 0.0)
    timings.composite += (time.perf_counter() - t) * 1e3 - ct.get("readback", 0.0)
    frame.outputs.item.composited = list(roi)
