"""The photo's evidence of the probe's shadow, sampled on a grid of the ground, and the model it is fit with.

The photo is resampled on a regular grid of the ground plane z = 0 around the probe (every grid point
projected through the camera, lens distortion included; bilinear in linear light). A sample is *used* when
it is inside the image, unsaturated, not seen through the probe (the probe's own faces, dilated by :data:`PROBE_SEAM_PX`)
and not on the marker's pattern. The marker's paper is a second albedo class (:func:`.paper.paper_cells`: the
sheet's rectangle, lit or shadowed). The shadow model of a candidate light is the probe's exact ground shadow (the
projection of its vertices from the light: their convex hull for a convex probe, the union of its projected
triangles otherwise). A convex probe's is drawn as the grid's samples see it (:func:`hull_coverage`): each
edge a step blurred by the photo's own point spread (measured on the marker), its pixels and the
resampling, in metres of ground across that edge (:func:`edge_sigma`); it moves continuously with the light.
A non-convex probe's is rasterised with 4 x 4 supersampling (soft coverage at the edges, in steps).

The fit (per frame, closed form): ``hp(log Y) = delta * hp(S)`` in least squares, ``Y`` the luminance,
``S`` the modelled shadow coverage, ``delta`` the log of the shadow's darkness, and ``hp`` a high-pass: the
value minus its Gaussian-weighted local mean (scale ``sigma``, a little under the probe's width) among the
used cells of the same albedo class (floor or paper; normalised convolution). The high-pass removes the
floor's slow variations and the paper / floor step, and keeps what a shadow changes: its edges and its
inside near them. The rest of the texture is the residual; its sum of squares (RSS) is the objective the
light is chosen by (analysis by synthesis: a light is as good as its exact shadow explains the photo).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import erfc

from ..camera.model import Intrinsics
from ..compose.composite import SRGB_TO_LINEAR
from ..geometry.exact import ground_shadow_triangles, points_in_triangles
from ..transforms import transform_points
from .exposure import LUMA
from .optics import PIXEL_VARIANCE
from .paper import paper_cells

__all__ = [
    "LUMA",
    "Evidence",
    "build_evidence",
    "edge_sigma",
    "fit_levels",
    "ground_jacobian",
    "hull_coverage",
    "sample_blur_px",
    "shadow_coverage",
]

#: supersampling of the shadow raster (per grid cell side)
SS = 4
#: :func:`edge_pairs`' edge cells: ``|blurred coverage - 0.5|`` under this (Phi(0.5) - 0.5: half a cell)
EDGE_BAND = 0.19
#: blur-scaled distances past which a blurred edge's coverage is 0 or 1 (Phi(-6) ~ 1e-9)
ERF_REACH = 6.0
#: the least blur of a shadow's edge on a grid, cells (:func:`edge_sigma`)
MIN_EDGE_CELLS = 0.3
#: variance (px^2) the bilinear resampling's tent adds across an edge (averaged over the sample's phase)
TENT_VARIANCE = 1.0 / 6.0
#: the probe's image is left out with this seam, pixels (its faces bleed into the ground through blur)
PROBE_SEAM_PX = 4.0


@dataclass
class Evidence:
    """One photo's samples of the ground around the probe.

    Attributes
    ----------
    x0, y0, step : float
        World (x, y) of grid cell (0, 0) and the grid spacing, metres; cell (i, j) is at
        ``(x0 + j * step, y0 + i * step)``.
    log_y : (ny, nx) float64
        Log luminance (linear light) of the photo at each cell.
    rgb : (ny, nx, 3) float64
        Linear RGB at each cell.
    used : (ny, nx) bool
        Cells that enter the fit.
    paper : (ny, nx) bool
        Cells of the paper class.
    verts : (n, 3) float64, faces : (m, 3) int
        The probe in the world frame.
    convex : bool
        The probe is convex (its shadow is the hull of its projected vertices).
    sigma : float
        Scale of the high-pass, metres.
    supersample : int
        Samples per cell side of a non-convex probe's shadow raster.
    blur_px : float or None
        Standard deviation (image pixels) of a sharp edge on the ground as a grid sample sees it: the
        photo's blur, its pixels' area and the bilinear resampling (:func:`sample_blur_px`); None: unknown.
    jacobian : (2, 2) float64 or None
        ``d(u, v) / d(x, y)`` at the probe: image pixels per metre of ground (:func:`ground_jacobian`).
    """

    x0: float
    y0: float
    step: float
    log_y: np.ndarray
    rgb: np.ndarray
    used: np.ndarray
    paper: np.ndarray
    verts: np.ndarray
    faces: np.ndarray
    convex: bool
    sigma: float = 0.03
    supersample: int = SS
    blur_px: float | None = None
    jacobian: np.ndarray | None = None

    def __post_init__(self) -> None:
        self._norms: list | None = None
        self._residual: np.ndarray | None = None

    @property
    def shape(self) -> tuple:
        return self.log_y.shape

    def class_norms(self) -> list:
        """[(class mask (ny, nx) bool, Gaussian-blurred class mask (ny, nx) float32)] for the used floor and
        paper cells (cached)."""
        if self._norms is None:
            self._norms = []
            for cls in (self.used & ~self.paper, self.used & self.paper):
                if cls.any():
                    norm = smooth(self, cls.astype(np.float32))
                    self._norms.append((cls, np.maximum(norm, 1e-6)))
        return self._norms

    def residual(self) -> np.ndarray:
        """The high-passed log luminance (cached), (ny, nx) float32."""
        if self._residual is None:
            self._residual = highpass(self, self.log_y)
        return self._residual

    def cells_of(self, xy: np.ndarray) -> np.ndarray:
        """World (x, y) (n, 2) -> fractional grid (col, row) (n, 2)."""
        return (np.asarray(xy, np.float64) - [self.x0, self.y0]) / self.step


def _probe_footprint(uv_grid: np.ndarray, uvp: np.ndarray, faces: np.ndarray, dilate_px: float) -> np.ndarray:
    """bool (n,): image points ``uv_grid`` (n, 2) on the probe, whose vertices project to ``uvp`` (k, 2)
    (triangles ``faces``), dilated by ``dilate_px``."""
    tri = uvp[faces]
    ok = np.all(np.isfinite(tri), axis=(1, 2))
    inside = points_in_triangles(uv_grid, tri[ok])
    if dilate_px <= 0 or not inside.any():
        return inside
    lo = np.floor(np.nanmin(uvp, axis=0) - dilate_px - 2).astype(int)
    hi = np.ceil(np.nanmax(uvp, axis=0) + dilate_px + 2).astype(int)
    w, h = int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)
    img: np.ndarray = np.zeros((h, w), np.uint8)
    for t in tri[ok]:
        cv2.fillConvexPoly(img, np.round((t - lo) * 16).astype(np.int32), 1, cv2.LINE_8, shift=4)
    k = 2 * int(math.ceil(dilate_px)) + 1
    img = cv2.dilate(img, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    q = np.round(uv_grid - lo).astype(int)
    sel = (q[:, 0] >= 0) & (q[:, 0] < w) & (q[:, 1] >= 0) & (q[:, 1] < h)
    out = inside.copy()
    out[sel] |= img[q[sel, 1], q[sel, 0]] > 0
    return out


def build_evidence(
    image_bgr: np.ndarray,
    intr: Intrinsics,
    cam_from_world: np.ndarray,
    verts: np.ndarray,
    faces: np.ndarray,
    *,
    marker_length: float,
    paper_rgb: np.ndarray | Sequence[float],
    center: np.ndarray,
    half: float,
    step: float,
    convex: bool = True,
    sigma: float = 0.03,
    supersample: int = SS,
    blur_px: float | None = None,
) -> Evidence:
    """Sample one photo on a ground grid around the probe.

    Parameters
    ----------
    image_bgr : (H, W, 3) uint8
    intr : Intrinsics
        The photo's camera.
    cam_from_world : (4, 4) float64
    verts : (n, 3) float64, faces : (m, 3) int
        The probe, world frame.
    marker_length : float
        The marker's side (its pattern is left out; its paper margin is a class of its own).
    paper_rgb : (3,) float
        The lit paper's linear RGB (:func:`arshadow.estimate.exposure.measure_exposure`).
    center : (2,) float
        Grid centre, world (x, y).
    half, step : float
        Half-side of the square grid and its spacing, metres.
    convex : bool
        Whether the probe is convex.
    sigma : float
        Scale of the high-pass (metres): slower variations of the ground are left out of the fit.
    supersample : int
        Samples per cell side of a non-convex probe's shadow raster.
    blur_px : float, optional
        A sharp ground edge's blur as the samples see it, pixels (:func:`sample_blur_px`); the shadow's
        modelled edges take it (:func:`hull_coverage`).
    """
    n = round(2 * half / step) + 1
    x0, y0 = float(center[0]) - half, float(center[1]) - half
    gx, gy = np.meshgrid(x0 + step * np.arange(n), y0 + step * np.arange(n))
    pts = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    pose = np.asarray(cam_from_world, np.float64)
    cam = transform_points(pose, pts)
    front = cam[:, 2] > 1e-6
    uv = np.full((len(pts), 2), np.nan)
    uv[front] = intr.project(pts[front], pose)
    H, W = image_bgr.shape[:2]
    inimg = (
        front
        & np.all(np.isfinite(uv), axis=1)
        & (uv[:, 0] >= 1)
        & (uv[:, 0] <= W - 2)
        & (uv[:, 1] >= 1)
        & (uv[:, 1] <= H - 2)
    )
    uv_s = np.where(inimg[:, None], uv, -10.0).astype(np.float32).reshape(n, n, 2)
    lin = cv2.LUT(image_bgr, SRGB_TO_LINEAR)
    rgb = cv2.remap(lin, uv_s[:, :, 0], uv_s[:, :, 1], cv2.INTER_LINEAR).reshape(-1, 3)[:, ::-1].astype(np.float64)
    raw = cv2.remap(image_bgr, uv_s[:, :, 0], uv_s[:, :, 1], cv2.INTER_NEAREST).reshape(-1, 3)
    used = inimg & (raw.max(axis=1) < 253) & (rgb.min(axis=1) > 1e-4)
    # not through the probe (its faces and a 2 px seam), nor on the marker's pattern
    pin = np.full((len(pts), 2), np.nan)
    pin[front] = intr.project(pts[front], pose, distort=False)
    vuse = np.flatnonzero(used)
    uvp = intr.project(np.asarray(verts, np.float64), pose, distort=False)
    on_probe = _probe_footprint(pin[vuse], uvp, np.asarray(faces), PROBE_SEAM_PX)
    used[vuse[on_probe]] = False
    m = 0.5 * marker_length * 1.08
    used &= ~((np.abs(pts[:, 0]) <= m) & (np.abs(pts[:, 1]) <= m))
    paper = paper_cells(pts[:, :2].reshape(n, n, 2), rgb.reshape(n, n, 3), used.reshape(n, n), paper_rgb, marker_length)
    y = rgb @ LUMA
    log_y = np.log(np.maximum(y, 1e-6))
    return Evidence(
        x0,
        y0,
        float(step),
        log_y.reshape(n, n),
        rgb.reshape(n, n, 3),
        used.reshape(n, n),
        paper,
        np.asarray(verts, np.float64),
        np.asarray(faces),
        bool(convex),
        float(sigma),
        int(supersample),
        None if blur_px is None else float(blur_px),
        ground_jacobian(intr, pose, center),
    )


def shadow_coverage(ev: Evidence, light_h: np.ndarray) -> np.ndarray | None:
    """The probe's exact ground shadow for a light, as coverage of the evidence's grid.

    Parameters
    ----------
    ev : Evidence
    light_h : (4,) float
        ``(dx, dy, dz, 0)`` towards a directional light or ``(x, y, z, 1)`` a point light.

    Returns
    -------
    (ny, nx) float32 in [0, 1] or None
        None when the light casts no bounded shadow (below the probe's top or the horizon).
    """
    h = np.asarray(light_h, np.float64)
    v = ev.verts
    if h[3] == 0.0:
        if h[2] <= 1e-3:
            return None
        q = v[:, :2] - (v[:, 2] / h[2])[:, None] * h[None, :2]
    else:
        L = h[:3] / h[3]
        if L[2] <= v[:, 2].max() + 1e-3:
            return None
        t = L[2] / (L[2] - v[:, 2])
        q = L[None, :2] + t[:, None] * (v[:, :2] - L[None, :2])
    if ev.convex:
        if not np.all(np.isfinite(q)) or np.abs(q - [ev.x0, ev.y0]).max() > 1e3:
            return None
        return hull_coverage(ev, q)
    ny, nx = ev.shape
    ss = ev.supersample
    scale = ss * 16.0 / ev.step  # 4 fractional bits of cv2's fixed point
    img = np.zeros((ny * ss, nx * ss), np.uint8)
    off = np.array([ev.x0, ev.y0]) - 0.5 * ev.step + 0.5 * ev.step / ss
    tris = ground_shadow_triangles(v, ev.faces, h)
    for t in np.round((tris - off) * scale).astype(np.int32):
        cv2.fillConvexPoly(img, t, 255, cv2.LINE_8, shift=4)
    cov = cv2.resize(img, (nx, ny), interpolation=cv2.INTER_AREA)
    return cov.astype(np.float32) * np.float32(1.0 / 255.0)


def edge_sigma(ev: Evidence, directions: np.ndarray) -> np.ndarray:
    """The blur across ground edges of the given directions, metres: ``(k, 2)`` unit directions -> ``(k,)``.

    A ground edge along ``e`` moves ``|det J| / |J e|`` image pixels per metre across it (``J`` the
    evidence's :attr:`Evidence.jacobian`), so a blur of ``blur_px`` pixels is ``blur_px |J e| / |det J|``
    metres of ground: wider along the line of sight, where the ground is foreshortened. At least
    :data:`MIN_EDGE_CELLS` of a cell, so that the shadow's coverage (and the fit's objective) moves
    continuously with the light even on a coarse grid; that minimum alone when the blur is unknown.
    """
    floor = MIN_EDGE_CELLS * ev.step
    if ev.blur_px is None or ev.jacobian is None:
        return np.full(len(directions), floor)
    J = np.asarray(ev.jacobian, np.float64)
    det = abs(float(np.linalg.det(J)))
    if det <= 0.0:
        return np.full(len(directions), floor)
    across = ev.blur_px * np.linalg.norm(np.asarray(directions, np.float64) @ J.T, axis=1) / det
    out: np.ndarray = np.maximum(across, floor)
    return out


def hull_coverage(ev: Evidence, q: np.ndarray) -> np.ndarray:
    """The convex hull of ground points ``q`` (n, 2) (metres) as the grid's samples see it: ``(ny, nx)
    float32`` in [0, 1], ``Phi(-d)`` of each cell centre's blur-scaled signed distance ``d`` to the hull
    (the largest over its edges of the distance outside the edge's line over that edge's
    :func:`edge_sigma`): a straight edge's exact blurred profile, continuous in the light's parameters."""
    ny, nx = ev.shape
    out = np.zeros((ny, nx), np.float32)
    hull = cv2.convexHull(np.asarray(q, np.float32).reshape(-1, 1, 2)).reshape(-1, 2).astype(np.float64)
    a = hull
    e = np.concatenate([hull[1:], hull[:1]]) - a
    length = np.linalg.norm(e, axis=1)
    keep = length > 1e-12
    a, e, length = a[keep], e[keep], length[keep]
    if len(a) < 3:
        return out
    e /= length[:, None]
    ccw = float(np.sum(e[:-1, 0] * e[1:, 1] - e[:-1, 1] * e[1:, 0])) > 0.0  # turning left at its corners
    n = np.column_stack([e[:, 1], -e[:, 0]]) if ccw else np.column_stack([-e[:, 1], e[:, 0]])  # outward
    sig = edge_sigma(ev, e)
    reach = 5.0 * float(sig.max())
    lo = np.floor((hull.min(axis=0) - reach - [ev.x0, ev.y0]) / ev.step).astype(int)
    hi = np.ceil((hull.max(axis=0) + reach - [ev.x0, ev.y0]) / ev.step).astype(int) + 1
    j0, i0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    j1, i1 = min(int(hi[0]), nx), min(int(hi[1]), ny)
    if j1 <= j0 or i1 <= i0:
        return out
    X = ev.x0 + ev.step * np.arange(j0, j1)
    Y = ev.y0 + ev.step * np.arange(i0, i1)
    d = np.full((i1 - i0, j1 - j0), -np.inf)
    for k in range(len(a)):
        dk = ((X[None, :] - a[k, 0]) * n[k, 0] + (Y[:, None] - a[k, 1]) * n[k, 1]) / sig[k]
        np.maximum(d, dk, out=d)
    block = (d < 0.0).astype(np.float32)
    soft = np.abs(d) < ERF_REACH  # beyond, Phi is 0 or 1 to 1e-9
    block[soft] = 0.5 * erfc(d[soft] / math.sqrt(2.0))
    out[i0:i1, j0:j1] = block
    return out


def ground_jacobian(intr: Intrinsics, cam_from_world: np.ndarray, xy: Sequence[float] | np.ndarray) -> np.ndarray:
    """``d(u, v) / d(x, y)`` (2, 2) float64: image pixels per metre of the ground z = 0 at world ``xy``
    (central differences of the camera's projection, lens distortion included)."""
    h = 1e-4
    x, y = float(xy[0]), float(xy[1])
    pts = np.array([[x + h, y, 0.0], [x - h, y, 0.0], [x, y + h, 0.0], [x, y - h, 0.0]])
    uv = np.asarray(intr.project(pts, np.asarray(cam_from_world, np.float64)), np.float64)
    return np.column_stack([(uv[0] - uv[1]) / (2 * h), (uv[2] - uv[3]) / (2 * h)])


def sample_blur_px(photo_sigma_px: float) -> float:
    """The blur (pixels) of a sharp ground edge as a grid sample sees it: the photo's point spread
    ``photo_sigma_px`` (:func:`arshadow.estimate.optics.measure_blur`), its pixels' area (1/12 px^2) and
    the bilinear resampling's tent (1/6 px^2, averaged over the sample's phase).

    >>> round(sample_blur_px(0.0), 3)
    0.5
    """
    return math.sqrt(max(float(photo_sigma_px), 0.0) ** 2 + PIXEL_VARIANCE + TENT_VARIANCE)


def smooth(ev: Evidence, img: np.ndarray) -> np.ndarray:
    """The local-mean kernel: two box filters (a tent, standard deviation ``ev.sigma``), O(1) per cell."""
    w = max(3, round(math.sqrt(6.0 * (ev.sigma / ev.step) ** 2 + 1.0)) | 1)
    out = cv2.blur(img, (w, w), borderType=cv2.BORDER_CONSTANT)
    return cv2.blur(out, (w, w), borderType=cv2.BORDER_CONSTANT)


def _local_mean(ev: Evidence, values: np.ndarray) -> np.ndarray:
    """Per albedo class, the weighted local mean of ``values`` over the class's used cells (normalised
    convolution with :func:`smooth`): (ny, nx) float32."""
    norms = ev.class_norms()
    if len(norms) == 1:
        cls, norm = norms[0]
        mean: np.ndarray = smooth(ev, np.where(cls, values, 0.0).astype(np.float32)) / norm
        return mean
    out = np.zeros(ev.shape, np.float32)
    for cls, norm in norms:
        num = smooth(ev, np.where(cls, values, 0.0).astype(np.float32))
        out[cls] = num[cls] / norm[cls]
    return out


def highpass(ev: Evidence, values: np.ndarray) -> np.ndarray:
    """``values`` minus its local mean within its albedo class: what a shadow's edges change, without the
    floor's slow variations (nor the paper / floor step). (ny, nx) float32, 0 on unused cells."""
    v = np.asarray(values, np.float32)
    return np.where(ev.used, v - _local_mean(ev, v), 0.0).astype(np.float32)


def fit_levels(
    ev: Evidence, S: np.ndarray, values: np.ndarray | None = None, weight: np.ndarray | None = None
) -> tuple[float, float, float, int]:
    """Least squares of the high-passed photo by the high-passed shadow: ``hp(values) = delta * hp(S)``.

    Parameters
    ----------
    ev : Evidence
    S : (ny, nx) float
        Modelled shadow coverage.
    values : (ny, nx) float, optional
        Default the log luminance.
    weight : (ny, nx) bool, optional
        Restrict the sums to these cells (and the used ones).

    Returns
    -------
    (rss, delta, rss0, n)
        Residual sum of squares, the shadow's log darkness, the RSS without a shadow, the cells used.
    """
    r = ev.residual() if values is None else highpass(ev, values)
    sf = highpass(ev, S)
    use = ev.used if weight is None else (ev.used & weight)
    n = int(np.count_nonzero(use))
    if n < 10:
        return math.inf, 0.0, math.inf, n
    if weight is not None:
        r, sf = r[use], sf[use]
    rr = float(np.dot(r.ravel(), r.ravel()))
    rs = float(np.dot(r.ravel(), sf.ravel()))
    ss = float(np.dot(sf.ravel(), sf.ravel()))
    if ss <= 1e-12:
        return rr, 0.0, rr, n
    delta = rs / ss
    return max(rr - rs * rs / ss, 0.0), delta, rr, n


def edge_pairs(  # noqa: PLR0913 (the evidence, its shadow, the distance, and three keyword options)
    ev: Evidence,
    S: np.ndarray,
    distance: float,
    points: bool = False,
    outward: float = 0.0,
    within: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """Pairs of ground cells straddling the modelled shadow's edge: for every edge cell, the points
    ``distance`` (metres) inside and outside along the edge's normal, kept when both are used, of the same
    albedo class, clearly in and out of the shadow. Returns ``(inside rgb (k, 3), outside rgb (k, 3))``
    float64 (linear, bilinear samples); with ``points``, also their ground points ``(inside xy (k, 2),
    outside xy (k, 2))`` float64 (metres, the evidence's ground frame). ``outward`` (metres): both points
    moved that far out along the normal, where both must be clearly lit (the floor's own change beside the
    edge: :mod:`arshadow.estimate.ratio`'s ``lit_gradient`` and texture check); 0: straddling the edge.
    ``within`` (ny, nx) bool: only pairs whose both points' cells are in it (None: any)."""
    sb = cv2.GaussianBlur(S.astype(np.float32), (0, 0), 1.0)
    gy, gx = np.gradient(sb)
    # the cells within about half a cell of the edge, however blurred the model's edge is: ``sb`` is the
    # edge's profile at a standard deviation of about one cell, 0.5 -/+ 0.19 half a cell in and out
    edge = np.abs(sb - 0.5) < EDGE_BAND
    rr, cc = np.nonzero(edge)
    g = np.stack([gx[rr, cc], gy[rr, cc]], 1)
    norm = np.linalg.norm(g, axis=1)
    ok = norm > 1e-6
    rr, cc, g = rr[ok], cc[ok], g[ok] / norm[ok, None]  # g points into the shadow (S increases)
    k, o = distance / ev.step, outward / ev.step
    pin = np.stack([cc + (k - o) * g[:, 0], rr + (k - o) * g[:, 1]], 1)
    pout = np.stack([cc - (k + o) * g[:, 0], rr - (k + o) * g[:, 1]], 1)
    ny, nx = ev.shape

    def nearest(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = np.rint(p).astype(int)
        good = (q[:, 0] >= 0) & (q[:, 0] < nx) & (q[:, 1] >= 0) & (q[:, 1] < ny)
        q[~good] = 0
        return q, good

    qi, gi = nearest(pin)
    qo, go = nearest(pout)
    keep = (
        gi
        & go
        & ev.used[qi[:, 1], qi[:, 0]]
        & ev.used[qo[:, 1], qo[:, 0]]
        & (ev.paper[qi[:, 1], qi[:, 0]] == ev.paper[qo[:, 1], qo[:, 0]])
        & ((S[qi[:, 1], qi[:, 0]] > 0.99) if o == 0 else (S[qi[:, 1], qi[:, 0]] < 0.01))
        & (S[qo[:, 1], qo[:, 0]] < 0.01)
    )
    if within is not None:
        keep &= within[qi[:, 1], qi[:, 0]] & within[qo[:, 1], qo[:, 0]]
    if not keep.any():
        return (np.zeros((0, 3)), np.zeros((0, 3))) + ((np.zeros((0, 2)), np.zeros((0, 2))) if points else ())
    rgb = ev.rgb.astype(np.float32)

    def sample(p: np.ndarray) -> np.ndarray:
        m = p[keep].astype(np.float32).reshape(-1, 1, 2)
        return cv2.remap(rgb, m[:, :, 0], m[:, :, 1], cv2.INTER_LINEAR).reshape(-1, 3).astype(np.float64)

    if not points:
        return sample(pin), sample(pout)
    origin = np.array([ev.x0, ev.y0])
    return sample(pin), sample(pout), origin + ev.step * pin[keep], origin + ev.step * pout[keep]
