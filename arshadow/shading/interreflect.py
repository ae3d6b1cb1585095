"""The object's light on itself: first-order interreflection between the parts of a non-convex object.

A point of the object sees, over its hemisphere, the sky (its sky visibility ``V``), the ground (its ground
view ``G``, both cosine-weighted shares: :func:`arshadow.shading.sky.object_sky_visibility`) and, where
neither, the object itself: ``O = 1 - V - G`` (0 everywhere on a convex object). The object's shading
(:mod:`arshadow.gl`'s base pass) lights that share with the light the object's own surface reflects
(:func:`self_light`): without it the inside of a torus's ring, which sees the far side of the ring, is shaded
as if that side were black (on the path-traced reference: 3-8 % too dark there, docs/reference.md,
"the object's residual").

GL-free (numpy): the renderer calls :func:`self_light` once per light set and hands the result to its shader.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..geometry.caster import ShadowCaster

if TYPE_CHECKING:
    from ..renderer.request import Shading

__all__ = ["SelfView", "face_irradiance", "frame_self_light", "self_light", "self_view"]


class SelfView:
    """What :func:`self_light` needs of a mesh, per face (world frame, metres): ``normals (m, 3)`` unit,
    ``centres (m, 3)``, ``areas (m,)``, ``vis (m, 2)`` the face's sky visibility and ground view (the means of
    its corners'), ``seen (m,)`` the rest, ``O``: the share of its cosine-weighted hemisphere that meets the
    object."""

    def __init__(self, caster: ShadowCaster, vis: np.ndarray) -> None:
        tri = np.asarray(caster.vertices, np.float64)[np.asarray(caster.faces)]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.areas = 0.5 * np.linalg.norm(cross, axis=1)
        self.normals = np.asarray(caster.face_planes, np.float64)[:, :3]
        self.last: tuple[bytes, tuple[float, float, float]] | None = None  # frame_self_light's last key and value
        self.centres = tri.mean(axis=1)
        self.vis = np.clip(np.asarray(vis, np.float64).reshape(-1, 2), 0.0, 1.0)
        self.seen = np.clip(1.0 - self.vis[:, 0] - self.vis[:, 1], 0.0, 1.0)

    @property
    def weight(self) -> float:
        """``sum area O``: 0 for a convex mesh (nothing of it sees itself)."""
        return float(np.sum(self.areas * self.seen))

    def lit(self, light_h: np.ndarray) -> np.ndarray:
        """``(m,) float64``: each face's ``max(0, n.l)`` towards the light ``light_h (4,)`` (world; a point light:
        at the face's centre). The object's shadow on its own sending faces is left out: on the reference's
        torus under a 43 degree sun it darkens 7 of its 2048 lit faces (their direct light: 0.003 %), and an
        exact ray per face costs the 8 536-face knot 0.55 s for each new light (a moving sun: every frame)."""
        h = np.asarray(light_h, np.float64).reshape(4)
        to = h[:3] - self.centres * h[3]
        d = to / np.maximum(np.linalg.norm(to, axis=1, keepdims=True), 1e-300)
        out: np.ndarray = np.maximum(np.einsum("md,md->m", self.normals, d), 0.0)
        return out


def self_view(caster: ShadowCaster, faces_corner: np.ndarray, vis: np.ndarray) -> SelfView | None:
    """The mesh's :class:`SelfView` from its shading vertices' sky visibility and ground view ``vis (k, 2)``
    and each face corner's shading vertex ``faces_corner (m, 3)`` (indices into ``vis``); None when nothing
    of the mesh sees itself (a convex mesh, ``O`` under 1e-3 everywhere)."""
    v = np.asarray(vis, np.float64).reshape(-1, 2)
    if float(np.max(1.0 - v[:, 0] - v[:, 1], initial=0.0)) < 1e-3:
        return None
    return SelfView(caster, v[np.asarray(faces_corner)].mean(axis=1))


def face_irradiance(
    view: SelfView, lights: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]], shading: Shading
) -> np.ndarray:
    """``(m, 3)``: each face's irradiance in the renderer's units (the paper's is ``ambient + sum weight
    sin(elevation)``) as the object's ``shading`` (:class:`arshadow.renderer.request.Shading`) lights it: the
    sky ``ambient * ambient_tint V``, the ground ``bounce G`` (its ``sky``'s ``bounce``; the face's own sky
    visibility and ground view; the light it gets from the object itself is left out: a second bounce) and
    each light ``(light_h (4,), colour (3,))``, ``colour * direct_tint max(0, n.l)`` (:meth:`SelfView.lit`)
    times ``|L|^2 / |L - c|^2`` for a point light with ``point_falloff`` (the shader's fall-off)."""
    bounce = (0.0, 0.0, 0.0) if shading.sky is None else shading.sky.bounce
    point_falloff = bool(shading.point_falloff)
    sky, ground = view.vis[:, 0:1], view.vis[:, 1:2]
    e = float(shading.ambient) * np.asarray(shading.ambient_tint, np.float64).reshape(1, 3) * sky
    e = e + np.asarray(bounce, np.float64).reshape(1, 3) * ground
    tint = np.asarray(shading.direct_tint, np.float64).reshape(1, 3)
    for light_h, colour in lights:
        h = np.asarray(light_h, np.float64).reshape(4)
        k = view.lit(h)
        if h[3] != 0.0 and point_falloff:
            p = h[:3] / h[3]
            k = k * float(p @ p) / np.maximum(np.sum((p - view.centres) ** 2, axis=1), 1e-12)
        e = e + tint * np.asarray(colour, np.float64).reshape(1, 3) * k[:, None]
    out: np.ndarray = e
    return out


def self_light(view: SelfView, face_e: np.ndarray, albedo: npt.ArrayLike) -> np.ndarray:
    """``(3,)``: the light the object's surface sends onto its parts that see it, in the renderer's units
    (like the ground's bounce: reflectance times irradiance), per unit of the receiving point's share ``O``.

    Reciprocity: a face of area ``a`` and share ``O`` sends ``a O B`` of its radiosity ``B = albedo E`` to the
    rest of the object, and the receivers, weighted by their own ``O``, get on average
    ``sum a O B / sum a O`` (every receiver is taken to see the same mix of the object's faces).
    ``face_e (m, 3)``: :func:`face_irradiance`; ``albedo (3,)``: the object's reflectance (absolute, the
    paper's white being :data:`arshadow.shading.decide.PAPER_ALBEDO`).

    >>> from arshadow.geometry.mesh import load_occluder
    >>> v = SelfView(load_occluder("box:1,1,1"), np.full((12, 2), 0.25))  # made-up shares: O = 0.5 on every face
    >>> self_light(v, np.ones((12, 3)), (0.5, 0.5, 0.5)).tolist()
    [0.5, 0.5, 0.5]
    """
    w = view.areas * view.seen
    total = float(w.sum())
    if total <= 0.0:
        return np.zeros(3)
    out: np.ndarray = np.asarray(albedo, np.float64).reshape(3) * (w @ np.asarray(face_e, np.float64)) / total
    return out


def frame_self_light(view: SelfView | None, passes: Sequence, shading: Shading) -> tuple[float, float, float]:
    """The renderer's ``u_self`` for a frame: :func:`self_light` of the object under the frame's light passes
    (``light_h``, ``weight``, ``color``: :class:`arshadow.renderer.request.LightPass`) and shading
    (:class:`arshadow.renderer.request.Shading`: ``ambient``, ``diffuse``, the tints, ``point_falloff`` and
    its ``sky``'s ``bounce`` and ``albedo``); 0 without a view, a sky or the object's albedo."""
    sky = shading.sky
    albedo = None if sky is None else sky.albedo
    if view is None or sky is None or albedo is None:
        return (0.0, 0.0, 0.0)
    kd = float(shading.diffuse)
    lights = [
        (np.asarray(p.light_h, np.float64), kd * float(p.weight) * np.asarray(p.color, np.float64)[:3])
        for p in passes
        if float(p.weight) > 0
    ]
    terms = (float(shading.ambient), shading.ambient_tint, shading.direct_tint, sky.bounce)
    falloff = bool(shading.point_falloff)
    key = np.concatenate([np.r_[h, c] for h, c in lights] + [np.hstack(terms), np.asarray(albedo), [falloff]]).tobytes()
    if view.last is None or view.last[0] != key:  # the same light and shading as the last frame: kept
        e = face_irradiance(view, lights, shading)
        a, b, c = (float(x) for x in self_light(view, e, albedo))
        view.last = (key, (a, b, c))
    return view.last[1]
