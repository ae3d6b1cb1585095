"""A measured point light's shadow ratio across the ground, on the GPU (:attr:`Shading.ratio_falloff`).

The composite applies one shadow ratio ``r0`` (the sky's share of the ground's light where the object
stands): a pixel keeps ``1 - (1 - r0) mask - r0 sky``. A lamp's irradiance on the floor falls off as
``cos / d^2 = z / d^3`` while the sky's does not, so at a ground point where the lamp gives ``g`` times its
irradiance at the object the sky's share is ``q0 / (g + q0)``, ``q0 = r0 / (1 - r0)``: the lamp's blocked
share is ``a = g (1 + q0) / (g + q0)`` times the mask's and the sky's ``b = (1 + q0) / (g + q0)`` times the
sky channel's. The mask keeps the blocked weight (the saved shadow mask's contract, CONVENTIONS.md): the
mask pass (``mask.frag``) adds ``weight (a - 1) / q0`` to the sky channel instead, the same composite
(``r0 / q0 = 1 - r0``), and the ground pass (``ground.frag``) scales the ground occlusion map's value by
``b``. So the correction needs the sky channel: it is on with sky occlusion (a measured light's default),
off without. The mask pass finds its fragment's ground point from the canvas' inverse matrix (a
full-viewport triangle has no position to interpolate). Nothing here creates a context or imports moderngl.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .resources import uniform

if TYPE_CHECKING:
    import moderngl

    from ..renderer.request import LightPass, Shading

__all__ = ["Falloff", "frame_falloff", "set_falloff"]


@dataclass(frozen=True)
class Falloff:
    """A point light's shadow ratio across the ground (:attr:`Shading.ratio_falloff`) as the mask and sky
    shaders take it: the local frame's ``ref = (x0, y0, ground z, q0)``, the canvas' ``local_from_clip``
    (column-major float32 bytes) and size in pixels, and the lamp the ground pass uses for the sky channel (the point lights'
    weighted mean position; each mask pass uses its own)."""

    ref: tuple[float, float, float, float]
    inv_mvp: bytes
    viewport: tuple[float, float]
    lamp: tuple[float, float, float]


def frame_falloff(
    shading: Shading, passes: list[LightPass], origin: np.ndarray, mvp_local: np.ndarray, canvas: tuple[int, int]
) -> Falloff | None:
    """The frame's :class:`Falloff`, or None (no ``ratio_falloff``, no sky channel, or no point light above the
    ground)."""
    rf, sky = shading.ratio_falloff, shading.sky
    pts = [(np.asarray(p.light_h, np.float64), float(p.weight)) for p in passes if float(p.light_h[3]) != 0.0]
    if rf is None or sky is None or sky.ground is None or not pts or sum(w for _, w in pts) <= 0:
        return None  # (the correction rides on the sky channel: none without sky occlusion)
    lamp = sum(w * (h[:3] / h[3]) for h, w in pts) / sum(w for _, w in pts) - origin
    if lamp[2] <= -origin[2]:
        return None
    return Falloff(
        ref=(float(rf[0] - origin[0]), float(rf[1] - origin[1]), float(-origin[2]), float(rf[2])),
        inv_mvp=np.linalg.inv(mvp_local).T.astype(np.float32).tobytes(),
        viewport=(float(canvas[0]), float(canvas[1])),
        lamp=(float(lamp[0]), float(lamp[1]), float(lamp[2])),
    )


def set_falloff(prog: moderngl.Program, fo: Falloff | None, origin: np.ndarray, light_h: np.ndarray | None) -> None:
    """Write :class:`Falloff` ``fo`` into a mask or ground program (``u_falloff`` off without it or for a
    directional ``light_h``); ``light_h`` (4,) world: this pass's lamp (None: ``fo.lamp``)."""
    on = fo is not None and (light_h is None or float(light_h[3]) != 0.0)
    uniform(prog, "u_falloff").value = on
    if fo is None or not on:
        return
    lamp = fo.lamp if light_h is None else tuple(float(v) for v in light_h[:3] / light_h[3] - origin)
    uniform(prog, "u_lamp").value = lamp
    uniform(prog, "u_ref").value = fo.ref
    if prog.get("u_inv_mvp", None) is not None:
        uniform(prog, "u_inv_mvp").write(fo.inv_mvp)
        uniform(prog, "u_viewport").value = fo.viewport
