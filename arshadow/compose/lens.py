"""Lens distortion for compositing: render in pinhole space, warp to where the distorted camera sees it.

The renderer draws an ideal pinhole image. A photo from a real lens is distorted (OpenCV's model,
CONVENTIONS.md), so every composited pixel must be looked up where the *distorted* camera would have imaged
it. For each distorted pixel centre ``(u, v)`` of the photo, :meth:`Intrinsics.undistort_pixels` gives the
exact pinhole pixel ``(u', v')`` that the same ray hits (iterated to < 1e-6 px); the rendered
pinhole canvas is resampled there with :func:`cv2.remap` (bilinear). The map is built once per calibration
(:class:`LensWarp`, cached) and sliced per frame to the region of interest, so a frame pays only for the
pixels it composites.

A calibration without distortion needs no warp at all: the pipeline then renders straight into the photo's
pixel grid and never builds a map.

Rectangles: an image ROI is ``(x0, y0, w, h)`` integers (pixels ``x0 .. x0+w-1``); a pinhole rectangle is
``(u0, v0, u1, v1)`` floats (pixel-centre coordinates, inclusive bounds); a canvas is the integer
``(u0, v0, w, h)`` pixel sub-rectangle of the pinhole image that
:meth:`Intrinsics.gl_projection(..., canvas=...)` renders.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cached_property
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..errors import CalibrationError
from .composite import Workspace

if TYPE_CHECKING:
    from ..camera.model import Intrinsics

__all__ = ["LensWarp", "undistort_map"]

#: value stored in the map for distorted pixels whose undistortion does not exist (outside the model's
#: valid region): far outside any canvas, so remap returns the border value 0 there
INVALID = -1.0e6


def _undistort_grid(intrinsics: Intrinsics, us: np.ndarray, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole coordinates of the distorted pixel centres ``us x vs`` (float64, INVALID where none)."""
    uu, vv = np.meshgrid(np.asarray(us, np.float64), np.asarray(vs, np.float64))
    uv = np.column_stack([uu.ravel(), vv.ravel()])
    und = np.asarray(intrinsics.undistort_pixels(uv), dtype=np.float64).reshape(len(vs), len(us), 2)
    bad = ~np.all(np.isfinite(und), axis=2)
    und[bad] = INVALID
    return und[:, :, 0], und[:, :, 1]


def undistort_map(intrinsics: Intrinsics, roi: Sequence[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole pixel coordinates of every distorted pixel centre of the image (or of ``roi``).

    Parameters
    ----------
    intrinsics : arshadow.camera.Intrinsics
        Calibration with image size ``width`` x ``height`` and distortion.
    roi : (x0, y0, w, h), optional
        Only these pixels (default the whole image).

    Returns
    -------
    map_x, map_y : (h, w) float32
        ``(map_x[v, u], map_y[v, u])`` is the pinhole pixel that distorted pixel ``(x0 + u, y0 + v)``
        sees; :data:`INVALID` where the distortion cannot be inverted.
    """
    x0, y0, w, h = (0, 0, int(intrinsics.width), int(intrinsics.height)) if roi is None else roi
    maps_x = np.empty((h, w), np.float32)
    maps_y = np.empty((h, w), np.float32)
    rows = max(1, 262144 // max(w, 1))  # chunks of ~256k points keep memory small
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        mx, my = _undistort_grid(intrinsics, np.arange(x0, x0 + w), np.arange(y0 + r0, y0 + r1))
        maps_x[r0:r1] = mx
        maps_y[r0:r1] = my
    return maps_x, maps_y


class LensWarp:
    """Cached warp from pinhole canvases to the distorted photo for one calibration.

    Parameters
    ----------
    intrinsics : arshadow.camera.Intrinsics
        Calibration of the photo (already scaled to its size).
    stride : int
        Grid step (pixels) of the coarse map used to find the distorted ROI of a pinhole rectangle.

    Notes
    -----
    The full-resolution map is filled lazily in 64 x 64 tiles: a frame pays for
    :meth:`~Intrinsics.undistort_pixels` only on the tiles its ROI touches for the first time; later frames
    slice the cached map. The ROI search uses a coarse grid (every ``stride`` pixels) computed once.
    """

    #: side of the square tiles in which the full-resolution map is computed on first use
    TILE = 64

    def __init__(self, intrinsics: Intrinsics, stride: int = 8) -> None:
        self.intrinsics = intrinsics
        self.width, self.height = int(intrinsics.width), int(intrinsics.height)
        self.stride = int(stride)
        T = self.TILE
        self._mx = np.full((self.height, self.width), INVALID, np.float32)
        self._my = np.full((self.height, self.width), INVALID, np.float32)
        self._done = np.zeros(((self.height + T - 1) // T, (self.width + T - 1) // T), bool)

    def ensure(self, roi: Sequence[int]) -> None:
        """Compute the map's tiles that ``roi = (x0, y0, w, h)`` touches (each tile once per calibration)."""
        x0, y0, w, h = roi
        if w <= 0 or h <= 0:
            return
        T = self.TILE
        r0, r1 = y0 // T, (y0 + h - 1) // T + 1
        c0, c1 = x0 // T, (x0 + w - 1) // T + 1
        todo = ~self._done[r0:r1, c0:c1]
        if not np.any(todo):
            return
        # compute whole rows of missing tiles at once (one vectorised call per tile row)
        for r in range(r0, r1):
            cols = np.flatnonzero(todo[r - r0]) + c0
            if cols.size == 0:
                continue
            a, b = int(cols[0]), int(cols[-1]) + 1
            ys = slice(r * T, min(self.height, (r + 1) * T))
            xs = slice(a * T, min(self.width, b * T))
            mx, my = undistort_map(self.intrinsics, (xs.start, ys.start, xs.stop - xs.start, ys.stop - ys.start))
            self._mx[ys, xs] = mx
            self._my[ys, xs] = my
            self._done[r, a:b] = True

    @property
    def tiles_done(self) -> np.ndarray:
        """(rows, cols) bool, read-only: which ``TILE`` x ``TILE`` tiles of the map are computed."""
        v = self._done.view()
        v.flags.writeable = False
        return v

    def maps_partial(self) -> tuple[np.ndarray, np.ndarray]:
        """``(map_x, map_y)`` (H, W) float32 as computed so far (read-only; valid in :attr:`tiles_done`)."""
        mx, my = self._mx.view(), self._my.view()
        mx.flags.writeable = my.flags.writeable = False
        return mx, my

    @property
    def maps(self) -> tuple[np.ndarray, np.ndarray]:
        """``(map_x, map_y)`` (H, W) float32 for the whole image (computes every missing tile)."""
        self.ensure((0, 0, self.width, self.height))
        return self._mx, self._my

    @cached_property
    def _cells(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Coarse cells (``stride`` pixels, the last ones shorter) and the pinhole bounding box of each.

        Returns ``(rows, cols, lo_u, lo_v, hi_u, hi_v)``: node rows/columns and per-cell (r, c) boxes
        grown by a slack that covers the map's deviation from its corner values inside a cell (1 px plus
        the map's curvature bound; cells touching invalid nodes get the Lipschitz bound times the cell
        size).
        """
        s = self.stride
        cols = np.unique(np.r_[np.arange(0, self.width, s), self.width - 1])
        rows = np.unique(np.r_[np.arange(0, self.height, s), self.height - 1])
        cx, cy = _undistort_grid(self.intrinsics, cols, rows)
        valid = cx > INVALID / 2
        if not np.any(valid):
            raise CalibrationError("the distortion coefficients cannot be inverted anywhere in the image")
        corners = lambda a: np.stack([a[:-1, :-1], a[:-1, 1:], a[1:, :-1], a[1:, 1:]])  # noqa: E731
        vc = corners(valid)
        big = np.inf
        lo_u = np.where(vc, corners(cx), big).min(axis=0)
        hi_u = np.where(vc, corners(cx), -big).max(axis=0)
        lo_v = np.where(vc, corners(cy), big).min(axis=0)
        hi_v = np.where(vc, corners(cy), -big).max(axis=0)
        # Lipschitz bound of the map between neighbouring nodes (pinhole px per distorted px)
        lip = 1.0
        for arr in (cx, cy):
            for ax in (0, 1):
                d = np.abs(np.diff(arr, axis=ax))
                if ax == 0:
                    ok, step = valid[:-1] & valid[1:], np.diff(rows)[:, None]
                else:
                    ok, step = valid[:, :-1] & valid[:, 1:], np.diff(cols)[None, :]
                if np.any(ok):
                    lip = max(lip, float(np.max((d / step)[ok])))
        # inside a cell the smooth map departs from the box of its corner values by at most the
        # curvature term (second differences over the cell): measured, plus 1 px of safety
        curv = 0.0
        for arr in (cx, cy):
            for ax in (0, 1):
                d2 = np.abs(np.diff(arr, n=2, axis=ax))
                ok = (
                    (valid[:-2] & valid[1:-1] & valid[2:])
                    if ax == 0
                    else (valid[:, :-2] & valid[:, 1:-1] & valid[:, 2:])
                )
                if np.any(ok):
                    curv = max(curv, float(np.max(d2[ok])))
        slack = np.where(vc.all(axis=0), 1.0 + curv, lip * s * math.sqrt(2.0) + 1.0)
        return rows, cols, lo_u - slack, lo_v - slack, hi_u + slack, hi_v + slack

    @cached_property
    def pinhole_extent(self) -> tuple[float, float, float, float]:
        """``(u0, v0, u1, v1)``: bounding box of the pinhole pixels the whole distorted image sees (from the
        coarse cells, grown by their slack: conservative)."""
        _, _, lo_u, lo_v, hi_u, hi_v = self._cells
        ok = np.isfinite(lo_u)
        return (float(lo_u[ok].min()), float(lo_v[ok].min()), float(hi_u[ok].max()), float(hi_v[ok].max()))

    def distorted_roi(self, pinhole_rect: Sequence[float], margin: int = 1) -> tuple[int, int, int, int]:
        """The photo ROI ``(x0, y0, w, h)`` holding every distorted pixel whose pinhole point is in the rect.

        Conservative: the image is split into ``stride``-pixel cells, each with the pinhole bounding box of
        its corners grown by the map's measured curvature (+1 px); the ROI is the union of the cells
        whose box meets the rectangle, grown by ``margin``.

        Parameters
        ----------
        pinhole_rect : (u0, v0, u1, v1) float
            Pinhole pixel-centre rectangle (inclusive).
        """
        rows, cols, lo_u, lo_v, hi_u, hi_v = self._cells
        u0, v0, u1, v1 = (float(x) for x in pinhole_rect)
        hit = (hi_u >= u0) & (lo_u <= u1) & (hi_v >= v0) & (lo_v <= v1)
        if not np.any(hit):
            return (0, 0, 0, 0)
        r = np.flatnonzero(np.any(hit, axis=1))
        c = np.flatnonzero(np.any(hit, axis=0))
        m = int(margin)
        x0 = max(0, int(cols[c[0]]) - m)
        x1 = min(self.width, int(cols[c[-1] + 1]) + m + 1)
        y0 = max(0, int(rows[r[0]]) - m)
        y1 = min(self.height, int(rows[r[-1] + 1]) + m + 1)
        return (x0, y0, x1 - x0, y1 - y0)

    def canvas_for(self, roi: Sequence[int], pinhole_rect: Sequence[float] | None = None) -> tuple[int, int, int, int]:
        """The pinhole canvas ``(u0, v0, w, h)`` the photo ROI samples (bilinear neighbours included).

        Parameters
        ----------
        roi : (x0, y0, w, h) int
            Photo ROI (distorted pixels).
        pinhole_rect : (u0, v0, u1, v1) float, optional
            Where content can be at all; the canvas is clipped to it (grown by 2 px).
        """
        x0, y0, w, h = roi
        if w == 0 or h == 0:
            return (0, 0, 0, 0)
        self.ensure(roi)
        sx, sy = self._mx[y0 : y0 + h, x0 : x0 + w], self._my[y0 : y0 + h, x0 : x0 + w]
        valid = sx > INVALID / 2
        if not np.any(valid):
            return (0, 0, 0, 0)
        if np.all(valid):
            a0, a1, b0, b1 = float(sx.min()), float(sx.max()), float(sy.min()), float(sy.max())
        else:
            a0, a1, b0, b1 = (
                float(sx[valid].min()),
                float(sx[valid].max()),
                float(sy[valid].min()),
                float(sy[valid].max()),
            )
        if pinhole_rect is not None:
            p0, q0, p1, q1 = pinhole_rect
            a0, b0 = max(a0, p0 - 2.0), max(b0, q0 - 2.0)
            a1, b1 = min(a1, p1 + 2.0), min(b1, q1 + 2.0)
            if a1 < a0 or b1 < b0:
                return (0, 0, 0, 0)
        u0, v0 = math.floor(a0) - 1, math.floor(b0) - 1
        u1, v1 = math.ceil(a1) + 1, math.ceil(b1) + 1
        return (u0, v0, u1 - u0 + 1, v1 - v0 + 1)

    def warp(
        self,
        roi: Sequence[int],
        canvas: Sequence[int],
        *arrays: np.ndarray,
        interpolation: int | None = None,
        work: Workspace | None = None,
        bottom_up: bool = False,
    ) -> list[np.ndarray]:
        """Resample canvas-sized arrays at the photo ROI's pinhole points.

        Parameters
        ----------
        roi : (x0, y0, w, h) int
            Photo ROI (the output size is ``(h, w)``).
        canvas : (u0, v0, cw, ch) int
            Where the arrays sit in the pinhole image.
        *arrays : (ch, cw) or (ch, cw, c) float32
            Rendered arrays (mask, colour, alpha...). Not modified.
        interpolation : int, optional
            cv2 flag; bilinear by default.
        work : arshadow.compose.composite.Workspace, optional
            Scratch buffers to reuse (the results are then views into it, valid until the next call).
        bottom_up : bool
            The arrays' rows are OpenGL's (row 0 = the canvas's BOTTOM row); the flip is folded into the
            map, so no flipped copy is made.

        Returns
        -------
        list of (h, w[, c]) float32
            One per input; 0 where the ROI looks outside the canvas.
        """
        x0, y0, w, h = roi
        u0, v0 = canvas[0], canvas[1]
        self.ensure(roi)
        mx, my = self._mx, self._my
        if work is None:
            work = Workspace()
        map_x = work.get("lens_mx", (h, w), np.float32)
        map_y = work.get("lens_my", (h, w), np.float32)
        np.subtract(mx[y0 : y0 + h, x0 : x0 + w], np.float32(u0), out=map_x)
        if bottom_up:  # canvas row r (top-down) is array row ch - 1 - r
            np.subtract(np.float32(canvas[3] - 1 + v0), my[y0 : y0 + h, x0 : x0 + w], out=map_y)
        else:
            np.subtract(my[y0 : y0 + h, x0 : x0 + w], np.float32(v0), out=map_y)
        m1, m2 = cv2.convertMaps(map_x, map_y, cv2.CV_16SC2)
        flag = cv2.INTER_LINEAR if interpolation is None else interpolation
        out = []
        for i, a in enumerate(arrays):
            a = np.asarray(a)
            if a.dtype == bool:
                a = a.astype(np.float32)
            dst = work.get(f"lens_out{i}", (h, w) + a.shape[2:], a.dtype)
            cv2.remap(a, m1, m2, flag, dst=dst, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            out.append(dst)
        return out
