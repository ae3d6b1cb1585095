"""The renderer interface: what the executor hands a shadow renderer and what it gets back (no GL here).

A renderer is any object with the :class:`Renderer` protocol's ``render(**kwargs) -> RenderResult`` and
``release()``: the stencil shadow-volume renderer (:class:`arshadow.gl.stencil.ShadowRenderer`) and the
shadow-map baseline (``arshadow.gl.shadowmap``) both are. The planner (:mod:`arshadow.plan`) decides
per light what to draw (:class:`LightPass`: light, weight, technique and its geometry); the executor
(:mod:`arshadow.execute`) calls the renderer, then warps and composites the layers of its
:class:`RenderResult`.

Everything a renderer needs is in its arguments: it never calls back into the geometry modules
(silhouettes, volumes, projection shadows are computed before, on the CPU).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["LightPass", "RenderLayers", "RenderResult", "Renderer", "MODES"]

#: shadow modes a :class:`LightPass` may carry
MODES = ("zpass", "zfail", "planar")


@dataclass
class LightPass:
    """One light of a frame.

    Attributes
    ----------
    light_h : (4,) float64
        Homogeneous world position ``(x, y, z, 1)`` or direction towards the light ``(dx, dy, dz, 0)``.
    weight : float
        Share of the total light weight (the mask accumulates ``weight`` where this light is blocked).
    volume : ShadowVolume or None
        From :func:`arshadow.geometry.volume.shadow_volume` (``vertices (p, 4)`` homogeneous world, w = 0 at
        infinity; ``triangles (q, 3)`` outward-wound). None: the light casts no volume shadow (with mode
        ``"planar"`` the caster itself is flattened onto the ground).
    mode : str
        ``"zpass"`` | ``"zfail"`` | ``"planar"`` (stencil techniques; a renderer of another technique,
        e.g. shadow maps, may ignore it and ``volume``).
    color : (3,) linear RGB
        Light colour for the occluder's Phong shading.
    shadow_matrix : (4, 4) float64 or None
        Mode ``"planar"`` only: the projection-shadow matrix flattening the caster onto z = 0 from this
        light (:func:`arshadow.geometry.projection.planar_shadow_matrix`), filled in when not given; None when the
        light is not above the ground (it lights nothing from above: no planar shadow).
    direct : bool
        Mode ``"planar"`` of a convex closed caster only: its light-facing faces, flattened, cover the
        shadow exactly once, so a renderer may add the weight straight into the mask (no stencil count, no
        full-canvas mask pass).
    """

    light_h: np.ndarray
    weight: float
    volume: object = None
    mode: str = "zfail"
    color: tuple = (1.0, 1.0, 1.0)
    shadow_matrix: np.ndarray | None = None
    direct: bool = False

    def __post_init__(self):
        if self.mode == "planar" and self.shadow_matrix is None:
            from .geometry.projection import GROUND_PLANE, planar_shadow_matrix
            from .geometry.silhouette import as_light_h

            if as_light_h(self.light_h)[2] > 0.0:
                self.shadow_matrix = planar_shadow_matrix(GROUND_PLANE, self.light_h)


@dataclass(frozen=True)
class RenderLayers:
    """A renderer's raw output layers, bottom-up (row 0 = the canvas's *bottom* row, OpenGL's order).

    The executor warps or flips these directly (one remap or flip per layer) instead of three strided
    top-down views.

    Attributes
    ----------
    rgba : (h, w, 4) float32, C-contiguous
        rgb = shaded occluder (linear, premultiplied by a), a = occluder coverage.
    mask_ground : (h, w, 2|3) float32, C-contiguous
        Channel 0 = blocked light weight in [0, 1] (the shadow mask), channel 1 = ground coverage; channel 2
        (with sky occlusion only) = the share of the sky the object hides from the visible ground.
    """

    rgba: np.ndarray
    mask_ground: np.ndarray


@dataclass
class RenderResult:
    """What one ``render`` returns; rows are image rows top to bottom (row 0 = canvas row ``v0``), already
    flipped from OpenGL's bottom-up order. Fresh arrays: they stay valid after later renders.

    Attributes
    ----------
    mask : (h, w) float32 in [0, 1]
        Blocked light weight / total weight at pixels that see the ground plane and are not covered by the
        occluder; 0 elsewhere. With anti-aliasing it is coverage-weighted: the mean over the pixel's
        samples of (sample sees the ground) x (blocked weight of that sample).
    color : (h, w, 3) float32
        Linear RGB of the shaded occluder, **premultiplied by** ``alpha`` (equal to the straight colour
        wherever alpha = 1, 0 where alpha = 0).
    alpha : (h, w) float32
        Occluder coverage in [0, 1].
    ground : (h, w) bool
        The pixel (more than half of its samples) sees the (possibly size-limited) ground plane.
    ground_coverage : (h, w) float32
        Fraction of the pixel's samples that see the ground.
    timings_ms : dict
        ``upload`` (CPU: volumes to GPU), ``draw`` (GL passes, to completion), ``readback``, ``total``;
        with ``ShadowRenderer.profile = True`` also ``pass_<name>`` per GL pass (ctx.finish() after each).
    premultiplied : bool
        Always True: ``color`` is premultiplied by ``alpha``.
    layers : RenderLayers or None
        The same pixels as the raw bottom-up layers ``mask``/``color``/``alpha`` are views of, when the
        renderer has them (the executor then uses them); None: the executor uses the fields above.
    """

    mask: np.ndarray
    color: np.ndarray
    alpha: np.ndarray
    ground: np.ndarray
    ground_coverage: np.ndarray
    timings_ms: dict = field(default_factory=dict)
    premultiplied: bool = True
    layers: RenderLayers | None = None
    #: (h, w) float32 in [0, 1] or None: the share of the sky the object hides from the visible ground
    #: (coverage-weighted like ``mask``; :mod:`arshadow.shading.sky`), None without sky occlusion
    sky_occlusion: np.ndarray | None = None


@runtime_checkable
class Renderer(Protocol):
    """A shadow renderer the executor can drive (stencil volumes, shadow maps, ...).

    ``render`` takes keyword arguments only:

    projection : (4, 4) float64
        ``clip_from_gl_eye`` of the canvas (``Intrinsics.gl_projection(znear, None, canvas=...)``).
    view : (4, 4) float64
        ``gl_from_world = CV_TO_GL @ cam_from_world``.
    width, height : int
        Canvas size in pixels.
    caster : arshadow.geometry.mesh.ShadowCaster
        The occluder, world frame.
    passes : sequence of LightPass
        One per (sample) light.
    ground_size : float or None
    draw_occluder : bool
    occluder_color : (3,) sRGB or None

    and returns a :class:`RenderResult` of the canvas. ``release()`` frees its GPU resources.
    """

    def render(
        self,
        *,
        projection,
        view,
        width,
        height,
        caster,
        passes,
        ground_size=None,
        draw_occluder=True,
        occluder_color=None,
        **kwargs,
    ) -> RenderResult: ...

    def release(self) -> None: ...
