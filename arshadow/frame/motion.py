"""Motion blur of the inserted layers in a video: the image motion the camera's pose change causes during
the exposure (``--camera-effects on``, ``--motion-blur on``; docs/shading.md "Camera effects").

The model, one frame at a time:

- the frame's image motion is one displacement ``(du, dv)`` px per frame interval: the mean, over the 8
  corners of the object's bounding box (the ground under it too: the box stands on it), of their projected
  positions' change between the neighbouring frames' poses (``cam_from_world``, the ground frame's camera),
  divided by the frames between them (:func:`image_motion`). Central (the previous and the next frame) where
  both have a tracked pose, else one-sided (this frame and the one neighbour that has one);
- during the exposure the image moves by that displacement times the shutter fraction (exposure time /
  frame interval), centred on the frame's time (:func:`frame_motion`);
- the layers (shadow mask, sky occlusion, object coverage and premultiplied colour) are convolved with a
  box kernel along that segment (:func:`motion_kernel`, :func:`motion_blur_layers`).

Left out: the variation of the motion across the object (a rotation about the view axis, a zoom, parallax
between the object's top and the ground), the object's own motion (it is still in the world), the rolling
shutter, and the pose noise in the displacement (the poses are the smoothed ones the frame is rendered with).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

if TYPE_CHECKING:
    from ..camera.model import Intrinsics

__all__ = [
    "DFT_AREA",
    "MIN_SHIFT_PX",
    "MotionBlur",
    "frame_motion",
    "image_motion",
    "kernel_pieces",
    "motion_blur_layers",
    "motion_kernel",
]

#: a blur shorter than this (px, the exposure's displacement) is skipped: under half a pixel the box kernel
#: changes an edge by less than the 8-bit output resolves at most contrasts, and it costs a 2-D filter
MIN_SHIFT_PX = 0.5
#: OpenCV's ``filter2D`` convolves float32 through the DFT from this kernel area on (measured: 6.7-6.9 ms
#: for a 15 x 15 kernel on a 341 x 261 x 4 layer, whatever its taps); below it directly, at the cost of its
#: non-zero taps, so a long kernel is applied in pieces under this area (:func:`kernel_pieces`)
DFT_AREA = 130


@dataclass(frozen=True, eq=False)
class MotionBlur:
    """One video frame's motion blur: what crosses from the video engine to the compositor.

    Attributes
    ----------
    shift_px : (2,) float
        ``(du, dv)`` px: the image displacement during the exposure (``frame_px * shutter``).
    frame_px : (2,) float
        ``(du, dv)`` px per frame interval (:func:`image_motion`).
    shutter : float
        Exposure time / frame interval (0.5: a 180° shutter).
    source : str
        Where the motion came from (the report's ``from``).
    """

    shift_px: tuple[float, float] = (0.0, 0.0)
    frame_px: tuple[float, float] = (0.0, 0.0)
    shutter: float = 0.5
    source: str = ""

    @property
    def length_px(self) -> float:
        """The exposure's displacement, px."""
        return float(math.hypot(*self.shift_px))

    @property
    def active(self) -> bool:
        """The blur is applied (at least :data:`MIN_SHIFT_PX`)."""
        return self.length_px >= MIN_SHIFT_PX

    @property
    def reach(self) -> int:
        """Pixels the blur reaches beyond the layers' content (the kernel's radius; 0 when not applied)."""
        k = self.kernel
        return 0 if k is None else k.shape[0] // 2

    @functools.cached_property
    def kernel(self) -> np.ndarray | None:
        """:func:`motion_kernel` of :attr:`shift_px`; None when not applied."""
        return motion_kernel(self.shift_px) if self.active else None

    def report(self) -> dict[str, object]:
        """The frame's values for the report (``plan.motion_blur``)."""
        why = (
            "applied: box kernel along the exposure's displacement"
            if self.active
            else f"skipped: the exposure's displacement is under {MIN_SHIFT_PX} px"
        )
        return {
            "shift_px": [round(float(v), 3) for v in self.shift_px],
            "length_px": round(self.length_px, 3),
            "frame_motion_px": [round(float(v), 3) for v in self.frame_px],
            "shutter": round(float(self.shutter), 4),
            "from": self.source,
            "applied": self.active,
            "why": why,
        }


def image_motion(
    intr: Intrinsics, points_world: np.ndarray, cam_from_world_a: np.ndarray, cam_from_world_b: np.ndarray
) -> np.ndarray | None:
    """The mean image displacement ``(2,) float64`` px of ``points_world (n, 3) float64`` (world frame)
    from the camera ``cam_from_world_a (4, 4)`` to ``cam_from_world_b (4, 4)`` (lens distortion applied:
    where the real camera images them); None when a point is behind either camera.

    >>> from arshadow.camera.model import Intrinsics
    >>> intr = Intrinsics(500.0, 500.0, 319.5, 239.5, 640, 480)
    >>> a = np.eye(4); a[2, 3] = 1.0
    >>> b = a.copy(); b[0, 3] = 0.01          # the world moves 1 cm to the camera's right, at 1 m
    >>> image_motion(intr, np.zeros((1, 3)), a, b).round(6).tolist()
    [5.0, 0.0]
    """
    pa = intr.project(points_world, cam_from_world_a)
    pb = intr.project(points_world, cam_from_world_b)
    if not (np.isfinite(pa).all() and np.isfinite(pb).all()):
        return None
    d: np.ndarray = (pb - pa).mean(axis=0)
    return d


def frame_motion(
    intr: Intrinsics,
    points_world: np.ndarray,
    cam_from_world: np.ndarray,
    before: tuple[np.ndarray, int] | None,
    after: tuple[np.ndarray, int] | None,
    shutter: float,
) -> MotionBlur:
    """A frame's :class:`MotionBlur` from its neighbours' poses.

    Parameters
    ----------
    intr : arshadow.camera.Intrinsics
        The calibration at the frame's size.
    points_world : (n, 3) float64
        The points whose motion is averaged (the object's box corners, world frame).
    cam_from_world : (4, 4) float64
        The frame's own camera (used by a one-sided difference).
    before, after : ``(cam_from_world (4, 4), frames away (int > 0))`` or None
        The previous / next frame with a pose, None when there is none to use.
    shutter : float
        Exposure time / frame interval.

    Returns
    -------
    MotionBlur
        Zero displacement (not applied) when neither neighbour is given or a point is behind a camera.
    """
    if before is not None and after is not None:
        a, b, n = before[0], after[0], before[1] + after[1]
        source = "central: the previous and the next frame's poses"
    elif before is not None:
        a, b, n = before[0], cam_from_world, before[1]
        source = "backward: the previous frame's pose and this one's (no pose next)"
    elif after is not None:
        a, b, n = cam_from_world, after[0], after[1]
        source = "forward: this frame's pose and the next one's (no pose before)"
    else:
        return MotionBlur(shutter=float(shutter), source="none: no neighbouring frame with a pose")
    d = image_motion(intr, points_world, a, b)
    if d is None:
        return MotionBlur(shutter=float(shutter), source=f"none: the object is behind the camera ({source})")
    per_frame = d / float(n)
    shift = per_frame * float(shutter)
    return MotionBlur(
        shift_px=(float(shift[0]), float(shift[1])),
        frame_px=(float(per_frame[0]), float(per_frame[1])),
        shutter=float(shutter),
        source=source,
    )


def motion_kernel(shift_px: Sequence[float]) -> np.ndarray:
    """``(k, k) float32``, summing to 1: a box of length ``|shift_px|`` along ``shift_px = (du, dv)`` centred
    on the middle texel, sampled 4 times a pixel and splatted bilinearly (point-symmetric: convolution and
    correlation with it are the same); ``k = 2 ceil(|shift| / 2) + 3``.

    >>> k = motion_kernel((4.0, 0.0))
    >>> k.shape, round(float(k.sum()), 6), np.flatnonzero(k.sum(axis=1)).tolist()
    ((7, 7), 1.0, [3])
    >>> k[3].round(3).tolist()
    [0.0, 0.125, 0.25, 0.25, 0.25, 0.125, 0.0]
    """
    du, dv = float(shift_px[0]), float(shift_px[1])
    length = math.hypot(du, dv)
    r = int(math.ceil(length / 2.0)) + 1
    n = max(1, int(math.ceil(4.0 * length)))
    t = (np.arange(n, dtype=np.float64) + 0.5) / n - 0.5  # the midpoints of n equal parts of the segment
    x, y = r + t * du, r + t * dv
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    k = np.zeros((2 * r + 1, 2 * r + 1), np.float64)
    for oy, ox, w in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)), (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + oy, x0 + ox), w)
    kernel: np.ndarray = (k / k.sum()).astype(np.float32)
    return kernel


def kernel_pieces(kernel: np.ndarray) -> list[tuple[np.ndarray, int, int]]:
    """The non-zero taps of ``kernel (k, k)`` cut into pieces whose boxes are under :data:`DFT_AREA`, in
    bands along its longer extent: ``[(piece (h, w) float32, y0, x0)]``, each piece the kernel's values in
    its box at rows ``y0..``, columns ``x0..``; their sum is the kernel.

    >>> ps = kernel_pieces(motion_kernel((30.0, 30.0)))
    >>> len(ps), all(p.size < DFT_AREA for p, _, _ in ps)
    (4, True)
    """
    ys, xs = np.nonzero(kernel)
    horizontal = np.ptp(xs) >= np.ptp(ys)
    along, across = (xs, ys) if horizontal else (ys, xs)
    pieces, start, hi = [], int(along.min()), int(along.max())
    while start <= hi:
        end = start
        while end < hi:  # widen the band while its box stays under the DFT's area
            sel = (along >= start) & (along <= end + 1)
            if (end + 2 - start) * (int(np.ptp(across[sel])) + 1) >= DFT_AREA:
                break
            end += 1
        sel = (along >= start) & (along <= end)
        y0, x0 = int(ys[sel].min()), int(xs[sel].min())
        piece = np.zeros((int(ys[sel].max()) + 1 - y0, int(xs[sel].max()) + 1 - x0), np.float32)
        piece[ys[sel] - y0, xs[sel] - x0] = kernel[ys[sel], xs[sel]]
        pieces.append((piece, y0, x0))
        start = end + 1
    return pieces


def motion_blur_layers(kernel: np.ndarray | None, *layers: np.ndarray | None) -> list[np.ndarray | None]:
    """Each ``(h, w[, c]) float32`` layer convolved with ``kernel (k, k)`` (:func:`motion_kernel`; border:
    0, nothing drawn beyond the arrays); new arrays (None, or a None kernel, passes them through). A kernel
    of :data:`DFT_AREA` or more is applied in :func:`kernel_pieces` on the layer padded by its radius, each
    piece's result taken at its offset: the same sums (to float rounding), at the cost of the taps."""
    out: list[np.ndarray | None] = []
    pieces = None if kernel is None or kernel.size < DFT_AREA else kernel_pieces(kernel)
    for a in layers:
        if a is None or kernel is None:
            out.append(a)
            continue
        a32 = np.ascontiguousarray(a, np.float32)
        if pieces is None:
            out.append(cv2.filter2D(a32, -1, kernel, borderType=cv2.BORDER_CONSTANT))
            continue
        r, (h, w) = kernel.shape[0] // 2, a32.shape[:2]
        padded = cv2.copyMakeBorder(a32, r, r, r, r, cv2.BORDER_CONSTANT, value=0)
        acc = np.zeros_like(a32)
        for piece, y0, x0 in pieces:  # the piece's taps at (y0 + i, x0 + j) read padded[y + y0 + i, x + x0 + j]
            acc += cv2.filter2D(padded, -1, piece, anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)[
                y0 : y0 + h, x0 : x0 + w
            ]
        out.append(acc)
    return out
