"""Silhouette detection: which mesh edges bound the shadow volume for one light.

One interface, five detectors (``silhouette(caster, light_h, method=...)``):

``adjacency`` (default)
    One exact sign test per face (``face_planes @ light_h > 0``), then per edge compare the facing bits
    of its two faces (precomputed edge -> face indices): a silhouette edge is one whose faces differ.
    Because each face is tested exactly once, every vertex of the result has equal in- and out-degree:
    the loops always close, whatever the rounding.
``triangular`` (TA, [Kolivand-HSD])
    Toggle the directed edges of every light-facing triangle in a set: an edge whose reverse is already
    there cancels it; what is left is the silhouette. Needs no adjacency. Vectorised as a sort of the
    edge keys plus a signed sum (same result as the sequential set).
``vnv`` (Visible-non-Visible, [Kolivand-HSD])
    Count the light-facing faces on every edge (all incidences, precomputed); exactly one => silhouette.
``hsd`` (Hybrid Silhouette Detection, [Kolivand-HSD])
    Connected coplanar triangles are merged into polygons once per mesh; per light one sign test per
    polygon, then TA over the boundary edges of the light-facing polygons only (fewer edge operations
    on flat-faced meshes).
``delta_plus`` (Delta+, [Kolivand-DeltaPlus])
    For every edge of a light-facing face, push the edge's midpoint by epsilon outwards (perpendicular to
    the edge and to the light ray, away from the face), cast the ray from the light through the pushed
    point and test it against the light-facing faces with a bounding volume hierarchy; no hit => the
    edge is a silhouette edge. This finds the outline *seen from the light*, not every front/back
    transition; loops need not close (measured in ``docs/geometry.md``).

Every detector returns a :class:`Silhouette`: directed vertex-index pairs ``(a, b)`` oriented as the
light-facing face winds them, so that the side quad ``(b, a, a', b')`` (``'`` = extruded away from the
light) faces outwards; and the per-face facing mask.

Open meshes (see :mod:`arshadow.geometry.mesh`) are two-sided: every face contributes, back-facing ones reversed,
and the silhouette is the net boundary of that chain (a fold edge of a sheet can appear twice).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import LightError, UsageError
from ._bvh import any_hit, moller_trumbore
from .mesh import ShadowCaster, plane_side

__all__ = ["Silhouette", "silhouette", "METHODS", "as_light_h", "silhouette_loops"]

METHODS = ("adjacency", "triangular", "vnv", "hsd", "delta_plus")

#: a detector's result: directed edges (k, 2) intp, light-facing faces (m,) bool, operation counts
_Detected = tuple[np.ndarray, np.ndarray, dict[str, Any]]


@dataclass(frozen=True)
class Silhouette:
    """The silhouette of a :class:`~arshadow.geometry.mesh.ShadowCaster` for one light.

    Attributes
    ----------
    edges : (k, 2) intp
        Directed vertex-index pairs ``(a, b)``, oriented as the light-facing face traverses them: the
        extruded side quad is ``(b, a, a', b')``. An edge may repeat on two-sided (open) meshes.
    facing : (m,) bool
        Light-facing faces (``face_planes @ light_h > 0``).
    method : str
    stats : dict
        Operation counts: ``faces_tested``, ``edge_ops`` (edges visited / toggled), ``n_edges``, plus
        detector-specific counts.
    two_sided : bool
        True when the mesh is open / non-manifold and every face casts (see :mod:`arshadow.geometry.mesh`).
    light_h : (4,) float64
        The light used (normalised: w is 0 or 1).
    """

    edges: np.ndarray
    facing: np.ndarray
    method: str
    stats: dict = field(default_factory=dict)
    two_sided: bool = False
    light_h: np.ndarray | None = None

    @property
    def n_edges(self) -> int:
        return int(self.edges.shape[0])


def as_light_h(light: object) -> np.ndarray:
    """Validate a light as a homogeneous ``(4,) float64`` (w = 1 point, w = 0 direction towards it).

    Accepts a ``(4,)`` array or any object with a ``.homogeneous`` attribute (``arshadow.lights.spec.Light``).
    A point with w != 1 is divided by w.

    Raises
    ------
    LightError
        Wrong shape, NaN/inf, or a zero direction.

    Examples
    --------
    >>> as_light_h([0, 0, 2, 2]).tolist()
    [0.0, 0.0, 1.0, 1.0]
    """
    if hasattr(light, "homogeneous"):
        light = light.homogeneous
    try:
        h = np.array(light, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise LightError(f"light {light!r} is not a homogeneous (4,) vector") from None
    if h.shape != (4,):
        raise LightError(f"light must be a homogeneous (4,) vector (x, y, z, w), got shape {h.shape}")
    if not np.all(np.isfinite(h)):
        raise LightError(f"light {h.tolist()} contains NaN or inf")
    if h[3] != 0.0:
        h = h / h[3]
        h[3] = 1.0
    elif not np.any(h[:3] != 0.0):
        raise LightError("directional light has a zero direction")
    return h


def _check_light_outside(caster: ShadowCaster, h: np.ndarray) -> None:
    """LightError when a point light is inside a closed mesh (its one-sided volume would be empty)."""
    if h[3] == 0.0 or caster.two_sided:
        return
    lo, hi = caster.bounds
    if np.any(h[:3] < lo) or np.any(h[:3] > hi):
        return
    w = caster.winding_number(h[:3])
    if abs(w) > 0.5:
        raise LightError(
            f"point light at {h[:3].tolist()} is inside the closed mesh {caster.name!r}: it lights nothing "
            "outside the mesh (move the light outside)"
        )


def _from_net(caster: ShadowCaster, net: np.ndarray) -> np.ndarray:
    """Directed edges from a per-edge net winding (sign = direction relative to ``caster.edges``,
    magnitude = multiplicity)."""
    idx = np.flatnonzero(net)
    mult = np.abs(net[idx]).astype(np.intp)
    e = caster.edges[idx]
    e = np.where((net[idx] > 0)[:, None], e, e[:, ::-1])
    if mult.size and mult.max() > 1:
        e = np.repeat(e, mult, axis=0)
    return np.ascontiguousarray(e, dtype=np.intp)


def _net_two_sided(caster: ShadowCaster, facing: np.ndarray) -> np.ndarray:
    """Net boundary of the faces turned towards the light (two-sided rule)."""
    inc_edge, inc_face, inc_sign = caster.edge_incidence
    o = np.where(facing, 1, -1).astype(np.int64)
    w = o[inc_face] * inc_sign
    return np.rint(np.bincount(inc_edge, weights=w, minlength=len(caster.edges))).astype(np.int64)


# ---------------------------------------------------------------------------- detectors
def _adjacency(caster: ShadowCaster, h: np.ndarray, **_: object) -> _Detected:
    facing = caster.facing(h)
    m = facing.shape[0]
    if caster.two_sided:
        e = _from_net(caster, _net_two_sided(caster, facing))
        return e, facing, {"faces_tested": m, "edge_ops": int(caster.edge_incidence[0].size)}
    ef0, ef1, edges0 = caster.closed_edge_faces
    f0 = facing[ef0]
    diff = f0 != facing[ef1]
    idx = np.flatnonzero(diff)
    e = edges0[idx]
    rev = ~f0[idx]
    e[rev] = e[rev, ::-1]
    return e, facing, {"faces_tested": m, "edge_ops": int(ef0.size)}


def _toggle(faces_or_edges_a: np.ndarray, b: np.ndarray, n_vertices: int) -> np.ndarray:
    """Vectorised TA toggle: directed edges (a -> b) cancel against their reverses; returns the net
    directed edges (with multiplicity)."""
    a = faces_or_edges_a
    lo = np.minimum(a, b)
    hi = np.maximum(a, b)
    key = lo.astype(np.int64) * n_vertices + hi
    sign = np.where(a < b, 1, -1)
    uk, inv = np.unique(key, return_inverse=True)
    net = np.rint(np.bincount(inv.reshape(-1), weights=sign, minlength=uk.size)).astype(np.int64)
    keep = np.flatnonzero(net)
    k = uk[keep]
    lo_k, hi_k = k // n_vertices, k % n_vertices
    e = np.stack([lo_k, hi_k], axis=1)
    neg = net[keep] < 0
    e[neg] = e[neg, ::-1]
    mult = np.abs(net[keep])
    if mult.size and mult.max() > 1:
        e = np.repeat(e, mult, axis=0)
    return np.ascontiguousarray(e, dtype=np.intp)


def _triangular(caster: ShadowCaster, h: np.ndarray, **_: object) -> _Detected:
    facing = caster.facing(h)
    f = caster.faces
    if caster.two_sided:
        tri = np.where(facing[:, None], f, f[:, ::-1])  # every face, turned towards the light
    else:
        tri = f[facing]
    a = tri.reshape(-1)
    b = tri[:, [1, 2, 0]].reshape(-1)
    e = _toggle(a, b, len(caster.vertices))
    return e, facing, {"faces_tested": int(f.shape[0]), "edge_ops": int(a.size)}


def _vnv(caster: ShadowCaster, h: np.ndarray, **_: object) -> _Detected:
    facing = caster.facing(h)
    inc_edge, inc_face, inc_sign = caster.edge_incidence
    ne = len(caster.edges)
    if caster.two_sided:
        e = _from_net(caster, _net_two_sided(caster, facing))
    else:
        vis = facing[inc_face]
        count = np.bincount(inc_edge, weights=vis, minlength=ne)
        direction = np.bincount(inc_edge, weights=vis * inc_sign, minlength=ne)
        net = np.where(np.rint(count) == 1, np.rint(direction), 0).astype(np.int64)
        e = _from_net(caster, net)
    return e, facing, {"faces_tested": int(facing.size), "edge_ops": ne, "incidences_read": int(inc_edge.size)}


def _hsd(caster: ShadowCaster, h: np.ndarray, **_: object) -> _Detected:
    poly = caster.polygons
    pvis = plane_side(poly["planes"], h) > 0.0
    facing = pvis[poly["face_polygon"]]
    pe = poly["edges"]
    if caster.two_sided:
        sel = np.where(pvis[poly["edge_polygon"]][:, None], pe, pe[:, ::-1])
    else:
        sel = pe[pvis[poly["edge_polygon"]]]
    e = _toggle(sel[:, 0], sel[:, 1], len(caster.vertices))
    return (
        e,
        facing,
        {
            "faces_tested": int(pvis.size),
            "polygons": int(pvis.size),
            "edge_ops": int(sel.shape[0]),
        },
    )


def _delta_plus(caster: ShadowCaster, h: np.ndarray, eps: float = 1e-6, **_: object) -> _Detected:
    facing = caster.facing(h)
    ef = caster.edge_faces
    edges = caster.edges
    v = caster.vertices
    if caster.two_sided:
        cand = np.arange(len(edges))
        vf = ef[:, 0]
        vis_faces = np.ones_like(facing)
        flip = ~facing[vf]
    else:
        f0 = facing[ef[:, 0]]
        f1 = np.where(ef[:, 1] >= 0, facing[np.maximum(ef[:, 1], 0)], False)
        cand = np.flatnonzero(f0 | f1)
        vf = np.where(f0[cand], ef[cand, 0], ef[cand, 1])
        vis_faces = facing
        flip = ~f0[cand]
    p = v[edges[cand, 0]]
    q = v[edges[cand, 1]]
    mid = 0.5 * (p + q)
    u = q - p
    if h[3] == 0.0:
        ray = np.broadcast_to(-h[:3] / np.linalg.norm(h[:3]), mid.shape)
    else:
        ray = mid - h[:3]
    w = np.cross(u, ray)
    # third vertex of the visible face: the one not on the edge
    fv = caster.faces[vf]
    is_edge = (fv == edges[cand, 0:1]) | (fv == edges[cand, 1:2])
    r = v[fv[np.arange(len(cand)), np.argmin(is_edge, axis=1)]]
    side = np.einsum("ij,ij->i", r - mid, w)
    w = np.where((side > 0)[:, None], -w, w)
    wn = np.linalg.norm(w, axis=1)
    ok = wn > 0
    delta = np.zeros_like(w)
    delta[ok] = w[ok] / wn[ok, None] * (eps * np.linalg.norm(u[ok], axis=1))[:, None]
    pushed = mid + delta
    if h[3] == 0.0:
        origins = pushed
        dirs = np.broadcast_to(h[:3] / np.linalg.norm(h[:3]), pushed.shape).copy()
        tmin = np.full(len(cand), -np.inf)
    else:
        origins = np.broadcast_to(h[:3], pushed.shape).copy()
        dirs = pushed - h[:3]
        tmin = np.zeros(len(cand))
    # test the edge's other face first (a cheap local test that settles most interior edges), then
    # the rays still unblocked go through the hierarchy; the order does not change the result
    other = np.where(vf == ef[cand, 0], ef[cand, 1], ef[cand, 0])
    ok_other = (other >= 0) & vis_faces[np.maximum(other, 0)]
    hit = np.zeros(len(cand), bool)
    if ok_other.any():
        t = caster.triangles[other[ok_other]]
        hit[ok_other] = moller_trumbore(
            origins[ok_other], dirs[ok_other], tmin[ok_other], t[:, 0], t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        )
    rest = np.flatnonzero(~hit)
    hit_rest, bstats = any_hit(caster, origins[rest], dirs[rest], tmin[rest], vis_faces)
    hit[rest] = hit_rest
    bstats = {"local_tests": int(ok_other.sum()), "bvh_rays": int(rest.size), **bstats}
    sil = ~hit
    e = edges[cand[sil]].copy()
    fl = flip[sil]
    e[fl] = e[fl, ::-1]
    stats = {"faces_tested": int(facing.size), "edge_ops": int(len(cand)), "rays": int(len(cand)), **bstats}
    return np.ascontiguousarray(e, dtype=np.intp), facing, stats


_DETECTORS: dict[str, Callable[..., _Detected]] = {
    "adjacency": _adjacency,
    "triangular": _triangular,
    "vnv": _vnv,
    "hsd": _hsd,
    "delta_plus": _delta_plus,
}


def silhouette(caster: ShadowCaster, light_h: object, method: str = "adjacency", **options: Any) -> Silhouette:
    """Detect the silhouette of ``caster`` for one light.

    Parameters
    ----------
    caster : ShadowCaster
    light_h : (4,) float64 or Light
        ``(x, y, z, 1)`` point light or ``(dx, dy, dz, 0)`` direction towards a directional light, world
        frame.
    method : {'adjacency', 'triangular', 'vnv', 'hsd', 'delta_plus'}
    **options
        ``eps`` (delta_plus only): the push, as a fraction of the edge's length (default 1e-6).

    Returns
    -------
    Silhouette

    Raises
    ------
    UsageError
        Unknown method.
    LightError
        Malformed light, or a point light inside a closed mesh.

    Examples
    --------
    >>> from arshadow.geometry.mesh import load_occluder
    >>> box = load_occluder("box:1,1,1")
    >>> s = silhouette(box, [0.2, 0.3, 5.0, 1.0])
    >>> s.n_edges, int(s.facing.sum())
    (4, 2)
    >>> sorted(map(tuple, silhouette(box, [0.2, 0.3, 5.0, 1.0], "triangular").edges)) == sorted(map(tuple, s.edges))
    True
    """
    try:
        fn = _DETECTORS[method]
    except KeyError:
        raise UsageError(f"unknown silhouette method {method!r} (choose from {', '.join(METHODS)})") from None
    h = as_light_h(light_h)
    _check_light_outside(caster, h)
    t0 = time.perf_counter()
    e, facing, stats = fn(caster, h, **options)
    stats = dict(stats)
    stats["n_edges"] = int(e.shape[0])
    stats["time_ms"] = (time.perf_counter() - t0) * 1e3
    facing.flags.writeable = False
    e.flags.writeable = False
    return Silhouette(edges=e, facing=facing, method=method, stats=stats, two_sided=caster.two_sided, light_h=h)


def silhouette_loops(edges: npt.ArrayLike) -> tuple[list[np.ndarray], int]:
    """Split directed silhouette edges into closed loops.

    Walks unused out-edges from each vertex until it returns to its start. Vertices shared by several
    loops are fine (each loop is returned separately).

    Parameters
    ----------
    edges : (k, 2) int

    Returns
    -------
    loops : list of (j,) intp
        Vertex indices of each closed loop, in order.
    n_open : int
        Number of edges left over that do not close into loops (0 whenever every vertex has as many
        incoming as outgoing edges, which the adjacency, TA, VnV and HSD detectors guarantee).

    Examples
    --------
    >>> loops, n_open = silhouette_loops([[0, 1], [1, 2], [2, 0], [5, 6]])
    >>> [l.tolist() for l in loops], n_open
    ([[0, 1, 2]], 1)
    """
    e = np.asarray(edges, np.intp).reshape(-1, 2)
    out: dict[int, list[int]] = {}
    for i, a in enumerate(e[:, 0].tolist()):
        out.setdefault(a, []).append(i)
    used = np.zeros(len(e), bool)
    loops = []
    for i0 in range(len(e)):
        if used[i0]:
            continue
        # follow a path; if it returns to its start it is a loop
        path = [i0]
        used[i0] = True
        start = int(e[i0, 0])
        cur = int(e[i0, 1])
        while cur != start:
            nxt = None
            for j in out.get(cur, ()):
                if not used[j]:
                    nxt = j
                    break
            if nxt is None:
                break
            used[nxt] = True
            path.append(nxt)
            cur = int(e[nxt, 1])
        if cur == start:
            loops.append(e[path, 0].copy())
        else:  # an open chain: give the edges back except the first, they may close elsewhere
            for j in path[1:]:
                used[j] = False
    n_loop_edges = sum(len(lp) for lp in loops)
    return loops, int(len(e) - n_loop_edges)
