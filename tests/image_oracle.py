"""Independent per-pixel oracle for the renderer's shadow mask (no GL, no arshadow geometry code).

For a pinhole camera ``K``, ``cam_from_world`` and an occluder given as raw ``vertices (n, 3)`` /
``faces (m, 3)``:

- ground point of a pixel centre ``(u, v)``: back-project the ray ``R^T K^-1 (u, v, 1)`` from the camera
  centre and intersect it with z = 0 (only rays going down reach the ground);
- occluder coverage: the ray hits an occluder triangle above the ground (z >= 0) before reaching it;
  computed by testing the pixel centre against every triangle's image (projected vertices, all in front
  of the camera) and checking the hit point's height;
- shadow: the ground point lies inside the union of the occluder's triangles projected from the light
  onto z = 0 (:func:`oracle.ground_shadow_triangles`, the tests' one analytic ground shadow); tested in
  ground coordinates, so shadow triangles reaching behind the camera need no clipping.

Everything is vectorised numpy with a per-triangle loop over bounding-box candidates. Points are arbitrary
(sub-pixel) image positions, so the same code gives the pixel-centre oracle and the fine-resolution
boundary-distance measurement (:func:`boundary_distance`).
"""

from __future__ import annotations

import numpy as np

from oracle import ground_shadow_triangles, iou

__all__ = ["ShadowOracle", "boundary_distance", "ground_points", "iou", "occluder_coverage"]


def _cam(K, cam_from_world):
    K = np.asarray(K, np.float64)
    T = np.asarray(cam_from_world, np.float64)
    R, t = T[:3, :3], T[:3, 3]
    return K, R, t, -R.T @ t


def ground_points(u, v, K, cam_from_world):
    """Ground hits ``(n, 2)`` of the rays through image points ``(u, v)`` and a bool ``(n,)`` hit flag."""
    K, R, t, C = _cam(K, cam_from_world)
    u = np.asarray(u, np.float64).ravel()
    v = np.asarray(v, np.float64).ravel()
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], 1)
    d = d_cam @ R  # = (R^T d_cam^T)^T
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -C[2] / d[:, 2]
    hit = (d[:, 2] < 0) & (C[2] > 0) & np.isfinite(s) & (s > 0)
    g = C[:2][None, :] + np.where(hit, s, 0.0)[:, None] * d[:, :2]
    return g, hit


def _points_in_triangles(pts, tris):
    """bool (n,): point inside (or on) any 2-D triangle of ``tris (m, 3, 2)``."""
    pts = np.asarray(pts, np.float64)
    inside = np.zeros(len(pts), bool)
    if len(pts) == 0 or len(tris) == 0:
        return inside
    lo = tris.min(axis=1)
    hi = tris.max(axis=1)
    # sort points by x for fast bbox candidate selection
    order = np.argsort(pts[:, 0], kind="stable")
    xs = pts[order, 0]
    for k in range(len(tris)):
        a, b, c = tris[k]
        area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        if area == 0.0:
            continue
        i0, i1 = np.searchsorted(xs, lo[k, 0], side="left"), np.searchsorted(xs, hi[k, 0], side="right")
        if i1 <= i0:
            continue
        idx = order[i0:i1]
        idx = idx[~inside[idx]]
        if idx.size == 0:
            continue
        q = pts[idx]
        sel = (q[:, 1] >= lo[k, 1]) & (q[:, 1] <= hi[k, 1])
        idx, q = idx[sel], q[sel]
        if idx.size == 0:
            continue
        s = np.sign(area)
        w0 = s * ((b[0] - q[:, 0]) * (c[1] - q[:, 1]) - (b[1] - q[:, 1]) * (c[0] - q[:, 0]))
        w1 = s * ((c[0] - q[:, 0]) * (a[1] - q[:, 1]) - (c[1] - q[:, 1]) * (a[0] - q[:, 0]))
        w2 = s * ((a[0] - q[:, 0]) * (b[1] - q[:, 1]) - (a[1] - q[:, 1]) * (b[0] - q[:, 0]))
        hit = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
        inside[idx[hit]] = True
    return inside


def occluder_coverage(u, v, K, cam_from_world, vertices, faces):
    """bool (n,): the ray through image point (u, v) hits an occluder triangle at height z >= 0 before
    the ground (every triangle must lie in front of the camera)."""
    K, R, t, C = _cam(K, cam_from_world)
    V = np.asarray(vertices, np.float64)
    F = np.asarray(faces)
    Xc = V @ R.T + t
    zf = Xc[F, 2]
    behind = np.all(zf <= 0, axis=1)  # cannot be hit by rays going forwards
    if np.any(np.any(zf <= 0, axis=1) & ~behind):
        raise ValueError("oracle: an occluder triangle straddles the camera plane")
    F = F[~behind]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([K[0, 0] * Xc[:, 0] / Xc[:, 2] + K[0, 2], K[1, 1] * Xc[:, 1] / Xc[:, 2] + K[1, 2]], 1)
    pts = np.stack([np.ravel(u), np.ravel(v)], 1).astype(np.float64)
    # occluder entirely above ground: a hit is always before the ground
    if V[:, 2].min() >= 0:
        return _points_in_triangles(pts, uv[F])
    raise NotImplementedError("oracle: occluders reaching below the ground are not supported")


def in_ground_square(g, ground_size):
    if ground_size is None:
        return np.ones(len(g), bool)
    h = ground_size / 2.0
    return (np.abs(g[:, 0]) <= h) & (np.abs(g[:, 1]) <= h)


class ShadowOracle:
    """Classify arbitrary image points for one scene (several lights with weights).

    Parameters
    ----------
    K : (3, 3), cam_from_world : (4, 4)
    vertices : (n, 3), faces : (m, 3)
    lights : list of ((4,) light_h, weight)
    ground_size : float or None
    """

    def __init__(self, K, cam_from_world, vertices, faces, lights, ground_size=None):
        self.K = np.asarray(K, np.float64)
        self.T = np.asarray(cam_from_world, np.float64)
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(faces)
        self.lights = [(np.asarray(h, np.float64), float(w)) for h, w in lights]
        self.total = sum(w for _, w in self.lights)
        self.ground_size = ground_size
        self.shadow_tris = [ground_shadow_triangles(self.V, self.F, h) for h, _ in self.lights]

    def classify(self, u, v):
        """Returns ``(mask (n,) float64 blocked weight fraction, ground (n,) bool, occluder (n,) bool)``."""
        g, hit = ground_points(u, v, self.K, self.T)
        occ = occluder_coverage(u, v, self.K, self.T, self.V, self.F)
        ground = hit & ~occ & in_ground_square(g, self.ground_size)
        mask = np.zeros(len(g))
        idx = np.flatnonzero(ground)
        for (h, w), tris in zip(self.lights, self.shadow_tris):
            inside = _points_in_triangles(g[idx], tris)
            mask[idx[inside]] += w / self.total
        return mask, ground, occ

    def image(self, width, height, canvas=None):
        """Pixel-centre classification of a canvas ``(u0, v0, w, h)`` (default the whole image):
        ``(mask (h, w), ground (h, w), occluder (h, w))``."""
        u0, v0, w, h = (0, 0, width, height) if canvas is None else canvas
        vv, uu = np.mgrid[v0:v0 + h, u0:u0 + w]
        m, g, o = self.classify(uu.ravel().astype(np.float64), vv.ravel().astype(np.float64))
        return m.reshape(h, w), g.reshape(h, w), o.reshape(h, w)


def boundary_distance(oracle: ShadowOracle, pixels_uv, threshold, radius=1.0, step=1.0 / 32, far_radius=4.0):
    """Distance (px) from each given pixel centre to the boundary of the oracle's thresholded mask
    ``mask >= threshold``, measured on a fine grid (``step`` px) within ``radius``; pixels with no
    opposite-class sample within ``radius`` are re-measured with a coarser grid up to ``far_radius``
    (and get ``far_radius`` if still none is found: a gross error).

    Returns (n,) float64.
    """
    pixels_uv = np.asarray(pixels_uv, np.float64).reshape(-1, 2)
    out = np.full(len(pixels_uv), np.nan)
    for r, st in ((radius, step), (far_radius, 0.25)):
        todo = np.flatnonzero(np.isnan(out))
        if todo.size == 0:
            break
        offs = np.arange(-r, r + st / 2, st)
        du, dv = np.meshgrid(offs, offs)
        du, dv = du.ravel(), dv.ravel()
        dist = np.hypot(du, dv)
        keep = dist <= r
        du, dv, dist = du[keep], dv[keep], dist[keep]
        for i in todo:
            u, v = pixels_uv[i]
            c0 = oracle.classify(np.array([u]), np.array([v]))[0][0] >= threshold
            m = oracle.classify(u + du, v + dv)[0] >= threshold
            opp = m != c0
            if np.any(opp):
                out[i] = float(dist[opp].min())
    out[np.isnan(out)] = far_radius
    return out
