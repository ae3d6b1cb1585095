"""The occluder: a triangle mesh prepared once for silhouette detection and shadow volumes.

Everything that does not depend on the light is computed here, once per mesh, and cached as read-only
arrays (:class:`ShadowCaster`): welded vertices, face planes in float64, the edge -> face adjacency with
boundary ("dangling") and non-manifold edges marked, the per-corner edge incidence used by the general
(open / non-manifold) path, the coplanar polygons of the Hybrid Silhouette Detector and a bounding volume
hierarchy for the Delta+ detector. Per light, :mod:`arshadow.geometry.silhouette` only does one sign test per face
plus gathers.

Closed and open meshes
----------------------
A mesh whose every edge is shared by exactly two faces traversing it in opposite directions is *closed*
(:attr:`ShadowCaster.is_closed`); its shadow is cast by its light-facing faces only (the classic one-sided
shadow volume). Any other mesh (boundary edges, non-manifold edges, inconsistent winding, even a single
triangle) is treated as *two-sided*: every face casts, turned towards the light, so a sheet casts the same
shadow whichever side the light is on. See ``docs/geometry.md``.

(About 610 lines, at the project's ~600: one class whose cached properties all derive from the welded arrays.)
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from .._check import check_shape
from ..compose.composite import srgb_to_linear
from ..errors import MeshError, ShapeError

if TYPE_CHECKING:  # an annotation only (mesh.py sets it)
    from .material import Material

__all__ = ["ShadowCaster", "connected_labels", "plane_side"]


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


def _as_rgba(colors: npt.ArrayLike | None, count: int, name: str) -> np.ndarray | None:
    """Colours (count, 3|4) uint8 (0..255) or float (0..1) -> (count, 4) float32 RGBA, or None."""
    if colors is None:
        return None
    c = np.asarray(colors)
    if c.ndim == 1:
        c = np.broadcast_to(c, (count, c.shape[0]))
    if c.ndim != 2 or c.shape[0] != count or c.shape[1] not in (3, 4):
        raise ShapeError(f"{name} has the wrong shape", actual_shape=c.shape, expected_shape=f"({count}, 3|4)")
    if c.dtype.kind in "ui":
        c = c.astype(np.float32) / 255.0
    c = c.astype(np.float32)
    if not np.all(np.isfinite(c)):
        raise MeshError(f"{name} contains NaN or inf")
    if c.shape[1] == 3:
        c = np.concatenate([c, np.ones((count, 1), np.float32)], axis=1)
    rgba: np.ndarray = np.clip(c, 0.0, 1.0)
    return rgba


class ShadowCaster:
    """A triangle mesh prepared for shadow computation (welded, validated, adjacency cached).

    Parameters
    ----------
    vertices : (n, 3) float
        Vertex positions, metres, world frame.
    faces : (m, 3) int
        Triangles as vertex indices, counter-clockwise seen from outside (outward normals).
    vertex_colors : (n, 3|4) uint8 or float in [0, 1], optional
    face_colors : (m, 3|4) uint8 or float in [0, 1], optional
    name : str
        Shown in messages.

    Notes
    -----
    Exact duplicate vertices are welded and unreferenced vertices dropped (the first colour of a welded
    group is kept); faces that repeat a vertex or have exactly zero area are dropped and counted in
    :attr:`n_dropped_faces`. NaN / inf vertices, indices out of range, an empty mesh or a mesh whose
    faces are all degenerate raise :class:`~arshadow.errors.MeshError`. The input arrays are copied, never
    modified.

    Examples
    --------
    >>> c = ShadowCaster([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], name="tri")
    >>> c.face_planes.tolist()
    [[0.0, 0.0, 1.0, -0.0]]
    >>> c.is_closed, len(c.boundary_edges)
    (False, 3)
    """

    def __init__(
        self,
        vertices: npt.ArrayLike,
        faces: npt.ArrayLike,
        vertex_colors: npt.ArrayLike | None = None,
        face_colors: npt.ArrayLike | None = None,
        name: str = "",
    ) -> None:
        self.name = str(name)
        label = f"mesh {self.name!r}" if self.name else "mesh"
        try:
            v = check_shape(vertices, "N,3", f"{label} vertices")
            f = check_shape(faces, "M,3", f"{label} faces")
        except ShapeError as exc:
            raise MeshError(str(exc)) from None
        except (ValueError, TypeError) as exc:  # ragged lists, objects
            raise MeshError(f"{label}: vertices / faces are not numeric arrays ({exc})") from None
        if v.shape[0] == 0 or f.shape[0] == 0:
            raise MeshError(f"{label} is empty ({v.shape[0]} vertices, {f.shape[0]} faces)")
        if v.dtype.kind not in "fiu":
            raise MeshError(f"{label} vertices are not numbers (dtype {v.dtype})")
        v = np.array(v, dtype=np.float64)  # copy
        if not np.all(np.isfinite(v)):
            bad = int(np.count_nonzero(~np.all(np.isfinite(v), axis=1)))
            raise MeshError(f"{label} has {bad} vertex(es) with NaN or inf coordinates")
        if f.dtype.kind not in "iu":
            if f.dtype.kind == "f" and np.all(np.isfinite(f)) and np.all(f == np.round(f)):
                f = f.astype(np.int64)
            else:
                raise MeshError(f"{label} faces are not integer vertex indices (dtype {f.dtype})")
        f = np.array(f, dtype=np.intp)
        if f.min() < 0 or f.max() >= v.shape[0]:
            raise MeshError(
                f"{label} faces index vertices out of range [0, {v.shape[0] - 1}] (found {f.min()}..{f.max()})"
            )
        vc = _as_rgba(vertex_colors, v.shape[0], f"{label} vertex_colors")
        fc = _as_rgba(face_colors, f.shape[0], f"{label} face_colors")

        # weld exact duplicates (-0.0 == 0.0 first so they weld too)
        n_in = v.shape[0]
        v = v + 0.0
        uniq, first, inverse = np.unique(v, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        order = np.argsort(first, kind="stable")  # keep the input's vertex order
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        v = uniq[order]
        f = rank[inverse][f]
        if vc is not None:
            vc = vc[first[order]]
        self.n_welded_vertices = n_in - v.shape[0]

        # drop degenerate faces: repeated index or exactly zero area
        rep = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
        cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        zero = ~np.any(cross != 0.0, axis=1)
        keep = ~(rep | zero)
        self.n_dropped_faces = int(np.count_nonzero(~keep))
        if not keep.any():
            raise MeshError(f"{label}: all {f.shape[0]} faces are degenerate (zero area)")
        f = f[keep]
        if fc is not None:
            fc = fc[keep]
        #: (m,) int: each face's index among the faces given (degenerate ones dropped): per-corner data read
        #: with the file (texture coordinates) follows the faces through it
        self.source_faces = _readonly(np.flatnonzero(keep))
        #: the surface's :class:`arshadow.geometry.material.Material` when the mesh file has one (set by
        #: :func:`arshadow.geometry.mesh.load_occluder`), else None
        self.material: Material | None = None

        # drop unreferenced vertices
        used = np.zeros(v.shape[0], bool)
        used[f.ravel()] = True
        if not used.all():
            remap = np.cumsum(used) - 1
            f = remap[f]
            v = v[used]
            if vc is not None:
                vc = vc[used]

        self.vertices = _readonly(v)
        self.faces = _readonly(f.astype(np.intp))
        self.vertex_colors = None if vc is None else _readonly(vc)
        self.face_colors = None if fc is None else _readonly(fc)

    # ------------------------------------------------------------------ basic properties
    def __repr__(self) -> str:
        return (
            f"ShadowCaster(name={self.name!r}, vertices={len(self.vertices)}, faces={len(self.faces)}, "
            f"closed={self.is_closed})"
        )

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @functools.cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: min and max corner of the axis-aligned bounding box."""
        return _readonly(np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)]))

    @functools.cached_property
    def scale(self) -> float:
        """Length of the bounding-box diagonal (metres); used for relative tolerances."""
        return float(np.linalg.norm(self.bounds[1] - self.bounds[0])) or 1.0

    @functools.cached_property
    def triangles(self) -> np.ndarray:
        """(m, 3, 3) float64: the faces' vertex positions."""
        return _readonly(self.vertices[self.faces])

    @functools.cached_property
    def _raw_normals(self) -> np.ndarray:
        t = self.triangles
        return np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])

    @functools.cached_property
    def face_areas(self) -> np.ndarray:
        """(m,) float64 triangle areas."""
        return _readonly(0.5 * np.linalg.norm(self._raw_normals, axis=1))

    @functools.cached_property
    def face_planes(self) -> np.ndarray:
        """(m, 4) float64 planes ``(n, d)``: unit outward normal n, ``n . x + d = 0`` on the face.

        Faces that belong to one flat polygon (:attr:`polygons`) share the polygon's plane bit for bit, so
        the per-face facing test can never split a flat polygon (this is what makes HSD and the per-face
        detectors agree exactly, even for a light in the polygon's plane).
        """
        planes = self._own_face_planes()
        labels, poly_planes = self._polygon_grouping
        multi = np.bincount(labels)[labels] > 1
        planes[multi] = poly_planes[labels[multi]]
        return _readonly(planes)

    @functools.cached_property
    def colors(self) -> np.ndarray | None:
        """(n, 4) float32 RGBA per vertex, or None.

        Vertex colours when given; otherwise face colours averaged onto vertices (area-weighted).
        """
        if self.vertex_colors is not None:
            return self.vertex_colors
        if self.face_colors is None:
            return None
        w = self.face_areas[:, None] * self.face_colors
        acc = np.zeros((len(self.vertices), 4))
        wsum = np.zeros(len(self.vertices))
        for k in range(3):
            np.add.at(acc, self.faces[:, k], w)
            np.add.at(wsum, self.faces[:, k], self.face_areas)
        return _readonly((acc / np.maximum(wsum, 1e-300)[:, None]).astype(np.float32))

    @functools.cached_property
    def mean_albedo(self) -> np.ndarray | None:
        """``(3,) float64`` linear RGB: the surface's area-weighted mean colour (its material's base colour
        times its texture, :meth:`arshadow.geometry.material.Material.texture_mean`, or its vertex / face
        colours, sRGB-decoded), or None for a mesh with none (the renderer's default grey). What the object reflects
        onto the ground (colour bleeding, :meth:`arshadow.plan.scene_geometry.SceneGeometry.object_bleed`).

        >>> c = ShadowCaster(np.eye(3), [[0, 1, 2]], vertex_colors=[[255, 0, 0]] * 3)
        >>> c.mean_albedo.round(3).tolist()
        [1.0, 0.0, 0.0]
        """
        m, w = self.material, self.face_areas
        if w.sum() <= 0:
            return None
        if m is not None and m.textured:
            return m.texture_mean(w)
        if m is not None:
            return np.asarray(m.base_color, np.float64)[:3].copy()
        if self.colors is None:
            return None
        lin = srgb_to_linear(np.asarray(self.colors, np.float64)[:, :3])
        per_face = lin[self.faces].mean(axis=1)
        mean: np.ndarray = (w @ per_face) / w.sum()
        return mean

    # ------------------------------------------------------------------ facing test
    @functools.cached_property
    def _facing_prep(self) -> dict:
        """float32 planes re-centred on the bounding-box centre, (4, m) contiguous, for the fast
        pre-test of :meth:`facing`, and the bounds its error margin needs."""
        planes = self.face_planes
        c = self.bounds.mean(axis=0)
        d_c = planes[:, 3] + planes[:, :3] @ c  # plane offsets relative to the centre
        pt32 = np.ascontiguousarray(np.vstack([planes[:, :3].T, d_c[None, :]]).astype(np.float32))
        return {
            "centre": c,
            "pt32": _readonly(pt32),
            "dmax_c": float(np.abs(d_c).max()),
            "dmax": float(np.abs(planes[:, 3]).max()),
        }

    def facing(self, light_h: np.ndarray) -> np.ndarray:
        """(m,) bool: faces that face the light, ``n . L + d w > 0``, decided exactly as the float64
        expression ``((n_x L_x + n_y L_y) + n_z L_z) + d w`` (:func:`plane_side`) decides it.

        Fast path: one float32 element-wise pass over the planes re-centred on the mesh, then every
        face whose float32 value lies within a rigorous error bound of zero is re-evaluated with the
        float64 expression; all other signs are provably the same. ``light_h`` must be a validated
        ``(4,)`` float64 (see :func:`arshadow.geometry.silhouette.as_light_h`).
        """
        h = light_h
        prep = self._facing_prep
        lc = h[:3] - prep["centre"] * h[3]
        nl = float(np.sqrt(lc @ lc))
        w = abs(float(h[3]))
        if not (nl < 1e30 and prep["dmax_c"] < 1e30):
            return plane_side(self.face_planes, h) > 0.0
        l32 = np.array([lc[0], lc[1], lc[2], h[3]], dtype=np.float32)
        u = 2.0**-24
        # |s32 - exact| <= 8u (|L'| + |d'| |w|) (conversions + a length-4 dot product, any order);
        # |float64 expression - exact| <= 1e-15 (|L| + |d| |w|); 1e-30 covers float32 underflow
        margin = (
            8.0 * u * (nl * (1.0 + 1e-6) + prep["dmax_c"] * w)
            + 1e-15 * (float(np.sqrt(h[:3] @ h[:3])) + prep["dmax"] * w)
            + 1e-30
        )
        pt = prep["pt32"]
        m = pt.shape[1]
        fac = np.empty(m, bool)
        # element-wise in cache-sized chunks, single-threaded (a BLAS sgemv is as fast when the machine
        # is idle but stalls when it is busy; chunks keep the temporaries in cache)
        ch = min(m, 1 << 16)
        s32 = np.empty(ch, np.float32)
        tmp = np.empty(ch, np.float32)
        near0 = np.empty(ch, bool)
        unsure = []
        for a in range(0, m, ch):
            b = min(m, a + ch)
            n = b - a
            s, t, z = s32[:n], tmp[:n], near0[:n]
            np.multiply(pt[0, a:b], l32[0], out=s)
            for k in (1, 2, 3):
                np.multiply(pt[k, a:b], l32[k], out=t)
                np.add(s, t, out=s)
            np.greater(s, 0.0, out=fac[a:b])
            np.abs(s, out=t)
            np.less_equal(t, margin, out=z)
            if z.any():
                unsure.append(np.flatnonzero(z) + a)
        if unsure:
            idx = np.concatenate(unsure)
            fac[idx] = plane_side(self.face_planes[idx], h) > 0.0
        return fac

    # ------------------------------------------------------------------ adjacency
    @functools.cached_property
    def _adjacency(self) -> dict[str, np.ndarray]:
        f = self.faces
        m = f.shape[0]
        n = len(self.vertices)
        a = f.reshape(-1)  # corner edges: (f0,f1), (f1,f2), (f2,f0)
        b = f[:, [1, 2, 0]].reshape(-1)
        face_of = np.repeat(np.arange(m, dtype=np.intp), 3)
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        key = lo.astype(np.int64) * n + hi
        order = np.argsort(key, kind="stable")
        ks = key[order]
        start = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
        counts = np.diff(np.r_[start, ks.size])
        e = start.size
        inc_edge = np.empty(3 * m, np.intp)
        inc_edge[order] = np.repeat(np.arange(e, dtype=np.intp), counts)
        fwd = a < b  # corner traverses lo -> hi
        # per edge: number of incidences traversing lo->hi and hi->lo
        n_fwd = np.bincount(inc_edge, weights=fwd, minlength=e).astype(np.intp)
        n_bwd = counts - n_fwd
        # the first face of each edge: a face traversing lo->hi if any, else the first incidence
        first_fwd = np.full(e, -1, np.intp)
        first_any = np.full(e, -1, np.intp)
        so = order  # incidences sorted by edge; within an edge by original corner order
        se = inc_edge[so]
        # last write wins -> iterate reversed so the first incidence wins
        first_any[se[::-1]] = so[::-1]
        fw = fwd[so]
        first_fwd[se[fw][::-1]] = so[fw][::-1]
        c0 = np.where(first_fwd >= 0, first_fwd, first_any)  # corner index of face 0
        # second incidence: any corner of the edge other than c0 (prefer the opposite direction)
        second = np.full(e, -1, np.intp)
        other = so != c0[se]
        opp = other & (fwd[so] != fwd[c0[se]])
        second[se[other][::-1]] = so[other][::-1]
        second[se[opp][::-1]] = so[opp][::-1]
        edges = np.stack([a[c0], b[c0]], axis=1)
        ef0 = face_of[c0]
        ef1 = np.where(second >= 0, face_of[np.maximum(second, 0)], -1)
        # +1 where the corner traverses the edge as stored in `edges`, -1 where reversed
        inc_sign = np.where(a == edges[inc_edge, 0], 1, -1).astype(np.int8)
        boundary = np.flatnonzero(counts == 1)
        nonmanifold = np.flatnonzero(counts > 2)
        misoriented = np.flatnonzero((counts == 2) & (n_fwd != n_bwd))
        return {
            "edges": edges.astype(np.intp),
            "edge_faces": np.stack([ef0, ef1], axis=1).astype(np.intp),
            "inc_edge": inc_edge,
            "inc_face": face_of,
            "inc_sign": inc_sign,
            "edge_counts": counts.astype(np.intp),
            "boundary": boundary.astype(np.intp),
            "nonmanifold": nonmanifold.astype(np.intp),
            "misoriented": misoriented.astype(np.intp),
        }

    @functools.cached_property
    def edges(self) -> np.ndarray:
        """(e, 2) intp unique edges, each oriented as face ``edge_faces[i, 0]`` traverses it."""
        return _readonly(self._adjacency["edges"])

    @functools.cached_property
    def edge_faces(self) -> np.ndarray:
        """(e, 2) intp: the faces on each edge; column 0 traverses ``edges[i]`` as stored, column 1 the
        other way round on a consistently wound mesh; -1 marks a boundary edge. Non-manifold edges (3+
        faces, see :attr:`nonmanifold_edges`) list two of their faces here; all incidences are in
        :attr:`edge_incidence`."""
        return _readonly(self._adjacency["edge_faces"])

    @functools.cached_property
    def edge_incidence(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(edge (3m,) intp, face (3m,) intp, sign (3m,) int8)``: every face corner-edge, with +1 where
        the face traverses the edge as stored in :attr:`edges` and -1 where it traverses it reversed."""
        d = self._adjacency
        return _readonly(d["inc_edge"]), _readonly(d["inc_face"]), _readonly(d["inc_sign"])

    @functools.cached_property
    def boundary_edges(self) -> np.ndarray:
        """(b,) intp indices into :attr:`edges` of edges with a single face."""
        return _readonly(self._adjacency["boundary"])

    @functools.cached_property
    def nonmanifold_edges(self) -> np.ndarray:
        """(k,) intp indices into :attr:`edges` of edges shared by three or more faces."""
        return _readonly(self._adjacency["nonmanifold"])

    @functools.cached_property
    def misoriented_edges(self) -> np.ndarray:
        """(k,) intp indices of two-face edges that both faces traverse in the same direction."""
        return _readonly(self._adjacency["misoriented"])

    @functools.cached_property
    def is_closed(self) -> bool:
        """True when every edge has exactly two faces traversing it in opposite directions."""
        return bool(
            self.boundary_edges.size == 0 and self.nonmanifold_edges.size == 0 and self.misoriented_edges.size == 0
        )

    @functools.cached_property
    def is_convex(self) -> bool:
        """A closed mesh with every vertex on or behind every face's plane (to ``1e-9 x scale``); computed
        once (O(faces x vertices) in blocks, stopping at the first vertex in front). Open meshes never are.

        >>> from arshadow.geometry.mesh import load_occluder
        >>> load_occluder("box:1,1,1").is_convex, load_occluder("torus:1,0.3").is_convex
        (True, False)
        """
        if not self.is_closed:
            return False
        v = np.c_[self.vertices, np.ones(len(self.vertices))]
        tol = 1e-9 * max(float(self.scale), 1e-300)
        block = max(1, 2_000_000 // max(len(v), 1))
        return not any(
            np.any(v @ self.face_planes[s : s + block].T > tol) for s in range(0, len(self.face_planes), block)
        )

    @property
    def two_sided(self) -> bool:
        """True for meshes that are not closed: all their faces cast shadows, turned towards the light."""
        return not self.is_closed

    @functools.cached_property
    def closed_edge_faces(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fast-path arrays of the adjacency detector on closed meshes: ``(f_lo (e,), f_hi (e,),
        edges_lo (e, 2))``, contiguous intp, sorted by ``f_lo`` (the lower face index of each edge, so the
        gather ``facing[f_lo]`` walks memory in order), each edge oriented as face ``f_lo`` winds it."""
        ef = self.edge_faces
        e = self.edges
        swap = ef[:, 1] < ef[:, 0]
        lo = np.where(swap, ef[:, 1], ef[:, 0])
        hi = np.where(swap, ef[:, 0], ef[:, 1])
        el = np.where(swap[:, None], e[:, ::-1], e)
        order = np.argsort(lo, kind="stable")
        return _readonly(lo[order]), _readonly(hi[order]), _readonly(el[order])

    # ------------------------------------------------------------------ flat polygons (HSD)
    def _own_face_planes(self) -> np.ndarray:
        """(m, 4) float64: each face's own plane (unit normal, offset through its centroid), before
        :attr:`face_planes` gives the faces of a flat polygon the polygon's shared plane. Not cached
        (needed twice, at preparation only)."""
        n = self._raw_normals
        n = n / np.linalg.norm(n, axis=1)[:, None]
        d = -np.einsum("ij,ij->i", n, self.triangles.mean(axis=1))
        return np.concatenate([n, d[:, None]], axis=1)

    @functools.cached_property
    def _polygon_grouping(self) -> tuple[np.ndarray, np.ndarray]:
        """``(labels (m,), polygon planes (P, 4))`` from the faces' own planes (computed once)."""
        return self._polygon_labels_planes(self._own_face_planes())

    def _polygon_labels_planes(self, planes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Group faces into connected coplanar polygons.

        Two faces sharing a two-face edge join when their unit normals agree to 1e-12 and the far vertex
        of each lies within 1e-12 x mesh size of the other's plane. Returns ``labels (m,)`` and the
        polygons' planes ``(P, 4)`` (area-weighted normal, offset through the polygon's vertex centroid).
        """
        adj = self._adjacency
        ef = adj["edge_faces"]
        ok = (ef[:, 1] >= 0) & (adj["edge_counts"] == 2)
        f0, f1 = ef[ok, 0], ef[ok, 1]
        tol = 1e-12 * self.scale
        same = np.einsum("ij,ij->i", planes[f0, :3], planes[f1, :3]) >= 1.0 - 1e-12
        t = self.triangles
        dist01 = np.abs(np.einsum("ikj,ij->ik", t[f1], planes[f0, :3]) + planes[f0, 3:4]).max(axis=1)
        dist10 = np.abs(np.einsum("ikj,ij->ik", t[f0], planes[f1, :3]) + planes[f1, 3:4]).max(axis=1)
        same &= (dist01 <= tol) & (dist10 <= tol)
        labels = connected_labels(len(planes), f0[same], f1[same])
        p = labels.max() + 1
        area_n = self._raw_normals  # length = 2 x area
        nsum = np.stack([np.bincount(labels, weights=area_n[:, k], minlength=p) for k in range(3)], axis=1)
        nrm = nsum / np.linalg.norm(nsum, axis=1)[:, None]
        cen_f = t.mean(axis=1)
        csum = np.stack([np.bincount(labels, weights=cen_f[:, k], minlength=p) for k in range(3)], axis=1)
        cnt = np.bincount(labels, minlength=p)
        cen = csum / cnt[:, None]
        d = -np.einsum("ij,ij->i", nrm, cen)
        return labels, np.concatenate([nrm, d[:, None]], axis=1)

    @functools.cached_property
    def polygons(self) -> dict[str, np.ndarray]:
        """Connected coplanar faces merged into polygons (Hybrid Silhouette Detection, [Kolivand-HSD]).

        Returns a dict: ``face_polygon (m,) intp`` (polygon of each face), ``planes (P, 4)`` (the plane
        shared by the polygon's faces), ``edges (B, 2) intp`` (the polygons' boundary edges, oriented
        as the polygon winds them, internal edges cancelled), ``edge_polygon (B,) intp``.
        """
        planes = self.face_planes
        labels, _ = self._polygon_grouping
        p = labels.max() + 1
        # a polygon's plane = the (shared) plane of any of its faces
        first = np.full(p, -1, np.intp)
        first[labels[::-1]] = np.arange(len(labels))[::-1]
        poly_planes = planes[first]
        inc_edge, inc_face, inc_sign = self.edge_incidence
        # net winding of each (edge, polygon) pair; non-zero pairs are polygon boundary edges
        key = inc_edge.astype(np.int64) * p + labels[inc_face]
        uk, inv = np.unique(key, return_inverse=True)
        net = np.bincount(inv.reshape(-1), weights=inc_sign).astype(np.int64)
        keep = net != 0
        e_idx = (uk[keep] // p).astype(np.intp)
        pol = (uk[keep] % p).astype(np.intp)
        mult = np.abs(net[keep])
        e_idx = np.repeat(e_idx, mult)
        sgn = np.repeat(np.sign(net[keep]), mult)
        pol = np.repeat(pol, mult)
        ed = self.edges[e_idx]
        ed = np.where((sgn > 0)[:, None], ed, ed[:, ::-1])
        return {
            "face_polygon": _readonly(labels.astype(np.intp)),
            "planes": _readonly(poly_planes),
            "edges": _readonly(ed.astype(np.intp)),
            "edge_polygon": _readonly(pol),
        }

    # ------------------------------------------------------------------ geometry helpers
    def winding_number(self, point: npt.ArrayLike) -> float:
        """Generalised winding number of the surface around ``point (3,)`` (1 inside, 0 outside a closed
        outward-wound mesh), by the solid angles of the triangles (Van Oosterom & Strackee)."""
        p = np.asarray(point, np.float64).reshape(3)
        t = self.triangles - p
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        num = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = (
            la * lb * lc
            + np.einsum("ij,ij->i", a, b) * lc
            + np.einsum("ij,ij->i", b, c) * la
            + np.einsum("ij,ij->i", c, a) * lb
        )
        return float(np.sum(2.0 * np.arctan2(num, den)) / (4.0 * np.pi))


def plane_side(planes: np.ndarray, light_h: np.ndarray) -> np.ndarray:
    """The facing expression for planes ``(k, 4)`` and a homogeneous light ``(4,)``: ``(k,) float64``
    ``((n_x L_x + n_y L_y) + n_z L_z) + d w``, element-wise in this order (no BLAS, so a face's value
    does not depend on which other faces are evaluated with it)."""
    h = light_h
    side: np.ndarray = ((planes[:, 0] * h[0] + planes[:, 1] * h[1]) + planes[:, 2] * h[2]) + planes[:, 3] * h[3]
    return side


def connected_labels(n: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Connected-component labels ``(n,) intp`` (0..C-1, in order of first node) of the graph with edges
    ``(u[i], v[i])``; vectorised hooking + pointer jumping (no scipy)."""
    parent = np.arange(n, dtype=np.intp)
    u = np.asarray(u, np.intp)
    v = np.asarray(v, np.intp)
    while u.size:
        pu, pv = parent[u], parent[v]
        lo, hi = np.minimum(pu, pv), np.maximum(pu, pv)
        diff = lo != hi
        if not diff.any():
            break
        np.minimum.at(parent, hi[diff], lo[diff])
        while True:
            pp = parent[parent]
            if np.array_equal(pp, parent):
                break
            parent = pp
    _, labels = np.unique(parent, return_inverse=True)
    return labels.reshape(-1).astype(np.intp)
