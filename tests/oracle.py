"""The tests' independent shadow oracle: analytic ground shadows of triangles and exact rasterisers.

Nothing here uses arshadow's silhouettes or volumes: a mesh's shadow on the ground z = 0 is the union of
its triangles projected from the light onto the plane (each triangle first clipped to z >= 0, because the
part of a mesh below the ground casts nothing onto it). The GL tests import
:func:`ground_shadow_triangles` as their ground truth too.

All functions are pure numpy and take plain arrays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arshadow.geometry.exact import ground_shadow_triangles, iou  # noqa: F401 (re-exported: the tests import them from here)


@dataclass(frozen=True)
class Grid:
    """A pixel grid on the ground: pixel (i, j) has its centre at ``(x0 + (j + 0.5) h, y0 + (i + 0.5) h)``."""

    x0: float
    y0: float
    h: float
    width: int
    height: int

    @staticmethod
    def around(points_2d, n: int = 2048, margin: float = 0.02) -> Grid:
        p = np.asarray(points_2d, np.float64).reshape(-1, 2)
        lo, hi = p.min(axis=0), p.max(axis=0)
        size = float(np.max(hi - lo)) * (1 + 2 * margin) or 1.0
        c = 0.5 * (lo + hi)
        h = size / n
        return Grid(c[0] - size / 2, c[1] - size / 2, h, n, n)

    def centres(self):
        xs = self.x0 + (np.arange(self.width) + 0.5) * self.h
        ys = self.y0 + (np.arange(self.height) + 0.5) * self.h
        return xs, ys


def rasterize_triangles(tris_2d, grid: Grid) -> np.ndarray:
    """Union of 2-D triangles at pixel centres: ``(H, W) bool``. Each triangle is tested on the pixels
    of its bounding box with exact edge functions (inclusive edges); orientation does not matter."""
    mask = np.zeros((grid.height, grid.width), bool)
    xs, ys = grid.centres()
    for t in np.asarray(tris_2d, np.float64):
        lo = np.floor((t.min(axis=0) - [grid.x0, grid.y0]) / grid.h - 0.5).astype(int)
        hi = np.ceil((t.max(axis=0) - [grid.x0, grid.y0]) / grid.h - 0.5).astype(int)
        j0, i0 = max(lo[0], 0), max(lo[1], 0)
        j1, i1 = min(hi[0], grid.width - 1), min(hi[1], grid.height - 1)
        if j1 < j0 or i1 < i0:
            continue
        X, Y = np.meshgrid(xs[j0 : j1 + 1], ys[i0 : i1 + 1])
        e = []
        for k in range(3):
            a, b = t[k], t[(k + 1) % 3]
            e.append((b[0] - a[0]) * (Y - a[1]) - (b[1] - a[1]) * (X - a[0]))
        inside = ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))
        mask[i0 : i1 + 1, j0 : j1 + 1] |= inside
    return mask


def plane_section_segments(vertices_h, triangles, z: float = 0.0) -> np.ndarray:
    """Oriented segments ``(k, 2, 2)`` where outward-wound triangles (homogeneous vertices, w >= 0)
    cross the plane ``z``; the region they bound (counter-clockwise seen from +z) is the solid's
    section. A triangle's boundary goes down through the plane at one point and back up at another;
    the segment runs from the down-crossing to the up-crossing."""
    V = np.asarray(vertices_h, np.float64).copy()
    V[:, 2] -= z * V[:, 3]  # homogeneous translation by -z
    T = V[np.asarray(triangles, np.intp)]  # (q, 3, 4)
    zz = T[:, :, 2]
    pos = zz > 0
    segs_down = np.full((T.shape[0], 2), np.nan)
    segs_up = np.full((T.shape[0], 2), np.nan)
    for k in range(3):
        A, B = T[:, k], T[:, (k + 1) % 3]
        pa, pb = pos[:, k], pos[:, (k + 1) % 3]
        cross = pa != pb
        t = np.zeros(T.shape[0])
        den = A[:, 2] - B[:, 2]
        t[cross] = A[cross, 2] / den[cross]
        P = A + t[:, None] * (B - A)
        with np.errstate(invalid="ignore", divide="ignore"):
            xy = P[:, :2] / P[:, 3:4]
        down = cross & pa
        up = cross & pb
        segs_down[down] = xy[down]
        segs_up[up] = xy[up]
    ok = np.all(np.isfinite(segs_down), axis=1) & np.all(np.isfinite(segs_up), axis=1)
    return np.stack([segs_down[ok], segs_up[ok]], axis=1)


def rasterize_segments_winding(segments, grid: Grid) -> np.ndarray:
    """Non-zero winding number of closed oriented segments at pixel centres: ``(H, W) int``.

    Scanline: for each pixel row the crossings of a ray towards +x are summed (+1 for upward segments,
    -1 for downward ones; half-open in y so shared end points count once).
    """
    s = np.asarray(segments, np.float64).reshape(-1, 2, 2)
    xs, ys = grid.centres()
    H, W = grid.height, grid.width
    acc = np.zeros((H, W + 1), np.int64)
    p, q = s[:, 0], s[:, 1]
    up = q[:, 1] > p[:, 1]
    lo_y = np.minimum(p[:, 1], q[:, 1])
    hi_y = np.maximum(p[:, 1], q[:, 1])
    i0 = np.ceil((lo_y - grid.y0) / grid.h - 0.5).astype(np.int64)  # first row centre >= lo_y
    i1 = np.ceil((hi_y - grid.y0) / grid.h - 0.5).astype(np.int64)  # rows < hi_y
    i0 = np.clip(i0, 0, H)
    i1 = np.clip(i1, 0, H)
    nrow = np.maximum(i1 - i0, 0)
    seg = np.repeat(np.arange(len(s)), nrow)
    if seg.size == 0:
        return np.zeros((H, W), np.int64)
    row = np.repeat(i0, nrow) + (np.arange(seg.size) - np.repeat(np.cumsum(nrow) - nrow, nrow))
    y = ys[row]
    a, b = p[seg], q[seg]
    x = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    sign = np.where(up[seg], 1, -1)
    # the ray from pixel centre xc towards +x crosses the segment iff x > xc: pixels j < K
    K = np.clip(np.ceil((x - grid.x0) / grid.h - 0.5).astype(np.int64), 0, W)
    np.add.at(acc, (row, np.zeros_like(K)), sign)
    np.add.at(acc, (row, K), -sign)
    return np.cumsum(acc, axis=1)[:, :W]


def points_in_shadow(points, vertices, faces, light_h) -> np.ndarray:
    """Brute force: is the segment from each point to the light (ray towards a directional light)
    blocked by any triangle? ``(k,) bool``; every triangle tested (Moller-Trumbore, float64)."""
    P = np.asarray(points, np.float64).reshape(-1, 3)
    tri = np.asarray(vertices, np.float64)[np.asarray(faces, np.intp)]
    h = np.asarray(light_h, np.float64).reshape(4)
    v0 = tri[:, 0]
    e1 = tri[:, 1] - v0
    e2 = tri[:, 2] - v0
    out = np.zeros(len(P), bool)
    chunk = max(1, 2_000_000 // max(len(tri), 1))
    for s0 in range(0, len(P), chunk):
        p = P[s0 : s0 + chunk, None, :]  # (k, 1, 3)
        d = np.broadcast_to(h[:3], p.shape) if h[3] == 0 else h[:3] / h[3] - p
        tmax = np.inf if h[3] == 0 else 1.0
        pv = np.cross(d, e2[None])
        det = np.einsum("kij,kij->ki", np.broadcast_to(e1, pv.shape), pv)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = p - v0[None]
            u = np.einsum("kij,kij->ki", s, pv) * inv
            q = np.cross(s, e1[None])
            v = np.einsum("kij,kij->ki", q, np.broadcast_to(d, q.shape)) * inv
            t = np.einsum("kij,kij->ki", np.broadcast_to(e2, q.shape), q) * inv
        hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-12) & (t < tmax)
        out[s0 : s0 + chunk] = hit.any(axis=1)
    return out


def directed_edge_balance(triangles) -> tuple[int, int]:
    """For triangles ``(q, 3)``: ``(n_unbalanced, n_not_exactly_twice)`` where the first counts
    undirected edges whose uses a->b and b->a differ in number (0 = closed, consistently wound surface)
    and the second counts edges not used exactly once each way."""
    t = np.asarray(triangles, np.int64)
    a = t.reshape(-1)
    b = t[:, [1, 2, 0]].reshape(-1)
    n = int(max(a.max(initial=0), b.max(initial=0))) + 1
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    uk, inv = np.unique(key, return_inverse=True)
    inv = inv.reshape(-1)
    fwd = np.bincount(inv, weights=(a < b), minlength=uk.size)
    bwd = np.bincount(inv, weights=(a > b), minlength=uk.size)
    return int(np.count_nonzero(fwd != bwd)), int(np.count_nonzero((fwd != 1) | (bwd != 1)))


# ------------------------------------------------------------------------------------ penumbra profiles
def disc_segment_fraction(u):
    """Exact fraction of a unit disc's area beyond the chord at signed distance ``u``: the part
    ``{p : p . e > u}`` for a unit vector e (``u`` clipped to [-1, 1]; scalar or array). The blocked
    fraction of a uniform disc light behind a straight edge: the exact penumbra profile."""
    u = np.clip(np.asarray(u, np.float64), -1.0, 1.0)
    return (np.arccos(u) - u * np.sqrt(1.0 - u * u)) / np.pi


def profile_crossing(x, f, level: float) -> float:
    """First ``x`` where the (decreasing) sampled profile ``f(x)`` drops to ``level`` (linear
    interpolation between the two samples around it)."""
    i = int(np.argmax(f <= level))
    return x[i - 1] + (f[i - 1] - level) * (x[i] - x[i - 1]) / (f[i - 1] - f[i])
