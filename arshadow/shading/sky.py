"""Sky visibility: how much of the sky the object leaves to the ground around it and to its own surface.

The ambient share of the measured light is a sky: light from every direction of the upper hemisphere. The
object hides part of that sky from the ground near it (the contact shadow, and the umbra deepening towards
the object) and from its own lower parts and concavities. Both depend on the object and the ground only,
never on the camera: they are computed once per scene in the ground frame and projected per frame.

Sky visibility of a point with normal ``n`` is the sky irradiance it receives as a fraction of the
unoccluded horizontal ground's: ``V = (1/E0) * integral over the sky of L(w) vis(w) max(0, n.w) dw`` with
``E0`` the same integral for ``n = +z`` and ``vis = 1``. Open ground: 1; a vertical face of a convex object
under a uniform sky: 0.5 (the ground hides the lower half of its hemisphere); the ground right under it: 0.

(About 690 lines, over the project's ~600: the ground map, the object's own visibility and the light
they exchange share one grid, one set of directions and one rasteriser protocol; split, each half would
import the other's private pieces.)

Method (chosen by error against time, see ``docs/shading.md``)
--------------------------------------------------------------
- **Ground**: a fixed set of ``n`` cosine-weighted sky directions (a Fibonacci spiral in the projected
  disc: equal cosine-weighted solid angle each, no random noise). For each direction the object's exact
  shadow on the ground for a directional light from there (:func:`arshadow.geometry.exact.ground_shadow_triangles`,
  the light-facing faces of a closed mesh) is rasterised over a texel grid round the footprint; the map is
  the (sky-weighted) mean of the unshadowed texels. Error O(1/n) for smooth occluders (256 directions: a
  few thousandths), cost one projection + one rasterisation per direction.
- **Object**: per shading point (the GL vertex buffer's (vertex, normal) corners), the cosine-weighted
  directions round its normal; a direction below the horizon sees the ground, one above sees the sky unless
  a ray along it hits the mesh (:func:`arshadow.geometry.rays.rays_blocked`, exact float64). A convex mesh
  cannot hide itself, so no rays are cast for it.

Sky models: ``"uniform"`` (default) and ``"cie"`` (CIE standard overcast sky, radiance proportional to
``(1 + 2 cos(theta)) / 3``, brighter above: theta the zenith angle).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Protocol

import cv2
import numpy as np
import numpy.typing as npt

from ..errors import UsageError
from ..geometry.caster import ShadowCaster
from ..geometry.exact import ground_shadow_triangles
from ..geometry.rays import rays_blocked
from .raster import ItemBuffer, hidden_directions

__all__ = [
    "SKY_MODELS",
    "GroundGrid",
    "GroundOcclusion",
    "GroundRaster",
    "Interreflection",
    "SkyShading",
    "cosine_directions",
    "ground_grid",
    "ground_raster_cpu",
    "ground_sky_visibility",
    "lamp_incidence",
    "rotate_to",
    "object_sky_visibility",
    "sky_radiance",
]

#: sky radiance models: uniform, or the CIE standard overcast sky (brighter above)
SKY_MODELS = ("uniform", "cie")
#: rasterisation sub-pixel bits of cv2.fillConvexPoly
_SHIFT = 8
#: sub-texels per texel side (odd: one sits at the texel centre)
_SUB = 3
#: the map's change of the ground below the second value tapers linearly to 0 at the first (far from the
#: object): the larger of the sky's share the object hides and the light it reflects there (over the sky's
#: share). Occlusion alone decided until 2026-11-29: the reflected light in front of a lit face reaches 2-3 x
#: further, and cutting it left the path-traced reference's ground too dark there (held-out ground
#: 0.128 -> 0.122, own 0.149 -> 0.148, the same region on the 720p bench photo; docs/reference.md).
#: (0.03, 0.06) before: the same residual then, for a 1.5 x bigger region
ACTIVE_OCCLUSION = (0.05, 0.1)


def cosine_directions(n: int, normal: npt.ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """``(n, 3) float64`` unit directions distributed with density ``cos(angle to normal) / pi`` over the
    hemisphere round ``normal (3,)``: a Fibonacci spiral in the unit disc lifted to the hemisphere, each
    carrying ``1/n`` of the cosine-weighted solid angle (``pi``).

    >>> d = cosine_directions(1000)
    >>> bool(np.all(d[:, 2] > 0)), round(float(d[:, 2].mean()), 3)  # E[cos] = 2/3 under the cosine density
    (True, 0.667)
    """
    n = int(n)
    if n < 1:
        raise UsageError(f"need at least one sky direction, got {n}")
    u = (np.arange(n) + 0.5) / n
    phi = np.arange(n) * (math.pi * (3.0 - math.sqrt(5.0)))
    r = np.sqrt(u)
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - u)], axis=1)
    return rotate_to(local, np.asarray(normal, np.float64).reshape(3))


def sky_radiance(dirs: np.ndarray, sky: str = "uniform") -> np.ndarray:
    """``(k,) float64`` relative sky radiance towards world directions ``dirs (k, 3)`` (z up); 0 below the
    horizon. ``"uniform"``: 1; ``"cie"``: ``(1 + 2 cos(theta)) / 3``.

    >>> sky_radiance(np.array([[0, 0, 1.0], [0.8, 0, 0.6], [0, 0, -1]]), "cie").round(3).tolist()
    [1.0, 0.733, 0.0]
    """
    if sky not in SKY_MODELS:
        raise UsageError(f"sky model {sky!r}: choose one of {', '.join(SKY_MODELS)}")
    z = np.asarray(dirs, np.float64)[:, 2]
    up = z > 0.0
    return np.where(up, 1.0 if sky == "uniform" else (1.0 + 2.0 * np.clip(z, 0.0, 1.0)) / 3.0, 0.0)


#: the unoccluded horizontal ground's sky irradiance divided by pi, per model: uniform 1, CIE 7/9
_E0 = {"uniform": 1.0, "cie": 7.0 / 9.0}


@dataclasses.dataclass(frozen=True)
class GroundOcclusion:
    """Sky visibility of the ground round the object, on a texel grid in the ground frame.

    ``visibility[i, j]`` (``(h, w) float32``, 0..1) is the value at the ground point
    ``(x0 + (j + 0.5) * texel, y0 + (i + 0.5) * texel)`` (metres, ground frame); outside the grid the
    object hides and reflects less than ``ACTIVE_OCCLUSION[0]`` of the sky and the ground counts as open (1);
    ``edge_occlusion`` is the largest occlusion on the border of the full square computed. ``bounce``
    (``(h, w) float32`` >= 0, or None without interreflection) is the part of ``visibility`` that is the
    light the object reflects onto the ground over the sky's share (``visibility`` = sky visibility +
    ``bounce``), computed for the object's mean albedo: a coloured object's reflected light is ``bounce``
    times its colour over its mean (colour bleeding, :func:`arshadow.compose.composite.composite`).
    """

    x0: float
    y0: float
    texel: float
    visibility: np.ndarray
    n_dirs: int
    sky: str
    edge_occlusion: float  # largest 1 - V on the grid's border
    bounce: np.ndarray | None = None

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` metres, the grid's bounds in the ground frame."""
        h, w = self.visibility.shape
        return (self.x0, self.y0, self.x0 + w * self.texel, self.y0 + h * self.texel)

    def outline(self) -> np.ndarray:
        """``(k, 3) float64``: ground points (z = 0, metres) whose convex hull holds every texel where the map
        is not 1 (where sky occlusion changes the ground): tighter than the grid's square, whose corners
        are open ground. The square's corners when nothing is occluded (an empty map has none to bound).

        >>> v = np.ones((4, 4), np.float32); v[1, 1] = 0.5
        >>> GroundOcclusion(0.0, 0.0, 1.0, v, 8, "uniform", 0.0).outline()[:, :2].min(axis=0).tolist()
        [1.0, 1.0]
        """
        active = np.abs(self.visibility - 1.0) > 0.0
        if not active.any():
            x0, y0, x1, y1 = self.extent
            return np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
        ii, jj = np.nonzero(active)
        corners = np.concatenate([np.c_[jj + dj, ii + di] for di in (0, 1) for dj in (0, 1)]).astype(np.int32)
        hull = cv2.convexHull(corners).reshape(-1, 2).astype(np.float64)
        out: np.ndarray = np.c_[
            self.x0 + hull[:, 0] * self.texel, self.y0 + hull[:, 1] * self.texel, np.zeros(len(hull))
        ]
        return out

    def sample(self, xy: np.ndarray) -> np.ndarray:
        """``(k,) float64`` bilinear visibility at ground points ``xy (k, 2)`` (1 off the grid)."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        h, w = self.visibility.shape
        fx = (xy[:, 0] - self.x0) / self.texel - 0.5
        fy = (xy[:, 1] - self.y0) / self.texel - 0.5
        out = np.ones(len(xy))
        ok = (fx >= -0.5) & (fx <= w - 0.5) & (fy >= -0.5) & (fy <= h - 0.5)
        fx, fy = np.clip(fx[ok], 0, w - 1), np.clip(fy[ok], 0, h - 1)
        i0, j0 = np.minimum(fy.astype(int), h - 2 if h > 1 else 0), np.minimum(fx.astype(int), w - 2 if w > 1 else 0)
        i1, j1 = np.minimum(i0 + 1, h - 1), np.minimum(j0 + 1, w - 1)
        ty, tx = fy - i0, fx - j0
        v = self.visibility.astype(np.float64)
        out[ok] = (
            v[i0, j0] * (1 - tx) * (1 - ty)
            + v[i0, j1] * tx * (1 - ty)
            + v[i1, j0] * (1 - tx) * ty
            + v[i1, j1] * tx * ty
        )
        return out


@dataclasses.dataclass(frozen=True, eq=False)
class SkyShading:
    """What the renderer needs for sky occlusion and the object's sky shading (one per scene).

    Attributes
    ----------
    ground : GroundOcclusion or None
        The ground occlusion map (the contact shadow); None: the ground is not sky-occluded.
    object_sky : str or None
        Sky model of the object's per-vertex sky visibility and ground view (:func:`object_sky_visibility`);
        None: a uniform ambient term (the old shading).
    bounce : (3,) float
        Linear RGB light bounced from the ground onto the object, in the renderer's light units: the
        ground's albedo times the open ground's irradiance (``ambient + sum weight * sin(elevation)``);
        multiplied by each vertex's ground view.
    bleed : (3,) float or None
        Colour bleeding: the object's linear RGB colour over its mean, minus 1 (the light it reflects onto
        the ground, ``ground.bounce``, is that much stronger per channel); None: a grey object (the sky
        channel stays one plane).
    albedo : (3,) float or None
        The object's mean reflectance, linear RGB (absolute: the paper's white is ``PAPER_ALBEDO``): the light
        it reflects onto its own parts (:mod:`arshadow.shading.interreflect`); None: no interreflection.
    object_ground : callable or None
        ``(k, 2)`` ground points -> ``(k,)`` the ground's light there over ``bounce`` (NaN where unknown: the
        photo's ground, :class:`arshadow.shading.decide.GroundLight`): each shading vertex's ground view is
        weighted by the ground its faces see (:mod:`arshadow.shading.objground`); None: ``bounce`` everywhere.

    Examples
    --------
    >>> SkyShading().colored, SkyShading(bleed=(0.3, -0.1, -0.2)).colored
    (False, True)
    """

    ground: GroundOcclusion | None = None
    object_sky: str | None = "uniform"
    bounce: tuple = (0.0, 0.0, 0.0)
    bleed: tuple | None = None
    albedo: tuple | None = None
    object_ground: Callable[[np.ndarray], np.ndarray] | None = None

    @property
    def colored(self) -> bool:
        """The sky channel is per colour channel: a coloured object's reflected light on a map that has it."""
        return self.bleed is not None and (self.ground is None or self.ground.bounce is not None)


def ground_grid(caster: ShadowCaster, resolution: int = 256, margin: float | None = None) -> tuple[float, float, float]:
    """``(x0, y0, texel)``: the ground occlusion map's square (ground frame, metres) and texel size."""
    lo, hi = caster.bounds
    height = max(float(hi[2]), 0.0)
    if margin is None:
        # occlusion of the sky by an object of height h at distance d falls as ~(h/d)^3: at 3 h it is ~1 %
        margin = 3.0 * height if height > 0 else 0.1 * caster.scale
    cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
    half = 0.5 * max(hi[0] - lo[0], hi[1] - lo[1]) + float(margin)
    texel = 2.0 * half / resolution
    return cx - half, cy - half, texel


@dataclasses.dataclass(frozen=True)
class GroundGrid:
    """The ground occlusion map's texel grid: ``res x res`` texels of side ``texel`` metres, texel ``(i, j)``
    centred on the ground point ``(x0 + (j + 0.5) * texel, y0 + (i + 0.5) * texel)`` (ground frame)."""

    x0: float
    y0: float
    texel: float
    res: int


class GroundRaster(Protocol):
    """Who rasterises the object's shadows for the ground occlusion map: :func:`ground_raster_cpu` (numpy
    and OpenCV) or a renderer's (:class:`arshadow.gl.sky.GLGroundRaster`, the same sums on the GPU).

    Called with the caster, the sky directions ``dirs (n, 3)`` (unit, z > 0) and their weights ``(n,)``,
    the :class:`GroundGrid` and ``face_values (m,)`` (or None); returns ``(open, bounce)``: ``(res, res)
    float64`` sums over the directions of ``weight * (texel centre not in the object's shadow along d)``,
    and of ``weight * face_values[f]`` for the face ``f`` a texel centre meets first along ``d`` (0 where it
    meets none; None when ``face_values`` is None)."""

    def __call__(
        self,
        caster: ShadowCaster,
        dirs: np.ndarray,
        weights: np.ndarray,
        grid: GroundGrid,
        face_values: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray | None]: ...


@dataclasses.dataclass(frozen=True, eq=False)
class Interreflection:
    """The light the object reflects onto the ground (:func:`ground_sky_visibility`'s ``bounce``): each
    blocked sky direction sees the object's face nearest along it, lit by the direct light on its lit side,
    by the sky (``sky_share``, ``(1 + n_z) / 2`` of it) and by the ground round it (``(1 - n_z) / 2`` of
    ``ground``), times ``albedo``; added to the map as ``bounce / sky_share``, so that it holds
    ``V + bounce / r`` (more than 1 beside a lit face), what the composite's sky term multiplies.

    Attributes
    ----------
    light : (3,) float64
        Towards the strongest light from the object (any length), weight ``1 - sky_share`` of the open
        ground's light.
    sky_share : float
        The sky's share of the open ground's light.
    albedo : float
        The object's mean albedo.
    ground : float
        The ground's albedo times its irradiance, a share of the open ground's light (0: not measured).
    lamp : ((3,), (3,)) or None
        ``(position, ref)`` (world, metres) for a point light: each face's direct light is the lamp's at the
        face's own distance and incidence over its light on the open ground at ``ref``, where ``sky_share``
        holds (:func:`lamp_incidence`); None: a far light.
    ground_field : callable or None
        ``(k, 2)`` ground points -> ``(k,)`` the ground's reflected light there over ``ground``, NaN where
        unknown (:class:`arshadow.shading.decide.GroundLight`, read from the photo: a white paper beside the
        object, 3-4); None: ``ground`` everywhere.
    """

    light: np.ndarray
    sky_share: float
    albedo: float
    ground: float = 0.0
    lamp: tuple | None = None
    ground_field: Callable[[np.ndarray], np.ndarray] | None = None


def ground_sky_visibility(  # noqa: PLR0913 (the caster, and keyword-only options)
    caster: ShadowCaster,
    *,
    n_dirs: int = 256,
    resolution: int = 256,
    margin: float | None = None,
    sky: str = "uniform",
    max_triangle_draws: int = 2_000_000,
    bounce: Interreflection | tuple | None = None,
    taper: tuple | None = ACTIVE_OCCLUSION,
    raster: GroundRaster | None = None,
) -> GroundOcclusion:
    """The object's :class:`GroundOcclusion` (ground frame = the caster's world frame, ground z = 0).

    Parameters
    ----------
    caster : ShadowCaster
        The object, metres, standing on or above the ground (parts below z = 0 cast nothing).
    n_dirs : int
        Cosine-weighted sky directions; reduced (never below 32) so that directions x light-facing
        triangles stays under ``max_triangle_draws`` (a big mesh: a coarser sky, same time).
    resolution : int
        Texels along each side of the square grid.
    margin : float, optional
        Metres of ground round the footprint's bounding square; default 3 x the object's height.
    sky : {"uniform", "cie"}
    bounce : Interreflection, optional
        Also the light the object reflects onto the ground (or the :class:`Interreflection`'s fields as a
        tuple: ``(light, sky_share, albedo[, ground[, lamp]])``).
    taper : (t0, t1) or None
        Where both the occlusion and the reflected light (over the sky's share) are under ``t1``, the map's
        change tapers linearly to 0 at ``t0``, and the map is cropped to where it is not 0
        (:data:`ACTIVE_OCCLUSION`: the frame's region stays small); None: the exact visibility everywhere on
        the grid (the light estimate's allowance for its probe).
    raster : GroundRaster, optional
        Who rasterises the shadows (a renderer's GPU one); default :func:`ground_raster_cpu`.
    """
    if resolution < 2:
        raise UsageError(f"ground occlusion resolution must be at least 2 texels, got {resolution}")
    n_faces = caster.n_faces if not caster.is_closed else max(1, caster.n_faces // 2)
    n_dirs = int(max(32, min(int(n_dirs), max_triangle_draws // max(n_faces, 1))))
    x0, y0, texel = ground_grid(caster, resolution, margin)
    grid = GroundGrid(x0, y0, texel, resolution)
    dirs = cosine_directions(n_dirs)
    weights = sky_radiance(dirs, sky)
    rast = raster or ground_raster_cpu
    if bounce is not None and not isinstance(bounce, Interreflection):
        bounce = Interreflection(*bounce)
    seen = None
    if bounce is not None and bounce.ground > 0:
        seen = _ground_seen(caster, bounce, rast, dirs, weights, grid)
    face_e = _face_irradiance(caster, bounce, seen) if bounce is not None else None
    acc, acc_b = rast(caster, dirs, weights, grid, face_e)
    vis = _fill_under((acc / weights.sum()).astype(np.float32))
    border = np.concatenate([vis[0], vis[-1], vis[:, 0], vis[:, -1]])
    edge = float(1.0 - border.min())
    # where both the occlusion and the reflected light are under ACTIVE_OCCLUSION[1] they taper to 0 at
    # ACTIVE_OCCLUSION[0] (far from the object), and the map keeps only the texels where they are not 0
    # (+ 2 texels): the frame's region shrinks to what changes
    occ = 1.0 - vis
    refl = None  # the reflected light over the sky's share
    if acc_b is not None and bounce is not None and bounce.sky_share > 0:
        refl = float(bounce.albedo) * acc_b / weights.sum() / float(bounce.sky_share)
    t0, t1 = taper if taper is not None else (-1.0, 0.0)
    w = np.clip(((occ if refl is None else np.maximum(refl, occ)) - t0) / (t1 - t0), 0.0, 1.0)
    vis = (1.0 - occ * w).astype(np.float32)
    (rows,) = np.nonzero((w > 0.0).any(axis=1))
    (cols,) = np.nonzero((w > 0.0).any(axis=0))
    reflected = None if refl is None else (refl * w).astype(np.float32)
    if reflected is not None:
        vis = (vis + reflected).astype(np.float32)
    if rows.size:
        r0, r1 = max(int(rows[0]) - 2, 0), min(int(rows[-1]) + 3, resolution)
        c0, c1 = max(int(cols[0]) - 2, 0), min(int(cols[-1]) + 3, resolution)
        vis, x0, y0 = vis[r0:r1, c0:c1].copy(), x0 + c0 * texel, y0 + r0 * texel
        reflected = None if reflected is None else reflected[r0:r1, c0:c1].copy()
    return GroundOcclusion(x0, y0, texel, vis, n_dirs, sky, edge, reflected)


def ground_raster_cpu(
    caster: ShadowCaster,
    dirs: np.ndarray,
    weights: np.ndarray,
    grid: GroundGrid,
    face_values: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """:class:`GroundRaster` with OpenCV: per direction the exact shadow triangles
    (:func:`arshadow.geometry.exact.ground_shadow_triangles`, the light-facing faces of a closed mesh) filled
    with ``cv2.fillConvexPoly`` at 3 x 3 sub-texels and read at each texel's centre sub-texel (cv2 fills a
    polygon's boundary pixels too, which biases a shadow outward by up to one sub-texel: a third of a texel)."""
    res = grid.res
    sub = _SUB * res
    scale = float(1 << _SHIFT) * _SUB / grid.texel
    half = 1 << (_SHIFT - 1)
    lim = (sub + 2) << _SHIFT
    sub_grid = (grid.x0, grid.y0, scale, half, lim, sub)
    closed, planes = caster.is_closed, caster.face_planes
    acc = np.zeros((res, res), np.float64)
    acc_b = np.zeros((res, res), np.float64) if face_values is not None else None
    img = np.zeros((sub, sub), np.uint8)
    c = _SUB // 2
    for d, w in zip(dirs, weights, strict=True):
        h = np.r_[d, 0.0]
        faces = caster.faces[planes @ h > 0.0] if closed else caster.faces
        tri = ground_shadow_triangles(caster.vertices, faces, h)
        # sub-texel (a, b) centre at pixel coordinate (b, a): cv2 samples pixel centres at integers
        q = np.round((tri - [grid.x0, grid.y0]) * scale - half).astype(np.int64)
        off = np.all(q < 0, axis=1).any(axis=1) | np.all(q > lim, axis=1).any(axis=1)
        q = np.clip(q[~off], -(1 << 30), 1 << 30).astype(np.int32)
        img[:] = 0
        for t in q:
            cv2.fillConvexPoly(img, t, 1, lineType=cv2.LINE_8, shift=_SHIFT)
        acc += w * (1.0 - img[c::_SUB, c::_SUB])
        if acc_b is not None and face_values is not None:
            acc_b += w * _bounce_image(caster, d, face_values, sub_grid)[c::_SUB, c::_SUB]
    return acc, acc_b


def _face_irradiance(caster: ShadowCaster, bounce: Interreflection, seen: np.ndarray | None = None) -> np.ndarray:
    """``(m,)``: each face's irradiance as a share of the open ground's (direct on its lit side + sky + the
    light the ground reflects up to it: the path tracer's ground -> object -> ground path, which lights a box's
    shadowed faces and a sphere's underside about as much as the sky does). ``seen (m,)``: each face's view of
    the ground weighted by the ground's irradiance there (:func:`_ground_seen`); None: open ground,
    ``(1 - n_z) / 2``."""
    light, r = np.asarray(bounce.light, np.float64), float(bounce.sky_share)
    light = light / np.linalg.norm(light)
    n = caster.face_planes[:, :3]
    if bounce.lamp is None:
        direct = (1.0 - r) * np.maximum(n @ light, 0.0) / max(float(light[2]), 1e-3)
    else:
        direct = (1.0 - r) * lamp_incidence(caster, bounce.lamp[0], bounce.lamp[1])
    g = float(bounce.ground)
    view = (1.0 - n[:, 2]) / 2.0 if seen is None else seen
    out: np.ndarray = direct + r * (1.0 + n[:, 2]) / 2.0 + g * view
    return out


def lamp_incidence(caster: ShadowCaster, lamp: npt.ArrayLike, ref: npt.ArrayLike) -> np.ndarray:
    """``(m,)``: each face's mean irradiance from a point lamp at ``lamp (3,)`` (world, metres) over the open
    ground's at the ground point ``ref (3,)``: ``mean over the face of max(0, n.(P - q)) / |P - q|^3``
    divided by ``(P_z - ref_z) / |P - ref|^3``, the mean taken at the triangle's edge midpoints (exact for
    a quadratic). A near lamp lights a face nearer to it more than the ground where the ratio is measured,
    and unevenly (``1 / d^2`` and the incidence per point); a far lamp gives ``max(0, n.L) / L_z``.

    >>> from arshadow.geometry.caster import ShadowCaster
    >>> tri = ShadowCaster(np.array([[0.0, -1, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2]]))
    >>> round(float(lamp_incidence(tri, (1e6, 0.0, 1e6), (0.0, 0.0, 0.0))[0]), 4)  # far: cos 45 / sin 45
    1.0
    """
    p = np.asarray(lamp, np.float64).reshape(3)
    q0 = np.asarray(ref, np.float64).reshape(3)
    tri = caster.vertices[caster.faces]  # (m, 3, 3)
    mid = 0.5 * (tri + np.roll(tri, -1, axis=1))  # (m, 3, 3) edge midpoints
    n = caster.face_planes[:, :3]
    d = p - mid
    e = np.maximum(np.einsum("mkd,md->mk", d, n), 0.0) / np.linalg.norm(d, axis=2) ** 3
    e_ref = max(float(p[2] - q0[2]), 1e-9) / float(np.linalg.norm(p - q0)) ** 3
    out: np.ndarray = e.mean(axis=1) / e_ref
    return out


#: cosine-weighted directions per face for :func:`_ground_seen`
GROUND_SEEN_DIRS = 64


def _ground_seen(  # noqa: PLR0913 (the caster, its light, the map's rasteriser and its grid)
    caster: ShadowCaster,
    bounce: Interreflection,
    rast: GroundRaster,
    dirs: np.ndarray,
    weights: np.ndarray,
    grid: GroundGrid,
) -> np.ndarray:
    """``(m,)``: each face's view of the ground, each ground point counted at its irradiance as a share of the
    open ground's, ``(1 - r) lit + r V``: the ground under and beside an object is in its shadow and sees less
    sky, so its lower faces get less of the ground's light than the open ground's ring measures. ``V`` is the
    map's sky visibility and ``lit`` the direct light's (one direction, ``bounce.light``), both rasterised on the
    map's grid; each face looks along :data:`GROUND_SEEN_DIRS` cosine-weighted directions from its centre and
    the ones that reach the ground read it there (1 off the grid, the object itself not counted as a blocker).
    Open ground everywhere gives ``(1 - n_z) / 2``. ``bounce.ground_field``: each ground point's reflected
    light over ``bounce.ground`` multiplies its irradiance (the ground's albedo is not the same everywhere: a
    white paper beside the object; 1 where it is NaN)."""
    light, r = np.asarray(bounce.light, np.float64), float(bounce.sky_share)
    light = light / np.linalg.norm(light)
    acc, _ = rast(caster, dirs, weights, grid, None)
    lit, _ = rast(caster, light[None], np.ones(1), grid, None)
    e = ((1.0 - r) * lit + r * _fill_under((acc / weights.sum()).astype(np.float32))).astype(np.float32)
    ground = GroundOcclusion(grid.x0, grid.y0, grid.texel, e, 0, "uniform", 0.0)
    n = caster.face_planes[:, :3]
    c = caster.vertices[caster.faces].mean(axis=1)
    d = rotate_to(cosine_directions(GROUND_SEEN_DIRS), n)  # (m, k, 3) round each face's normal
    down = d[..., 2] < -1e-6  # (m, k) directions that reach the ground
    tz = np.where(down, -np.maximum(c[:, None, 2], 0.0) / np.where(down, d[..., 2], -1.0), 0.0)
    q = c[:, None, :2] + tz[..., None] * d[..., :2]
    val = ground.sample(q.reshape(-1, 2)).reshape(q.shape[:2])
    if bounce.ground_field is not None:
        rel = np.asarray(bounce.ground_field(q.reshape(-1, 2)), np.float64).reshape(q.shape[:2])
        val = val * np.where(np.isfinite(rel), rel, 1.0)
    out: np.ndarray = np.where(down, val, 0.0).sum(axis=1) / d.shape[1]
    return out


def _bounce_image(caster: ShadowCaster, d: np.ndarray, face_e: np.ndarray, grid: tuple) -> np.ndarray:
    """``(sub, sub) float32``: the irradiance share of the face a ground sub-texel sees first along ``d``
    (0 where it sees the sky): the faces turned towards the ground point, drawn farthest first. ``grid``:
    ``(x0, y0, scale, half, lim, sub)`` of the map's rasterisation."""
    x0, y0, scale, half, lim, sub = grid
    n = caster.face_planes[:, :3]
    sel = np.flatnonzero(n @ d < 0.0) if caster.is_closed else np.arange(caster.n_faces)
    img = np.zeros((sub, sub), np.float32)
    if sel.size == 0:
        return img
    tri = ground_shadow_triangles(caster.vertices, caster.faces[sel], np.r_[d, 0.0])
    if len(tri) != len(sel):  # faces below the ground were split or dropped: no interreflection then
        return img
    t = caster.vertices[caster.faces[sel], 2].mean(axis=1) / max(float(d[2]), 1e-6)
    q = np.round((tri - [x0, y0]) * scale - half).astype(np.int64)
    off = np.all(q < 0, axis=1).any(axis=1) | np.all(q > lim, axis=1).any(axis=1)
    q = np.clip(q, -(1 << 30), 1 << 30).astype(np.int32)
    for i in np.argsort(-t):  # farthest along d first: the nearest face ends on top
        if not off[i]:
            cv2.fillConvexPoly(img, q[i], float(face_e[sel[i]]), lineType=cv2.LINE_8, shift=_SHIFT)
    return img


def _fill_under(vis: np.ndarray) -> np.ndarray:
    """Texels under the object (sky fully hidden: 0) take their open neighbours' largest value (two 3 x 3
    dilations), so that bilinear sampling of the ground just outside the footprint is not darkened by
    the hidden texels under it (never seen: the object stands on them)."""
    out = vis.copy()
    kernel = np.ones((3, 3), np.uint8)
    for _ in range(2):
        under = out <= 0.0
        if not under.any():
            break
        out[under] = cv2.dilate(out, kernel)[under]
    return out


def object_sky_visibility(  # noqa: PLR0913 (the points, and keyword-only options)
    caster: ShadowCaster,
    points: np.ndarray,
    normals: np.ndarray,
    *,
    n_dirs: int = 64,
    sky: str = "uniform",
    method: str = "raster",
    max_rays: int = 400_000,
    item_buffer: ItemBuffer | None = None,
    res: int = 384,
) -> tuple[np.ndarray, np.ndarray]:
    """Sky visibility and ground view of points on the object's surface.

    Parameters
    ----------
    caster : ShadowCaster
    points : (k, 3) float
        Surface points (world frame, metres): the shading vertices.
    normals : (k, 3) float
        Their unit shading normals.
    n_dirs : int
        ``"raster"``: directions over the whole sphere (uniform solid angle, shared by every point; at least
        16); ``"rays"``: cosine-weighted directions per point (reduced, never below 16, so that points x
        directions stays under ``max_rays``). Unused for a convex mesh.
    sky : {"uniform", "cie"}
    method : {"raster", "rays"}
        How a non-convex mesh's self-occlusion is found: item buffers per direction
        (:func:`arshadow.shading.raster.hidden_directions`, fast) or exact BVH rays per point and
        direction (:func:`arshadow.geometry.rays.rays_blocked`, the reference).
    item_buffer, res : optional
        ``"raster"``: who draws the item buffers (:func:`arshadow.shading.raster.hidden_directions`; the
        renderer hands the GPU's) and their side in pixels.

    Returns
    -------
    sky_visibility : (k,) float64
        The point's sky irradiance / the open horizontal ground's (0..1; a vertical face of a convex
        object: 0.5 under a uniform sky).
    ground_view : (k,) float64
        The cosine-weighted share (0..1) of its hemisphere that reaches the ground without meeting the
        object: the weight of light bounced from the ground (a vertical face: 0.5).
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    convex = caster.is_convex
    if convex and sky == "uniform":
        # nothing of a convex object hides its own sky: a plane tilted by a from the horizontal sees
        # (1 + cos a) / 2 of the cosine lobe above the horizon and the rest of it on the ground
        nz: np.ndarray = np.clip(nrm[:, 2], -1.0, 1.0)
        return (1.0 + nz) / 2.0, (1.0 - nz) / 2.0
    if method == "raster" or convex:
        n = 2048 if convex else max(16, int(n_dirs))
        return _object_raster(caster, p, nrm, n, sky, hide=not convex, item_buffer=item_buffer, res=res)
    if method != "rays":
        raise UsageError(f"object sky visibility method {method!r}: choose raster or rays")
    return _object_rays(caster, p, nrm, int(max(16, min(int(n_dirs), max_rays // max(len(p), 1)))), sky)


def _sphere_directions(n: int) -> np.ndarray:
    """``(n, 3)`` unit directions of equal solid angle (a Fibonacci sphere)."""
    z = 1.0 - (2.0 * np.arange(n) + 1.0) / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = np.arange(n) * (math.pi * (3.0 - math.sqrt(5.0)))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _object_raster(  # noqa: PLR0913 (the mesh, the points, the quadrature and how to draw it)
    caster: ShadowCaster,
    p: np.ndarray,
    nrm: np.ndarray,
    n: int,
    sky: str,
    hide: bool,
    item_buffer: ItemBuffer | None = None,
    res: int = 384,
) -> tuple[np.ndarray, np.ndarray]:
    """Directions shared by every point, each weighted by the point's cosine (uniform-solid-angle
    quadrature, normalised by the same quadrature of the open horizontal ground)."""
    dirs = _sphere_directions(n)
    cos = nrm @ dirs.T  # (k, n)
    front = cos > 0.0
    if hide:
        fn = caster.face_planes[:, :3] if caster.is_closed else None
        off = p + 1e-5 * caster.scale * nrm  # off the surface: its own faces lie behind it
        free = ~hidden_directions(
            caster.vertices, caster.faces, off, dirs, need=front, normals=fn, item_buffer=item_buffer, res=res
        )
    else:
        free = front
    free &= front
    rad = sky_radiance(dirs, sky)
    e_open = float(np.sum(rad * np.maximum(dirs[:, 2], 0.0)))  # the open ground, same quadrature
    up = dirs[:, 2] > 0.0
    sky_v = (cos * free) @ rad / e_open
    g_open = float(np.sum(np.maximum(-dirs[:, 2], 0.0)))
    ground_v = (cos * free) @ (~up).astype(np.float64) / g_open
    return sky_v, ground_v


def _object_rays(
    caster: ShadowCaster, p: np.ndarray, nrm: np.ndarray, n: int, sky: str
) -> tuple[np.ndarray, np.ndarray]:
    """Cosine-weighted directions per point, each tested with an exact ray (the reference method)."""
    k = len(p)
    base = cosine_directions(n)
    sky_v = np.zeros(k)
    ground_v = np.zeros(k)
    e0 = _E0[sky]
    eps = 1e-6 * caster.scale
    chunk = max(1, 65536 // n)
    for s in range(0, k, chunk):
        pp, nn = p[s : s + chunk], nrm[s : s + chunk]
        dirs = rotate_to(base, nn)  # (c, n, 3)
        up = dirs[..., 2] > 0.0
        o = np.repeat(pp + eps * nn, n, axis=0)
        free = ~rays_blocked(caster, o, dirs.reshape(-1, 3)).reshape(dirs.shape[:2])
        rad = sky_radiance(dirs.reshape(-1, 3), sky).reshape(dirs.shape[:2])
        sky_v[s : s + chunk] = (rad * free).mean(axis=1) / e0
        ground_v[s : s + chunk] = (free & ~up).mean(axis=1)
    return sky_v, ground_v


def rotate_to(base: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """``base (n, 3)`` directions round +z turned round ``normal (3,)`` -> ``(n, 3)``, or round each of
    ``normal (m, 3)`` -> ``(m, n, 3)`` (the frame of :func:`cosine_directions`).

    >>> rotate_to(np.array([[0.0, 0.0, 1.0]]), np.array([1.0, 0.0, 0.0])).round(6).tolist()  # +z onto +x
    [[1.0, 0.0, 0.0]]
    """
    nz = np.atleast_2d(np.asarray(normal, np.float64))
    nz = nz / np.linalg.norm(nz, axis=1, keepdims=True)
    a = np.where(np.abs(nz[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    tx = np.cross(a, nz)
    tx /= np.linalg.norm(tx, axis=1, keepdims=True)
    ty = np.cross(nz, tx)
    out: np.ndarray = np.einsum("nk,mkd->mnd", base, np.stack([tx, ty, nz], axis=1))
    return out[0] if np.ndim(normal) == 1 else out
