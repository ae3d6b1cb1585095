"""Is the probe where the user says it is? Its projected outline against the photo's edges.

A probe given at the wrong place (or not in the photo at all) still gets a "light": the fit finds the
shadow-like pattern that best explains the ground around where the probe is said to be. What the light fit
cannot tell, the probe's own image can: a probe standing where it is given has its outline (the silhouette
edges of its mesh, projected through the calibrated camera) on edges of the photo.

For points every few pixels along the projected silhouette (:func:`silhouette_edges`: mesh edges between a
face turned to the camera and one turned away), the photo's luminance gradient across the outline (along its
image normal) is read at offsets ``-R..R`` pixels. A point *agrees* when its strongest gradient across that
span lies within :data:`ALIGN_PX` of the outline, moved by one image shift common to all points (the best
within :data:`SHIFT_PX`: the marker's pose error). :func:`outline_agreement` returns the share of agreeing
points: about 0.2 by chance, 0.6..1 for a probe in place on the synthetic set.

The probe's own other edges are not evidence against a point: a box's lit and unlit faces meet in a crease
(:func:`crease_edges`) that is usually the strongest edge near the unlit side's outline (that side stands
against its own shadow, shaded against shaded), so the span's offsets on the probe's other projected edges (a
crease or another outline segment, more than :data:`ALIGN_PX` + 1 px from the point) are not read. (Cutting
each span at the first such edge instead raised the agreement of probes given 3-5 cm away, the chance level,
by ~0.03; skipping only the edges' own pixels leaves it as it was: docs/light.md.)
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..camera.model import Intrinsics
from ..transforms import transform_points

__all__ = ["ALIGN_PX", "CREASE_DEG", "crease_edges", "outline_agreement", "silhouette_edges"]

#: the outline agrees at a point when the photo's strongest edge across it is this close (pixels)
ALIGN_PX = 2.0
#: offsets read across the outline, each side (pixels)
SPAN_PX = 20
#: the outline is compared at every image shift up to this (pixels, each axis): the marker's pose error
#: moves the probe's projection by a few pixels (5 px on a synthetic photo 10 cm from a 5 cm marker)
SHIFT_PX = 8
#: spacing of the points along the outline (pixels)
STEP_PX = 3.0
#: two faces turned to the camera meet in a crease (an edge the photo shows) when their normals differ by more
#: than this (degrees): a box's 90, not a 32-sided cylinder's 11
CREASE_DEG = 30.0


def _visible_edges(
    verts: np.ndarray, faces: np.ndarray, eye: np.ndarray, min_deg: float = CREASE_DEG
) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's edges a photo from ``eye`` (3,) shows, world frame: ``(silhouette, creases)``, each
    (k, 2, 3) float64 segment ends (:func:`silhouette_edges`, :func:`crease_edges`), from one edge table."""
    v = np.asarray(verts, np.float64)
    f = np.asarray(faces)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # orient the normals away from the mesh's centroid (primitives and closed meshes: outward)
    out = np.sum(n * (tri.mean(axis=1) - v.mean(axis=0)), axis=1) < 0
    n[out] *= -1.0
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    front = np.sum(n * (np.asarray(eye, np.float64) - tri[:, 0]), axis=1) > 0
    face_of = np.tile(np.arange(len(f)), 3)  # the face of each entry of the face-edge list
    key = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    edges, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    n_front = np.bincount(inv, weights=front[face_of].astype(float), minlength=len(cnt))
    # an edge of two faces: exactly one turned to the eye; an open edge (one face): that face to the eye
    sil = (cnt <= 2) & (n_front == 1)
    # the two faces of each edge: its entries are consecutive once the list is ordered by edge
    order = np.argsort(inv, kind="stable")
    start = np.cumsum(cnt) - cnt
    f0, f1 = face_of[order[start]], face_of[order[np.minimum(start + 1, len(order) - 1)]]
    crease = (cnt == 2) & (n_front == 2) & (np.sum(n[f0] * n[f1], axis=1) < math.cos(math.radians(min_deg)))
    return v[edges[sil]], v[edges[crease]]


def silhouette_edges(verts: np.ndarray, faces: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """The mesh's silhouette seen from ``eye`` (3,), world frame: edges shared by a face turned towards
    ``eye`` and one turned away, and open edges of front faces. Returns (k, 2, 3) float64 segment ends.

    >>> from arshadow.geometry.mesh import load_occluder
    >>> m = load_occluder("box:1,1,1")
    >>> len(silhouette_edges(np.asarray(m.vertices), np.asarray(m.faces), np.array([5.0, 0.2, 0.5])))
    4
    """
    return _visible_edges(verts, faces, eye)[0]


def crease_edges(verts: np.ndarray, faces: np.ndarray, eye: np.ndarray, min_deg: float = CREASE_DEG) -> np.ndarray:
    """Edges seen from ``eye`` (3,) between two faces both turned to it whose normals differ by more than
    ``min_deg`` degrees (world frame): the edges inside the probe's outline a photo shows. Returns (k, 2, 3)
    float64 segment ends.

    >>> from arshadow.geometry.mesh import load_occluder
    >>> m = load_occluder("box:1,1,1")
    >>> len(crease_edges(np.asarray(m.vertices), np.asarray(m.faces), np.array([5.0, 2.0, 0.5])))  # two faces seen
    1
    >>> len(crease_edges(np.asarray(m.vertices), np.asarray(m.faces), np.array([5.0, 4.0, 3.0])))  # three
    3
    """
    return _visible_edges(verts, faces, eye, min_deg)[1]


def _samples(intr: Intrinsics, pose: np.ndarray, segs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points along the projected segments every :data:`STEP_PX` and their unit image normals:
    ((n, 2), (n, 2)) float64 (distortion included)."""
    pts, nrm = [], []
    for a, b in segs:
        ab = intr.project(np.array([a, b]), pose)
        if not np.all(np.isfinite(ab)):
            continue
        length = float(np.linalg.norm(ab[1] - ab[0]))
        k = int(length // STEP_PX)
        if k < 2:
            continue
        t = (np.arange(k) + 0.5) / k
        p3 = a[None] + t[:, None] * (b - a)[None]
        uv = intr.project(p3, pose)
        eps = intr.project(p3 + 1e-4 * (b - a)[None], pose) - uv  # the tangent, distortion included
        tang = eps / np.maximum(np.linalg.norm(eps, axis=1, keepdims=True), 1e-12)
        pts.append(uv)
        nrm.append(np.column_stack([-tang[:, 1], tang[:, 0]]))
    if not pts:
        return np.zeros((0, 2)), np.zeros((0, 2))
    return np.concatenate(pts), np.concatenate(nrm)


def outline_agreement(
    image_bgr: np.ndarray, intr: Intrinsics, cam_from_world: np.ndarray, verts: np.ndarray, faces: np.ndarray
) -> tuple:
    """The share of the probe's projected outline that lies on an edge of the photo.

    Parameters
    ----------
    image_bgr : (H, W, 3) uint8
    intr : Intrinsics
        The photo's camera.
    cam_from_world : (4, 4) float64
    verts : (n, 3) float64, faces : (m, 3) int
        The probe, world frame.

    Returns
    -------
    (agreement, points) : (float, int)
        The share of the outline's points in the image whose strongest edge across the outline
        (``+/- SPAN_PX``) is within :data:`ALIGN_PX` of it, and how many points were read (NaN, 0 when none).
    """
    pose = np.asarray(cam_from_world, np.float64)
    eye = transform_points(np.linalg.inv(pose), np.zeros((1, 3)))[0]
    outline, creases = _visible_edges(verts, faces, eye)
    pts, nrm = _samples(intr, pose, outline)
    H, W = image_bgr.shape[:2]
    offs = np.arange(-SPAN_PX, SPAN_PX + 1, dtype=np.float64)
    ends = [pts + s * nrm for s in (offs[0], offs[-1])]
    ok = np.ones(len(pts), bool)
    for q in ends:
        ok &= (q[:, 0] >= 2) & (q[:, 0] <= W - 3) & (q[:, 1] >= 2) & (q[:, 1] <= H - 3)
    pts, nrm = pts[ok], nrm[ok]
    if len(pts) == 0:
        return math.nan, 0
    gray: np.ndarray = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    gray = cv2.GaussianBlur(gray, (0, 0), 1.0)
    gx = cv2.Sobel(gray, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(gray, cv2.CV_32F, 0, 1, ksize=3)
    q = pts[:, None, :] + offs[None, :, None] * nrm[:, None, :]  # (n, k, 2)
    mx = q[:, :, 0].astype(np.float32)
    my = q[:, :, 1].astype(np.float32)
    sx = cv2.remap(gx, mx, my, cv2.INTER_LINEAR)
    sy = cv2.remap(gy, mx, my, cv2.INTER_LINEAR)
    g = np.abs(sx * nrm[:, None, 0] + sy * nrm[:, None, 1])  # the gradient across the outline
    own = _own_edges(intr, pose, np.concatenate([outline, creases]), (H, W))
    g[_on_own_edge(own, q, offs)] = 0.0
    peak = offs[np.argmax(g, axis=1)]
    # the marker's pose error moves the whole outline by a few pixels: the best shift within SHIFT_PX
    s = np.arange(-SHIFT_PX, SHIFT_PX + 1, dtype=np.float64)
    t = np.stack(np.meshgrid(s, s), -1).reshape(-1, 2)  # (k, 2) image shifts
    agree = np.abs(peak[None, :] - t @ nrm.T) <= ALIGN_PX  # (k, n)
    return float(agree.mean(axis=1).max()), int(len(pts))


def _own_edges(intr: Intrinsics, pose: np.ndarray, segs: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """``(H, W) uint8``: 1 within a pixel of the probe's projected edges ``segs (k, 2, 3)`` (world frame;
    each drawn as 8 pieces, the lens distortion followed)."""
    img = np.zeros(shape, np.uint8)
    if len(segs) == 0:
        return img
    t = np.linspace(0.0, 1.0, 9)[None, :, None]
    uv = intr.project((segs[:, :1] + t * (segs[:, 1:] - segs[:, :1])).reshape(-1, 3), pose).reshape(len(segs), 9, 2)
    ok = np.all(np.isfinite(uv), axis=(1, 2)) & (np.abs(np.nan_to_num(uv)).max(axis=(1, 2)) < 1e6)
    lines = list(np.round(uv[ok] * 16).astype(np.int32))
    cv2.polylines(img, lines, False, 1, thickness=3, shift=4)
    return img


def _on_own_edge(own: np.ndarray, q: np.ndarray, offs: np.ndarray) -> np.ndarray:
    """``(n, k) bool``: the offsets ``offs (k,)`` of each point's span ``q (n, k, 2)`` that lie on one of the
    probe's own other edges (``own``, :func:`_own_edges`), more than :data:`ALIGN_PX` + 1 px from the point."""
    hit = cv2.remap(own, q[:, :, 0].astype(np.float32), q[:, :, 1].astype(np.float32), cv2.INTER_NEAREST) > 0
    hit &= np.abs(offs)[None, :] > ALIGN_PX + 1.0
    return hit
