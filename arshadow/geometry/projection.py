"""Projection shadows ([Kolivand-Stencil] and [Kolivand-Sun]): the planar shadow matrix and a mesh flattened onto the ground.

The matrix ``M = (p . L) I - L p^T`` (``p`` the plane as a 4-vector, ``L`` the homogeneous light) maps a
homogeneous point X to the intersection of the line through X and the light with the plane: for a point
light that is the central projection, for a directional light (w = 0) the parallel one. It is what
[Kolivand-Stencil] prints, once its symbols are read as ``D = N . L`` and ``E = N . C - N . L`` (C a point of the
plane; see :func:`paper_shadow_matrix`): as printed, with D the plane offset, its matrix maps points off
the plane. [Kolivand-Sun] uses the same matrix with the sun as a directional light.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..errors import LightError, ShapeError
from .mesh import ShadowCaster
from .silhouette import as_light_h

__all__ = ["planar_shadow_matrix", "paper_shadow_matrix", "project_to_ground", "GROUND_PLANE"]

#: (4,) float64: the ground plane z = 0 as ``(a, b, c, d)`` with ``a x + b y + c z + d = 0``, normal up.
GROUND_PLANE = np.array([0.0, 0.0, 1.0, 0.0])


def planar_shadow_matrix(plane: npt.ArrayLike, light_h: npt.ArrayLike) -> np.ndarray:
    """The (4, 4) matrix that projects homogeneous points from the light onto a plane.

    Parameters
    ----------
    plane : (4,) float
        ``(a, b, c, d)``: the plane ``a x + b y + c z + d = 0`` (need not be normalised).
    light_h : (4,) float
        ``(x, y, z, 1)`` point light or ``(dx, dy, dz, 0)`` direction towards a directional light.

    Returns
    -------
    (4, 4) float64
        ``M`` with ``M @ X`` on the plane for every homogeneous X, scaled so that points strictly between
        the light and the plane (on the light's side) get w > 0 (as OpenGL clipping needs).

    Raises
    ------
    LightError
        The light lies in the plane (point light) or is parallel to it (directional light).
    ShapeError
        The plane is not 4 finite numbers with a non-zero normal.

    Examples
    --------
    >>> M = planar_shadow_matrix([0, 0, 1, 0], [1.0, 0.0, 2.0, 1.0])
    >>> X = M @ [0.0, 0.0, 1.0, 1.0]
    >>> (X[:3] / X[3]).tolist()
    [-1.0, 0.0, 0.0]
    """
    p = np.asarray(plane, np.float64).reshape(-1)
    if p.shape != (4,) or not np.all(np.isfinite(p)) or not np.any(p[:3] != 0):
        raise ShapeError(f"plane must be 4 finite numbers (a, b, c, d) with a non-zero normal, got {p.tolist()}")
    L = as_light_h(light_h)
    pl = float(p @ L)
    if pl == 0.0:
        what = "lies in" if L[3] else "is parallel to"
        raise LightError(f"the light {what} the projection plane {p.tolist()}: no projection shadow")
    M = pl * np.eye(4) - np.outer(L, p)
    return M if pl > 0 else -M


def paper_shadow_matrix(normal: npt.ArrayLike, point_on_plane: npt.ArrayLike, light_xyz: npt.ArrayLike) -> np.ndarray:
    """[Kolivand-Stencil]'s printed shadow matrix for a point light, with its symbols read as ``E = N . C - N . L``
    and ``D = N . L`` (the only reading under which it maps onto the plane). Kept for comparison:
    equals :func:`planar_shadow_matrix` up to a scale factor (``-1``)."""
    N = np.asarray(normal, np.float64).reshape(3)
    C = np.asarray(point_on_plane, np.float64).reshape(3)
    Lx = np.asarray(light_xyz, np.float64).reshape(3)
    D = float(N @ Lx)
    E = float(N @ C) - D
    M = np.zeros((4, 4))
    M[:3, :3] = np.outer(Lx, N) + E * np.eye(3)
    M[:3, 3] = -E * Lx - D * Lx
    M[3, :3] = N
    M[3, 3] = -D
    return M


def project_to_ground(caster: ShadowCaster, light_h: npt.ArrayLike) -> np.ndarray:
    """Every face of the mesh projected from the light onto the ground z = 0.

    Parameters
    ----------
    caster : ShadowCaster
    light_h : (4,) float64

    Returns
    -------
    (m, 3, 3) float64
        The projected triangles (z exactly 0), in the faces' order and winding. Their union is the
        mesh's shadow on the ground when the whole mesh is at or above z = 0.

    Raises
    ------
    LightError
        The shadow is unbounded: a point light not strictly above every vertex, or a directional light
        that does not point down onto the ground (``dz <= 0``, e.g. a sun below the horizon).

    Examples
    --------
    >>> from arshadow.geometry.mesh import load_occluder
    >>> t = project_to_ground(load_occluder("box:1,1,1"), [0.0, 0.0, 2.0, 1.0])
    >>> t.shape, float(t[..., :2].max()), float(abs(t[..., 2]).max())
    ((12, 3, 3), 1.0, 0.0)
    """
    L = as_light_h(light_h)
    v = caster.vertices
    if L[3] == 0.0:
        if L[2] <= 0.0:
            raise LightError(f"directional light {L[:3].tolist()} does not shine down onto the ground (dz <= 0)")
    else:
        top = float(v[:, 2].max())
        if L[2] <= top:
            raise LightError(
                f"point light at height {L[2]:g} is not above the mesh (top at {top:g}): its ground shadow is "
                "unbounded; use shadow volumes"
            )
    M = planar_shadow_matrix(GROUND_PLANE, L)
    X = v @ M[:3, :3].T + M[:3, 3]
    w = v @ M[3, :3] + M[3, 3]
    P = X / w[:, None]
    P[:, 2] = 0.0
    tris: np.ndarray = P[caster.faces]
    return tris
