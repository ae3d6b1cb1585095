"""Shadow volume geometry: side quads, z-fail caps, the receiver-plane truncated variant, and the
conservative "is the camera possibly inside a shadow?" test that picks z-pass or z-fail.

Winding: every triangle is wound counter-clockwise seen from *outside* the volume, so a two-sided stencil
pass (front faces increment, back faces decrement on z-pass) works, and for a closed mesh each volume edge
is used exactly twice with opposite orientation (watertight; tested for point and directional lights).

Homogeneous vertices ``(x, y, z, w)``: ``w = 1`` finite points, ``w = 0`` points at infinity in direction
``(x, y, z)`` away from the light (unit length). For a directional light every extruded vertex is the same
point at infinity ``(-d, 0)``. Render with an infinite far plane (``Intrinsics.gl_projection(zfar=None)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import LightError, UsageError
from .mesh import ShadowCaster
from .silhouette import Silhouette, as_light_h

__all__ = [
    "ShadowVolume",
    "shadow_volume",
    "camera_may_be_in_shadow",
    "near_plane_radius",
    "MIN_DESCENT",
    "layer_bound",
    "STENCIL_COUNT_RANGE",
    "BATCH_LAYERS",
]

#: a single-pass stencil count is exact while no pixel is covered by more than this many volume layers
#: (6 count bits: counts are kept modulo 64, so 1..63 are all non-zero)
STENCIL_COUNT_RANGE = 63
#: light-facing faces per closed sub-volume of a batched volume (5 count bits + 1 "shadowed" bit: a
#: batch's count is in 0..31 and so exact modulo 32)
BATCH_LAYERS = 31

#: truncated volumes need every extruded ray to descend at least this much (z of the unit ray
#: direction <= -MIN_DESCENT, i.e. at most 1e4 x the vertex height of extrusion); otherwise the whole
#: volume is extruded to infinity instead (exact, just more fill).
MIN_DESCENT = 1e-4


@dataclass(frozen=True)
class ShadowVolume:
    """Vertex and index arrays of one light's shadow volume, ready to upload.

    Attributes
    ----------
    vertices : (p, 4) float64
        Homogeneous world coordinates (w = 0 at infinity).
    triangles : (q, 3) intp
        Outward-wound triangles: ``triangles[:n_side]`` the side quads (two triangles per silhouette
        edge), then ``n_near_cap`` near-cap and ``n_far_cap`` far-cap triangles (z-fail only).
    n_side, n_cap, n_near_cap, n_far_cap : int
    truncated : bool
        True when the sides and far cap end on the plane ``z = truncate_z`` ([Kolivand-Stencil] variant); False for
        volumes extruded to infinity (also when a truncation was asked for but a ray does not descend
        enough to meet the plane, see :data:`MIN_DESCENT`).
    truncate_z : float or None
        The plane asked for.
    light_h : (4,) float64
    two_sided : bool
        The mesh is open / non-manifold and every face casts (see :mod:`arshadow.geometry.mesh`).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    n_side: int
    n_cap: int
    n_near_cap: int
    n_far_cap: int
    truncated: bool
    truncate_z: float | None
    light_h: np.ndarray
    two_sided: bool = False
    #: upper bound of the number of volume layers over any point (:func:`layer_bound`)
    max_layers: int = 0
    #: None: one volume (stencil count exact, ``max_layers <= STENCIL_COUNT_RANGE``). Otherwise
    #: ``((first_triangle, n_triangles), ...)``: closed z-fail sub-volumes of at most
    #: :data:`BATCH_LAYERS` light-facing faces each (sides + both caps) whose union is the shadow; the
    #: renderer counts each one separately and ORs the results (exact whatever the depth complexity).
    batches: tuple | None = None

    @property
    def side_triangles(self) -> np.ndarray:
        """(n_side, 3) intp: the triangles a z-pass render needs."""
        return self.triangles[: self.n_side]


def _extrude(v: np.ndarray, h: np.ndarray, truncate_z: float | None) -> tuple[np.ndarray, bool]:
    """Extrude points ``v (k, 3)`` away from the light: ``(k, 4)`` homogeneous, and whether truncated."""
    k = v.shape[0]
    out = np.empty((k, 4))
    if h[3] == 0.0:
        dirs = np.broadcast_to(-h[:3] / np.linalg.norm(h[:3]), (k, 3))
    else:
        dv = v - h[:3]
        nrm = np.linalg.norm(dv, axis=1)
        if np.any(nrm == 0.0):
            raise LightError(f"point light at {h[:3].tolist()} lies exactly on a mesh vertex: no shadow direction")
        dirs = dv / nrm[:, None]
    if truncate_z is not None:
        tz = float(truncate_z)
        above = v[:, 2] > tz
        if not np.any(above) or np.all(dirs[above, 2] <= -MIN_DESCENT):
            out[:, :3] = v
            out[:, 3] = 1.0
            if np.any(above):
                a = np.flatnonzero(above)
                if h[3] == 0.0:
                    s = (v[a, 2] - tz) / -dirs[a, 2]
                    p = v[a] + s[:, None] * dirs[a]
                else:
                    # from the light: L + t (v - L), t = (Lz - tz) / (Lz - vz) (>= 1)
                    t = (h[2] - tz) / (h[2] - v[a, 2])
                    p = h[:3] + t[:, None] * (v[a] - h[:3])
                p[:, 2] = tz
                out[a, :3] = p
            return out, True
    out[:, :3] = dirs
    out[:, 3] = 0.0
    return out, False


def _same_light(a: np.ndarray, b: np.ndarray) -> bool:
    """Same point, or same direction up to a positive scale (directional lights need not be unit)."""
    if a[3] != b[3]:
        return False
    if a[3] == 0.0:
        a, b = a[:3] / np.linalg.norm(a[:3]), b[:3] / np.linalg.norm(b[:3])
    return bool(np.allclose(a, b, rtol=1e-12, atol=1e-15))


def shadow_volume(
    caster: ShadowCaster, light_h: npt.ArrayLike, sil: Silhouette, *, caps: bool = True, truncate_z: float | None = None
) -> ShadowVolume:
    """Build the shadow volume of ``caster`` for one light from its silhouette.

    Parameters
    ----------
    caster : ShadowCaster
    light_h : (4,) float64
        The light the silhouette was computed for (homogeneous, world frame).
    sil : Silhouette
        From :func:`arshadow.geometry.silhouette.silhouette` with the same light.
    caps : bool
        Add the z-fail caps: light-facing triangles as the near cap and back-facing ones extruded as the
        far cap (Everitt-Kilgard, Doom 3). Two-sided (open) meshes: every face turned towards the light
        is the near cap and its extruded reverse the far cap.
    truncate_z : float, optional
        Extrude only down to the plane ``z = truncate_z`` (just below the ground, e.g. ``-1e-3 *
        caster.scale``) instead of to infinity ([Kolivand-Stencil]). Vertices at or below the plane stay where they
        are (zero-length extrusion). If any extruded ray does not descend by at least
        :data:`MIN_DESCENT` (light at or below a vertex, a sun at the horizon) the volume is extruded to
        infinity instead and ``truncated`` is False.

    Returns
    -------
    ShadowVolume

    Raises
    ------
    LightError
        Point light exactly on a vertex of the volume.
    UsageError
        ``sil`` was computed for another light or another mesh.

    Examples
    --------
    >>> from arshadow.geometry.mesh import load_occluder
    >>> from arshadow.geometry.silhouette import silhouette
    >>> box = load_occluder("box:1,1,1")
    >>> L = [0.2, 0.3, 5.0, 1.0]
    >>> vol = shadow_volume(box, L, silhouette(box, L))
    >>> vol.n_side, vol.n_near_cap, vol.n_far_cap, vol.vertices.shape
    (8, 2, 10, (12, 4))
    """
    h = as_light_h(light_h)
    if sil.light_h is not None and not _same_light(sil.light_h, h):
        raise UsageError("the silhouette was computed for a different light")
    if sil.facing.shape[0] != caster.n_faces:
        raise UsageError("the silhouette was computed for a different mesh")
    faces = caster.faces
    facing = sil.facing
    lit = np.where(facing[:, None], faces, faces[:, ::-1]) if caster.two_sided else faces[facing]
    bound = layer_bound(caster.vertices, sil.edges, h, lit)
    if bound > STENCIL_COUNT_RANGE:
        return _batched_volume(caster, h, lit, bound, truncate_z)
    return _volume(caster, h, sil.edges, lit, facing, caps, truncate_z, bound)


def _volume(
    caster: ShadowCaster,
    h: np.ndarray,
    edges: np.ndarray,
    lit: np.ndarray,
    facing: np.ndarray | None,
    caps: bool,
    truncate_z: float | None,
    bound: int,
    far_faces: np.ndarray | None = None,
) -> ShadowVolume:
    """One closed volume: sides on the directed ``edges (k, 2)``, near cap ``lit``, far cap."""
    n = len(caster.vertices)
    if caps:
        near = lit
        if far_faces is not None:
            far = far_faces
        elif caster.two_sided:
            far = lit[:, ::-1]
        else:
            assert facing is not None  # only the batched volumes, which give far_faces, pass None
            far = caster.faces[~facing]
    else:
        near = far = np.empty((0, 3), np.intp)
    # vertices used at the light side (finite) and extruded
    used_fin = np.zeros(n, bool)
    used_ext = np.zeros(n, bool)
    used_fin[edges.reshape(-1)] = True
    used_ext[edges.reshape(-1)] = True
    used_fin[near.reshape(-1)] = True
    used_ext[far.reshape(-1)] = True
    fin_idx = np.flatnonzero(used_fin)
    ext_idx = np.flatnonzero(used_ext)
    pos_fin = np.full(n, -1, np.intp)
    pos_fin[fin_idx] = np.arange(fin_idx.size)
    pos_ext = np.full(n, -1, np.intp)
    pos_ext[ext_idx] = fin_idx.size + np.arange(ext_idx.size)
    v = caster.vertices
    if h[3] != 0.0 and np.any(np.all(v[fin_idx] == h[:3], axis=1)):
        raise LightError(f"point light at {h[:3].tolist()} lies exactly on a mesh vertex")
    ext, truncated = _extrude(v[ext_idx], h, truncate_z)
    verts = np.empty((fin_idx.size + ext_idx.size, 4))
    verts[: fin_idx.size, :3] = v[fin_idx]
    verts[: fin_idx.size, 3] = 1.0
    verts[fin_idx.size :] = ext
    a, b = edges[:, 0], edges[:, 1]
    fa, fb, xa, xb = pos_fin[a], pos_fin[b], pos_ext[a], pos_ext[b]
    # quad fb, fa, xa, xb split along the diagonal from the larger vertex index to the extrusion of the
    # smaller one, so that the quad of b->a (a neighbouring batch, see _batched_volume) is exactly these
    # triangles reversed: no rasterisation seam between batches
    side = np.empty((2 * len(edges), 3), np.intp)
    up = (a < b)[:, None]
    side[0::2] = np.where(up, np.stack([fb, fa, xa], axis=1), np.stack([fb, fa, xb], axis=1))
    side[1::2] = np.where(up, np.stack([fb, xa, xb], axis=1), np.stack([fa, xa, xb], axis=1))
    tris = np.concatenate([side, pos_fin[near], pos_ext[far]]).astype(np.intp)
    verts.flags.writeable = False
    tris.flags.writeable = False
    return ShadowVolume(
        vertices=verts,
        triangles=tris,
        n_side=int(side.shape[0]),
        n_cap=int(near.shape[0] + far.shape[0]),
        n_near_cap=int(near.shape[0]),
        n_far_cap=int(far.shape[0]),
        truncated=bool(truncated and truncate_z is not None),
        truncate_z=None if truncate_z is None else float(truncate_z),
        light_h=h,
        two_sided=caster.two_sided,
        max_layers=int(bound),
    )


def _batched_volume(
    caster: ShadowCaster, h: np.ndarray, lit: np.ndarray, bound: int, truncate_z: float | None
) -> ShadowVolume:
    """The volume as closed z-fail sub-volumes of :data:`BATCH_LAYERS` light-facing faces each.

    A batch S of light-facing faces bounds the closed volume S (near cap) + S reversed and extruded (far
    cap) + sides on S's own boundary edges (directed edges of S whose reverse is not in S). Its winding
    number at a point is the number of faces of S between the point and the light, so 0..|S|; the union of
    the batches is the shadow of all light-facing faces, i.e. the shadow.
    """
    parts, batches, first = [], [], 0
    n_side = n_near = n_far = 0
    truncated = True
    for k in range(0, len(lit), BATCH_LAYERS):
        s = lit[k : k + BATCH_LAYERS]
        e = np.concatenate([s[:, [0, 1]], s[:, [1, 2]], s[:, [2, 0]]])
        key = e[:, 0].astype(np.int64) * (len(caster.vertices) + 1) + e[:, 1]
        rkey = e[:, 1].astype(np.int64) * (len(caster.vertices) + 1) + e[:, 0]
        e = e[~np.isin(key, rkey)]
        vol = _volume(caster, h, e, s, None, True, truncate_z, bound, far_faces=s[:, ::-1])
        parts.append(vol)
        truncated = truncated and vol.truncated
        batches.append((first, len(vol.triangles)))
        n_side += vol.n_side
        n_near += vol.n_near_cap
        n_far += vol.n_far_cap
        first += len(vol.triangles)
    offs = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
    verts = np.concatenate([p.vertices for p in parts])
    tris = np.concatenate([p.triangles + o for p, o in zip(parts, offs, strict=True)]).astype(np.intp)
    verts.flags.writeable = False
    tris.flags.writeable = False
    return ShadowVolume(
        vertices=verts,
        triangles=tris,
        n_side=n_side,
        n_cap=n_near + n_far,
        n_near_cap=n_near,
        n_far_cap=n_far,
        truncated=bool(truncated and truncate_z is not None),
        truncate_z=None if truncate_z is None else float(truncate_z),
        light_h=h,
        two_sided=caster.two_sided,
        max_layers=int(bound),
        batches=tuple(batches),
    )


def layer_bound(
    vertices: npt.ArrayLike, edges: npt.ArrayLike, light_h: npt.ArrayLike, lit_faces: np.ndarray | None = None
) -> int:
    """Upper bound of the depth complexity of a shadow volume: the largest number of light-facing faces
    any ray from the light crosses (so the largest stencil count of its volume).

    Seen from the light, the light-facing faces all project with the same orientation and their boundary
    is the silhouette, so the number of them over a point equals the winding number of the projected
    silhouette loops around it. A winding number is at most the number of loop edges a ray from the point
    crosses on either side, hence at most half the edges a line through it stabs: the bound is the
    largest such stab count, halved, over horizontal and vertical lines (a sweep over the edges' spans).

    Parameters
    ----------
    vertices : (n, 3) float64
    edges : (k, 2) int
        Silhouette edges (``Silhouette.edges``).
    light_h : (4,) float64
    lit_faces : (m, 3) int, optional
        The light-facing faces; the trivial bound ``len(lit_faces)`` is returned when it is smaller or
        when the point light is not strictly on one side of the silhouette (no central projection).

    Returns
    -------
    int

    Examples
    --------
    >>> from arshadow.geometry.mesh import load_occluder
    >>> from arshadow.geometry.silhouette import silhouette
    >>> box = load_occluder("box:1,1,1")
    >>> L = [0.0, 0.0, 1.0, 0.0]
    >>> layer_bound(box.vertices, silhouette(box, L).edges, L)
    1
    """
    h = as_light_h(light_h)
    e = np.asarray(edges, np.intp).reshape(-1, 2)
    trivial = len(lit_faces) if lit_faces is not None else 2**31 - 1
    if len(e) == 0:
        return 0
    v = np.asarray(vertices, np.float64)
    used = np.unique(e.reshape(-1))
    if h[3] == 0.0:
        d = h[:3] / np.linalg.norm(h[:3])
        rel = v[used]
    else:
        rel = v[used] - h[:3]
        c = rel.mean(axis=0)
        nc = np.linalg.norm(c)
        if not nc > 0:
            return int(trivial)
        d = -c / nc
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    x, y = rel @ e1, rel @ e2
    if h[3] != 0.0:
        depth = rel @ -d
        if not np.all(depth > 1e-9 * float(np.max(np.abs(rel)))):
            return int(trivial)
        x, y = x / depth, y / depth
    pos = np.full(len(v), -1, np.intp)
    pos[used] = np.arange(len(used))
    ea, eb = pos[e[:, 0]], pos[e[:, 1]]
    best: int | None = None
    for c in (x, y):
        lo, hi = np.minimum(c[ea], c[eb]), np.maximum(c[ea], c[eb])
        # closed spans: at a tie the openings come first (conservative)
        ev = np.concatenate([lo, hi])
        kind = np.concatenate([np.zeros(len(lo)), np.ones(len(hi))])
        order = np.lexsort((kind, ev))
        step = np.where(kind[order] == 0, 1, -1)
        stab = int(np.cumsum(step).max())
        best = stab if best is None else min(best, stab)
    assert best is not None  # the loop ran (twice)
    return int(min(best // 2, trivial))


def near_plane_radius(
    znear: float, width: int, height: int, fx: float, fy: float, cx: float | None = None, cy: float | None = None
) -> float:
    """Distance from the eye to the farthest corner of the near-plane rectangle of a pinhole camera.

    This is the ``near`` to pass to :func:`camera_may_be_in_shadow` (``znear`` alone is too small: the
    near rectangle's corners lie farther out).

    Examples
    --------
    >>> round(near_plane_radius(0.01, 640, 480, 500.0, 500.0), 6)
    0.012806
    """
    cx = (width - 1) / 2.0 if cx is None else cx
    cy = (height - 1) / 2.0 if cy is None else cy
    du = max(abs(-0.5 - cx), abs(width - 0.5 - cx)) / fx
    dv = max(abs(-0.5 - cy), abs(height - 0.5 - cy)) / fy
    return float(znear * np.sqrt(1.0 + du * du + dv * dv))


def camera_may_be_in_shadow(
    caster: ShadowCaster, light_h: npt.ArrayLike, eye_world: npt.ArrayLike, near: float
) -> bool:
    """Conservative test: could the camera's near-plane rectangle touch this caster's shadow volume?

    ``False`` proves that every point within ``near`` of the eye is outside the (infinite) shadow
    volume, so z-pass is safe; ``True`` means use z-fail. After Doom 3's
    ``R_PotentiallyInsideInfiniteShadow``: a point X is in the volume only if the segment from X to the
    light (the ray towards a directional light) meets the mesh, hence its bounding box; for any X within
    ``near`` of the eye E, the segment from E to the light then meets the box grown by ``near`` (the two
    segments stay within ``near`` of each other). So the test is: does the segment (ray) from the eye to
    the light meet the bounding box grown by ``near`` (plus 1e-9 x mesh size)?

    Parameters
    ----------
    caster : ShadowCaster
    light_h : (4,) float64
    eye_world : (3,) float64
        Camera centre in the world frame.
    near : float
        Radius around the eye that contains the near-plane rectangle (:func:`near_plane_radius`).

    Returns
    -------
    bool

    Examples
    --------
    >>> from arshadow.geometry.mesh import load_occluder
    >>> box = load_occluder("box:1,1,1")
    >>> camera_may_be_in_shadow(box, [0, 0, 10, 1], [0, 0, -5], 0.01)
    True
    >>> camera_may_be_in_shadow(box, [0, 0, 10, 1], [5, 0, 1], 0.01)
    False
    """
    h = as_light_h(light_h)
    e = np.asarray(eye_world, np.float64).reshape(3)
    if not np.all(np.isfinite(e)) or not np.isfinite(near) or near < 0:
        raise UsageError(f"camera_may_be_in_shadow: bad eye {e.tolist()} or near {near}")
    grow = float(near) + 1e-9 * caster.scale + 1e-12 * float(np.max(np.abs(caster.bounds)))
    lo = caster.bounds[0] - grow
    hi = caster.bounds[1] + grow
    if np.all(e >= lo) and np.all(e <= hi):
        return True
    if h[3] == 0.0:
        d = h[:3]
        t_max = np.inf
    else:
        d = h[:3] - e
        t_max = 1.0
    t_lo, t_hi = 0.0, t_max
    for k in range(3):
        if d[k] == 0.0:
            if e[k] < lo[k] or e[k] > hi[k]:
                return False
            continue
        t1 = (lo[k] - e[k]) / d[k]
        t2 = (hi[k] - e[k]) / d[k]
        if t1 > t2:
            t1, t2 = t2, t1
        t_lo = max(t_lo, t1)
        t_hi = min(t_hi, t2)
        if t_lo > t_hi:
            return False
    return True
