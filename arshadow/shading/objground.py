"""The ground's light as each part of the object sees it (the object's shading; docs/shading.md).

The object's base pass lights each shading vertex with the ground's reflected light ``bounce`` (measured on a
ring round the footprint) times its ground view ``G``. The ground a face sees is not the ring: the marker's
white paper beside it, the darker floor under a sphere, the floor's texture. :func:`vertex_ground` gives each
shading vertex the ground light its faces see, over the ring's: each face looks along cosine-weighted
directions from points spread over it (the mean over the face, not one point: a box face's corner at its foot
sends every direction to one ground point, one texel of the floor's texture), reads the photo's ground there
(:class:`arshadow.shading.decide.GroundLight`, relative to the ring's value) and each shading vertex takes the
area-weighted mean of its faces'.

GL-free (numpy); the renderer writes the result into its shading vertices once per measured ground.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..geometry.caster import ShadowCaster, connected_labels
from .sky import cosine_directions, rotate_to

__all__ = ["face_ground", "vertex_ground"]


def _subtriangle_centres(n: int) -> np.ndarray:
    """``(n^2, 3)`` barycentric coordinates of the centroids of the n^2 equal sub-triangles of a triangle cut
    n times along each side (a uniform quadrature of the triangle's area)."""
    up = [((i + 1 / 3) / n, (j + 1 / 3) / n) for i in range(n) for j in range(n - i)]
    down = [((i + 2 / 3) / n, (j + 2 / 3) / n) for i in range(n - 1) for j in range(n - 1 - i)]
    ab = np.array(up + down)
    out: np.ndarray = np.c_[ab, 1.0 - ab.sum(axis=1)]
    return out


#: barycentric sample points per face
_BARY = _subtriangle_centres(6)
#: cosine-weighted directions per sample point
GROUND_DIRS = 32


def face_ground(
    caster: ShadowCaster, light: Callable[[np.ndarray], np.ndarray], n_dirs: int = GROUND_DIRS
) -> np.ndarray:
    """``(m,)``: each face's ground light as it sees it over the ring's: the mean of ``light`` (``(q, 2)``
    ground points (world, metres) -> ``(q,)``, NaN where unknown: counted as 1) at the points where its
    downward cosine-weighted directions (``n_dirs`` round the face's normal, from sample points spread over
    the face) meet the ground; 1 for a face that sees no ground."""
    tri = np.asarray(caster.vertices, np.float64)[np.asarray(caster.faces)]
    n = np.asarray(caster.face_planes, np.float64)[:, :3]
    d = rotate_to(cosine_directions(n_dirs), n)  # (m, k, 3)
    down = d[..., 2] < -1e-6
    total, count = np.zeros(len(tri)), down.sum(axis=1).astype(np.float64) * len(_BARY)
    for b in _BARY:
        c = b @ tri  # (m, 3) one sample point per face
        t = np.where(down, -np.maximum(c[:, None, 2], 0.0) / np.where(down, d[..., 2], -1.0), 0.0)
        q = c[:, None, :2] + t[..., None] * d[..., :2]
        val = np.asarray(light(q.reshape(-1, 2)), np.float64).reshape(q.shape[:2])
        total += np.where(down, np.where(np.isfinite(val), val, 1.0), 0.0).sum(axis=1)
    out: np.ndarray = np.where(count > 0, total / np.maximum(count, 1.0), 1.0)
    return out


def vertex_ground(
    caster: ShadowCaster, corner_vertex: np.ndarray, n_vertices: int, face_values: np.ndarray
) -> np.ndarray:
    """``(n_vertices,)``: each shading vertex's area-weighted mean of ``face_values (m,)`` over the faces whose
    corners it shades (``corner_vertex (m, 3)``: each face corner's shading vertex; a crease gives a corner its
    own vertex); 1 for a vertex of no face. A flat patch (faces sharing shading vertices in one plane: a box
    face's two triangles, a cylinder's side quad) first takes its area-weighted mean on every face: its
    triangles cover different heights, and a vertex shared by some of them would otherwise shade a gradient
    across the patch that is only the triangulation's.

    >>> from arshadow.geometry.mesh import load_occluder
    >>> box = load_occluder("box:1,1,1")
    >>> vertex_ground(box, np.asarray(box.faces), 8, np.full(12, 0.5)).tolist() == [0.5] * 8
    True
    """
    tri = np.asarray(caster.vertices, np.float64)[np.asarray(caster.faces)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    cv = np.asarray(corner_vertex, np.int64)
    fv = _patch_means(caster, cv, area, np.asarray(face_values, np.float64))
    w = np.repeat(area, 3)
    num = np.bincount(cv.ravel(), weights=w * np.repeat(fv, 3), minlength=n_vertices)
    den = np.bincount(cv.ravel(), weights=w, minlength=n_vertices)
    out: np.ndarray = np.where(den > 0, num / np.maximum(den, 1e-300), 1.0)
    return out


def _patch_means(caster: ShadowCaster, cv: np.ndarray, area: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``(m,)``: ``values`` replaced by their area-weighted mean over each flat patch (faces joined by a shared
    shading vertex ``cv (m, 3)`` whose planes agree to 1e-9)."""
    m = len(cv)
    corner_face = np.repeat(np.arange(m), 3)
    order = np.argsort(cv.ravel(), kind="stable")
    vs, fs = cv.ravel()[order], corner_face[order]
    same = vs[1:] == vs[:-1]
    u, v = fs[:-1][same], fs[1:][same]
    n = np.asarray(caster.face_planes, np.float64)[:, :3]
    flat = np.einsum("kd,kd->k", n[u], n[v]) > 1.0 - 1e-9
    labels = connected_labels(m, u[flat], v[flat])
    num = np.bincount(labels, weights=area * values)
    den = np.bincount(labels, weights=area)
    out: np.ndarray = np.where(den[labels] > 0, num[labels] / np.maximum(den[labels], 1e-300), values)
    return out
