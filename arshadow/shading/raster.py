"""Which directions a mesh hides from points on its own surface, by orthographic item buffers (GL-free).

For each direction ``w`` the mesh's triangles are projected along ``w`` onto a plane perpendicular to it and
z-buffered (vectorised, at pixel centres) into an item buffer of triangle indices (``res`` x ``res`` over
the mesh's projected extent). A query point looks up the nearest triangle
over it in that direction; it is hidden when the point lies inside that triangle's projection (barycentric
test, exact) and behind its plane. One rasterisation per direction serves every point, so a mesh of 10^4
triangles and 10^4 points costs ~10 ms a direction instead of 10^4 BVH rays. The nearest triangle is
found at the pixel's centre: within a pixel of a silhouette edge the point may test a neighbour instead
(an error of up to one direction there).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["ItemBuffer", "hidden_directions", "item_buffer", "points_hidden"]

#: who draws an item buffer: :func:`item_buffer`'s arguments ``(xy, depth, faces, res)`` and result
ItemBuffer = Callable[[np.ndarray, np.ndarray, np.ndarray, int], np.ndarray]


def item_buffer(xy: np.ndarray, depth: np.ndarray, f: np.ndarray, res: int) -> np.ndarray:
    """``(res, res) int32``: per pixel (centre), the index into ``f`` of the triangle nearest to the source
    (largest ``depth``) covering it, -1 where none; ``xy (n, 2)`` pixel coordinates of the vertices.
    A vectorised z-buffer: every triangle's bounding-box pixels tested with edge functions at once."""
    img = np.full(res * res, -1, np.int32)
    if len(f) == 0:
        return img.reshape(res, res)
    t = xy[f]  # (m, 3, 2)
    x0 = np.clip(np.floor(t[:, :, 0].min(axis=1) - 0.5), 0, res - 1).astype(np.int64)
    x1 = np.clip(np.ceil(t[:, :, 0].max(axis=1) - 0.5), 0, res - 1).astype(np.int64)
    y0 = np.clip(np.floor(t[:, :, 1].min(axis=1) - 0.5), 0, res - 1).astype(np.int64)
    y1 = np.clip(np.ceil(t[:, :, 1].max(axis=1) - 0.5), 0, res - 1).astype(np.int64)
    w, h = x1 - x0 + 1, y1 - y0 + 1
    cnt = w * h
    tri = np.repeat(np.arange(len(f)), cnt)
    local = np.arange(len(tri)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    px = x0[tri] + local % w[tri]
    py = y0[tri] + local // w[tri]
    cx, cy = px + 0.5, py + 0.5
    a, b, c = t[tri, 0], t[tri, 1], t[tri, 2]
    den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = ((b[:, 1] - c[:, 1]) * (cx - c[:, 0]) + (c[:, 0] - b[:, 0]) * (cy - c[:, 1])) / den
        l2 = ((c[:, 1] - a[:, 1]) * (cx - c[:, 0]) + (a[:, 0] - c[:, 0]) * (cy - c[:, 1])) / den
    l3 = 1.0 - l1 - l2
    ins = (l1 >= 0) & (l2 >= 0) & (l3 >= 0) & np.isfinite(l1)
    d = depth[f]
    z = l1 * d[tri, 0] + l2 * d[tri, 1] + l3 * d[tri, 2]
    key, z, tri = (py * res + px)[ins], z[ins], tri[ins]
    order = np.lexsort((z, key))
    key, tri = key[order], tri[order]
    last = np.r_[key[1:] != key[:-1], True]  # the largest depth of each pixel comes last
    img[key[last]] = tri[last]
    return img.reshape(res, res)


def _frame(w: np.ndarray) -> np.ndarray:
    """(3, 3): rows e1, e2, w (orthonormal, w last)."""
    a = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(a, w)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(w, e1), w])


def hidden_directions(  # noqa: PLR0913 (the mesh, the queries, and four keyword-only options)
    vertices: np.ndarray,
    faces: np.ndarray,
    points: np.ndarray,
    dirs: np.ndarray,
    *,
    res: int = 384,
    eps: float = 0.0,
    need: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    item_buffer: ItemBuffer | None = None,
) -> np.ndarray:
    """``(k, d) bool``: is direction ``dirs[j]`` (unit, ``(d, 3)``) hidden from ``points[i]`` (``(k, 3)``,
    offset off the surface by the caller) by a triangle of the mesh ``vertices (n, 3)``, ``faces (m, 3)``?

    ``eps``: a triangle must be more than this in front of the point (metres); ``need (k, d) bool``: only
    these pairs are tested (others False); ``normals (m, 3)``: the faces' outward normals of a *closed* mesh
    (only faces turned towards a direction are drawn for it), None: every face; ``item_buffer``: a
    callable with :func:`item_buffer`'s arguments and result that draws it elsewhere (the GPU:
    :class:`arshadow.gl.sky.GLItemBuffer`), default :func:`item_buffer` (numpy).
    """
    draw = item_buffer or globals()["item_buffer"]
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.intp)
    p = np.asarray(points, np.float64)
    out = np.zeros((len(p), len(dirs)), bool)
    dirs = np.asarray(dirs, np.float64)
    # a closed mesh's nearest surface towards w is always a face turned towards w: draw only those
    facing = None if normals is None else (np.asarray(normals, np.float64) @ dirs.T > 0.0)
    for j, w in enumerate(dirs):
        q = np.arange(len(p)) if need is None else np.flatnonzero(need[:, j])
        if q.size == 0:
            continue
        fr = _frame(w)
        pv, pp = v @ fr.T, p[q] @ fr.T  # (n, 3), (q, 3): (e1, e2, depth towards w)
        lo, hi = pv[:, :2].min(axis=0), pv[:, :2].max(axis=0)
        scale = (res - 2) / max(float((hi - lo).max()), 1e-300)
        xy = (pv[:, :2] - lo) * scale + 1.0
        fj = f if facing is None else f[facing[:, j]]
        img = draw(xy, pv[:, 2], fj, res)
        out[q, j] = points_hidden(img, xy, pv[:, 2], fj, (pp[:, :2] - lo) * scale + 1.0, pp[:, 2], eps)
    return out


def points_hidden(  # noqa: PLR0913 (the item buffer, its mesh, the queries)
    img: np.ndarray,
    xy: np.ndarray,
    depth: np.ndarray,
    f: np.ndarray,
    qxy: np.ndarray,
    qdepth: np.ndarray,
    eps: float = 0.0,
) -> np.ndarray:
    """``(q,) bool``: is each query point (pixel coordinates ``qxy (q, 2)``, depth ``qdepth (q,)``) behind
    the triangle the item buffer ``img (res, res)`` (indices into ``f``, -1: none) holds at its pixel?
    Exact: the point must lie inside that triangle's projection (``xy (n, 2)`` of the vertices) and more
    than ``eps`` behind its plane (``depth (n,)``, larger = nearer the source)."""
    res = img.shape[0]
    ij = np.floor(qxy).astype(np.int64)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < img.shape[1]) & (ij[:, 1] >= 0) & (ij[:, 1] < res)
    tid = np.full(len(qxy), -1)
    tid[inside] = img[ij[inside, 1], ij[inside, 0]]
    out = np.zeros(len(qxy), bool)
    ok = tid >= 0
    if not ok.any():
        return out
    t = f[tid[ok]]
    a, b, c = xy[t[:, 0]], xy[t[:, 1]], xy[t[:, 2]]
    x = qxy[ok]
    den = (b[:, 1] - c[:, 1]) * (a[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (a[:, 1] - c[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        l1 = ((b[:, 1] - c[:, 1]) * (x[:, 0] - c[:, 0]) + (c[:, 0] - b[:, 0]) * (x[:, 1] - c[:, 1])) / den
        l2 = ((c[:, 1] - a[:, 1]) * (x[:, 0] - c[:, 0]) + (a[:, 0] - c[:, 0]) * (x[:, 1] - c[:, 1])) / den
    l3 = 1.0 - l1 - l2
    within = (l1 >= 0) & (l2 >= 0) & (l3 >= 0) & np.isfinite(l1)
    z = l1 * depth[t[:, 0]] + l2 * depth[t[:, 1]] + l3 * depth[t[:, 2]]
    out[ok] = within & (z > qdepth[ok] + eps)
    return out
