"""Edge-based corner refinement: fit the four border edges of a marker at full resolution and intersect
them (``refine="edge"``; unbiased at any marker size, docs/tracking.md)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from ..camera.model import Intrinsics

__all__ = ["refine_corners_edges"]


def refine_corners_edges(
    gray: np.ndarray,
    corners: npt.ArrayLike,
    intrinsics: Intrinsics | None = None,
    *,
    bits: int = 8,
    iterations: int = 3,
    n_samples: int = 24,
    reach_in: float = 0.45,
    reach_out: float = 0.45,
    tol_px: float = 0.01,
) -> np.ndarray:
    """Refine marker corners by fitting the four border edges and intersecting them.

    Why: ``cv2.cornerSubPix`` (ArUco's ``subpix``) puts a corner where the image gradients around it are
    orthogonal to the corner direction. At an *outer* corner of a dark square the blur of the optics
    (and the demosaicing / JPEG) rounds the corner off, and the gradient-orthogonality point moves
    *into* the square by a fraction of the blur radius. The shift is a fixed number of pixels, so the
    smaller the marker, the larger the relative error: every corner moves inwards, the marker looks
    smaller and the pose comes out too far (1-4 % at 640x360 with a 45-px marker, docs/video.md).
    A straight edge blurred by a symmetric point-spread function keeps its 50 % level exactly at the
    edge, so the lines through the edges' mid-level crossings, away from the corners, are unbiased;
    their intersections are the corners.

    Per edge: ``n_samples`` intensity profiles across the edge (bilinear, 0.25-px steps, from the
    inner black border (``reach_in`` of a cell: the data cells beyond it may be white) to the paper
    (``reach_out`` of a cell); the two reaches must be equal: with a blur comparable to the window the
    profile's ends do not reach the plateaus, and only a window centred on the edge truncates them
    equally (measured: 0.45 / 0.6 of a cell puts the corners 0.11 px outwards at blur 0.8, 0.45 / 0.45
    0.002 px)) between 15 % and 85 % of
    its length; the 50 % crossing between the profile's dark and light ends, linearly interpolated; the
    crossings are undistorted to pinhole pixels (``intrinsics``), a total-least-squares line is fitted
    (with one outlier rejection pass), adjacent lines are intersected and the corners distorted back.
    Repeated around the new corners (the profiles re-centred) until no corner moves more than ``tol_px``
    (at most ``iterations`` times).

    Parameters
    ----------
    gray : (H, W) uint8
    corners : (n, 4, 2) float64
        Initial corners TL, TR, BR, BL (distorted pixels), within about a pixel.
    intrinsics : Intrinsics, optional
        The camera (its lens distortion makes the edges curved in the image; None: straight).
    bits : int
        Marker cells across, border included (ArUco 6x6: 8).

    Returns
    -------
    (n, 4, 2) float64
        Refined corners (a marker whose edges cannot be measured keeps its input corners).
    """
    img = np.asarray(gray)
    c_all = np.asarray(corners, np.float64).reshape(-1, 4, 2).copy()
    t = np.linspace(0.15, 0.85, n_samples)
    for m in range(len(c_all)):
        c = c_all[m]
        for _ in range(iterations):
            new, side = _refine_step(img, c, intrinsics, t, bits, reach_in, reach_out)
            if new is None:
                break
            move = np.max(np.linalg.norm(new - c, axis=1)) if np.all(np.isfinite(new)) else np.inf
            if not move < 0.25 * side:
                break
            c = new
            if move <= tol_px:
                break
        c_all[m] = c
    return c_all


def _refine_step(
    img: np.ndarray,
    c: np.ndarray,
    intrinsics: Intrinsics | None,
    t: np.ndarray,
    bits: int,
    reach_in: float,
    reach_out: float,
) -> tuple[np.ndarray | None, float]:
    """One refinement round of one marker ``c (4, 2)``: (new corners (4, 2) or None, mean side px)."""
    H, W = img.shape[:2]
    n_samples = len(t)
    side = float(np.mean(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)))
    bit = side / bits
    offs = np.arange(-float(np.clip(reach_in * bit, 1.0, 6.0)), float(np.clip(reach_out * bit, 1.0, 8.0)) + 1e-9, 0.25)
    centre = c.mean(axis=0)
    a, b = c, np.roll(c, -1, axis=0)  # edge k: corner k -> corner k + 1
    d = b - a
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    nrm = np.stack([d[:, 1], -d[:, 0]], axis=1)
    mid = 0.5 * (a + b)
    flip = np.sum((mid - centre) * nrm, axis=1) < 0
    nrm[flip] *= -1.0  # outward: from the black border to the paper
    base = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]  # (4, S, 2)
    pts = base[:, :, None, :] + offs[None, None, :, None] * nrm[:, None, None, :]  # (4, S, P, 2)
    if pts[..., 0].min() < 0 or pts[..., 1].min() < 0 or pts[..., 0].max() > W - 1 or pts[..., 1].max() > H - 1:
        return None, side  # too close to the image border to measure: keep the corners
    o, ok = _edge_crossings(img, pts, offs)
    edge_pts = base.reshape(-1, 2) + o[:, None] * np.repeat(nrm, n_samples, axis=0)
    ok = ok.reshape(4, n_samples)
    if np.any(ok.sum(axis=1) < 4):
        return None, side
    lens = intrinsics if intrinsics is not None and intrinsics.has_distortion else None
    if lens is not None:
        edge_pts = lens.undistort_pixels(edge_pts)
    lines = _fit_lines(edge_pts.reshape(4, n_samples, 2), ok)
    prev = np.roll(lines, 1, axis=0)  # corner k = edge k-1 x edge k
    x = np.stack(
        [
            prev[:, 1] * lines[:, 2] - prev[:, 2] * lines[:, 1],
            prev[:, 2] * lines[:, 0] - prev[:, 0] * lines[:, 2],
            prev[:, 0] * lines[:, 1] - prev[:, 1] * lines[:, 0],
        ],
        axis=1,
    )
    if np.any(np.abs(x[:, 2]) < 1e-12):
        return None, side
    new = x[:, :2] / x[:, 2:3]
    if lens is not None:
        new = lens.distort_pixels(new)
    return new, side


def _edge_crossings(img: np.ndarray, pts: np.ndarray, offs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 50 % crossing of each profile sampled at ``pts (4, S, P, 2)``: (offset along the normal (4S,),
    valid (4S,) bool)."""
    mx = np.ascontiguousarray(pts[..., 0].reshape(-1, len(offs)), np.float32)
    my = np.ascontiguousarray(pts[..., 1].reshape(-1, len(offs)), np.float32)
    prof = cv2.remap(img, mx, my, cv2.INTER_LINEAR).astype(np.float64)  # (4S, P)
    lo, hi = prof[:, :2].mean(axis=1), prof[:, -2:].mean(axis=1)
    ok = hi - lo > 20.0  # a real dark-to-light edge
    level = 0.5 * (lo + hi)
    above = prof > level[:, None]
    # the crossing: the last sample below the level before the profile stays above it
    idx = len(offs) - 1 - np.argmin(above[:, ::-1], axis=1)  # last index that is below
    idx = np.clip(idx, 0, len(offs) - 2)
    ok &= ~above[np.arange(len(prof)), idx] & above[np.arange(len(prof)), idx + 1]
    p0, p1 = prof[np.arange(len(prof)), idx], prof[np.arange(len(prof)), idx + 1]
    frac = (level - p0) / np.where(p1 - p0 == 0, 1.0, p1 - p0)
    return offs[idx] + frac * (offs[1] - offs[0]), ok


def _fit_lines(q: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Total-least-squares line (closed form) through each edge's points ``q (4, S, 2)`` (valid ``ok
    (4, S)``), with one outlier rejection pass: (4, 3) lines ``a x + b y + c = 0``."""
    w = ok.astype(np.float64)
    for _rej in range(2):
        sw = w.sum(axis=1)
        mu = np.einsum("es,esk->ek", w, q) / sw[:, None]
        dq = q - mu[:, None, :]
        sxx = np.einsum("es,es->e", w, dq[..., 0] ** 2)
        syy = np.einsum("es,es->e", w, dq[..., 1] ** 2)
        sxy = np.einsum("es,es->e", w, dq[..., 0] * dq[..., 1])
        th = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # direction of the line
        nl = np.stack([-np.sin(th), np.cos(th)], axis=1)  # its unit normal
        r = np.einsum("esk,ek->es", dq, nl)
        sd = np.sqrt(np.einsum("es,es->e", w, r * r) / sw)
        keep = (np.abs(r) <= np.maximum(3.0 * sd, 0.05)[:, None]) & ok
        if _rej or np.array_equal(keep, ok) or np.any(keep.sum(axis=1) < 4):
            break
        w = keep.astype(np.float64)
    return np.column_stack([nl, -np.einsum("ek,ek->e", nl, mu)])
