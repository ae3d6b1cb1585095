"""Paper-faithful reference silhouette detectors, instrumented to count their operations.

Slow on purpose (plain Python loops as the papers' pseudo code is written): they exist to check the fast,
vectorised detectors of :mod:`arshadow.geometry.silhouette` (same edges on small meshes) and to put the papers'
operation-count formulas next to counted operations and measured time (``arshadow bench``).

``ta_reference`` ([Kolivand-HSD], sec. IV.1)
    For each light-facing triangle, for each of its sides ``(a, b)``: search the array S linearly for the
    reversed edge ``(b, a)``; delete it when found, else append ``(a, b)``. What stays in S is the
    silhouette.
``vnv_reference`` ([Kolivand-HSD], sec. IV.2)
    For each edge, loop over every face and count the light-facing faces that contain the edge; exactly
    one => silhouette. (The printed pseudo code omits the "contains the edge" test, which would count
    every visible face for every edge; it is implied by the text and done here.)
``delta_plus_reference`` ([Kolivand-DeltaPlus], Algorithm 4)
    For each edge of a light-facing face, push its midpoint by ``eps`` x the edge length outwards
    (perpendicular to the edge and the light ray, away from the face), cast the ray from the light
    through the pushed point and test it against *all* light-facing faces ("Step 4. For all visible
    faces"), stopping at the first hit; no hit => silhouette. Without a hierarchy this is O(edges x
    faces), not the O(n log n) the paper states.

Every function takes plain arrays (``vertices (n, 3) float64``, ``faces (m, 3) int`` of a closed,
consistently wound mesh, ``light_h (4,)`` homogeneous world light) and returns ``(edges (k, 2) intp,
counts dict)``: directed edges oriented as the light-facing face traverses them (the convention of
:class:`arshadow.geometry.silhouette.Silhouette`) and the operations counted.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ._bvh import moller_trumbore
from .mesh import plane_side

__all__ = [
    "ta_reference",
    "vnv_reference",
    "delta_plus_reference",
    "paper000_formulas",
    "paper003_claim",
    "face_planes",
]


def face_planes(vertices: npt.ArrayLike, faces: npt.ArrayLike) -> np.ndarray:
    """``(m, 4) float64`` planes ``(n, d)`` of the triangles (unit normal by the right-hand rule)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.intp)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    planes: np.ndarray = np.c_[n, -np.einsum("ij,ij->i", n, v[f[:, 0]])]
    return planes


def _facing(
    vertices: npt.ArrayLike, faces: npt.ArrayLike, light_h: npt.ArrayLike, planes: np.ndarray | None = None
) -> np.ndarray:
    planes = face_planes(vertices, faces) if planes is None else planes
    return plane_side(planes, np.asarray(light_h, np.float64)) > 0.0


def ta_reference(
    vertices: npt.ArrayLike, faces: npt.ArrayLike, light_h: npt.ArrayLike, planes: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, int]]:
    """Triangular Algorithm with the linear array search ([Kolivand-HSD]). See the module docstring.

    Returns
    -------
    edges : (k, 2) intp
    counts : dict
        ``face_tests`` (visibility tests), ``compares`` (edge comparisons in the linear searches),
        ``reads`` (array elements read: = compares + 1 per deletion), ``writes`` (appends + deletions),
        ``max_len`` (largest size S reached).
    """
    facing = _facing(vertices, faces, light_h, planes)
    S: list[tuple[int, int]] = []
    compares = writes = deletes = max_len = 0
    for p, f in enumerate(np.asarray(faces).tolist()):
        if not facing[p]:
            continue
        for q in range(3):
            a, b = f[q], f[(q + 1) % 3]
            found = -1
            for i, (x, y) in enumerate(S):
                compares += 1
                if x == b and y == a:
                    found = i
                    break
            if found >= 0:
                S.pop(found)
                deletes += 1
            else:
                S.append((a, b))
            writes += 1
            max_len = max(max_len, len(S))
    counts = {
        "face_tests": int(np.shape(faces)[0]),
        "compares": compares,
        "reads": compares + deletes,
        "writes": writes,
        "max_len": max_len,
    }
    return np.asarray(S, np.intp).reshape(-1, 2), counts


def _unique_edges(faces: npt.ArrayLike) -> list[tuple[int, int]]:
    seen: dict[tuple[int, int], tuple[int, int]] = {}
    for f in np.asarray(faces).tolist():
        for q in range(3):
            a, b = f[q], f[(q + 1) % 3]
            key = (min(a, b), max(a, b))
            seen.setdefault(key, (a, b))
    return list(seen.values())


def vnv_reference(
    vertices: npt.ArrayLike, faces: npt.ArrayLike, light_h: npt.ArrayLike, planes: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, int]]:
    """Visible / non-visible: the edge x face loop ([Kolivand-HSD]). See the module docstring.

    Returns
    -------
    edges : (k, 2) intp
    counts : dict
        ``pairs`` (edge x face iterations = visibility reads), ``membership_tests`` (edge-in-face tests
        on visible faces), ``writes``.
    """
    facing = _facing(vertices, faces, light_h, planes).tolist()
    F = np.asarray(faces).tolist()
    edges = _unique_edges(faces)
    out = []
    pairs = member = 0
    for a, b in edges:
        counter = 0
        vis_face: list[int] | None = None
        for f, vis in zip(F, facing, strict=True):
            pairs += 1
            if vis:
                member += 1
                if a in f and b in f:
                    counter += 1
                    vis_face = f
        if counter == 1:
            # orient as the visible face traverses it
            assert vis_face is not None  # counter == 1: the one visible face holding the edge
            i = vis_face.index(a)
            out.append((a, b) if vis_face[(i + 1) % 3] == b else (b, a))
    return np.asarray(out, np.intp).reshape(-1, 2), {"pairs": pairs, "membership_tests": member, "writes": len(out)}


def delta_plus_reference(
    vertices: npt.ArrayLike,
    faces: npt.ArrayLike,
    light_h: npt.ArrayLike,
    eps: float = 1e-6,
    planes: np.ndarray | None = None,
) -> tuple[np.ndarray, dict[str, int]]:
    """Delta+ as written in [Kolivand-DeltaPlus]: every candidate ray against all light-facing faces, first hit stops.

    Returns
    -------
    edges : (k, 2) intp
    counts : dict
        ``rays`` (edges of light-facing faces), ``ray_face_tests`` (intersection tests performed),
        ``ray_face_tests_no_early_exit`` (rays x visible faces, the loop as printed without a break).
    """
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.intp)
    h = np.asarray(light_h, np.float64)
    facing = _facing(v, f, h, planes)
    vis = np.flatnonzero(facing)
    tv = v[f[vis]]
    v0, e1, e2 = tv[:, 0], tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]
    # candidate edges: each undirected edge of a light-facing face once, with that face's orientation
    cand: dict[tuple[int, int], tuple[int, int, int]] = {}
    for fi in vis.tolist():
        tri = f[fi].tolist()
        for q in range(3):
            a, b, c = tri[q], tri[(q + 1) % 3], tri[(q + 2) % 3]
            cand.setdefault((min(a, b), max(a, b)), (a, b, c))
    out = []
    tests = 0
    direction = None if h[3] != 0 else h[:3] / np.linalg.norm(h[:3])
    for a, b, c in cand.values():
        p, q, r = v[a], v[b], v[c]
        mid = 0.5 * (p + q)
        u = q - p
        ray = -direction if direction is not None else mid - h[:3]
        w = np.cross(u, ray)
        if np.dot(r - mid, w) > 0:  # away from the face's third vertex
            w = -w
        wn = np.linalg.norm(w)
        pushed = mid + (w / wn * eps * np.linalg.norm(u) if wn > 0 else 0.0)
        if direction is None:
            o, d, t0 = h[:3], pushed - h[:3], 0.0
        else:
            o, d, t0 = pushed, direction, -np.inf
        n = len(vis)
        hits = moller_trumbore(np.broadcast_to(o, (n, 3)), np.broadcast_to(d, (n, 3)), np.full(n, t0), v0, e1, e2)
        first = int(np.argmax(hits)) if hits.any() else -1
        tests += (first + 1) if first >= 0 else n
        if first < 0:
            out.append((a, b))
    counts = {"rays": len(cand), "ray_face_tests": tests, "ray_face_tests_no_early_exit": len(cand) * len(vis)}
    return np.asarray(out, np.intp).reshape(-1, 2), counts


# ------------------------------------------------------------------------------------------ the papers
def paper000_formulas(n: float, m: float) -> dict:
    """[Kolivand-HSD] sec. VI, as printed: operation counts of TA, VnV and HSD for ``n`` faces with ``m``
    sides each (the paper takes e_n = 6n). Returns per algorithm the counts of Compares, Reads, Mults,
    Adds, Writes and their ``total`` (every operation counted once: the paper gives no cycle weights)."""
    ta = {"C": 6 * n * n * m, "R": 6 * n * n * m + m * n + 8 * n, "M": (m + 10) * n, "A": 8 * n, "W": 2 * m * n}
    vnv = {"C": 6 * n * n + 6 * n, "R": 48 * n * n + 6 * n, "M": 60 * n * n, "A": 54 * n * n, "W": 6 * n}
    hsd = {"C": 6 * n * n + n, "R": 6 * n * n + 9 * n, "M": 11 * n, "A": 8 * n, "W": 2 * n}
    out = {}
    for name, d in (("TA", ta), ("VnV", vnv), ("HSD", hsd)):
        out[name] = {**{k: float(x) for k, x in d.items()}, "total": float(sum(d.values()))}
    return out


def paper003_claim(n_vertices: int = 5000) -> dict:
    """[Kolivand-DeltaPlus] Table II as printed: O(n^2) = n^2 for BSB tree / HFC against O(n log2 n) for Delta+."""
    return {"n": n_vertices, "quadratic": float(n_vertices) ** 2, "n_log2_n": n_vertices * math.log2(n_vertices)}
