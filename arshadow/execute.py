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

import numpy as np

from ._check import check_shape
from .compose.composite import clip_roi, composite
from .render_api import LightPass
from .transforms import CV_TO_GL

__all__ = ["execute", "STAGES"]

#: the per-stage timings of a frame (report ``timings_ms``)
STAGES = ("detect", "pose", "silhouette", "volume", "render", "readback", "warp", "composite", "total")


def execute(plan, image, intr, *, geometry, renderer, lens=None, work, timings=None, want_mask=True, out=None,
            mask_out=None, chooser=None, gpu=None):
    """Render and composite one planned frame.

    Parameters
    ----------
    plan : arshadow.plan.FramePlan
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
    timings : dict, optional
        Stage timings (:data:`STAGES`) to add to.
    want_mask : bool
        Also return the full-size mask.
    out, mask_out : arrays, optional
        Buffers for the composite ``(H, W, 3) uint8`` and the mask ``(H, W) uint8``.
    chooser : arshadow.gl.compose.PathChooser, optional
        Picks the numpy (``"cpu"``) or the shader (``"gpu"``) lens warp + composite by measurement, per
        photo size, anti-aliasing and lens; without it (or without ``gpu``) the numpy path runs.
    gpu : callable, optional
        ``gpu() -> arshadow.gl.compose.GpuCompositor`` (made on first use by the caller); needs a renderer
        with ``render(..., readback=False)`` (``renderer.gpu_layers``).

    Returns
    -------
    out : (H, W, 3) uint8
    mask : (H, W) uint8 or None
    info : dict
        ``mode``, ``modes``, ``silhouette_edges``, ``roi``, ``canvas``, ``znear``, ``plan`` (the planner's
        decisions with their reasons, for the report) and, when something was drawn, ``compose`` (the
        path taken), ``content`` (canvas pixels with content) and ``composited`` (photo pixels composited).
    """
    timings = timings if timings is not None else dict.fromkeys(STAGES, 0.0)
    H, W = image.shape[:2]
    roi, canvas = plan.roi, plan.canvas
    # CPU geometry: the volumes the plan needs (cached per light)
    passes, n_edges = [], 0
    plan_lights = []
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
        passes.append(LightPass(light_h=ls.light_h, weight=ls.weight, volume=vol,
                                mode="zpass" if lp.mode == "none" else lp.mode,
                                direct=lp.mode == "planar" and geometry.convex))

    opts_plan = geometry.options.plan
    which = "planar" if geometry.options.shadow_method == "planar" and opts_plan == "auto" else opts_plan
    roi_why = next((d.reason for d in plan.decisions if d.name == "roi"), "")
    info = {"mode": plan.mode, "modes": plan.modes, "silhouette_edges": n_edges, "roi": list(roi),
            "canvas": list(canvas), "znear": plan.znear,
            "plan": {"plan": which, "roi": roi_why, "lights": plan_lights}}

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
    if plan.empty:
        return out, mask_full, info  # nothing of the scene is in view

    # render, lens warp, composite: the numpy path or the shader path (arshadow/gl/compose.py), whichever
    # measured faster for this photo size on this backend (timed on first use)
    args = (plan, image, intr, geometry, renderer, lens, work, passes, out, mask_full, want_mask, info)
    x0, y0, w, h = roi
    clean = None  # the photo's ROI each run starts from, when the chooser runs several (below)

    def run(fn):
        def go():
            if clean is not None:
                np.copyto(out[y0 : y0 + h, x0 : x0 + w], clean)
                if mask_full is not None:
                    mask_full[y0 : y0 + h, x0 : x0 + w] = 0
            t = dict.fromkeys(STAGES, 0.0)
            fn(*args, timings=t)
            return t
        return go

    paths = {"cpu": run(_compose_cpu)}
    if (chooser is not None and gpu is not None and getattr(renderer, "gpu_layers", False)
            and out.flags.c_contiguous and (mask_full is None or mask_full.flags.c_contiguous)):
        paths["gpu"] = run(lambda *a, timings: _compose_gpu(*a, gpu=gpu(), timings=timings))
    ctx = getattr(renderer, "ctx", None)
    backend = (getattr(ctx, "info", None) or {}).get("GL_RENDERER", "?") if ctx is not None else "?"
    key = (backend, W, H, int(geometry.options.aa), lens is not None)
    if len(paths) > 1 and chooser.force is None and key not in chooser.decisions:
        # the chooser times every path, one run after the other: each must start from the untouched photo
        # ROI (a copy of it when the caller composites in place, out is image: the video engine)
        clean = image[y0 : y0 + h, x0 : x0 + w]
        if np.shares_memory(out, image):
            clean = clean.copy()
    if len(paths) == 1 or chooser.force == "cpu":
        choice, used = "cpu", paths["cpu"]()
        why = "numpy (the shader path is not available here)" if len(paths) == 1 else "forced cpu"
    else:
        choice, used = chooser.run(key, paths)
        why = f"forced {choice}" if chooser.force else \
            f"measured on first use in this process: {chooser.decisions[key]['ms']} ms (median)"
    for k, v in used.items():
        timings[k] += v
    info["compose"] = choice
    info["plan"]["compose"] = why
    return out, mask_full, info


def _compose_gpu(plan, image, intr, geometry, renderer, lens, work, passes, out, mask_full, want_mask, info, *,
                 gpu, timings):
    """Render with the layers kept on the GPU; lens warp + composite in a shader; one 8-bit readback."""
    opts = geometry.options
    roi, canvas = plan.roi, plan.canvas
    proj = intr.gl_projection(plan.znear, None, canvas=canvas)
    t = time.perf_counter()
    lay = renderer.render(projection=proj, view=CV_TO_GL @ plan.cam_from_world, width=int(canvas[2]),
                          height=int(canvas[3]), caster=geometry.caster, passes=passes, ground_size=opts.ground_size,
                          draw_occluder=opts.draw_occluder, occluder_color=opts.occluder_color, readback=False)
    timings["render"] += (time.perf_counter() - t) * 1e3
    ct = {}
    t = time.perf_counter()
    gpu.compose(image, lay, roi, canvas, lens=lens, opacity=opts.opacity, shadow_color=opts.shadow_color,
                draw_occluder=opts.draw_occluder, out=out, mask_out=mask_full if want_mask else None, timings=ct)
    # the readback waits for the render and the shader to finish: it holds the GPU time of both
    timings["readback"] += ct.get("readback", 0.0)
    timings["composite"] += (time.perf_counter() - t) * 1e3 - ct.get("readback", 0.0)
    info["composited"] = list(roi)


def _compose_cpu(plan, image, intr, geometry, renderer, lens, work, passes, out, mask_full, want_mask, info, *,
                 timings):
    """Render, read the float layers back, lens warp (cv2.remap) or flip, composite in numpy."""
    H, W = image.shape[:2]
    opts = geometry.options
    roi, canvas = plan.roi, plan.canvas
    # render the canvas
    proj = intr.gl_projection(plan.znear, None, canvas=canvas)
    view = CV_TO_GL @ plan.cam_from_world
    t = time.perf_counter()
    res = renderer.render(projection=proj, view=view, width=int(canvas[2]), height=int(canvas[3]),
                          caster=geometry.caster, passes=passes, ground_size=opts.ground_size,
                          draw_occluder=opts.draw_occluder, occluder_color=opts.occluder_color)
    dt = (time.perf_counter() - t) * 1e3
    rt = getattr(res, "timings_ms", None) or {}
    if "readback" in rt:
        timings["readback"] += float(rt["readback"])
        timings["render"] += dt - float(rt["readback"])
    else:
        timings["render"] += dt
    layers = getattr(res, "layers", None)
    # lens warp (pinhole canvas -> distorted photo ROI)
    t = time.perf_counter()
    if layers is not None:
        # the renderer's own bottom-up RGBA (colour, alpha) and RG (mask, ground) arrays: one remap or
        # flip each instead of three strided arrays; and only over the part that has content
        c0, c1 = layers.rgba, layers.mask_ground
        ch, cw = c0.shape[:2]
        act = c1[:, :, 0] > 0
        act |= c0[:, :, 3] > 0
        rows = np.flatnonzero(act.any(axis=1))
        if rows.size == 0:  # nothing drawn: the photo is unchanged
            timings["warp"] += (time.perf_counter() - t) * 1e3
            info["content"] = None
            return
        cols = np.flatnonzero(act.any(axis=0))
        r0, r1 = ch - 1 - int(rows[-1]), ch - 1 - int(rows[0])  # top-down canvas rows
        k0, k1 = int(cols[0]), int(cols[-1])
        info["content"] = [int(canvas[0]) + k0, int(canvas[1]) + r0, k1 - k0 + 1, r1 - r0 + 1]
        if lens is not None:
            # photo pixels whose pinhole point can see the content (+1 px: bilinear support)
            rect = (canvas[0] + k0 - 1.0, canvas[1] + r0 - 1.0, canvas[0] + k1 + 1.0, canvas[1] + r1 + 1.0)
            sub = clip_roi(lens.distorted_roi(rect, margin=1), W, H)
            x0 = max(sub[0], roi[0])
            y0 = max(sub[1], roi[1])
            x1 = min(sub[0] + sub[2], roi[0] + roi[2])
            y1 = min(sub[1] + sub[3], roi[1] + roi[3])
            if x1 <= x0 or y1 <= y0:
                timings["warp"] += (time.perf_counter() - t) * 1e3
                return
            roi = (x0, y0, x1 - x0, y1 - y0)
            l0, l1 = lens.warp(roi, canvas, c0, c1, work=work, bottom_up=True)
        else:
            import cv2

            roi = (int(canvas[0]) + k0, int(canvas[1]) + r0, k1 - k0 + 1, r1 - r0 + 1)
            b0, b1 = ch - 1 - r1, ch - r0  # the same rows, bottom-up
            s0, s1 = c0[b0:b1, k0 : k1 + 1], c1[b0:b1, k0 : k1 + 1]
            l0 = cv2.flip(s0, 0, dst=work.get("flip0", s0.shape, np.float32))
            l1 = cv2.flip(s1, 0, dst=work.get("flip1", s1.shape, np.float32))
        info["composited"] = list(roi)
        mask, alpha, color = l1[:, :, 0], l0[:, :, 3], l0
    else:
        mask, alpha, color = res.mask, res.alpha, res.color
        if lens is not None:
            mask, alpha, color = lens.warp(roi, canvas, mask, alpha, color, work=work)
    timings["warp"] += (time.perf_counter() - t) * 1e3

    # composite
    t = time.perf_counter()
    composite(out, mask, roi, color=color if opts.draw_occluder else None,
              alpha=alpha if opts.draw_occluder else None, opacity=opts.opacity,
              shadow_color=opts.shadow_color, premultiplied=getattr(res, "premultiplied", True), out=out, work=work)
    if want_mask:
        x0, y0, w, h = roi
        m = work.get("mask255", (h, w), np.float32)
        np.multiply(mask, np.float32(255.0), out=m)
        m += np.float32(0.5)
        np.clip(m, np.float32(0.0), np.float32(255.0), out=m)
        np.copyto(mask_full[y0 : y0 + h, x0 : x0 + w], m, casting="unsafe")
    timings["composite"] += (time.perf_counter() - t) * 1e3
