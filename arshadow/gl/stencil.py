"""Offscreen stencil shadow-volume renderer (moderngl + raw GL stencil through ctypes): :class:`ShadowRenderer`.

(About 780 lines, over the project's ~600, on purpose: this is one class, and its methods are the frame's
passes (clear, occluder base, ground, light, planar direct, count, mask, resolve, readback), each under 80
lines; this docstring, the frame's stencil layout and pass order, is 60 of them. The passes
share the frame's raw GL state (stencil function and operations, write masks, depth test, bound
framebuffer), which each pass sets from what the previous one left and the last resets. Split across
modules, that state contract would span files and could no longer be read in one place. What is not a
pass lives elsewhere: GPU resources in :mod:`arshadow.gl.resources`, render targets in
:mod:`arshadow.gl.targets`, the GPU-resident layers in :mod:`arshadow.gl.layers`.)

The renderer is handed a moderngl context (see :mod:`arshadow.gl.context`); it never creates one. Its GPU
resources (programs, caster buffers, framebuffers, the ground) are in :mod:`arshadow.gl.resources`; each
pass below is one method. :meth:`ShadowRenderer.render` reads the layers back (:class:`RenderResult`),
:meth:`ShadowRenderer.render_gpu` leaves them in textures (:class:`~arshadow.gl.layers.GpuLayers`).

Frame layout (one framebuffer, all renderbuffers, optional MSAA)::

    colour 0  RGBA16F   rgb = shaded occluder (linear), a = occluder coverage
    colour 1  RG16F     r = blocked light weight (the shadow mask), g = ground coverage
    depth/stencil       GL_DEPTH24_STENCIL8, made with glRenderbufferStorage(Multisample) through ctypes

Stencil bits: bit 7 = "this sample sees the ground plane" (set by the ground depth pass), bit 6 = "this
sample sees the occluder", bits 0-5 = the shadow-volume count of the current light (modulo 64, two-sided
INCR_WRAP/DECR_WRAP with write mask 0x3F). Modulo 64 is exact only while no sample lies in more than 63
volume layers; :func:`arshadow.geometry.volume.shadow_volume` bounds the layers (:func:`~arshadow.geometry.volume.layer_bound`)
and otherwise hands closed sub-volumes (``ShadowVolume.batches``) of <= 31 layers each: those are counted
one at a time in bits 0-4 and OR-ed into bit 5 (``SHADOWED_BIT``), so any depth complexity is exact.

Passes per frame
----------------
1. base: clear; occluder (depth + ambient colour + coverage); ground plane z = 0 (depth, ground bit; an
   unlimited plane drawn through homogeneous coordinates as four triangles with vertices at infinity, or a
   ``ground_size`` square); no polygon offset by default (measured: docs/rendering.md, ``ground_offset``).
2. per light: clear the count bits; draw the light's shadow volume with depth test on (GL_LESS), depth
   and colour writes off, depth clamp on, and two-sided stencil:
   z-pass  front: depth-pass -> INCR_WRAP, back: depth-pass -> DECR_WRAP (sides only);
   z-fail  back: depth-fail -> INCR_WRAP, front: depth-fail -> DECR_WRAP (sides + both caps);
   planar  the caster flattened onto z = 0 by the projection-shadow matrix ([Kolivand-Stencil]) -> REPLACE 1.
   Then a full-viewport triangle adds the light's weight to the mask where ``stencil > 0x80`` (ground bit
   set and count != 0), and the occluder is redrawn with GL_EQUAL depth adding this light's Phong
   diffuse + specular where the stencil is exactly 0x40 (occluder, count 0: self-shadowing).
3. MSAA resolve / supersampling downsample (glBlitFramebuffer), one readback per attachment of just the
   canvas, rows flipped to top-down.

moderngl keeps its own copy of some GL state (bound framebuffer, enable flags, depth function, colour and
depth masks). Each pass sets moderngl's flags explicitly (``ctx.enable_only``, ``ctx.depth_func``) and the
raw state (stencil, depth clamp, draw buffers, colour masks, polygon offset) is set per pass and reset at
the end.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import TYPE_CHECKING

import numpy as np

from .._check import check_finite, check_shape
from ..compose.composite import sky_planes
from ..errors import UsageError
from ..renderer.request import MODES, LightPass, RenderLayers, RenderRequest, RenderResult, Shading
from ..shading.interreflect import frame_self_light
from . import glraw as G
from .context import current, is_software
from .falloff import Falloff, frame_falloff, set_falloff
from .layers import GpuLayers
from .resources import (
    CasterBuffers,
    CasterCache,
    GroundBuffer,
    VolumeBuffers,
    program,
    screen_box,
    set_uniforms,
    translation,
    uniform,
)
from .sky import GLGroundRaster, GroundSkyMap
from .targets import FrameTargets, RenderTarget

if TYPE_CHECKING:  # annotations only: the context is handed in (arshadow.gl.context makes it)
    import moderngl

    from ..shading.sky import GroundOcclusion, SkyShading

__all__ = ["LightPass", "RenderResult", "ShadowRenderer"]

GROUND_BIT = 0x80
OCCLUDER_BIT = 0x40
COUNT_MASK = 0x3F
#: batched volumes (more layers than a 6-bit count holds): bits 0-4 count one batch, bit 5 ORs the batches
BATCH_COUNT_MASK = 0x1F
SHADOWED_BIT = 0x20


def _sky_channel(c1: np.ndarray, sky: SkyShading | None) -> np.ndarray:
    """The result's sky occlusion from the mask target read back top-down ``c1 (h, w, 3|4)``: its b channel,
    per colour channel with a coloured object's reflected light (a), clipped to [-1, 1]."""
    refl = c1[..., 3] if c1.shape[2] > 3 else None
    bleed = sky.bleed if sky is not None else None
    out: np.ndarray = np.clip(sky_planes(c1[..., 2], refl, bleed), -1.0, 1.0)
    return out


def _object_sky(shading: Shading) -> str | None:
    """The sky model of the object's per-vertex sky visibility (None: the uniform ambient term)."""
    sky = getattr(shading, "sky", None)
    return None if sky is None else sky.object_sky


@dataclass
class _Frame:
    """What the passes of one frame share (made by :meth:`ShadowRenderer._begin`)."""

    width: int
    height: int
    mvp: np.ndarray  # (4, 4) float64 clip_from_world
    mvp_bytes: bytes  # clip_from_local as float32, column-major (GLSL)
    origin: np.ndarray  # (3,) the caster's local origin
    eye: np.ndarray  # (3,) the camera centre in the local frame
    front: str
    bufs: CasterBuffers | None  # None when neither the occluder nor a planar pass needs the caster's buffers
    passes: list[LightPass]
    ranges: list[tuple[int, int] | None]  # per pass: (first index, index count) of its volume, or None
    draw_occluder: bool
    t0: float
    t1: float = 0.0
    sky: SkyShading | None = None  # Shading.sky
    falloff: Falloff | None = None  # Shading.ratio_falloff, in the local frame
    self_light: tuple = (0.0, 0.0, 0.0)  # the object's light on itself (arshadow.shading.interreflect)

    @property
    def size(self) -> tuple[int, int]:
        return self.width, self.height

    @property
    def caster(self) -> CasterBuffers:
        """:attr:`bufs`, in the passes that run only when they were made (the occluder's, a planar light's)."""
        assert self.bufs is not None, "no caster buffers in this frame"
        return self.bufs


class ShadowRenderer:
    """Render hard shadows of one caster onto the ground plane z = 0 with stencil shadow volumes.

    Parameters
    ----------
    ctx : moderngl.Context
        An OpenGL >= 3.3 context from :func:`arshadow.gl.context.create_context` (not created here).
    max_width, max_height : int
        Largest canvas accepted. Buffers are allocated lazily at the first canvas size and grown (never
        shrunk) when a larger canvas comes.
    samples : int
        MSAA samples per pixel (0 = off; at most ``ctx.max_samples``).
    supersample : int
        1, 2 or 4: render at ``supersample`` x the canvas size and box-filter down (can be combined with
        MSAA).
    ground_offset : (float, float)
        ``glPolygonOffset(factor, units)`` of the ground plane's depth (see docs/rendering.md: keeps the
        volume/ground depth comparisons at z = 0 stable where the object stands on the ground).
    crease_deg : float
        Smoothing angle of the occluder's shading normals.

    Two entry points taking one :class:`arshadow.renderer.request.RenderRequest`: :meth:`render` reads the layers
    back (:class:`RenderResult`), :meth:`render_gpu` leaves them in textures (:class:`GpuLayers`).

    Examples
    --------
    >>> # ctx = create_context(); r = ShadowRenderer(ctx); res = r.render(RenderRequest(projection=P, ...))
    """

    @current
    def __init__(
        self,
        ctx: moderngl.Context,
        *,
        max_width: int = 4096,
        max_height: int = 4096,
        samples: int = 0,
        supersample: int = 1,
        ground_offset: tuple[float, float] = (0.0, 0.0),
        crease_deg: float = 40.0,
        max_cached_casters: int = 8,
    ) -> None:
        self.ctx = ctx
        self.gl = G.load()
        self.max_width, self.max_height = int(max_width), int(max_height)
        samples = int(samples)
        if samples < 0 or samples > max(int(ctx.max_samples), 0):
            raise UsageError(f"samples={samples} not supported (this GL allows 0..{ctx.max_samples})")
        if samples == 1:
            samples = 0
        self.samples = samples
        if int(supersample) not in (1, 2, 4):
            raise UsageError(f"supersample must be 1, 2 or 4, got {supersample}")
        self.supersample = int(supersample)
        limit = int(ctx.info.get("GL_MAX_RENDERBUFFER_SIZE", 16384))
        if self.max_width * self.supersample > limit or self.max_height * self.supersample > limit:
            raise UsageError(
                f"max canvas {self.max_width}x{self.max_height} x supersample {self.supersample} "
                f"exceeds GL_MAX_RENDERBUFFER_SIZE {limit}"
            )
        self.ground_offset = (float(ground_offset[0]), float(ground_offset[1]))
        self.crease_deg = float(crease_deg)
        self.max_cached_casters = int(max_cached_casters)
        # programs (compiled once per context)
        self.prog_occ_base = program(ctx, "occluder.vert", "occluder_base.frag")
        self.prog_occ_light = program(ctx, "occluder.vert", "occluder_light.frag")
        # the same with a texture, sky shading and the albedo gain (the realism work), for casters that need them:
        # the plain ones stay as fast as before
        self.prog_rich_base = program(ctx, "occluder_rich.vert", "occluder_rich_base.frag")
        self.prog_rich_light = program(ctx, "occluder_rich.vert", "occluder_rich_light.frag")
        self.prog_ground = program(ctx, "ground.vert", "ground.frag")
        self.prog_volume = program(ctx, "common.vert", "volume.frag")
        self.prog_mask = program(ctx, "fullscreen.vert", "mask.frag")
        self.prog_planar_mask = program(ctx, "common.vert", "mask.frag")  # direct planar shadows
        # static geometry: unlimited ground (4 triangles fanning out to points at infinity), full viewport
        self._ground = GroundBuffer(ctx, self.prog_ground)
        self._fs_vao = ctx.vertex_array(self.prog_mask, [])
        self._volumes = VolumeBuffers(ctx, self.prog_volume)
        self._casters = CasterCache(
            ctx,
            (self.prog_occ_base, self.prog_occ_light, self.prog_volume),
            self.max_cached_casters,
            rich_programs=(self.prog_rich_base, self.prog_rich_light),
        )
        self._targets = FrameTargets(ctx, self.gl, samples, self.supersample)
        self._sky_ground: GroundSkyMap | None = None  # of the last ground occlusion map drawn
        self._released = False
        # the capabilities of arshadow.renderer.request.Renderer
        #: render_gpu() keeps the layers on the GPU (arshadow.gl.gpu_compose composites them there)
        self.gpu_layers: bool = True
        #: the context rasterises on the CPU (llvmpipe): its "GPU" paths run on the pipeline's own cores
        self.software: bool = is_software(ctx)
        #: what renders (the GL renderer string): part of the compose path's key
        self.backend: str = str((ctx.info or {}).get("GL_RENDERER", "?"))
        #: the ground occlusion map's shadows drawn on this context (its GL objects made on first use)
        self.ground_raster: GLGroundRaster = GLGroundRaster(ctx)
        #: when True, render() calls ctx.finish() after each pass and reports per-pass times (slower)
        self.profile = False
        self._marks: list[tuple[str, float]] = []

    # ------------------------------------------------------------------ resources
    def __enter__(self) -> ShadowRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    @current
    def release(self) -> None:
        """Free every GL object this renderer made (programs stay cached on the context)."""
        if self._released:
            return
        self._targets.release()
        self._casters.release()
        self._volumes.release()
        self._ground.release()
        self._fs_vao.release()
        if self._sky_ground is not None:
            self._sky_ground.release()
        self.ground_raster.release()
        self._released = True

    @property
    def stencil_bits(self) -> int:
        """Stencil bits of the render target actually obtained (8 for GL_DEPTH24_STENCIL8); 0 before the
        first render."""
        return self._main.stencil_bits if self._main is not None else 0

    @property
    def actual_samples(self) -> int:
        """MSAA samples per pixel the driver actually allocated (0 = single-sampled; llvmpipe has only 4)."""
        return self._main.actual_samples if self._main is not None else 0

    @property
    def depth_bits(self) -> int:
        return self._main.depth_bits if self._main is not None else 0

    @property
    def _main(self) -> RenderTarget | None:
        """The main render target (None before the first render)."""
        return self._targets.main

    # ------------------------------------------------------------------ entry points
    @current
    def render(self, request: RenderRequest) -> RenderResult:
        """Render one frame (or one canvas sub-rectangle of it) and read its layers back.

        Parameters
        ----------
        request : arshadow.renderer.request.RenderRequest
            The frame: projection and view, canvas size (<= max_width, max_height), caster (its GPU buffers
            are cached per caster object), light passes, ground, what to draw, shading (Phong, [Kolivand-Stencil]:
            ``I = K_a I_a + sum_l I_l (K_d (N.L) + K_s (N.H)^n)``; the colour overrides the mesh's own).

        Returns
        -------
        RenderResult
            The layers as numpy arrays (top-down rows) and the raw bottom-up ones (``layers``).
        """
        f = self._draw(request)
        src = self._resolve_canvas(f)
        self.ctx.finish()
        return self._readback(f, src)

    @current
    def render_gpu(self, request: RenderRequest) -> GpuLayers:
        """As :meth:`render`, but the layers stay on the GPU: the (resolved) attachments are copied into two
        textures (no ``ctx.finish()``, no readback); :mod:`arshadow.gl.gpu_compose` samples them.

        Returns
        -------
        GpuLayers
            Valid until the next render.
        """
        f = self._draw(request)
        tt = self._targets.texture(f.width, f.height)
        if self.supersample == 1:
            # resolve (MSAA) or copy straight into the texture target
            main = self._main
            assert main is not None  # made by _draw
            self._targets.blit(main, tt, f.width, f.height, f.width, f.height, G.GL_NEAREST)
            self._mark("resolve")
        else:
            src = self._resolve_canvas(f)
            self._targets.blit(src, tt, f.width, f.height, f.width, f.height, G.GL_NEAREST)
        t2 = time.perf_counter()
        return GpuLayers(
            tt.color_tex,
            tt.mask_tex,
            f.width,
            f.height,
            timings_ms={
                "upload": (f.t1 - f.t0) * 1e3,
                "draw": (t2 - f.t1) * 1e3,
                "readback": 0.0,
                "total": (t2 - f.t0) * 1e3,
            },
            sky=f.sky is not None and f.sky.ground is not None,
            bleed=f.sky.bleed if f.sky is not None and f.sky.ground is not None and f.sky.colored else None,
        )

    # ------------------------------------------------------------------ one frame, pass by pass
    def _draw(self, request: RenderRequest) -> _Frame:
        """Every pass of one frame into the main target; GL state reset at the end."""
        f = self._begin(request)
        self._clear_pass(f)
        self._occluder_base_pass(f)
        self._ground_pass(f)
        for i, (p, rng) in enumerate(zip(f.passes, f.ranges, strict=True)):
            self._light_pass(f, i, p, rng)
        self._mark("occluder_light")
        self._reset_state()
        return f

    def _begin(self, request: RenderRequest) -> _Frame:
        """Check the arguments, upload what changed (caster, volumes, light subsets, ground), size the targets."""
        t0 = time.perf_counter()
        if self._released:
            raise UsageError("this ShadowRenderer has been released")
        width, height = int(request.width), int(request.height)
        if not (0 < width <= self.max_width and 0 < height <= self.max_height):
            raise UsageError(f"canvas {width}x{height} outside 1..{self.max_width} x 1..{self.max_height}")
        proj = check_finite(check_shape(request.projection, "4,4", "projection"), "projection")
        view = check_finite(check_shape(request.view, "4,4", "view"), "view")
        passes, draw_occluder, shading = list(request.passes), bool(request.draw_occluder), request.shading
        for p in passes:
            if p.mode not in MODES:
                raise UsageError(f"unknown shadow mode {p.mode!r} (choose {', '.join(MODES)})")
            if not (math.isfinite(float(p.weight)) and float(p.weight) >= 0):
                raise UsageError(f"light weight must be finite and >= 0, got {p.weight}")
        mvp = proj @ view
        origin = request.caster.bounds.mean(axis=0)  # = local_origin(caster.vertices), from the cached bounds
        mvp_local = mvp @ translation(origin)
        bufs = (
            self._casters.get(
                request.caster,
                shading.color,
                self.crease_deg,
                _object_sky(shading),
                rich=tuple(shading.albedo_gain) != (1.0, 1.0, 1.0),
            )
            if (draw_occluder or any(p.mode == "planar" for p in passes))
            else None
        )
        ranges = self._volumes.upload(passes, origin)
        if bufs is not None and (draw_occluder or any(p.mode == "planar" and p.direct for p in passes)):
            bufs.upload_light_subsets(passes)
        self._ground.set(request.ground_size, origin)
        if draw_occluder:
            progs = (self.prog_occ_base, self.prog_occ_light, self.prog_rich_base, self.prog_rich_light)
            set_uniforms(progs, shading.uniforms())
        self._targets.ensure(width, height, sky=shading.sky is not None and shading.sky.ground is not None)
        f = _Frame(
            width=width,
            height=height,
            mvp=mvp,
            mvp_bytes=mvp_local.T.astype(np.float32).tobytes(),  # GLSL is column-major
            origin=origin,
            eye=-view[:3, :3].T @ view[:3, 3] - origin,
            # mirrored projections flip the winding: keep "front" = outward side seen from outside
            front="cw" if np.linalg.det(mvp) > 0 else "ccw",
            bufs=bufs,
            passes=passes,
            ranges=ranges,
            draw_occluder=draw_occluder,
            t0=t0,
            sky=shading.sky,
            falloff=frame_falloff(
                shading, passes, origin, mvp_local, (width * self.supersample, height * self.supersample)
            ),
        )
        if draw_occluder and bufs is not None and shading.sky is not None:
            bufs.set_object_ground(shading.sky.object_ground)
        if draw_occluder and bufs is not None and bufs.self_view is not None:
            f.self_light = frame_self_light(bufs.self_view, passes, shading)
        f.t1 = time.perf_counter()
        self._marks = [("start", f.t1)]
        return f

    def _clear_pass(self, f: _Frame) -> None:
        """Bind the main target and clear colour, depth and stencil of the canvas (scissored: the buffers
        may be larger)."""
        ctx, gl = self.ctx, self.gl
        s = self.supersample
        rw, rh = f.width * s, f.height * s
        main = self._main
        assert main is not None  # made by _begin (FrameTargets.ensure)
        fbo = main.mgl
        fbo.viewport = (0, 0, rw, rh)
        fbo.scissor = (0, 0, rw, rh)  # clears touch only the canvas
        fbo.use()  # binds, sets viewport/scissor, and moderngl's colour/depth masks (all on)
        gl.draw_buffers(2)
        ctx.front_face = f.front
        ctx.enable_only(ctx.NOTHING)
        gl.glEnable(G.GL_SCISSOR_TEST)
        gl.glScissor(0, 0, rw, rh)
        gl.glStencilMask(0xFF)
        gl.glClearStencil(0)
        gl.glClearDepth(1.0)
        gl.glClearColor(0.0, 0.0, 0.0, 0.0)
        gl.glClear(G.GL_COLOR_BUFFER_BIT | G.GL_DEPTH_BUFFER_BIT | G.GL_STENCIL_BUFFER_BIT)
        self._mark("clear")

    def _occluder_base_pass(self, f: _Frame) -> None:
        """Occluder depth + ambient colour + coverage, occluder stencil bit (depth LESS, writes on)."""
        ctx, gl = self.ctx, self.gl
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        if f.draw_occluder:
            bufs = f.caster
            ctx.enable_only(ctx.DEPTH_TEST | (ctx.CULL_FACE if bufs.cull else 0))
            ctx.cull_face = "back"
            gl.glEnable(G.GL_STENCIL_TEST)
            gl.glStencilFunc(G.GL_ALWAYS, OCCLUDER_BIT, 0xFF)
            gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_REPLACE)
            # colour 1 stays 0 on the occluder (cleared; the ground pass overwrites it where it is nearer)
            gl.draw_buffer_list([0])
            prog = bufs.prog_base
            vao = bufs.base_vao if bufs.shade_base_vao is None else bufs.shade_base_vao
            uniform(prog, "u_mvp").write(f.mvp_bytes)  # the shading's uniforms: written by _begin
            if bufs.rich:
                use_vis = bufs.sky is not None and f.sky is not None
                uniform(prog, "u_use_vis").value = use_vis
                bounce = tuple(float(x) for x in f.sky.bounce) if use_vis and f.sky is not None else (0.0, 0.0, 0.0)
                uniform(prog, "u_bounce").value = bounce
                uniform(prog, "u_self").value = f.self_light if use_vis else (0.0, 0.0, 0.0)
                self._bind_texture(prog, bufs)
            vao.render(ctx.TRIANGLES, vertices=bufs.n_indices)
            gl.draw_buffers(2)
        self._mark("occluder")

    def _ground_pass(self, f: _Frame) -> None:
        """The ground plane's depth, ground coverage (colour 1 g), sky channel (colour 1 b, a: the ground occlusion
        map read at each ground sample, with sky occlusion) and ground stencil bit."""
        ctx, gl = self.ctx, self.gl
        ctx.enable_only(ctx.DEPTH_TEST | ctx.CULL_FACE)
        ctx.cull_face = "back"
        gl.glEnable(G.GL_STENCIL_TEST)
        gl.glStencilFunc(G.GL_ALWAYS, GROUND_BIT, 0xFF)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_REPLACE)
        if self.ground_offset != (0.0, 0.0):
            gl.glEnable(G.GL_POLYGON_OFFSET_FILL)
            gl.glPolygonOffset(*self.ground_offset)
        if f.draw_occluder and not f.caster.below_ground:
            gl.draw_buffer_list([None, 1])  # nothing of the occluder below z = 0 to erase: skip colour 0
        else:
            gl.draw_buffers(2)
        prog = self.prog_ground
        uniform(prog, "u_mvp").write(f.mvp_bytes)
        if f.sky is not None and f.sky.ground is not None:  # the sky channel from the ground occlusion map
            self._sky_map(f.sky.ground).bind(prog, f.origin)
            set_falloff(prog, f.falloff, f.origin, None)
        else:
            uniform(prog, "u_sky").value = False
        self._ground.render(ctx)
        gl.draw_buffers(2)
        gl.glDisable(G.GL_POLYGON_OFFSET_FILL)
        self._mark("ground")

    @staticmethod
    def _bind_texture(prog: moderngl.Program, bufs: CasterBuffers) -> None:
        """The caster's base-colour texture on unit 0 (``u_textured`` off without one)."""
        uniform(prog, "u_textured").value = bufs.texture is not None
        if bufs.texture is not None:
            bufs.texture.use(location=0)
            uniform(prog, "u_tex").value = 0

    def _sky_map(self, ground: GroundOcclusion) -> GroundSkyMap:
        """The ground occlusion map ``ground`` (``f.sky.ground``) on the GPU, made on first use per map."""
        sm = self._sky_ground
        if sm is None or sm.occlusion is not ground:
            if sm is not None:
                sm.release()
            sm = self._sky_ground = GroundSkyMap(self.ctx, ground)
        return sm

    def _light_pass(self, f: _Frame, i: int, p: LightPass, rng: tuple[int, int] | None) -> None:
        """One light: its shadow into the mask, then its lighting of the occluder."""
        planar = p.mode == "planar"
        if rng is None and not planar:
            # casts nothing: the occluder gets this light unshadowed
            if f.draw_occluder:
                self._light_occluder(f, p, i, stencil=False)
            return
        if planar and p.direct and f.caster.cull and i in f.caster.sub_ranges:
            self._planar_direct_pass(f, p, i)
            self._mark("mask")
            if f.draw_occluder:
                self._light_occluder(f, p, i, stencil=False)
            return
        self._count_pass(f, p, rng)
        self._mark("volume")
        self._mask_pass(f, p)
        self._mark("mask")
        if f.draw_occluder:
            self._light_occluder(f, p, i, stencil=not planar)

    def _planar_direct_pass(self, f: _Frame, p: LightPass, i: int) -> None:
        """Convex closed caster: its light-facing faces, flattened from the light, tile the shadow exactly
        once -> add the weight straight into the mask where the ground is visible and the occluder is not
        (stencil ground bit set, occluder bit clear); no count, no clear."""
        ctx, gl = self.ctx, self.gl
        first, count = f.caster.sub_ranges[i]
        if p.shadow_matrix is None or not p.weight > 0 or not count:
            return
        ctx.enable_only(ctx.BLEND)  # no depth test, no culling (projection may mirror)
        ctx.blend_func = ctx.ONE, ctx.ONE
        gl.glDepthMask(G.GL_FALSE)
        gl.glColorMask(1, 1, 1, 1)
        gl.glEnable(G.GL_DEPTH_CLAMP)
        gl.glStencilMask(0)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
        gl.glStencilFunc(G.GL_EQUAL, GROUND_BIT, GROUND_BIT | OCCLUDER_BIT)
        gl.draw_buffer_list([None, 1])
        smat = np.asarray(p.shadow_matrix, dtype=np.float64)
        prog = self.prog_planar_mask
        uniform(prog, "u_mvp").write((f.mvp @ smat @ translation(f.origin)).T.astype(np.float32).tobytes())
        uniform(prog, "u_weight").value = float(p.weight)
        set_falloff(prog, f.falloff, f.origin, np.asarray(p.light_h, np.float64))
        f.caster.planar_sub_vao(self.ctx, prog).render(ctx.TRIANGLES, vertices=count, first=first)
        gl.draw_buffers(2)
        gl.glDisable(G.GL_DEPTH_CLAMP)

    def _count_pass(self, f: _Frame, p: LightPass, rng: tuple[int, int] | None) -> None:
        """The light's stencil count: clear the count bits (keep the ground bit), then draw its volume
        (z-pass, z-fail, batched) or its flattened caster (planar) with depth test on, depth/colour writes
        off, depth clamp on, two-sided stencil."""
        ctx, gl = self.ctx, self.gl
        gl.glStencilMask(COUNT_MASK)
        gl.glClear(G.GL_STENCIL_BUFFER_BIT)
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        gl.glDepthMask(G.GL_FALSE)
        gl.glColorMask(0, 0, 0, 0)
        gl.glEnable(G.GL_DEPTH_CLAMP)
        gl.glStencilFunc(G.GL_ALWAYS, 0, 0xFF)
        if p.mode == "planar":
            # projection shadow ([Kolivand-Stencil]): the caster flattened onto z = 0; depth test "always",
            # the ground bit limits it to visible ground in the mask pass. A light at or below the
            # ground lights none of it from above: nothing to draw.
            # (LightPass.shadow_matrix: None when the light is not above the ground)
            if p.shadow_matrix is not None:
                ctx.depth_func = "1"
                gl.glStencilFunc(G.GL_ALWAYS, 1, 0xFF)
                gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_REPLACE)
                smat = np.asarray(p.shadow_matrix, dtype=np.float64)
                uniform(self.prog_volume, "u_mvp").write(
                    (f.mvp @ smat @ translation(f.origin)).T.astype(np.float32).tobytes()
                )
                f.caster.planar_vao.render(ctx.TRIANGLES, vertices=f.caster.n_indices)
            return
        assert rng is not None  # a volume pass with nothing to draw returned in _light_pass
        batches = getattr(p.volume, "batches", None)  # ShadowVolume.batches
        if batches:
            self._batched_volume(batches, rng[0], f.mvp_bytes)
        else:
            if p.mode == "zpass":
                gl.glStencilOpSeparate(G.GL_FRONT, G.GL_KEEP, G.GL_KEEP, G.GL_INCR_WRAP)
                gl.glStencilOpSeparate(G.GL_BACK, G.GL_KEEP, G.GL_KEEP, G.GL_DECR_WRAP)
            else:  # zfail
                gl.glStencilOpSeparate(G.GL_BACK, G.GL_KEEP, G.GL_INCR_WRAP, G.GL_KEEP)
                gl.glStencilOpSeparate(G.GL_FRONT, G.GL_KEEP, G.GL_DECR_WRAP, G.GL_KEEP)
            uniform(self.prog_volume, "u_mvp").write(f.mvp_bytes)
            self._volumes.array.render(ctx.TRIANGLES, vertices=rng[1], first=rng[0])

    def _mask_pass(self, f: _Frame, p: LightPass) -> None:
        """Add the light's weight to the mask where the ground bit is set and the count != 0
        (``0x80 < stencil``), with a full-viewport triangle."""
        ctx, gl = self.ctx, self.gl
        gl.glDisable(G.GL_DEPTH_CLAMP)
        gl.glStencilMask(0)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
        if p.weight > 0:
            ctx.enable_only(ctx.BLEND)
            ctx.blend_func = ctx.ONE, ctx.ONE
            gl.glColorMask(1, 1, 1, 1)
            gl.draw_buffer_list([None, 1])  # adds (weight, 0): the ground channel is unchanged
            gl.glStencilFunc(G.GL_LESS, GROUND_BIT, 0xFF)
            uniform(self.prog_mask, "u_weight").value = float(p.weight)
            set_falloff(self.prog_mask, f.falloff, f.origin, np.asarray(p.light_h, np.float64))
            self._fs_vao.render(ctx.TRIANGLES, vertices=3)
            gl.draw_buffers(2)

    def _reset_state(self) -> None:
        """Reset the raw GL state and make moderngl's view of it consistent."""
        ctx, gl = self.ctx, self.gl
        gl.draw_buffers(2)
        gl.glDisable(G.GL_STENCIL_TEST)
        gl.glStencilMask(0xFF)
        gl.glStencilFunc(G.GL_ALWAYS, 0, 0xFF)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
        gl.glDisable(G.GL_DEPTH_CLAMP)
        gl.glDisable(G.GL_POLYGON_OFFSET_FILL)
        gl.glDisable(G.GL_SCISSOR_TEST)
        gl.glDepthMask(G.GL_TRUE)
        gl.glColorMask(1, 1, 1, 1)
        ctx.enable_only(ctx.NOTHING)
        ctx.depth_func = "<"
        ctx.front_face = "ccw"

    def _resolve_canvas(self, f: _Frame) -> RenderTarget:
        """MSAA resolve / supersampling downsample into a single-sample canvas-size target (returned)."""
        src = self._targets.resolve_canvas(f.width, f.height)
        self._mark("resolve")
        return src

    def _readback(self, f: _Frame, src: RenderTarget) -> RenderResult:
        """One read per attachment of just the canvas, rows flipped to top-down. Colour: only the
        occluder's conservative screen box is read (np.zeros pages elsewhere stay untouched);
        mask/ground: the whole canvas."""
        ctx, gl = self.ctx, self.gl
        width, height = f.width, f.height
        t2 = time.perf_counter()
        c0 = np.zeros((height, width, 4), dtype=np.float32)
        sky = f.sky is not None and f.sky.ground is not None
        rgb = sky and f.sky is not None and f.sky.colored
        c1 = np.empty((height, width, (4 if rgb else 3) if sky else 2), dtype=np.float32)
        gl.glBindBuffer(G.GL_PIXEL_PACK_BUFFER, 0)
        gl.glPixelStorei(G.GL_PACK_ALIGNMENT, 4)
        gl.glBindFramebuffer(G.GL_READ_FRAMEBUFFER, src.fbo)
        box = screen_box(f.mvp, f.caster.box_corners, width, height) if f.draw_occluder else None
        if box is not None and box[2] > box[0] and box[3] > box[1]:
            x0, y0, x1, y1 = box
            gl.glPixelStorei(G.GL_PACK_ROW_LENGTH, width)
            gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0)
            gl.glReadPixels(x0, y0, x1 - x0, y1 - y0, G.GL_RGBA, G.GL_FLOAT, c0[y0:, x0:].ctypes.data)
        gl.glPixelStorei(G.GL_PACK_ROW_LENGTH, 0)
        gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0 + 1)
        fmt = (G.GL_RGBA if rgb else G.GL_RGB) if sky else G.GL_RG
        gl.glReadPixels(0, 0, width, height, fmt, G.GL_FLOAT, c1.ctypes.data)
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, 0)
        ctx.screen.use() if ctx.screen is not None else None
        layers = RenderLayers(rgba=c0, mask_ground=c1)  # the raw bottom-up arrays
        c0 = c0[::-1]
        c1 = c1[::-1]
        mask = c1[..., 0]
        np.clip(mask, 0.0, 1.0, out=mask)
        gcov = c1[..., 1]
        t3 = time.perf_counter()
        passes = {f"pass_{b[0]}": (b[1] - a[1]) * 1e3 for a, b in pairwise(self._marks)} if self.profile else {}
        return RenderResult(
            mask=mask,
            color=c0[..., :3],
            alpha=c0[..., 3],
            ground=gcov > 0.5,
            ground_coverage=gcov,
            layers=layers,
            sky_occlusion=_sky_channel(c1, f.sky) if sky else None,
            timings_ms={
                "upload": (f.t1 - f.t0) * 1e3,
                "draw": (t2 - f.t1) * 1e3,
                "readback": (t3 - t2) * 1e3,
                "total": (t3 - f.t0) * 1e3,
                **passes,
            },
        )

    def _mark(self, name: str) -> None:
        if self.profile:
            self.ctx.finish()
            self._marks.append((name, time.perf_counter()))

    def _batched_volume(self, batches: Sequence[tuple[int, int]], first_index: int, mvp_bytes: bytes) -> None:
        """Count a batched volume (:attr:`arshadow.geometry.volume.ShadowVolume.batches`) exactly: each closed
        z-fail batch is counted in bits 0-4 (its count is 0..31, so exact modulo 32), then a full-viewport
        pass sets :data:`SHADOWED_BIT` where that count is not 0 and the count bits are cleared for the
        next batch. Leaves ``SHADOWED_BIT`` set where any batch (so the union: the shadow) covers the
        sample and the count bits 0, as the mask and occluder-lighting passes expect."""
        ctx, gl = self.ctx, self.gl
        for first_tri, n_tri in batches:
            ctx.enable_only(ctx.DEPTH_TEST)
            ctx.depth_func = "<"
            gl.glColorMask(0, 0, 0, 0)
            gl.glEnable(G.GL_DEPTH_CLAMP)
            gl.glStencilMask(BATCH_COUNT_MASK)
            gl.glStencilFunc(G.GL_ALWAYS, 0, 0xFF)
            gl.glStencilOpSeparate(G.GL_BACK, G.GL_KEEP, G.GL_INCR_WRAP, G.GL_KEEP)
            gl.glStencilOpSeparate(G.GL_FRONT, G.GL_KEEP, G.GL_DECR_WRAP, G.GL_KEEP)
            uniform(self.prog_volume, "u_mvp").write(mvp_bytes)
            self._volumes.array.render(ctx.TRIANGLES, vertices=3 * n_tri, first=first_index + 3 * first_tri)
            gl.glDisable(G.GL_DEPTH_CLAMP)
            # count != 0 -> set the shadowed bit (ref & mask = 0: passes where the count is not 0; REPLACE
            # writes ref = SHADOWED_BIT through the write mask SHADOWED_BIT)
            ctx.enable_only(ctx.NOTHING)
            gl.glStencilMask(SHADOWED_BIT)
            gl.glStencilFunc(G.GL_NOTEQUAL, SHADOWED_BIT, BATCH_COUNT_MASK)
            gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_REPLACE)
            self._fs_vao.render(ctx.TRIANGLES, vertices=3)
            gl.glStencilMask(BATCH_COUNT_MASK)
            gl.glClear(G.GL_STENCIL_BUFFER_BIT)
        # the mask pass tests "stencil > GROUND_BIT": with the count bits 0 that is "shadowed bit set"
        ctx.enable_only(ctx.DEPTH_TEST)

    def _light_occluder(self, f: _Frame, p: LightPass, i: int, stencil: bool) -> None:
        """Add one light's Phong diffuse + specular to the occluder where its count is 0."""
        ctx, gl, bufs = self.ctx, self.gl, f.caster
        ctx.enable_only(ctx.DEPTH_TEST | ctx.BLEND | (ctx.CULL_FACE if bufs.cull else 0))
        ctx.cull_face = "back"
        ctx.depth_func = "=="
        ctx.blend_func = ctx.ONE, ctx.ONE
        gl.glDepthMask(G.GL_FALSE)
        gl.glColorMask(1, 1, 1, 1)  # additive with alpha 0: coverage unchanged
        gl.glEnable(G.GL_STENCIL_TEST)
        gl.glStencilMask(0)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
        # occluder pixels (bit 6) whose count is 0; without a volume: every occluder pixel
        gl.glStencilFunc(G.GL_EQUAL, OCCLUDER_BIT, 0xFF if stencil else 0xC0)
        gl.draw_buffer_list([0])
        prog = bufs.prog_light
        uniform(prog, "u_mvp").write(f.mvp_bytes)
        lh = np.asarray(p.light_h, dtype=np.float64).copy()
        lh[:3] -= bufs.origin * lh[3]  # the caster's local frame, like v_world
        uniform(prog, "u_light").value = tuple(float(x) for x in lh)
        if lh[3] != 0:  # a point light's squared distance to the world origin (Shading.point_falloff)
            world = np.asarray(p.light_h, np.float64)
            uniform(prog, "u_light_d2").value = float(np.sum((world[:3] / world[3]) ** 2))
        col = np.asarray(p.color, dtype=np.float64)[:3] * float(p.weight)
        uniform(prog, "u_light_color").value = tuple(float(x) for x in col)
        uniform(prog, "u_eye").value = tuple(float(x) for x in f.eye)  # the shading's uniforms: written by _begin
        if bufs.rich:
            self._bind_texture(prog, bufs)
        # closed meshes: only the light-facing faces (the others lie in this light's own shadow; with a
        # planar or no volume pass this is also what keeps a convex occluder's terminator as the volume has it)
        if i in bufs.sub_ranges:
            first, count = bufs.sub_ranges[i]
            if count:
                bufs.sub_vao.render(ctx.TRIANGLES, vertices=count, first=first)
        else:
            bufs.vao.render(ctx.TRIANGLES, vertices=bufs.n_indices)
        gl.draw_buffers(2)
        ctx.depth_func = "<"
