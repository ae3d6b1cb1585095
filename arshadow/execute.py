"""Carrying out a :class:`arshadow.plan.FramePlan`: CPU geometry -> renderer -> lens warp -> composite.

:func:`execute` builds (or reuses) each light's shadow volume as the plan says, hands the renderer (any
:class:`arshadow.render_api.Renderer`) the canvas's projection and one :class:`~arshadow.render_api.LightPass`
per light, warps the result's layers into the photo's ROI (:class:`arshadow.lens.LensWarp`, or a flip
without distortion) and composites them (:func:`arshadow.composite.composite`).

Mask (CONVENTIONS.md)
    ``(H, W) uint8``: ``round(255 * blocked weight / total weight)`` at pixels that see the ground and are
    not covered by the object, 0 elsewhere.
"""

from __future__ import annotations

import time

import numpy as np

from ._check import check_shape
from .composite import clip_roi, composite
from .render_api import LightPass
from .transforms import CV_TO_GL

__all__ = ["execute", "STAGES"]

#: the per-stage timings of a frame (report ``timings_ms``)
STAGES = ("detect", "pose", "silhouette", "volume", "render", "readback", "warp", "composite", "total")


def execute(plan, image, intr, *, geometry, renderer, lens=None, work, timings=None, want_mask=True, out=None,
            mask_out=None):
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
    lens : arshadow.lens.LensWarp or None
        The plan's lens warp (``plan.distorted``).
    work : arshadow.composite.Workspace
        Scratch buffers reused across frames.
    timings : dict, optional
        Stage timings (:data:`STAGES`) to add to.
    want_mask : bool
        Also return the full-size mask.
    out, mask_out : arrays, optional
        Buffers for the composite ``(H, W, 3) uint8`` and the mask ``(H, W) uint8``.

    Returns
    -------
    out : (H, W, 3) uint8
    mask : (H, W) uint8 or None
    info : dict
        ``mode``, ``modes``, ``silhouette_edges``, ``roi``, ``canvas``, ``znear`` and, when something was
        drawn, ``content`` (canvas pixels with content) and ``composited`` (photo pixels composited).
    """
    timings = timings if timings is not None else dict.fromkeys(STAGES, 0.0)
    H, W = image.shape[:2]
    opts = geometry.options
    roi, canvas = plan.roi, plan.canvas
    # CPU geometry: the volumes the plan needs (cached per light)
    passes, n_edges = [], 0
    for lp in plan.lights:
        ls = geometry.lights[lp.index]
        if lp.mode == "planar":
            vol = sil = None
        else:
            vol = geometry.volume(ls, caps=lp.caps, timings=timings)
            sil = ls.sil
        if sil is not None:
            n_edges += int(len(sil.edges))
        passes.append(LightPass(light_h=ls.light_h, weight=ls.weight, volume=vol, mode=lp.mode))

    info = {"mode": plan.mode, "modes": plan.modes, "silhouette_edges": n_edges, "roi": list(roi),
            "canvas": list(canvas), "znear": plan.znear}

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
            return out, mask_full, info
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
                return out, mask_full, info
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
    return out, mask_full, info
