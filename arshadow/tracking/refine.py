"""Edge-based corner refinement: fit the four border edges of a marker at full resolution and intersect
them (``refine="edge"``; unbiased at any marker size and whether the image was blurred in linear light or
in code values, docs/tracking.md).

A straight edge blurred by a symmetric point-spread function keeps its 50 % level at the edge *in the
space the blur acted in*. Optics and the sensor's pixel area blur light (linear), then the camera's tone
curve (sRGB) bends the profile: its 50 % code value moves towards the dark side (0.67 x the blur's sigma;
~0.2 px on the path-traced reference plates). Sharpening, JPEG and :mod:`arshadow.synth` blur code
values, where the 50 % code value is right and the 50 % of linear light moves towards the light side. The
marker itself says which is right: its black border is one cell wide. Any bias towards the dark side
makes the measured square smaller *and* the border's white-facing inner edges move outwards, so the
border is measured too thin for the square, by ``2 (1 - border / cells)`` times the bias. So each
marker's edges are fitted in code values and that bias measured; where it is significant, the edges are
fitted again on the image decoded to linear light (:data:`arshadow.compose.composite.SRGB_TO_LINEAR`),
the bias measured there too, and the corners interpolated to where it vanishes (a photo blurred partly in
each space lies between the two fits).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import numpy.typing as npt

from ..compose.composite import SRGB_TO_LINEAR, linear_to_srgb

if TYPE_CHECKING:
    from ..camera.model import Intrinsics

__all__ = [
    "MIN_CONTRAST",
    "MIN_RING_PROFILES",
    "SIGNIFICANCE",
    "SPACES",
    "EdgeRefinement",
    "border_bias",
    "interpolation_weight",
    "refine_corners_edges",
    "refine_edges",
]

#: the spaces the edges' 50 % crossings can be found in: ``auto`` (both, interpolated by the border's
#: width), ``code`` (the image's code values: right for blur in code values), ``linear`` (decoded sRGB)
SPACES = ("auto", "code", "linear")
#: a profile is an edge when its ends differ by more than this many 8-bit code values
MIN_CONTRAST = 20.0
#: the border's inner edges measured with fewer valid profiles than this: no bias measured (code values)
MIN_RING_PROFILES = 8
#: where along each white cell's side the border's inner edge is measured (fractions of the cell)
RING_SAMPLES = (0.35, 0.5, 0.65)
#: the border's bias counts only beyond this many standard errors (:func:`interpolation_weight`): a photo
#: blurred in one space keeps that space's fit despite the measure's noise (measured on the shared webcam
#: clips, whose code values are right: weights at the 90th percentile 0.24 with none, 0.12 with 3)
SIGNIFICANCE = 3.0


@dataclass(frozen=True)
class EdgeRefinement:
    """What :func:`refine_edges` returns.

    Attributes
    ----------
    corners : (n, 4, 2) float64
        The refined corners TL, TR, BR, BL (distorted pixels).
    linear_weight : (n,) float64
        Per marker: 0 the code-value fit, 1 the linear-light fit, between: the interpolation of the two;
        NaN where the border's bias could not be measured (the code-value fit kept) or not asked for.
    bias_code_px, bias_linear_px : (n,) float64
        The border's bias towards the dark side (pixels, along the edges' normals) measured with each fit
        (:func:`border_bias`): ~0 in the space the image was blurred in. NaN where not measured (the
        linear fit's: where the code values' bias was not significant).
    bias_code_se_px, bias_linear_se_px : (n,) float64
        Their standard errors (pixels).
    """

    corners: np.ndarray
    linear_weight: np.ndarray
    bias_code_px: np.ndarray
    bias_linear_px: np.ndarray
    bias_code_se_px: np.ndarray
    bias_linear_se_px: np.ndarray


def refine_corners_edges(
    gray: np.ndarray, corners: npt.ArrayLike, intrinsics: Intrinsics | None = None, **options: Any
) -> np.ndarray:
    """The corners of :func:`refine_edges` (``options``: its keyword parameters): ``(n, 4, 2) float64``
    distorted pixels.

    Examples
    --------
    >>> from arshadow.camera import Intrinsics
    >>> from arshadow.synth import look_at_pose, render_marker_photo
    >>> cam = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    >>> photo = render_marker_photo(cam, look_at_pose([0.1, -0.2, 0.5], [0, 0, 0]), marker_length=0.05,
    ...                             blur_sigma=0.8, noise_sigma=2.0, seed=1)
    >>> start = photo.corners_px[0] + [[0.4, -0.3], [0.2, 0.3], [-0.3, 0.2], [0.1, -0.4]]
    >>> c = refine_corners_edges(cv2.cvtColor(photo.image, cv2.COLOR_BGR2GRAY), start[None], cam)
    >>> bool(np.abs(c[0] - photo.corners_px[0]).max() < 0.1)
    True
    """
    return refine_edges(gray, corners, intrinsics, **options).corners


def refine_edges(
    gray: np.ndarray,
    corners: npt.ArrayLike,
    intrinsics: Intrinsics | None = None,
    *,
    bits: int = 8,
    border: int = 1,
    space: str | Sequence[str] = "auto",
    iterations: int = 3,
    n_samples: int = 24,
    reach_in: float = 0.45,
    reach_out: float = 0.45,
    tol_px: float = 0.01,
) -> EdgeRefinement:
    """Refine marker corners by fitting the four border edges and intersecting them.

    Why: ``cv2.cornerSubPix`` (ArUco's ``subpix``) puts an *outer* corner of a dark square, which the blur
    rounds off, inside the square by a fraction of the blur radius: the smaller the marker, the larger the
    relative error (the pose 1-4 % too far at 640x360 with a 45-px marker, docs/video.md). The lines
    through the edges' 50 % crossings, away from the corners, are unbiased when the crossings are taken in
    the space the blur acted in (the module's docstring); their intersections are the corners.

    Per edge: ``n_samples`` intensity profiles across the edge (bilinear, 0.25-px steps, from the inner
    black border (``reach_in`` of a cell: the data cells beyond it may be white) to the paper
    (``reach_out`` of a cell); the two reaches must be equal: with a blur comparable to the window the
    profile's ends do not reach the plateaus, and only a window centred on the edge truncates them
    equally (measured: 0.45 / 0.6 of a cell puts the corners 0.11 px outwards at blur 0.8, 0.45 / 0.45
    0.002 px)) between 15 % and 85 % of its length; the 50 % crossing between the profile's dark and
    light ends, linearly interpolated; the crossings are undistorted to pinhole pixels (``intrinsics``), a
    total-least-squares line is fitted (with one outlier rejection pass), adjacent lines are intersected
    and the corners distorted back. Repeated around the new corners (the profiles re-centred) until no
    corner moves more than ``tol_px`` (at most ``iterations`` times): in code values, then from there on
    the image decoded to linear light. ``space="auto"``: the border's inner edges facing white data cells
    (the middle of each such cell's side) are measured with the code-value fit's corners
    (:func:`border_bias`); without a bias towards the dark side of more than :data:`SIGNIFICANCE`
    standard errors the code-value fit is the answer (the linear fit is not run); else the same with the
    linear-light fit's corners, and the corners are interpolated between the two fits to where the border's
    bias vanishes (:func:`interpolation_weight`).

    Parameters
    ----------
    gray : (H, W) uint8
        The photo's grey, sRGB code values.
    corners : (n, 4, 2) float64
        Initial corners TL, TR, BR, BL (distorted pixels), within about a pixel.
    intrinsics : Intrinsics, optional
        The camera (its lens distortion makes the edges curved in the image; None: straight).
    bits : int
        Marker cells across, border included (ArUco 6x6: 8).
    border : int
        Cells of black border (ArUco's ``markerBorderBits``).
    space : {"auto", "code", "linear"} or sequence of them
        Where the 50 % crossings are taken (:data:`SPACES`), for all markers or per marker (``n``; a video's
        markers locked to the code values, :class:`arshadow.tracking.edgelock.EdgeSpaceLock`); ``code`` is
        this function's behaviour before 2026-11-28.

    Returns
    -------
    EdgeRefinement
        A marker whose edges cannot be measured keeps its input corners.
    """
    lens = intrinsics if intrinsics is not None and intrinsics.has_distortion else None
    c_all = np.asarray(corners, np.float64).reshape(-1, 4, 2).copy()
    spaces = [space] * len(c_all) if isinstance(space, str) else list(space)
    asked = {space} if isinstance(space, str) else set(spaces)
    if len(spaces) != len(c_all) or not asked <= set(SPACES):
        raise ValueError(f"space must be one of {SPACES} or one of them per marker ({len(c_all)}), got {space!r}")
    weight = np.full(len(c_all), np.nan)
    bias = np.full((4, len(c_all)), np.nan)  # code, linear, their standard errors
    fit = _EdgeFit(np.asarray(gray), lens, np.linspace(0.15, 0.85, n_samples), bits, border, reach_in, reach_out,
                   iterations, tol_px)  # fmt: skip
    for m in range(len(c_all)):
        c_all[m], weight[m], bias[:, m] = fit.marker(c_all[m], spaces[m])
    return EdgeRefinement(c_all, weight, *bias)


def interpolation_weight(
    bias_code: float,
    bias_linear: float,
    se_code: float = 0.0,
    se_linear: float = 0.0,
    significance: float = SIGNIFICANCE,
) -> float:
    """Where between the code-value fit (0) and the linear-light fit (1) the border's bias vanishes.

    From the bias measured with each fit (:func:`border_bias`, pixels towards the dark side; the code
    values' is the larger: the sRGB curve is concave) linearly interpolated, clipped to [0, 1]. The bias
    nearer zero counts only where it exceeds ``significance`` standard errors (``se_*``; it is shrunk
    towards zero by as much): a photo blurred in one space keeps that space's fit exactly instead of a
    weight that follows the measure's noise.

    Returns
    -------
    float
        The weight; NaN when either bias is unknown or the code values' is not the larger (the two fits
        too close to tell apart).

    Examples
    --------
    >>> interpolation_weight(0.75, -0.25), interpolation_weight(0.0, -0.7), interpolation_weight(0.5, 0.25)
    (0.75, 0.0, 1.0)
    >>> interpolation_weight(0.05, -0.6, 0.02, 0.02)  # 0.05 px is 2.5 standard errors: the code fit
    0.0
    >>> interpolation_weight(float("nan"), -0.2)
    nan
    """
    if not (np.isfinite(bias_code) and np.isfinite(bias_linear)) or bias_code - bias_linear <= 1e-6:
        return float("nan")
    w = bias_code / (bias_code - bias_linear)
    if w < 0.5:  # nearer the code fit: its bias shrunk towards zero
        bias_code = float(np.sign(bias_code)) * max(abs(bias_code) - significance * se_code, 0.0)
    else:
        bias_linear = float(np.sign(bias_linear)) * max(abs(bias_linear) - significance * se_linear, 0.0)
    return float(np.clip(bias_code / (bias_code - bias_linear), 0.0, 1.0))


@dataclass(frozen=True)
class _EdgeFit:
    """The edge fit's fixed inputs (one image, one set of parameters) for each marker (:meth:`marker`)."""

    img: np.ndarray
    lens: Intrinsics | None
    t: np.ndarray
    bits: int
    border: int
    reach_in: float
    reach_out: float
    iterations: int
    tol_px: float

    def marker(self, c: np.ndarray, space: str) -> tuple[np.ndarray, float, np.ndarray]:
        """One marker's corners ``c (4, 2)`` refined as :func:`refine_edges` says: ``(corners (4, 2), weight of
        the linear fit, (4,) biases: code, linear, their standard errors)`` (NaN where not measured)."""
        bias = np.full(4, np.nan)
        cc = self.run(c, linear=False) if space != "linear" else c
        if cc is None:
            return c, np.nan, bias  # unmeasurable in code values: the input corners
        if space == "auto":
            bias[0], bias[2] = border_bias(self.img, cc, self.lens, self.bits, self.border, self.reach_in)
            if not bias[0] > SIGNIFICANCE * bias[2]:  # no significant bias towards the dark side: the code
                return cc, (0.0 if np.isfinite(bias[0]) else np.nan), bias  # values' (the linear's is larger)
        cl = self.run(cc, linear=True) if space != "code" else None
        if cl is None or space == "linear":
            return (cc if cl is None else cl), np.nan, bias
        bias[1], bias[3] = border_bias(self.img, cl, self.lens, self.bits, self.border, self.reach_in, linear=True)
        w = interpolation_weight(*bias)
        return (cc + w * (cl - cc) if np.isfinite(w) else cc), w, bias

    def run(self, c: np.ndarray, linear: bool) -> np.ndarray | None:
        """The fit of one marker ``c (4, 2)`` repeated until it settles: corners (4, 2), or None when its
        first round cannot measure the edges (a later round that cannot keeps the corners before it)."""
        for k in range(self.iterations):
            new, side = _refine_step(self.img, c, self.lens, self.t, self.bits, self.reach_in, self.reach_out, linear)
            if new is None:
                return None if k == 0 else c
            move = np.max(np.linalg.norm(new - c, axis=1)) if np.all(np.isfinite(new)) else np.inf
            if not move < 0.25 * side:
                return None if k == 0 else c
            c = new
            if move <= self.tol_px:
                break
        return c


def _refine_step(
    img: np.ndarray,
    c: np.ndarray,
    lens: Intrinsics | None,
    t: np.ndarray,
    bits: int,
    reach_in: float,
    reach_out: float,
    linear: bool,
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
    o, ok = _edge_crossings(_profiles(img, pts.reshape(-1, len(offs), 2), linear), offs, linear)
    edge_pts = base.reshape(-1, 2) + o[:, None] * np.repeat(nrm, n_samples, axis=0)
    ok = ok.reshape(4, n_samples)
    if np.any(ok.sum(axis=1) < 4):
        return None, side
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


def border_bias(
    gray: np.ndarray,
    corners: np.ndarray,
    lens: Intrinsics | None,
    bits: int = 8,
    border: int = 1,
    reach: float = 0.45,
    *,
    linear: bool = False,
) -> tuple[float, float]:
    """How far towards the dark side the edges measured in one space sit, read off the border's width.

    With the corners ``corners (4, 2)`` (distorted pixels) of a fit whose crossings are biased by ``e``
    pixels towards the dark side, the marker's cells come out ``2 e / bits`` too small and the border's
    inner edges (dark outside, white data cell inside) ``e`` too far out: an inner edge is found
    ``2 e (1 - border / bits)`` outside where the corners' homography puts it. Measured where a white data
    cell touches the border (:data:`RING_SAMPLES` of each such cell's side, profiles of ``reach`` cell
    either side, in the same space as the fit: code values, or decoded to linear light when ``linear``),
    in pinhole pixels (``lens``), the median over the profiles.

    Returns
    -------
    (bias, standard error) : (float, float)
        ``e`` in pixels (positive: towards the dark side) and the median's standard error (from the
        profiles' median absolute deviation); NaN, NaN when fewer than :data:`MIN_RING_PROFILES` profiles
        measure (no white cell along the border, the marker too blurred or off the image).

    Examples
    --------
    >>> from arshadow.camera import Intrinsics
    >>> from arshadow.synth import look_at_pose, render_marker_photo
    >>> cam = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    >>> photo = render_marker_photo(cam, look_at_pose([0.1, -0.2, 0.5], [0, 0, 0]), marker_length=0.05,
    ...                             blur_sigma=1.2, seed=1)  # blurred in code values
    >>> gray = cv2.cvtColor(photo.image, cv2.COLOR_BGR2GRAY)
    >>> bias, se = border_bias(gray, photo.corners_px[0], None)  # the true corners, code values: none
    >>> abs(bias) < 0.03, se < 0.02
    (True, True)
    >>> border_bias(gray, photo.corners_px[0], None, linear=True)[0] < -0.3  # linear light: the light side
    True
    """
    q = lens.undistort_pixels(corners) if lens is not None else np.asarray(corners, np.float64)
    unit = np.array([[0, 0], [bits, 0], [bits, bits], [0, bits]], np.float32)
    hom = cv2.getPerspectiveTransform(unit, q.astype(np.float32)).astype(np.float64)
    base, nrm, white = _ring_layout(gray, hom, lens, bits, border)
    nan = (float("nan"), float("nan"))
    if base is None or nrm is None or not np.any(white):
        return nan
    base, nrm = base[white], nrm[white]
    side = float(np.mean(np.linalg.norm(q - np.roll(q, -1, axis=0), axis=1)))
    r = float(np.clip(reach * side / bits, 1.0, 6.0))
    offs = np.arange(-r, r + 1e-9, 0.25)
    pts = base[:, None, :] + offs[None, :, None] * nrm[:, None, :]  # (k, P, 2) pinhole px, dark -> light
    if lens is not None:
        pts = lens.distort_pixels(pts.reshape(-1, 2)).reshape(pts.shape)
    H, W = gray.shape[:2]
    if not np.all(np.isfinite(pts)) or pts.min() < 0 or pts[..., 0].max() > W - 1 or pts[..., 1].max() > H - 1:
        return nan
    o, ok = _edge_crossings(_profiles(gray, pts, linear), offs, linear)
    if ok.sum() < MIN_RING_PROFILES:
        return nan
    v = o[ok]
    med = float(np.median(v))
    se = 1.2533 * 1.4826 * float(np.median(np.abs(v - med))) / np.sqrt(v.size)  # the median's, normal errors
    scale = 2.0 * (1.0 - border / bits)
    return -med / scale, float(se) / scale


@lru_cache(maxsize=8)
def _ring_cells(bits: int, border: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where :func:`_ring_layout` reads, in marker cells (0..bits, x right, y down), sides top, right,
    bottom, left: ``(points (12 k, 2): the k data cells touching each side's border, then the border's
    cells beside them, then the paper 0.4 cell outside; edge (4 k r, 2): :data:`RING_SAMPLES` points on
    each such cell's side along the border; into (4 k r, 2): the unit direction from there into the cell)``.
    """
    inner = np.arange(border, bits - border, dtype=np.float64) + 0.5  # the data cells' centres along a side
    along = ((inner - 0.5)[:, None] + np.asarray(RING_SAMPLES)[None, :]).ravel()
    lo, hi = float(border), float(bits - border)

    def at(a: np.ndarray, b: float, vertical: bool) -> np.ndarray:  # points (a, b), or (b, a) on a vertical side
        xy = np.stack([a, np.full_like(a, b)], axis=1)
        return xy[:, ::-1] if vertical else xy

    # per side: (depth of the data cells, of the border's cells, of the paper, of the inner edge), vertical,
    # the direction into the marker
    sides = [
        ((lo + 0.5, border / 2.0, -0.4, lo), False, (0.0, 1.0)),
        ((hi - 0.5, bits - border / 2.0, bits + 0.4, hi), True, (-1.0, 0.0)),
        ((hi - 0.5, bits - border / 2.0, bits + 0.4, hi), False, (0.0, -1.0)),
        ((lo + 0.5, border / 2.0, -0.4, lo), True, (1.0, 0.0)),
    ]
    points = np.concatenate([at(inner, depth[j], vert) for j in range(3) for depth, vert, _ in sides])
    edge = np.concatenate([at(along, depth[3], vert) for depth, vert, _ in sides])
    into = np.concatenate([np.tile(d, (along.size, 1)) for _, _, d in sides])
    for a in (points, edge, into):
        a.setflags(write=False)
    return points, edge, into


def _ring_layout(
    gray: np.ndarray, hom: np.ndarray, lens: Intrinsics | None, bits: int, border: int
) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray]:
    """The border's inner edge next to each data cell that touches it: ``(base (m, 2) pinhole px on the
    inner edge, its unit normal into the cell (m, 2), the cell is white (m,) bool)``, with
    :data:`RING_SAMPLES` points per cell; ``hom`` maps marker cells (0..bits) to pinhole pixels. None,
    None when the cells cannot be read (off the image)."""
    points, edge, into = _ring_cells(bits, border)
    k = len(points) // 12
    v = _read(gray, _to_image(hom, points, lens))
    if v is None:
        return None, None, np.zeros(0, bool)
    dark, light = float(np.median(v[4 * k : 8 * k])), float(np.median(v[8 * k :]))
    white = np.repeat(v[: 4 * k] > 0.5 * (dark + light), len(RING_SAMPLES)) & (light - dark > MIN_CONTRAST)
    base = _apply(hom, edge)
    nrm = _apply(hom, edge + 0.01 * into) - base
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return base, nrm, white


def _apply(hom: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Homography ``hom (3, 3)`` applied to points ``uv (k, 2)``: (k, 2)."""
    p = uv @ hom[:, :2].T + hom[:, 2]
    out: np.ndarray = p[:, :2] / p[:, 2:3]
    return out


def _to_image(hom: np.ndarray, uv: np.ndarray, lens: Intrinsics | None) -> np.ndarray:
    """Marker cells ``uv (k, 2)`` -> distorted image pixels (k, 2)."""
    p = _apply(hom, uv)
    return lens.distort_pixels(p) if lens is not None else p


def _read(gray: np.ndarray, p: np.ndarray) -> np.ndarray | None:
    """Bilinear code values at pixels ``p (k, 2)``: (k,) float64, None when any is off the image."""
    H, W = gray.shape[:2]
    if not np.all(np.isfinite(p)) or p.min() < 0 or p[:, 0].max() > W - 1 or p[:, 1].max() > H - 1:
        return None
    x = np.ascontiguousarray(p[:, :1], np.float32)
    y = np.ascontiguousarray(p[:, 1:], np.float32)
    return cv2.remap(gray, x, y, cv2.INTER_LINEAR).ravel().astype(np.float64)


def _profiles(img: np.ndarray, pts: np.ndarray, linear: bool) -> np.ndarray:
    """The image sampled (bilinear) at ``pts (k, P, 2)`` pixels (all inside it): (k, P) float64 code
    values, or linear light when ``linear`` (the pixels decoded before the interpolation: the blur's space)."""
    mx = np.ascontiguousarray(pts[..., 0], np.float32)
    my = np.ascontiguousarray(pts[..., 1], np.float32)
    if not linear:
        return cv2.remap(img, mx, my, cv2.INTER_LINEAR).astype(np.float64)
    x0, y0 = int(np.floor(mx.min())), int(np.floor(my.min()))
    x1, y1 = int(np.ceil(mx.max())) + 1, int(np.ceil(my.max())) + 1
    crop = cv2.LUT(np.ascontiguousarray(img[y0:y1, x0:x1]), SRGB_TO_LINEAR)  # float32 linear light
    mx -= np.float32(x0)
    my -= np.float32(y0)
    return cv2.remap(crop, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)


def _edge_crossings(prof: np.ndarray, offs: np.ndarray, linear: bool) -> tuple[np.ndarray, np.ndarray]:
    """The 50 % crossing of each profile ``prof (k, P)`` sampled at offsets ``offs (P,)`` from dark to
    light: (offset (k,), valid (k,) bool). Valid: the ends differ by :data:`MIN_CONTRAST` code values."""
    lo, hi = prof[:, :2].mean(axis=1), prof[:, -2:].mean(axis=1)
    if linear:
        ok = 255.0 * (linear_to_srgb(hi) - linear_to_srgb(lo)) > MIN_CONTRAST
    else:
        ok = hi - lo > MIN_CONTRAST  # a real dark-to-light edge
    level = 0.5 * (lo + hi)
    above = prof > level[:, None]
    # the crossing: the last sample below the level before the profile stays above it
    idx = len(offs) - 1 - np.argmin(above[:, ::-1], axis=1)  # last index that is below
    idx = np.clip(idx, 0, len(offs) - 2)
    r = np.arange(len(prof))
    ok &= ~above[r, idx] & above[r, idx + 1]
    p0, p1 = prof[r, idx], prof[r, idx + 1]
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
