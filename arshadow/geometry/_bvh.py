"""A static bounding volume hierarchy over a mesh's triangles, for the Delta+ detector's ray tests.

Built once per mesh (cached on the :class:`~arshadow.geometry.mesh.ShadowCaster`): faces sorted along a Morton
curve of their centroids, grouped into leaves of ``LEAF`` faces, and a complete binary tree (heap layout:
node i has children 2i+1, 2i+2) of axis-aligned boxes above them. Queries traverse breadth-first for a
whole batch of rays at once (vectorised), so a ray costs O(log n) box tests plus the triangles of the
leaves it actually reaches. Which faces count (the light-facing ones) is a per-query mask: the tree does
not depend on the light.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .caster import ShadowCaster

LEAF = 8
_CHUNK = 65536


def _spread_bits(x: np.ndarray) -> np.ndarray:
    x = x.astype(np.uint64) & np.uint64(0x3FF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x030000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x0300F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x030C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x09249249)
    return x


def build(triangles: np.ndarray, scale: float) -> dict[str, Any]:
    """Build the tree for ``triangles (m, 3, 3)``; returns a dict of arrays (see module doc)."""
    m = triangles.shape[0]
    cen = triangles.mean(axis=1)
    lo, hi = cen.min(axis=0), cen.max(axis=0)
    q = ((cen - lo) / np.maximum(hi - lo, 1e-300) * 1023.0).astype(np.int64)
    code = (_spread_bits(q[:, 0]) << np.uint64(2)) | (_spread_bits(q[:, 1]) << np.uint64(1)) | _spread_bits(q[:, 2])
    order = np.argsort(code, kind="stable")
    n_leaves = max(1, -(-m // LEAF))
    depth = int(np.ceil(np.log2(n_leaves))) if n_leaves > 1 else 0
    n_l = 1 << depth
    leaf_faces: np.ndarray = np.full(n_l * LEAF, -1, np.intp)
    leaf_faces[:m] = order
    leaf_faces = leaf_faces.reshape(n_l, LEAF)
    tmin = triangles.min(axis=1)
    tmax = triangles.max(axis=1)
    pad = 1e-9 * scale  # boxes slightly inflated: a ray through a shared edge still reaches both leaves
    fmin = np.vstack([tmin - pad, np.full((1, 3), np.inf)])
    fmax = np.vstack([tmax + pad, np.full((1, 3), -np.inf)])
    lmin = fmin[leaf_faces].min(axis=1)  # index -1 picks the +inf row
    lmax = fmax[leaf_faces].max(axis=1)
    n_nodes = 2 * n_l - 1
    nmin = np.empty((n_nodes, 3))
    nmax = np.empty((n_nodes, 3))
    nmin[n_l - 1 :] = lmin
    nmax[n_l - 1 :] = lmax
    first = n_l - 1
    while first > 0:
        parents = np.arange((first - 1) // 2, first)
        nmin[parents] = np.minimum(nmin[2 * parents + 1], nmin[2 * parents + 2])
        nmax[parents] = np.maximum(nmax[2 * parents + 1], nmax[2 * parents + 2])
        first = (first - 1) // 2
    # the triangles' edge vectors for the Moller-Trumbore tests (per mesh, not per query)
    e1 = triangles[:, 1] - triangles[:, 0]
    e2 = triangles[:, 2] - triangles[:, 0]
    return {"nmin": nmin, "nmax": nmax, "leaf_faces": leaf_faces, "depth": depth, "n_leaves": n_l, "e1": e1, "e2": e2}


def _tree(caster: ShadowCaster) -> dict[str, Any]:
    """The caster's tree, built on first use and kept in its ``__dict__`` (per mesh, like its cached
    properties)."""
    t: dict[str, Any] | None = caster.__dict__.get("_bvh_cache")
    if t is None:
        t = build(caster.triangles, caster.scale)
        caster.__dict__["_bvh_cache"] = t
    return t


def any_hit(
    caster: ShadowCaster, origins: np.ndarray, dirs: np.ndarray, tmin: np.ndarray, face_mask: np.ndarray
) -> tuple[np.ndarray, dict[str, int]]:
    """For each ray ``origins[i] + t dirs[i]``, ``t > tmin[i]``, does it hit a face with ``face_mask``?

    Returns ``hit (r,) bool`` and counts ``{"node_tests", "triangle_tests"}`` (totals over all rays).
    Triangle test: Moller-Trumbore in float64, edges inclusive (a ray through a shared edge hits).
    """
    tree = _tree(caster)
    r = origins.shape[0]
    hit = np.zeros(r, bool)
    counts = {"node_tests": 0, "triangle_tests": 0}
    if r == 0 or not face_mask.any():
        return hit, counts
    tri = caster.triangles
    e1_all, e2_all = tree["e1"], tree["e2"]
    mask_pad = np.r_[face_mask, False]
    for s in range(0, r, _CHUNK):
        sl = slice(s, min(r, s + _CHUNK))
        o, d, t0 = origins[sl], dirs[sl], tmin[sl]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
        ray = np.arange(o.shape[0])
        node = np.zeros(o.shape[0], np.intp)
        for level in range(tree["depth"] + 1):
            counts["node_tests"] += int(node.size)
            with np.errstate(invalid="ignore"):
                t1 = (tree["nmin"][node] - o[ray]) * inv[ray]
                t2 = (tree["nmax"][node] - o[ray]) * inv[ray]
            tn = np.fmax.reduce(np.fmin(t1, t2), axis=1)
            tf = np.fmin.reduce(np.fmax(t1, t2), axis=1)
            keep = (tn <= tf) & (tf >= t0[ray])
            # a box the ray starts inside of, or that holds no usable face, is handled by the leaf test
            ray, node = ray[keep], node[keep]
            if level < tree["depth"]:
                ray = np.repeat(ray, 2)
                node = (2 * np.repeat(node, 2) + 1) + np.tile([0, 1], node.size)
        if ray.size == 0:
            continue
        leaf = node - (tree["n_leaves"] - 1)
        faces = tree["leaf_faces"][leaf]  # (pairs, LEAF)
        valid = mask_pad[faces]
        pr, slot = np.nonzero(valid)
        f = faces[pr, slot]
        rr = ray[pr]
        counts["triangle_tests"] += int(f.size)
        hh = moller_trumbore(o[rr], d[rr], t0[rr], tri[f, 0], e1_all[f], e2_all[f])
        hit_local = np.zeros(o.shape[0], bool)
        hit_local[rr[hh]] = True
        hit[sl] = hit_local
    return hit, counts


def moller_trumbore(
    o: np.ndarray, d: np.ndarray, t0: np.ndarray, v0: np.ndarray, e1: np.ndarray, e2: np.ndarray
) -> np.ndarray:
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = det != 0.0
    inv = np.zeros_like(det)
    inv[ok] = 1.0 / det[ok]
    s = o - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    qv = np.cross(s, e1)
    vv = np.einsum("ij,ij->i", d, qv) * inv
    t = np.einsum("ij,ij->i", e2, qv) * inv
    hit: np.ndarray = ok & (u >= 0.0) & (vv >= 0.0) & (u + vv <= 1.0) & (t > t0)
    return hit
