"""The numpy compose path of :func:`arshadow.frame.execute.execute`: render and read the layers back, give the
object's outline its coverage (the plan's ``outline_aa``: :func:`outline_aa`, :mod:`arshadow.compose.outline`; in
the ``warp`` stage's time), lens warp
(:class:`arshadow.compose.lens.LensWarp`) or flip them into the photo's ROI, apply the camera effects
(:mod:`arshadow.frame.effects`), composite (:func:`arshadow.compose.composite.composite`, one
:class:`~arshadow.compose.composite.Overlay` and the frame's :class:`~arshadow.compose.look.Look`) and make the
frame's compositing layers when asked for.

Mask (CONVENTIONS.md)
    ``(H, W) uint8``: ``round(255 * blocked weight / total weight)`` at pixels that see the ground and are
    not covered by the object, 0 elsewhere.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from ..compose.composite import Overlay, clip_roi, composite, sky_planes
from ..compose.layers import layers_from_warped, pinhole_layers
from ..compose.look import Look
from ..compose.outline import antialias_outline
from ..geometry.contour import outline_segments
from ..renderer.request import RenderLayers, RenderResult
from .effects import add_noise, blur_layers, pad_for
from .motion import motion_blur_layers
from .report import ReportItem, StageTimings

if TYPE_CHECKING:
    from ..compose.composite import Workspace
    from ..compose.layers import Layers
    from ..compose.lens import LensWarp
    from ..plan.planner import FramePlan
    from .execute import FrameJob

__all__ = ["compose_cpu", "outline_aa", "outline_on"]


def compose_cpu(frame: FrameJob, timings: StageTimings) -> None:
    """Render, read the float layers back, lens warp (cv2.remap) or flip, composite in numpy: one frame's job
    (:class:`arshadow.frame.execute.FrameJob`) into its buffers; stage times are added to ``timings``."""
    t = time.perf_counter()
    res = frame.renderer.render(frame.request)
    dt = (time.perf_counter() - t) * 1e3
    rt = res.timings_ms or {}
    if "readback" in rt:
        timings.readback += float(rt["readback"])
        timings.render += dt - float(rt["readback"])
    else:
        timings.render += dt
    # the outline's coverage (in the pinhole canvas), then the lens warp (pinhole canvas -> distorted photo ROI)
    t = time.perf_counter()
    if outline_on(frame.plan):
        outline_aa(frame, res)
    warped = _warp_result(frame, res)
    timings.warp += (time.perf_counter() - t) * 1e3
    if warped is None:  # nothing drawn, or nothing of it in the photo: the photo is unchanged
        return
    t = time.perf_counter()
    _composite_cpu(frame, warped)
    timings.composite += (time.perf_counter() - t) * 1e3


def outline_on(plan: FramePlan) -> bool:
    """The plan's ``outline_aa`` decision (:func:`arshadow.plan.planner.decide_outline_aa`; False without)."""
    return bool(next((d.value for d in reversed(plan.decisions) if d.name == "outline_aa"), False))


def outline_aa(frame: FrameJob, res: RenderResult) -> int:
    """Give the object's outline in ``res`` its pixels' coverage, in place (the renderer's fresh arrays;
    :func:`arshadow.compose.outline.antialias_outline`, in the render's pinhole canvas, before the lens
    warp); returns the pixels changed.

    The renderer's bottom-up layers (``res.layers``) are changed where the views ``res.mask`` / ``color`` /
    ``alpha`` see them; without them the top-down fields are changed (the contour's rows flipped)."""
    req = frame.request
    if not req.draw_occluder:
        return 0
    seg = outline_segments(req.caster, req.projection, req.view, req.width, req.height)
    layers = res.layers
    if layers is not None:
        return antialias_outline(layers.rgba, layers.mask_ground, seg)
    seg = seg.copy()
    seg[:, :, 1] = req.height - seg[:, :, 1]  # window (bottom-up) -> top-down rows
    sky = res.sky_occlusion
    planes = [res.mask, res.ground_coverage.astype(np.float32)]
    if sky is not None:
        planes += [sky] if sky.ndim == 2 else list(np.moveaxis(sky, 2, 0))
    rgba, ground = np.dstack([res.color, res.alpha]), np.dstack(planes)
    n = antialias_outline(rgba, ground, seg)
    res.color[...], res.alpha[...], res.mask[...] = rgba[:, :, :3], rgba[:, :, 3], ground[:, :, 0]
    res.ground_coverage = ground[:, :, 1]
    if sky is not None:
        sky[...] = ground[:, :, 2] if sky.ndim == 2 else ground[:, :, 2:5]
    return n


@dataclass
class _Warped:
    """The renderer's layers over the photo rectangle ``roi`` (top-down: ``overlay``, the compositor's input:
    mask, alpha, colour and the sky occlusion, None without), and the canvas's own ``pinhole = (mask, rgba)``
    (top-down) for undistorted layers."""

    roi: tuple[int, int, int, int]
    overlay: Overlay
    pinhole: tuple[np.ndarray, np.ndarray]


def _warp_result(frame: FrameJob, res: RenderResult) -> _Warped | None:
    """The result's layers warped (lens) or flipped into the photo; None when nothing of them lands in it."""
    plan, lens, work = frame.plan, frame.lens, frame.work
    H, W = frame.image.shape[:2]
    layers, premultiplied = res.layers, bool(res.premultiplied)
    if layers is not None:
        warped = _warp_layers(layers, plan, lens, work, frame.outputs.item, W, H)
        if warped is None:
            return None
        roi, (l0, l1) = warped
        sky_shading = frame.request.shading.sky
        refl = l1[:, :, 3] if l1.shape[2] > 3 else None
        bleed = sky_shading.bleed if sky_shading is not None else None
        sky = sky_planes(l1[:, :, 2], refl, bleed) if l1.shape[2] > 2 else None
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


def _composite_cpu(frame: FrameJob, wp: _Warped) -> None:
    """Composite the warped layers into the frame's buffers (and make its layers when asked for)."""
    look, layer_request = frame.look, frame.outputs.layers
    blurs: list[Callable[..., list[np.ndarray | None]]] = []
    reach = 0
    if look.motion is not None and look.motion.kernel is not None:  # the exposure's motion (a video frame)
        kernel = look.motion.kernel
        blurs.append(lambda *a: motion_blur_layers(kernel, *a))
        reach += look.motion.reach
    if look.camera is not None and look.camera.blur_px > 0:  # then the photo's point spread
        sigma = look.camera.blur_px
        blurs.append(lambda *a: blur_layers(sigma, *a))
        reach += pad_for(sigma)
    if blurs:
        wp = _blurred(wp, reach, frame.image.shape, blurs)
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
        table = look.camera.noise_table
        if table is not None:
            add_noise(frame.out[y0 : y0 + h, x0 : x0 + w], alpha, table, look.camera.noise_seed(frame.image))
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


def _blurred(
    wp: _Warped,
    p: int,
    shape: tuple[int, ...],
    blurs: Sequence[Callable[..., list[np.ndarray | None]]],
) -> _Warped:
    """The warped layers grown once by the blurs' reach ``p`` px (zeros: nothing drawn there; within the photo
    of ``shape``), then blurred by each of ``blurs`` in turn, ``blur(mask, alpha, color, sky)`` (the
    exposure's motion, :func:`arshadow.frame.motion.motion_blur_layers`, and the photo's point-spread width,
    :func:`arshadow.frame.effects.blur_layers`; their borders are 0, so one grow by the sum of their reaches
    gives what growing before each gave)."""
    x0, y0, w, h = wp.roi
    H, W = shape[:2]
    nx0, ny0, nx1, ny1 = max(x0 - p, 0), max(y0 - p, 0), min(x0 + w + p, W), min(y0 + h + p, H)
    top, bottom, left, right = y0 - ny0, ny1 - y0 - h, x0 - nx0, nx1 - x0 - w

    def grow(a: np.ndarray | None) -> np.ndarray | None:
        # cv2's border copy: np.pad's Python cost was 0.58 ms a frame for the four layers (720p bench video)
        if a is None:
            return None
        out: np.ndarray = cv2.copyMakeBorder(a, top, bottom, left, right, cv2.BORDER_CONSTANT, value=0)
        return out.reshape(out.shape[:2] + a.shape[2:])  # a (h, w, 1) layer comes back (h, w)

    ov = wp.overlay
    layers = [grow(ov.mask), grow(ov.alpha), grow(ov.color), grow(ov.sky)]
    for blur in blurs:
        layers = blur(*layers)
    mask, alpha, color, sky = layers
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


def _frame_layers(frame: FrameJob, wp: _Warped) -> Layers:
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
