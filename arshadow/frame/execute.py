"""Carrying out a :class:`arshadow.plan.FramePlan`: CPU geometry -> renderer -> lens warp -> composite.

:func:`execute` builds (or reuses) each light's shadow volume as the plan says, hands the renderer (any
:class:`arshadow.renderer.request.Renderer`) the canvas's projection and one :class:`~arshadow.renderer.request.LightPass`
per light, warps the result's layers into the photo's ROI (:class:`arshadow.compose.lens.LensWarp`, or a flip
without distortion) and composites them (:func:`arshadow.compose.composite.composite`).

(About 610 lines, just over the project's ~600: the frame's steps in order -- the request, the volumes, the
two compose paths, the layers, the sky-occlusion and camera-effect steps -- each a function under 80 lines
that reads the same FrameContext / FrameOutputs; the next step that grows goes to a module of its own.)

Mask (CONVENTIONS.md)
    ``(H, W) uint8``: ``round(255 * blocked weight / total weight)`` at pixels that see the ground and are
    not covered by the object, 0 elsewhere.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, TypedDict

import cv2
import numpy as np

from .._check import check_shape
from ..compose.composite import Overlay, clip_roi, composite
from ..compose.layers import layers_from_warped, pinhole_layers
from ..compose.look import Look
from ..plan.planner import MEASURED
from ..renderer.request import LightPass, RenderLayers, RenderRequest, RenderResult, Shading
from ..transforms import CV_TO_GL
from .effects import add_noise, blur_layers, pad_for
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
    from ..shading.sky import SkyShading
    from .effects import CameraEffects
    from .hooks import CalibrationState

__all__ = ["LAYERS_WHY", "STAGES", "FrameContext", "FrameOutputs", "LayerRequest", "execute", "render_request"]

#: the compose decision's reason when the layers are asked for
LAYERS_WHY = "numpy (layers asked for: the composite and its layers come from the numpy path)"
#: the object's own sky visibility and ground bounce (SkyShading.object_sky) in the commands: None (off). On
#: the path-traced reference (tests/benchmarks/score_realism.py, measured light) it made the object's residual
#: worse (held-out median 0.149 -> 0.191, own 0.125 -> 0.134) while the ground's sky occlusion helps; the
#: renderer and the API keep it (SkyShading(object_sky="uniform")) until the object's ambient is re-measured
OBJECT_SKY: str | None = None
#: the shader compositor applies no camera effects
CAMERA_WHY = "numpy (camera effects: blur and noise are applied by the numpy path)"
#: the shader compositor has no sky-occlusion channel yet
SKY_WHY = "numpy (sky occlusion: the sky channel is composited by the numpy path)"


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
class _Frame:
    """One frame's compose job, made once by :func:`execute` for whichever path (or both) runs."""

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
        shading=_shading(opts, geometry.caster, sky),
    )


def _shading(opts: RenderOptions, caster: ShadowCaster, sky: SkyShading | None) -> Shading:
    """:meth:`Shading.from_options` with the frame's sky; a mesh with its own colours or texture under a
    measured light keeps them, times the exposure gain (``material_gain``), instead of the grey default."""
    sh = Shading.from_options(opts) if sky is None else replace(Shading.from_options(opts), sky=sky)
    if opts.material_gain is not None and (
        getattr(caster, "material", None) is not None or getattr(caster, "colors", None) is not None
    ):
        g = [float(v) for v in opts.material_gain]
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
        if not plan.empty and plan.compose != "cpu":
            plan.decide("compose", "cpu", LAYERS_WHY)
    if plan.empty:
        return out, mask_full  # nothing of the scene is in view
    cal = context.calibration(W, H)
    sky = _sky_shading(plan, image, cal.intrinsics, geometry, outputs, color_gain)
    frame = _Frame(
        plan=plan,
        image=image,
        request=render_request(plan, cal.intrinsics, geometry, passes, sky),
        renderer=context.renderer(),
        lens=cal.lens,
        work=context.work,
        out=out,
        mask_full=mask_full,
        outputs=outputs,
        look=replace(Look.from_options(geometry.options, color_gain), camera=camera),
    )
    if camera is not None:
        outputs.item.plan["camera_effects"] = camera.report()  # type: ignore[index]  # _report_plan's dict
        if plan.compose not in (None, "cpu"):
            plan.decide("compose", "cpu", CAMERA_WHY)
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
    decision is off): the scene's ground occlusion map, the object's sky visibility and the ground bounce
    measured on this photo round the object (with a measured exposure; 0 otherwise)."""
    from ..shading.decide import decide_ambient_occlusion, ground_bounce
    from ..shading.sky import SkyShading

    opts = geometry.options
    made = next((d for d in plan.decisions if d.name == "ambient_occlusion"), None)
    on, why = (bool(made.value), made.reason) if made is not None else decide_ambient_occlusion(opts)
    outputs.item.plan["ambient_occlusion"] = why  # type: ignore[index]  # a dict: _report_plan made it
    if not on:
        return None
    if plan.compose not in (None, "cpu"):
        plan.decide("compose", "cpu", SKY_WHY)
    bounce: tuple[float, ...] = (0.0, 0.0, 0.0)
    if opts.exposure_gain is not None and opts.draw_occluder:
        b = geometry.bounds
        c, r = 0.5 * (b[0, :2] + b[1, :2]), 0.5 * float(np.linalg.norm(b[1, :2] - b[0, :2])) + 0.01
        a = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
        ring = np.c_[c[0] + r * np.cos(a), c[1] + r * np.sin(a), np.zeros(32)]
        gain = np.asarray(opts.exposure_gain, np.float64) * (1.0 if color_gain is None else np.asarray(color_gain))
        m = ground_bounce(image, intr.project(ring, plan.cam_from_world), gain)
        if m is not None:
            bounce = tuple(float(v) for v in m)
            geometry.set_ground_light(m)  # lights the object's lower faces, reflected back to the ground
            outputs.item.plan["ground_bounce"] = [round(v, 4) for v in bounce]  # type: ignore[index]
    return SkyShading(ground=geometry.sky_ground(outputs.timings), object_sky=OBJECT_SKY, bounce=bounce)


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
                direct=lp.mode == "planar" and geometry.convex,
            )
        )
    item.silhouette_edges = n_edges
    return passes, plan_lights


def _run_compose(frame: _Frame, context: FrameContext) -> None:
    """Render, lens warp, composite by the path the plan's ``compose`` decision names (``"measure"``: the
    chooser times both on this frame and keeps the faster for its key)."""
    plan, image, out, mask_full = frame.plan, frame.image, frame.out, frame.mask_full
    timings, item = frame.outputs.timings, frame.outputs.item
    x0, y0, w, h = plan.roi
    choice = plan.compose or "cpu"
    why = next((d.reason for d in reversed(plan.decisions) if d.name == "compose"), "")  # as plan.compose
    clean = None  # the photo's ROI each timed run starts from (below)

    def run(fn: Callable[[_Frame, StageTimings], None]) -> Callable[[], StageTimings]:
        def go() -> StageTimings:
            if clean is not None:
                np.copyto(out[y0 : y0 + h, x0 : x0 + w], clean)
                if mask_full is not None:
                    mask_full[y0 : y0 + h, x0 : x0 + w] = 0
            t = StageTimings()
            fn(frame, t)
            return t

        return go

    paths = {"cpu": run(_compose_cpu)}
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


def _compose_gpu(frame: _Frame, gpu: GpuCompositor, timings: StageTimings) -> None:
    """Render with the layers kept on the GPU; lens warp + composite in a shader; one 8-bit readback."""
    roi = frame.plan.roi
    t = time.perf_counter()
    lay = frame.renderer.render_gpu(frame.request)
    timings.render += (time.perf_counter() - t) * 1e3
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


def _compose_cpu(frame: _Frame, timings: StageTimings) -> None:
    """Render, read the float layers back, lens warp (cv2.remap) or flip, composite in numpy."""
    t = time.perf_counter()
    res = frame.renderer.render(frame.request)
    dt = (time.perf_counter() - t) * 1e3
    rt = res.timings_ms or {}
    if "readback" in rt:
        timings.readback += float(rt["readback"])
        timings.render += dt - float(rt["readback"])
    else:
        timings.render += dt
    # lens warp (pinhole canvas -> distorted photo ROI)
    t = time.perf_counter()
    warped = _warp_result(frame, res)
    timings.warp += (time.perf_counter() - t) * 1e3
    if warped is None:  # nothing drawn, or nothing of it in the photo: the photo is unchanged
        return
    t = time.perf_counter()
    _composite_cpu(frame, warped)
    timings.composite += (time.perf_counter() - t) * 1e3


@dataclass
class _Warped:
    """The renderer's layers over the photo rectangle ``roi`` (top-down: ``overlay``, the compositor's input:
    mask, alpha, colour and the sky occlusion, None without), and the canvas's own ``pinhole = (mask, rgba)``
    (top-down) for undistorted layers."""

    roi: tuple[int, int, int, int]
    overlay: Overlay
    pinhole: tuple[np.ndarray, np.ndarray]


def _warp_result(frame: _Frame, res: RenderResult) -> _Warped | None:
    """The result's layers warped (lens) or flipped into the photo; None when nothing of them lands in it."""
    plan, lens, work = frame.plan, frame.lens, frame.work
    H, W = frame.image.shape[:2]
    layers, premultiplied = res.layers, bool(res.premultiplied)
    if layers is not None:
        warped = _warp_layers(layers, plan, lens, work, frame.outputs.item, W, H)
        if warped is None:
            return None
        roi, (l0, l1) = warped
        sky = l1[:, :, 2] if l1.shape[2] > 2 else None
        # the canvas top-down (views), for undistorted layers
        pin = (layers.mask_ground[::-1, :, 0], layers.rgba[::-1])
        return _Warped(roi, Overlay(l1[:, :, 0], l0, l0[:, :, 3], sky, premultiplied), pin)
    roi, canvas = plan.roi, plan.canvas
    mask, alpha, color, sky = res.mask, res.alpha, res.color, res.sky_occlusion
    pinhole = (mask, np.dstack([color, alpha]))
    if lens is not None:
        if sky is not None:
            mask, alpha, color, sky = lens.warp(roi, canvas, mask, alpha, color, sky, work=work)
        else:
            mask, alpha, color = lens.warp(roi, canvas, mask, alpha, color, work=work)
    return _Warped(roi, Overlay(mask, color, alpha, sky, premultiplied), pinhole)


def _composite_cpu(frame: _Frame, wp: _Warped) -> None:
    """Composite the warped layers into the frame's buffers (and make its layers when asked for)."""
    look, layer_request = frame.look, frame.outputs.layers
    if look.camera is not None:
        wp = _blurred(wp, look.camera.blur_px, frame.image.shape)
    if layer_request is not None:  # execute's ``layers``: gets the frame's layers, with the gained colour
        wp = _gained(wp, look, bool(layer_request.get("undistorted")))
        look = replace(look, color_gain=None)  # applied
        layer_request["layers"] = _frame_layers(frame, wp)
    sky = wp.overlay.sky
    composite(
        frame.out,
        replace(wp.overlay, sky=None if sky is None else np.clip(sky, -1.0, 1.0)),
        wp.roi,
        look=look,
        out=frame.out,
        work=frame.work,
    )
    x0, y0, w, h = wp.roi
    alpha, mask = wp.overlay.alpha, wp.overlay.mask
    if look.camera is not None and look.draw_occluder and alpha is not None:
        seed = int(np.asarray(frame.image[::61, ::53], np.int64).sum())  # per photo, reproducible
        add_noise(frame.out[y0 : y0 + h, x0 : x0 + w], alpha, look.camera.noise, seed)
    if frame.mask_full is not None and mask is not None:  # the mask is wanted
        m = frame.work.get("mask255", (h, w), np.float32)
        np.multiply(mask, np.float32(255.0), out=m)
        m += np.float32(0.5)
        np.clip(m, np.float32(0.0), np.float32(255.0), out=m)
        np.copyto(frame.mask_full[y0 : y0 + h, x0 : x0 + w], m, casting="unsafe")


def _gained(wp: _Warped, look: Look, undistorted: bool) -> _Warped:
    """``wp`` with the look's exposure match applied to copies of its colour (linear light, premultiplied
    colour; the renderer's arrays stay) and, for ``undistorted`` layers, of its canvas-sized pinhole RGBA
    (only then); ``wp`` itself without a gain or without the object."""
    gain, color = look.color_gain, wp.overlay.color
    if gain is None or not look.draw_occluder or color is None:
        return wp
    color = np.array(color, np.float32)
    color[:, :, :3] *= gain
    pinhole = wp.pinhole
    if undistorted:
        pinhole = (pinhole[0], np.array(pinhole[1], np.float32))
        pinhole[1][:, :, :3] *= gain
    return _Warped(wp.roi, replace(wp.overlay, color=color), pinhole)


def _blurred(wp: _Warped, sigma: float, shape: tuple[int, ...]) -> _Warped:
    """The warped layers grown by the blur's reach (zeros: nothing drawn there) and blurred by the photo's
    point-spread width (:func:`arshadow.frame.effects.blur_layers`)."""
    if sigma <= 0:
        return wp
    p = pad_for(sigma)
    x0, y0, w, h = wp.roi
    H, W = shape[:2]
    nx0, ny0, nx1, ny1 = max(x0 - p, 0), max(y0 - p, 0), min(x0 + w + p, W), min(y0 + h + p, H)
    pads = ((y0 - ny0, ny1 - y0 - h), (x0 - nx0, nx1 - x0 - w))

    def grow(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.pad(a, pads + ((0, 0),) * (a.ndim - 2))

    ov = wp.overlay
    mask, alpha, color, sky = blur_layers(sigma, grow(ov.mask), grow(ov.alpha), grow(ov.color), grow(ov.sky))
    return _Warped((nx0, ny0, nx1 - nx0, ny1 - ny0), Overlay(mask, color, alpha, sky, ov.premultiplied), wp.pinhole)


def _warp_layers(
    layers: RenderLayers, plan: FramePlan, lens: LensWarp | None, work: Workspace, item: ReportItem, W: int, H: int
) -> tuple[tuple[int, int, int, int], tuple[np.ndarray, np.ndarray]] | None:
    """The renderer's own bottom-up RGBA (colour, alpha) and RG (mask, ground) arrays into the photo: one
    remap (lens) or flip each instead of three strided arrays, and only over the part that has content.

    Returns ``(roi, (rgba, mask_ground))`` top-down over the photo rectangle ``roi``, or None when nothing
    was drawn (``item.content`` None) or nothing of it lands in the plan's ROI. Sets ``item.content`` and
    ``item.composited``.
    """
    roi, canvas = plan.roi, plan.canvas
    c0, c1 = layers.rgba, layers.mask_ground
    ch, cw = c0.shape[:2]
    act = c1[:, :, 0] > 0
    act |= c0[:, :, 3] > 0
    if c1.shape[2] > 2:  # the sky-occlusion channel reaches beyond the shadow (the contact shadow)
        act |= c1[:, :, 2] != 0
    rows = np.flatnonzero(act.any(axis=1))
    if rows.size == 0:
        item.content = None
        return None
    cols = np.flatnonzero(act.any(axis=0))
    r0, r1 = ch - 1 - int(rows[-1]), ch - 1 - int(rows[0])  # top-down canvas rows
    k0, k1 = int(cols[0]), int(cols[-1])
    item.content = [int(canvas[0]) + k0, int(canvas[1]) + r0, k1 - k0 + 1, r1 - r0 + 1]
    if lens is not None:
        # photo pixels whose pinhole point can see the content (+1 px: bilinear support)
        rect = (canvas[0] + k0 - 1.0, canvas[1] + r0 - 1.0, canvas[0] + k1 + 1.0, canvas[1] + r1 + 1.0)
        sub = clip_roi(lens.distorted_roi(rect, margin=1), W, H)
        x0 = max(sub[0], roi[0])
        y0 = max(sub[1], roi[1])
        x1 = min(sub[0] + sub[2], roi[0] + roi[2])
        y1 = min(sub[1] + sub[3], roi[1] + roi[3])
        if x1 <= x0 or y1 <= y0:
            return None
        roi = (x0, y0, x1 - x0, y1 - y0)
        w0, w1 = lens.warp(roi, canvas, c0, c1, work=work, bottom_up=True)
        warped: tuple[np.ndarray, np.ndarray] = (w0, w1)
    else:
        roi = (int(canvas[0]) + k0, int(canvas[1]) + r0, k1 - k0 + 1, r1 - r0 + 1)
        b0, b1 = ch - 1 - r1, ch - r0  # the same rows, bottom-up
        s0, s1 = c0[b0:b1, k0 : k1 + 1], c1[b0:b1, k0 : k1 + 1]
        warped = (
            cv2.flip(s0, 0, dst=work.get("flip0", s0.shape, np.float32)),
            cv2.flip(s1, 0, dst=work.get("flip1", s1.shape, np.float32)),
        )
    item.composited = list(roi)
    return roi, warped


def _frame_layers(frame: _Frame, wp: _Warped) -> Layers:
    """The frame's :class:`arshadow.compose.layers.Layers` from the warped arrays the composite uses (and,
    with ``undistorted`` asked for, from the pinhole canvas ``wp.pinhole = (mask, rgba)`` too)."""
    look, shape, ov = frame.look, frame.image.shape[:2], wp.overlay
    rgba = None
    if look.draw_occluder and ov.color is not None and ov.alpha is not None:
        rgba = ov.color if np.shape(ov.color)[2] == 4 else np.dstack([ov.color, ov.alpha])
    kw: dict[str, Any] = {"opacity": look.opacity, "shadow_color": look.shadow_color, "premultiplied": ov.premultiplied}
    lay = layers_from_warped(ov.mask, rgba, wp.roi, shape, **kw)
    if (frame.outputs.layers or {}).get("undistorted"):
        lay.undistorted = (
            pinhole_layers(wp.pinhole[0], wp.pinhole[1] if look.draw_occluder else None, frame.plan.canvas, shape, **kw)
            if frame.lens is not None
            else lay
        )
    return lay
