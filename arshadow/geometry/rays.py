"""Occlusion rays against the occluder mesh: does a ray hit the mesh? (exact, float64, vectorised).

The public face of the bounding volume hierarchy of :mod:`arshadow.geometry._bvh` (the Delta+ silhouette
detector's ray test), for callers outside the geometry package (sky visibility in
:mod:`arshadow.shading.sky`). Rays that miss the mesh's bounding box are answered by one slab test without
entering the tree.
"""

from __future__ import annotations

import numpy as np

from ._bvh import any_hit
from .caster import ShadowCaster

__all__ = ["box_hit", "rays_blocked"]


def box_hit(origins: np.ndarray, dirs: np.ndarray, lo: np.ndarray, hi: np.ndarray, tmin: float = 0.0) -> np.ndarray:
    """``(r,) bool``: does ray ``origins[i] + t dirs[i]`` (``(r, 3)`` each), ``t > tmin``, meet the box
    ``lo..hi`` (``(3,)`` each)?

    >>> box_hit(np.zeros((2, 3)), np.array([[1.0, 0, 0], [-1.0, 0, 0]]), np.array([1.0, -1, -1]), np.array([2.0, 1, 1])).tolist()
    [True, False]
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dirs
        t1 = (lo - origins) * inv
        t2 = (hi - origins) * inv
    tn = np.fmax.reduce(np.fmin(t1, t2), axis=1)
    tf = np.fmin.reduce(np.fmax(t1, t2), axis=1)
    hit: np.ndarray = (tn <= tf) & (tf > tmin)
    return hit


def rays_blocked(caster: ShadowCaster, origins: np.ndarray, dirs: np.ndarray, tmin: float = 0.0) -> np.ndarray:
    """``(r,) bool``: does ray ``origins[i] + t dirs[i]``, ``t > tmin``, hit any face of ``caster``?

    ``origins, dirs (r, 3) float64`` in the caster's (world) frame; ``dirs`` need not be unit (``tmin`` is in
    their units). Edges are inclusive (a ray through a shared edge hits). Both sides of every face block.

    >>> c = ShadowCaster([[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 1, 2]])
    >>> rays_blocked(c, np.array([[0.2, 0.2, 0], [0.9, 0.9, 0]]), np.array([[0, 0, 1.0], [0, 0, 1.0]])).tolist()
    [True, False]
    """
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(dirs, np.float64).reshape(-1, 3)
    lo, hi = caster.bounds
    pad = 1e-9 * caster.scale
    near = np.nonzero(box_hit(o, d, lo - pad, hi + pad, tmin))[0]
    out = np.zeros(len(o), bool)
    if near.size:
        hit, _ = any_hit(caster, o[near], d[near], np.full(near.size, float(tmin)), np.ones(caster.n_faces, bool))
        out[near] = hit
    return out
