"""The object's contour as a camera sees it, projected into a render's canvas (the outline's anti-aliasing,
:mod:`arshadow.compose.outline`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..errors import LightError
from .silhouette import silhouette

if TYPE_CHECKING:
    from .caster import ShadowCaster

__all__ = ["outline_segments"]


def outline_segments(
    caster: ShadowCaster, projection: np.ndarray, view: np.ndarray, width: int, height: int
) -> np.ndarray:
    """The object's contour as seen by the camera, projected into the canvas.

    Parameters
    ----------
    caster : arshadow.geometry.caster.ShadowCaster
        The object, world frame.
    projection : (4, 4) float64
        ``clip_from_gl_eye`` of the canvas (:attr:`arshadow.renderer.request.RenderRequest.projection`).
    view : (4, 4) float64
        ``gl_from_world`` (:attr:`~arshadow.renderer.request.RenderRequest.view`).
    width, height : int
        The canvas size in pixels.

    Returns
    -------
    (s, 2, 2) float64
        Segments ``(start, end)`` of ``(x, y)`` in OpenGL window coordinates of the canvas (origin at its
        bottom-left corner, pixel centres at ``+ 0.5``: the bottom-up layers' own); edges with an end at or
        behind the camera's plane are left out; none when the camera is inside the closed object.

    Examples
    --------
    >>> from arshadow.geometry.mesh import load_occluder
    >>> from arshadow.camera.model import Intrinsics
    >>> from arshadow.transforms import CV_TO_GL
    >>> K = Intrinsics(100.0, 100.0, 31.5, 31.5, 64, 64)
    >>> cam = np.eye(4); cam[2, 3] = 1.0  # the box (z from 0 to 0.2) seen along its z axis, its near face 1 m away
    >>> seg = outline_segments(load_occluder("box:0.2,0.2,0.2"), K.gl_projection(0.1, None), CV_TO_GL @ cam, 64, 64)
    >>> len(seg), float(np.round(np.ptp(seg[:, :, 0]), 6))  # its square outline, 0.2 m at 1 m x 100 px wide
    (4, 20.0)
    """
    view = np.asarray(view, np.float64)
    eye = np.linalg.solve(view, np.array([0.0, 0.0, 0.0, 1.0]))
    try:
        sil = silhouette(caster, eye / eye[3])
    except LightError:  # the camera inside the (closed) object: it sees no outline
        return np.zeros((0, 2, 2))
    if sil.n_edges == 0:
        return np.zeros((0, 2, 2))
    v = np.asarray(caster.vertices, np.float64)
    clip = np.c_[v, np.ones(len(v))] @ (np.asarray(projection, np.float64) @ view).T
    e = np.asarray(sil.edges)
    w = clip[:, 3]
    keep = (w[e[:, 0]] > 1e-9) & (w[e[:, 1]] > 1e-9)
    xy = np.empty((len(v), 2))
    ok = w > 1e-9
    xy[ok, 0] = (clip[ok, 0] / w[ok] + 1.0) * (0.5 * width)
    xy[ok, 1] = (clip[ok, 1] / w[ok] + 1.0) * (0.5 * height)
    xy[~ok] = 0.0
    out: np.ndarray = xy[e[keep]]
    return out
