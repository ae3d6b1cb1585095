"""The renderer interface: what the executor hands a shadow renderer and what it gets back (no GL here).

The seam is one frozen value each way: the executor (:mod:`arshadow.frame.execute`) builds one
:class:`RenderRequest` per frame from the plan and the options (projection, view, canvas size, caster,
light passes, ground, what to draw, and the object's :class:`Shading`); a renderer answers
``render(request) -> RenderResult`` (layers read back) or ``render_gpu(request) -> GpuLayers`` (layers left
on the GPU, when its ``gpu_layers`` capability says it can). The planner (:mod:`arshadow.plan`) decides
per light what to draw (:class:`LightPass`: light, weight, technique and its geometry).

A renderer is any object with the :class:`Renderer` protocol's members: the stencil shadow-volume renderer
(:class:`arshadow.gl.stencil.ShadowRenderer`) and the shadow-map baseline
(:class:`arshadow.gl.shadowmap.ShadowMapRenderer`) both are; :class:`RendererBase` gives a new one the
capabilities' defaults.

Everything a renderer needs is in the request: it never calls back into the geometry modules
(silhouettes, volumes, projection shadows are computed before, on the CPU).

A new shading setting (docs/architecture.md, "The render seam") touches three places: the option
(:class:`arshadow.scene.options.RenderOptions`), :class:`Shading` (its field, :meth:`Shading.from_options`,
:meth:`Shading.uniforms`) and the shader that declares the uniform (``arshadow/gl/shaders``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from ..errors import UsageError
from ..shading.decide import sky_share

if TYPE_CHECKING:
    from ..geometry.mesh import ShadowCaster
    from ..gl.layers import GpuLayers
    from ..scene.options import RenderOptions
    from ..shading.sky import GroundRaster

__all__ = ["LightPass", "RenderLayers", "RenderRequest", "RenderResult", "Renderer", "RendererBase", "Shading", "MODES"]

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

    def __post_init__(self) -> None:
        if self.mode == "planar" and self.shadow_matrix is None:
            from ..geometry.projection import GROUND_PLANE, planar_shadow_matrix
            from ..geometry.silhouette import as_light_h

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
    mask_ground : (h, w, 2|3|4) float32, C-contiguous
        Channel 0 = blocked light weight in [0, 1] (the shadow mask), channel 1 = ground coverage; channel 2
        (with sky occlusion only) = the share of the sky the object hides from the visible ground (less its
        reflected light); channel 3 (a coloured object's, ``SkyShading.colored``) = that reflected light.
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
    #: (h, w) float32 in [-1, 1] or None: the share of the sky the object hides from the visible ground, less
    #: the light it reflects there over the sky's share (negative beside a lit face; coverage-weighted like
    #: ``mask``; :mod:`arshadow.shading.sky`), None without sky occlusion; (h, w, 3) linear RGB for a coloured
    #: object's reflected light (``SkyShading.colored``: colour bleeding, :func:`arshadow.compose.composite.sky_planes`)
    sky_occlusion: np.ndarray | None = None


def _rgb(v: Any) -> tuple[float, float, float]:
    """Three floats of an RGB-like sequence."""
    a, b, c = (float(x) for x in np.ravel(np.asarray(v, np.float64))[:3])
    return (a, b, c)


@dataclass(frozen=True)
class Shading:
    """How the object is shaded: one value, handed to the renderer inside :class:`RenderRequest`.

    The renderer writes :meth:`uniforms` into every occluder program that declares them (a program that
    does not declare one ignores it), so a new scalar setting needs no renderer code: add the option
    (:class:`arshadow.scene.options.RenderOptions`), a field here (read in :meth:`from_options`, named in
    :meth:`uniforms`) and the ``uniform`` in the shader. Values the renderer uploads otherwise (the colour:
    vertex colours of the cached caster buffers) are read by the renderer by name.

    Attributes
    ----------
    ambient : float
        ``K_a I_a``: the object's ambient term (linear, times its colour).
    diffuse : float
        ``K_d``: the diffuse weight of each light's Phong term.
    specular : float
        ``K_s``: the specular weight.
    shininess : float
        The Phong exponent ``n``.
    color : (3,) sRGB in [0, 1] or None
        Overrides the mesh's own colours (mesh colours and this are sRGB-encoded; the output is linear).
    sky : arshadow.shading.sky.SkyShading or None
        Sky occlusion (the realism work): the ground occlusion map drawn into the mask's sky channel
        (``RenderResult.sky_occlusion``), the object's own sky visibility and the light bounced from the
        ground; None: the uniform ambient term, no sky channel.
    albedo_gain : (3,) float
        Linear RGB gain on the mesh's own colours / texture (the measured exposure when no colour is given).
    ambient_tint, direct_tint : (3,) float
        Linear RGB tints of the ambient (sky) term and of every light's direct term
        (:attr:`arshadow.scene.options.RenderOptions.ambient_tint`; 1: grey).
    point_falloff : bool
        A point light's irradiance falls off as ``cos / d^2``: each light's term is scaled by ``d0^2 / d^2``,
        ``d0`` its distance to the world origin (the marker's paper, where a measured light's exposure is
        matched, so the paper keeps its measured level); False: no fall-off (the light's weight everywhere).
        On with a measured light (``RenderOptions.ambient_measured``).
    ratio_falloff : (3,) float or None
        ``(x0, y0, q0)``: a point light's shadow ratio across the ground. The sky-to-lamp ratio is ``q0`` at
        the ground point ``(x0, y0)`` (world, metres; where the composite's shadow ratio ``r0 = q0 / (1 +
        q0)`` holds) and ``q0 / g`` elsewhere, ``g = (d0 / d)^3`` the lamp's irradiance there relative to
        ``(x0, y0)`` (``cos / d^2`` on the floor). The renderer makes the composite's one ratio the one at each
        ground point through the sky channel (the mask keeps the blocked weight; arshadow/gl/falloff.py,
        docs/shading.md), so only with sky occlusion on; None: one ratio everywhere. Set from
        ``RenderOptions.ratio_at`` with a measured light.

    Phong ([Kolivand-Stencil]): ``I = K_a I_a + sum_l I_l (K_d (N.L) + K_s (N.H)^n)``.

    Examples
    --------
    >>> Shading(ambient=0.3).uniforms()["u_ambient"]
    0.3
    >>> from arshadow.scene.options import RenderOptions
    >>> Shading.from_options(RenderOptions(specular=0.0)).specular
    0.0
    """

    ambient: float = 0.25
    diffuse: float = 1.0
    specular: float = 0.25
    shininess: float = 32.0
    color: tuple[float, float, float] | None = None
    sky: Any = None
    albedo_gain: tuple[float, float, float] = (1.0, 1.0, 1.0)
    point_falloff: bool = False
    ambient_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    direct_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    ratio_falloff: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        for name in ("ambient", "diffuse", "specular", "shininess"):
            v = float(getattr(self, name))
            if not math.isfinite(v):
                raise UsageError(f"shading {name} {v}: must be a finite number")
        if self.color is not None:
            c = tuple(float(x) for x in np.ravel(self.color)[:3])
            if len(c) != 3:
                raise UsageError(f"shading color {self.color!r}: expected 3 sRGB values")
            object.__setattr__(self, "color", c)

    @classmethod
    def from_options(cls, options: RenderOptions) -> Shading:
        """The shading :class:`arshadow.scene.options.RenderOptions` ask for (``ambient``, ``specular``,
        ``occluder_color``; diffuse and shininess at their defaults)."""
        return cls(
            ambient=options.ambient,
            specular=options.specular,
            color=options.occluder_color,
            point_falloff=bool(options.ambient_measured),
            ambient_tint=_rgb(options.ambient_tint),
            direct_tint=_rgb(options.direct_tint),
            ratio_falloff=_ratio_falloff(options),
        )

    def uniforms(self) -> dict[str, float | tuple[float, ...]]:
        """Shader uniform name -> value, written into each occluder program that declares the name."""
        return {
            "u_ambient": float(self.ambient),
            "u_kd": float(self.diffuse),
            "u_ks": float(self.specular),
            "u_shininess": float(self.shininess),
            "u_albedo_gain": tuple(float(v) for v in self.albedo_gain),
            "u_point_falloff": 1.0 if self.point_falloff else 0.0,
            "u_ambient_tint": _rgb(self.ambient_tint),
            "u_direct_tint": _rgb(self.direct_tint),
        }


def _ratio_falloff(options: RenderOptions) -> tuple[float, float, float] | None:
    """:attr:`Shading.ratio_falloff` of ``options``: ``(x0, y0, q0)`` with a measured light's ``ratio_at``
    (``q0`` from the mean of the composite's sky share, ``1 - opacity (1 - shadow_color)``), else None.

    >>> from arshadow.scene.options import RenderOptions
    >>> o = RenderOptions(opacity=1.0, shadow_color=(0.2, 0.2, 0.2), ambient_measured=True, ratio_at=(0.1, 0.0))
    >>> [round(v, 6) for v in _ratio_falloff(o)]
    [0.1, 0.0, 0.25]
    """
    if not options.ambient_measured or options.ratio_at is None:
        return None
    r = float(np.clip(np.mean(sky_share(options.opacity, options.shadow_color)), 1e-3, 0.999))
    x0, y0 = (float(v) for v in options.ratio_at)
    return (x0, y0, r / (1.0 - r))


@dataclass(frozen=True, kw_only=True, eq=False)
class RenderRequest:
    """Everything a renderer draws one frame (or one canvas of it) from; built once per frame by the
    executor (:func:`arshadow.frame.execute.execute`) from the plan and the options.

    Attributes
    ----------
    projection : (4, 4) float64
        ``clip_from_gl_eye`` of the canvas (``Intrinsics.gl_projection(znear, None, canvas=...)``; an
        infinite far plane when volumes reach infinity).
    view : (4, 4) float64
        ``gl_from_world = CV_TO_GL @ cam_from_world`` (world: the ground frame).
    width, height : int
        Canvas size in pixels (the plan's ``canvas[2:]``; its offset is in ``projection``).
    caster : arshadow.geometry.mesh.ShadowCaster
        The occluder, world frame (renderers cache its GPU buffers per caster object).
    passes : tuple of LightPass
        One per (sample) light; ``weight`` is the light's share of the total weight.
    ground_size : float or None
        Side of the square of ground (centred on the origin) that receives shadows; None = unlimited.
    draw_occluder : bool
        False: the occluder is neither drawn nor hides the ground (shadow only).
    shading : Shading
        How the occluder is shaded.

    Examples
    --------
    >>> from arshadow.geometry.mesh import load_occluder
    >>> req = RenderRequest(projection=np.eye(4), view=np.eye(4), width=64, height=48, caster=load_occluder("box:0.1,0.1,0.1"),
    ...                     passes=[LightPass(np.array([0.0, 0.0, 1.0, 0.0]), 1.0)])
    >>> req.passes[0].weight, req.shading.ambient
    (1.0, 0.25)
    """

    projection: np.ndarray
    view: np.ndarray
    width: int
    height: int
    caster: ShadowCaster
    passes: tuple[LightPass, ...]
    ground_size: float | None = None
    draw_occluder: bool = True
    shading: Shading = field(default_factory=Shading)

    def __post_init__(self) -> None:
        object.__setattr__(self, "passes", tuple(self.passes))


@runtime_checkable
class Renderer(Protocol):
    """A shadow renderer the executor can drive (stencil volumes, shadow maps, ...).

    ``render(request)`` draws the :class:`RenderRequest` and returns a :class:`RenderResult` of its canvas;
    ``render_gpu(request)`` leaves the layers on the GPU (:class:`arshadow.gl.layers.GpuLayers`, for the
    shader compose path; only called when ``gpu_layers`` is True; with the request's sky occlusion drawn, as
    ``render``'s ``sky_occlusion``, and ``GpuLayers.sky`` True); ``release()`` frees its GPU resources.

    Attributes
    ----------
    gpu_layers : bool
        ``render_gpu`` works (the shader compose path may be chosen).
    software : bool
        Its context rasterises on the CPU (llvmpipe): the shader compose path competes with the pipeline's
        own cores, so the planner keeps numpy unless told to time it.
    backend : str
        What renders (the GL renderer string; ``"?"`` when unknown): part of the compose path's key.
    ctx : moderngl.Context or None
        The context its GPU layers live on (the shader compose path runs there); None without them.
    ground_raster : arshadow.shading.sky.GroundRaster or None
        Rasterises the ground occlusion map's shadows on this renderer's device
        (:class:`arshadow.gl.sky.GLGroundRaster`); None: the numpy one
        (:func:`arshadow.shading.sky.ground_raster_cpu`).
    """

    gpu_layers: bool
    software: bool
    backend: str
    ctx: Any

    @property
    def ground_raster(self) -> GroundRaster | None: ...

    def render(self, request: RenderRequest) -> RenderResult: ...

    def render_gpu(self, request: RenderRequest) -> GpuLayers: ...

    def release(self) -> None: ...


class RendererBase:
    """The :class:`Renderer` capabilities' defaults for a renderer without GPU-resident layers: subclass it
    and define ``render`` and ``release``.

    Examples
    --------
    >>> class Blank(RendererBase):
    ...     def render(self, request):
    ...         z = np.zeros((request.height, request.width), np.float32)
    ...         return RenderResult(z, np.zeros(z.shape + (3,), np.float32), z, z > 0, z)
    ...     def release(self):
    ...         pass
    >>> isinstance(Blank(), Renderer), Blank().gpu_layers
    (True, False)
    """

    gpu_layers: bool = False
    software: bool = False
    backend: str = "?"
    ctx: Any = None
    ground_raster: GroundRaster | None = None

    def render_gpu(self, request: RenderRequest) -> GpuLayers:
        """Not available (``gpu_layers`` is False): the executor never calls it."""
        raise UsageError(f"{type(self).__name__} keeps no layers on the GPU (gpu_layers is False)")
