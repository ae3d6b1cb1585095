"""The exact shadow of a mesh on the ground, independent of OpenGL and of arshadow's silhouettes and volumes.

Used as the ground truth of the GL tests and of ``arshadow bench``: a mesh's shadow on the ground z = 0 is
the union of its triangles projected from the light onto the plane (each triangle first clipped to
z >= 0, because the part of a mesh below the ground casts nothing onto it); an image pixel is in shadow
when the ray through its centre reaches the ground inside that union without first hitting the object
(the object's own triangles, projected into the image). Pure numpy, plain arrays, exact edge functions
at pixel centres; nothing here uses silhouettes, volumes or GL.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import cv2
import numpy as np
import numpy.typing as npt

__all__ = [
    "ShadowOracle",
    "boundary_error_px",
    "ground_points",
    "ground_shadow_triangles",
    "iou",
    "occluder_coverage",
    "points_in_triangles",
]


def ground_shadow_triangles(vertices: npt.ArrayLike, faces: npt.ArrayLike, light_h: npt.ArrayLike) -> np.ndarray:
    """The shadow of a triangle mesh on the ground plane z = 0, as 2-D triangles.

    Each triangle is clipped to the half-space z >= 0 (Sutherland-Hodgman; a triangle becomes 0, 1 or 2
    triangles), then every vertex p is projected along the ray from the light: for a point light L,
    ``L + (L_z / (L_z - p_z)) (p - L)``; for a directional light d (towards the light),
    ``p - (p_z / d_z) d``. The union of the returned triangles is the exact shadow on the ground.

    Parameters
    ----------
    vertices : (n, 3) float
        World coordinates, metres (z up).
    faces : (m, 3) int
        Triangles (winding irrelevant: every triangle casts, whichever side faces the light).
    light_h : (4,) float
        ``(x, y, z, 1)`` point light or ``(dx, dy, dz, 0)`` direction towards the light.

    Returns
    -------
    (m', 3, 2) float64
        Ground-plane (x, y) triangles; m' == m when the mesh lies entirely at or above z = 0, fewer
        when triangles are entirely below the ground, up to 2m when many straddle it. Orientation is
        arbitrary (not normalised).

    Raises
    ------
    ValueError
        If the light is not strictly above every (clipped) vertex: a point light with ``L_z <= p_z``
        or a directional light with ``d_z <= 0`` has no bounded shadow on the ground.
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.intp)
    h = np.asarray(light_h, np.float64).reshape(4)
    tri = v[f]  # (m, 3, 3)
    z = tri[:, :, 2]
    inside = z >= 0.0
    n_in = inside.sum(axis=1)
    out = [tri[n_in == 3]]
    # one vertex above: a single smaller triangle
    for count, keep_in in ((1, True), (2, False)):
        sel = np.flatnonzero(n_in == count)
        if sel.size == 0:
            continue
        t = tri[sel]
        ins = inside[sel]
        # rotate each triangle so that the odd vertex (the single inside / single outside) is first
        odd = np.argmax(ins if keep_in else ~ins, axis=1)
        idx = (odd[:, None] + np.arange(3)[None, :]) % 3
        t = np.take_along_axis(t, idx[:, :, None], axis=1)
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        ab = a + (a[:, 2] / (a[:, 2] - b[:, 2]))[:, None] * (b - a)
        ac = a + (a[:, 2] / (a[:, 2] - c[:, 2]))[:, None] * (c - a)
        ab[:, 2] = 0.0
        ac[:, 2] = 0.0
        if keep_in:  # a is above: triangle a, ab, ac
            out.append(np.stack([a, ab, ac], axis=1))
        else:  # a is below: quad ab, b, c, ac -> two triangles
            out.append(np.stack([ab, b, c], axis=1))
            out.append(np.stack([ab, c, ac], axis=1))
    tri = np.concatenate(out) if out else np.empty((0, 3, 3))
    p = tri.reshape(-1, 3)
    if h[3] == 0.0:
        if h[2] <= 0.0:
            raise ValueError("directional light does not point down onto the ground")
        q = p[:, :2] - (p[:, 2] / h[2])[:, None] * h[None, :2]
    else:
        L = h[:3] / h[3]
        if np.any(L[2] <= p[:, 2]):
            raise ValueError("point light is not above every vertex: unbounded shadow")
        t = L[2] / (L[2] - p[:, 2])
        q = L[None, :2] + t[:, None] * (p[:, :2] - L[None, :2])
    tris: np.ndarray = q.reshape(-1, 3, 2)
    return tris


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks (1.0 when both are empty)."""
    u = np.count_nonzero(a | b)
    return 1.0 if u == 0 else np.count_nonzero(a & b) / u


def _cam(K: npt.ArrayLike, cam_from_world: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    K = np.asarray(K, np.float64)
    T = np.asarray(cam_from_world, np.float64)
    R, t = T[:3, :3], T[:3, 3]
    return K, R, t, -R.T @ t


def ground_points(
    u: np.ndarray, v: np.ndarray, K: npt.ArrayLike, cam_from_world: npt.ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
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


def points_in_triangles(pts: np.ndarray, tris: np.ndarray) -> np.ndarray:
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


def occluder_coverage(
    u: np.ndarray,
    v: np.ndarray,
    K: npt.ArrayLike,
    cam_from_world: npt.ArrayLike,
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
) -> np.ndarray:
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
        return points_in_triangles(pts, uv[F])
    raise NotImplementedError("oracle: occluders reaching below the ground are not supported")


def in_ground_square(g: np.ndarray, ground_size: float | None) -> np.ndarray:
    if ground_size is None:
        return np.ones(len(g), bool)
    h = ground_size / 2.0
    inside: np.ndarray = (np.abs(g[:, 0]) <= h) & (np.abs(g[:, 1]) <= h)
    return inside


class ShadowOracle:
    """Classify arbitrary image points for one scene (several lights with weights).

    Parameters
    ----------
    K : (3, 3), cam_from_world : (4, 4)
    vertices : (n, 3), faces : (m, 3)
    lights : list of ((4,) light_h, weight)
    ground_size : float or None
    """

    def __init__(
        self,
        K: npt.ArrayLike,
        cam_from_world: npt.ArrayLike,
        vertices: npt.ArrayLike,
        faces: npt.ArrayLike,
        lights: Iterable[tuple[npt.ArrayLike, float]],
        ground_size: float | None = None,
    ) -> None:
        self.K = np.asarray(K, np.float64)
        self.T = np.asarray(cam_from_world, np.float64)
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(faces)
        self.lights = [(np.asarray(h, np.float64), float(w)) for h, w in lights]
        self.total = sum(w for _, w in self.lights)
        self.ground_size = ground_size
        self.shadow_tris = [ground_shadow_triangles(self.V, self.F, h) for h, _ in self.lights]

    def classify(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Returns ``(mask (n,) float64 blocked weight fraction, ground (n,) bool, occluder (n,) bool)``."""
        g, hit = ground_points(u, v, self.K, self.T)
        occ = occluder_coverage(u, v, self.K, self.T, self.V, self.F)
        ground = hit & ~occ & in_ground_square(g, self.ground_size)
        mask = np.zeros(len(g))
        idx = np.flatnonzero(ground)
        for (_h, w), tris in zip(self.lights, self.shadow_tris, strict=True):
            inside = points_in_triangles(g[idx], tris)
            mask[idx[inside]] += w / self.total
        return mask, ground, occ

    def image(
        self, width: int, height: int, canvas: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixel-centre classification of a canvas ``(u0, v0, w, h)`` (default the whole image):
        ``(mask (h, w), ground (h, w), occluder (h, w))``."""
        u0, v0, w, h = (0, 0, width, height) if canvas is None else canvas
        vv, uu = np.mgrid[v0 : v0 + h, u0 : u0 + w]
        m, g, o = self.classify(uu.ravel().astype(np.float64), vv.ravel().astype(np.float64))
        return m.reshape(h, w), g.reshape(h, w), o.reshape(h, w)


def boundary_error_px(mask: np.ndarray, exact: np.ndarray) -> dict[str, float]:
    """Distances (px) between the boundaries of two boolean masks ``(h, w)``: each boundary pixel of one
    mask to the nearest boundary pixel of the other (``cv2.distanceTransform``, L2), both directions.

    Returns ``{"mean": ..., "p95": ..., "max": ...}`` over both directions (0.0 when both are empty,
    ``inf`` when only one has a boundary).
    """

    def boundary(m: np.ndarray) -> np.ndarray:
        m = np.asarray(m, np.uint8)
        k = np.ones((3, 3), np.uint8)
        edge: np.ndarray = (m != cv2.erode(m, k, borderType=cv2.BORDER_REPLICATE)) & (m > 0)
        return edge

    ba, bb = boundary(mask), boundary(exact)
    if not ba.any() and not bb.any():
        return {"mean": 0.0, "p95": 0.0, "max": 0.0}
    if not ba.any() or not bb.any():
        return {"mean": float("inf"), "p95": float("inf"), "max": float("inf")}
    da = cv2.distanceTransform((~bb).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[ba]
    db = cv2.distanceTransform((~ba).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[bb]
    d = np.concatenate([da, db])
    return {"mean": float(d.mean()), "p95": float(np.percentile(d, 95)), "max": float(d.max())}
