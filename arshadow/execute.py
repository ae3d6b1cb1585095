"""Carrying out a :class:`arshadow.plan.FramePlan`: CPU geometry -> renderer -> lens warp -> composite.

:func:`execute` builds (or reuses) each light's shadow volume as the plan says, hands the renderer (any
:class:`arshadow.render_api.Renderer`) the canvas's projection and one :class:`~arshadow.render_api.LightPass`
per light, warps the result's layers into the photo's ROI (:class:`arshadow.compose.lens.LensWarp`, or a flip
without distortion) and composites them (:func:`arshadow.compose.composite.composite`).

Mask (CONVENTIONS.md)
    ``(H, W) uint8``: ``round(255 * blocked weight / total weight)`` at pixels that see the ground and are
    not covered by the object, 0 elsewhere.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from ._check import check_shape
from .compose.composite import clip_roi, composite
from .compose.layers import layers_from_warped, pinhole_layers
from .plan import MEASURED
from .render_api import LightPass
from .report import STAGES, ReportItem, StageTimings
from .transforms import CV_TO_GL

__all__ = ["LAYERS_WHY", "STAGES", "execute"]

#: the compose decision's reason when the layers are asked for
LAYERS_WHY = "numpy (layers asked for: the composite and its layers come from the numpy path)"


def execute(
    plan,
    image,
    intr,
    *,
    geometry,
    renderer,
    lens=None,
    work,
    timings: StageTimings | None = None,
    item: ReportItem | None = None,
    want_mask=True,
    out=None,
    mask_out=None,
    chooser=None,
    gpu=None,
    compose_key=None,
    layers: dict | None = None,
    color_gain=None,
):
    """Render and composite one planned frame.

    Parameters
    ----------
    plan : arshadow.plan.FramePlan
        With its ``compose`` decision (:func:`arshadow.plan.decide_compose`) unless empty.
    image : (H, W, 3) uint8
        BGR photo (not modified).
    intr : arshadow.camera.Intrinsics
        Calibration for this photo size (the one planned with).
    geometry : arshadow.plan.SceneGeometry
        Lights and cached silhouettes / volumes (volumes the plan needs are built into it).
    renderer : arshadow.render_api.Renderer
    lens : arshadow.compose.lens.LensWarp or None
        The plan's lens warp (``plan.distorted``).
    work : arshadow.compose.composite.Workspace
        Scratch buffers reused across frames.
    timings : arshadow.report.StageTimings, optional
        Stage times are added to it.
    item : arshadow.report.ReportItem, optional
        Gets the frame's keys: ``mode``, ``modes``, ``silhouette_edges``, ``roi``, ``canvas``, ``znear``,
        ``plan`` (the planner's decisions with their reasons) and, when something was drawn, ``compose``
        (the path taken), ``content`` (canvas pixels with content) and ``composited`` (photo pixels
        composited).
    want_mask : bool
        Also return the full-size mask.
    out, mask_out : arrays, optional
        Buffers for the composite ``(H, W, 3) uint8`` and the mask ``(H, W) uint8``.
    chooser : arshadow.gl.compose.PathChooser, optional
        Times the numpy (``"cpu"``) and the shader (``"gpu"``) lens warp + composite when the plan's
        ``compose`` decision is ``"measure"``, and records the faster under ``compose_key``.
    gpu : callable, optional
        ``gpu() -> arshadow.gl.compose.GpuCompositor`` (made on first use by the caller); the shader path
        needs a renderer with ``render_gpu(...)`` (``renderer.gpu_layers``).
    compose_key : hashable, optional
        The chooser's key of this frame (:meth:`arshadow.session.Session.compose_key`).
    layers : dict, optional
        Asks for the frame's compositing layers: ``layers["layers"]`` receives them
        (:class:`arshadow.compose.layers.Layers`; with ``layers["undistorted"]`` true also their pinhole
        version, ``.undistorted``). They come from the numpy path only: with layers asked for, the numpy path
        makes the composite too (the plan's compose decision becomes ``"cpu"``), so the composite and its
        layers are one computation.
    color_gain : (3,) float, optional
        Per-channel gain on the object's rendered linear colour (the marker paper's exposure match,
        :mod:`arshadow.estimate.match`).

    Returns
    -------
    out : (H, W, 3) uint8
    mask : (H, W) uint8 or None
    """
    timings = timings if timings is not None else StageTimings()
    item = item if item is not None else ReportItem(input="")
    H, W = image.shape[:2]
    passes = _light_passes(plan, geometry, timings, item)
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
    item.plan = {"plan": which, "roi": roi_why, "lights": item.plan}
    if out is None:
        out = image.copy()
    else:
        check_shape(out, f"{H},{W},3", "out")
        np.copyto(out, image)
    mask_full = None
    if want_mask:
        if mask_out is None:
            mask_full = np.zeros((H, W), np.uint8)
        else:
            mask_full = check_shape(mask_out, f"{H},{W}", "mask_out")
            mask_full.fill(0)
    if layers is not None:  # nothing drawn until the numpy path says otherwise
        empty = layers_from_warped(None, None, (0, 0, 0, 0), (H, W), opacity=0.0)
        layers["layers"] = empty
        if layers.get("undistorted"):
            empty.undistorted = layers_from_warped(None, None, (0, 0, 0, 0), (H, W), opacity=0.0)
        if not plan.empty and plan.compose != "cpu":
            plan.decide("compose", "cpu", LAYERS_WHY)
    if plan.empty:
        return out, mask_full  # nothing of the scene is in view
    gain = None if color_gain is None else np.asarray(color_gain, np.float32).reshape(3)
    args = (plan, image, intr, geometry, renderer, lens, work, passes, out, mask_full, want_mask, item, layers, gain)
    _run_compose(args, plan, timings, item, chooser, gpu, compose_key)
    return out, mask_full


def _light_passes(plan, geometry, timings, item) -> list:
    """The renderer's passes, building the volumes the plan needs; ``item.silhouette_edges`` and the
    per-light part of the report's ``plan`` are set (``item.plan``: the list, wrapped by the caller)."""
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
    item.plan = plan_lights
    return passes


def _run_compose(args, plan, timings, item, chooser, gpu, key) -> None:
    """Render, lens warp, composite by the path the plan's ``compose`` decision names (``"measure"``: the
    chooser times both on this frame and keeps the faster for its key)."""
    image, out, mask_full = args[1], args[8], args[9]
    x0, y0, w, h = plan.roi
    choice = plan.compose or "cpu"
    why = next((d.reason for d in reversed(plan.decisions) if d.name == "compose"), "")  # as plan.compose
    clean = None  # the photo's ROI each timed run starts from (below)

    def run(fn):
        def go():
            if clean is not None:
                np.copyto(out[y0 : y0 + h, x0 : x0 + w], clean)
                if mask_full is not None:
                    mask_full[y0 : y0 + h, x0 : x0 + w] = 0
            t = StageTimings()
            fn(*args, timings=t)
            return t

        return go

    paths = {"cpu": run(_compose_cpu)}
    if choice != "cpu":
        paths["gpu"] = run(lambda *a, timings: _compose_gpu(*a, gpu=gpu(), timings=timings))
    if choice == "measure":
        # the chooser times every path, one run after the other: each must start from the untouched photo
        # ROI (a copy of it when the caller composites in place, out is image: the video engine)
        clean = image[y0 : y0 + h, x0 : x0 + w]
        if np.shares_memory(out, image):
            clean = clean.copy()
        choice, used = chooser.run(key, paths)
        why = MEASURED.format(ms=chooser.decisions[key]["ms"])
    else:
        used = paths[choice]()
    timings.add(used)
    item.compose = choice
    item.plan["compose"] = why


def _compose_gpu(
    plan,
    image,
    intr,
    geometry,
    renderer,
    lens,
    work,
    passes,
    out,
    mask_full,
    want_mask,
    item,
    layer_request,
    gain,
    *,
    gpu,
    timings,
):
    """Render with the layers kept on the GPU; lens warp + composite in a shader; one 8-bit readback."""
    opts = geometry.options
    roi, canvas = plan.roi, plan.canvas
    proj = intr.gl_projection(plan.znear, None, canvas=canvas)
    t = time.perf_counter()
    lay = renderer.render_gpu(
        projection=proj,
        view=CV_TO_GL @ plan.cam_from_world,
        width=int(canvas[2]),
        height=int(canvas[3]),
        caster=geometry.caster,
        passes=passes,
        ground_size=opts.ground_size,
        draw_occluder=opts.draw_occluder,
        occluder_color=opts.occluder_color,
        ambient=opts.ambient,
        specular=opts.specular,
    )
    timings.render += (time.perf_counter() - t) * 1e3
    ct: dict = {}
    t = time.perf_counter()
    gpu.compose(
        image,
        lay,
        roi,
        canvas,
        lens=lens,
        opacity=opts.opacity,
        shadow_color=opts.shadow_color,
        draw_occluder=opts.draw_occluder,
        out=out,
        mask_out=mask_full if want_mask else None,
        timings=ct,
        color_gain=(1.0, 1.0, 1.0) if gain is None else tuple(float(v) for v in gain),
    )
    # the readback waits for the render and the shader to finish: it holds the GPU time of both
    timings.readback += ct.get("readback", 0.0)
    timings.composite += (time.perf_counter() - t) * 1e3 - ct.get("readback", 0.0)
    item.composited = list(roi)


def _compose_cpu(
    plan,
    image,
    intr,
    geometry,
    renderer,
    lens,
    work,
    passes,
    out,
    mask_full,
    want_mask,
    item,
    layer_request,
    gain,
    *,
    timings,
):
    """Render, read the float layers back, lens warp (cv2.remap) or flip, composite in numpy."""
    H, W = image.shape[:2]
    opts = geometry.options
    roi, canvas = plan.roi, plan.canvas
    # render the canvas
    proj = intr.gl_projection(plan.znear, None, canvas=canvas)
    view = CV_TO_GL @ plan.cam_from_world
    t = time.perf_counter()
    res = renderer.render(
        projection=proj,
        view=view,
        width=int(canvas[2]),
        height=int(canvas[3]),
        caster=geometry.caster,
        passes=passes,
        ground_size=opts.ground_size,
        draw_occluder=opts.draw_occluder,
        occluder_color=opts.occluder_color,
        ambient=opts.ambient,
        specular=opts.specular,
    )
    dt = (time.perf_counter() - t) * 1e3
    rt = getattr(res, "timings_ms", None) or {}
    if "readback" in rt:
        timings.readback += float(rt["readback"])
        timings.render += dt - float(rt["readback"])
    else:
        timings.render += dt
    layers = getattr(res, "layers", None)
    # lens warp (pinhole canvas -> distorted photo ROI)
    t = time.perf_counter()
    if layers is not None:
        warped = _warp_layers(layers, plan, lens, work, item, W, H)
        if warped is None:  # nothing drawn, or nothing of it in the photo: the photo is unchanged
            timings.warp += (time.perf_counter() - t) * 1e3
            return
        roi, (l0, l1) = warped
        mask, alpha, color = l1[:, :, 0], l0[:, :, 3], l0
        # the canvas top-down (views), for undistorted layers
        pinhole = (layers.mask_ground[::-1, :, 0], layers.rgba[::-1])
    else:
        mask, alpha, color = res.mask, res.alpha, res.color
        pinhole = (mask, np.dstack([color, alpha]))
        if lens is not None:
            mask, alpha, color = lens.warp(roi, canvas, mask, alpha, color, work=work)
    timings.warp += (time.perf_counter() - t) * 1e3

    # composite
    t = time.perf_counter()
    gained = gain is not None and opts.draw_occluder  # the exposure match, linear light (premultiplied colour)
    if gained and layer_request is not None:  # layers hold the gained colour (copies: the renderer's stay)
        color = np.array(color, np.float32)
        color[:, :, :3] *= gain
        if layer_request.get("undistorted"):  # the canvas-sized pinhole copy only for undistorted layers
            pinhole = (pinhole[0], np.array(pinhole[1], np.float32))
            pinhole[1][:, :, :3] *= gain
        gained = False  # applied
    if layer_request is not None:  # execute's ``layers``: gets the frame's layers
        layer_request["layers"] = _frame_layers(
            layer_request.get("undistorted"),
            mask,
            color,
            alpha,
            roi,
            (H, W),
            opts,
            lens is not None,
            pinhole,
            canvas,
            getattr(res, "premultiplied", True),
        )
    composite(
        out,
        mask,
        roi,
        color=color if opts.draw_occluder else None,
        alpha=alpha if opts.draw_occluder else None,
        opacity=opts.opacity,
        shadow_color=opts.shadow_color,
        premultiplied=getattr(res, "premultiplied", True),
        color_gain=gain if gained else None,
        out=out,
        work=work,
    )
    if want_mask:
        x0, y0, w, h = roi
        m = work.get("mask255", (h, w), np.float32)
        np.multiply(mask, np.float32(255.0), out=m)
        m += np.float32(0.5)
        np.clip(m, np.float32(0.0), np.float32(255.0), out=m)
        np.copyto(mask_full[y0 : y0 + h, x0 : x0 + w], m, casting="unsafe")
    timings.composite += (time.perf_counter() - t) * 1e3


def _warp_layers(layers, plan, lens, work, item, W: int, H: int):
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
        warped = lens.warp(roi, canvas, c0, c1, work=work, bottom_up=True)
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


def _frame_layers(undistorted, mask, color, alpha, roi, shape, opts, distorted, pinhole, canvas, premultiplied):
    """The frame's :class:`arshadow.compose.layers.Layers` from the warped arrays the composite uses (and,
    with ``undistorted``, from the pinhole canvas ``pinhole = (mask, rgba)`` too)."""
    rgba = None
    if opts.draw_occluder:
        rgba = color if np.shape(color)[2] == 4 else np.dstack([color, alpha])
    kw = {"opacity": opts.opacity, "shadow_color": opts.shadow_color, "premultiplied": premultiplied}
    lay = layers_from_warped(mask, rgba, roi, shape, **kw)
    if undistorted:
        lay.undistorted = (
            pinhole_layers(pinhole[0], pinhole[1] if opts.draw_occluder else None, canvas, shape, **kw)
            if distorted
            else lay
        )
    return lay
