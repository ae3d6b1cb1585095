"""Meshes and random lights shared by the geometry tests (pure numpy + trimesh; no scipy needed
except for the random convex hulls, which are skipped without it)."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from arshadow.geometry.mesh import ShadowCaster, load_occluder

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples" / "meshes"


def random_hull(seed: int, n_points: int = 60) -> ShadowCaster | None:
    """The convex hull of random points in an ellipsoid (None when scipy is unavailable)."""
    try:
        import scipy.spatial  # noqa: F401
        import trimesh
    except ImportError:
        return None
    r = np.random.default_rng(seed)
    p = r.normal(size=(n_points, 3)) * r.uniform(0.3, 1.5, size=3)
    h = trimesh.convex.convex_hull(p)
    return ShadowCaster(h.vertices, h.faces, name=f"hull{seed}")


def affine_icosphere(seed: int) -> ShadowCaster:
    """A random affine image of an icosphere: convex, closed, no scipy needed."""
    import trimesh

    r = np.random.default_rng(seed)
    s = trimesh.creation.icosphere(subdivisions=2)
    a = r.normal(size=(3, 3)) * 0.5 + np.eye(3)
    if np.linalg.det(a) < 0:
        a[:, 0] *= -1
    return ShadowCaster(np.asarray(s.vertices) @ a.T + [0, 0, 2], s.faces, name=f"affine{seed}")


@functools.cache
def closed_meshes() -> dict[str, ShadowCaster]:
    m = {
        "box": load_occluder("box:0.3,0.2,0.1", rotate=(10, 20, 30), place=(0, 0, 0.2)),
        "icosphere": load_occluder("sphere:0.5"),
        "torus": load_occluder("torus:0.4,0.1", rotate=(30, 0, 0), place=(0, 0, 0.2)),
        "affine0": affine_icosphere(0),
        "knot": load_occluder(SAMPLES / "knot.ply"),
        "house": load_occluder(SAMPLES / "house.obj"),
    }
    for seed in (1, 2, 3):
        h = random_hull(seed)
        if h is not None:
            m[f"hull{seed}"] = h
    return m


@functools.cache
def open_meshes() -> dict[str, ShadowCaster]:
    return {
        "umbrella": load_occluder(SAMPLES / "umbrella.ply"),
        "triangle": ShadowCaster([[0, 0, 0.1], [0.1, 0, 0.12], [0, 0.1, 0.15]], [[0, 1, 2]], name="triangle"),
        "sheet": _sheet(),
        "nonmanifold": _two_boxes_sharing_an_edge(),
    }


def _two_boxes_sharing_an_edge() -> ShadowCaster:
    """Two closed boxes touching along one edge (that edge has four faces: non-manifold)."""
    import trimesh

    b = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    v1 = np.asarray(b.vertices) + [0.05, 0.05, 0.15]
    v2 = np.asarray(b.vertices) + [-0.05, -0.05, 0.15]
    c = ShadowCaster(np.vstack([v1, v2]), np.vstack([b.faces, np.asarray(b.faces) + 8]), name="nonmanifold")
    assert len(c.nonmanifold_edges) == 1
    return c


def _sheet() -> ShadowCaster:
    """A wavy open sheet (folds towards and away from most lights)."""
    n = 24
    x, y = np.meshgrid(np.linspace(-0.1, 0.1, n), np.linspace(-0.1, 0.1, n))
    z = 0.1 + 0.03 * np.sin(30 * x) * np.cos(20 * y)
    v = np.stack([x, y, z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a = (i * n + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return ShadowCaster(v, f, name="sheet")


def random_lights(caster: ShadowCaster, n: int, rng, above_ground: bool = False) -> np.ndarray:
    """``(n, 4)`` lights: half point lights at 1.5-20 x the mesh size from its centre (outside it), half
    directional; all directions uniform on the sphere (upper half-sphere with ``above_ground``)."""
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    if above_ground:
        d[:, 2] = np.abs(d[:, 2]) + 0.05
        d /= np.linalg.norm(d, axis=1)[:, None]
    centre = caster.bounds.mean(axis=0)
    radius = 0.5 * caster.scale
    dist = radius * rng.uniform(1.5, 20.0, size=n)
    L = np.zeros((n, 4))
    point = np.arange(n) % 2 == 0
    L[point, :3] = centre + d[point] * dist[point, None]
    if above_ground:  # keep point lights above the mesh top so that the ground shadow is bounded
        L[point, 2] = np.maximum(L[point, 2], caster.bounds[1, 2] + 0.3 * radius)
    L[point, 3] = 1.0
    L[~point, :3] = d[~point]
    return L


def edge_multiset(edges) -> np.ndarray:
    """Directed edges sorted lexicographically (for exact comparison of silhouettes)."""
    e = np.asarray(edges).reshape(-1, 2)
    return e[np.lexsort((e[:, 1], e[:, 0]))]


def degrees_balanced(edges) -> bool:
    """Every vertex has as many outgoing as incoming silhouette edges (the loops close)."""
    e = np.asarray(edges).reshape(-1, 2)
    if e.size == 0:
        return True
    n = int(e.max()) + 1
    return bool(np.array_equal(np.bincount(e[:, 0], minlength=n), np.bincount(e[:, 1], minlength=n)))
