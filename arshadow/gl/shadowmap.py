"""Shadow-map baseline renderer: the technique of three.js, model-viewer and pyrender, for comparison.

Same :class:`~arshadow.renderer.request.RenderRequest` in and :class:`~arshadow.renderer.request.RenderResult` out as
:meth:`arshadow.gl.stencil.ShadowRenderer.render`, so the compositor and the benchmarks can swap it in
(``--shadow-method shadowmap``). The shadow volumes in ``passes`` are ignored: only ``light_h``,
``weight`` and ``color`` of each :class:`~arshadow.renderer.request.LightPass` are used.

Per light:

1. depth pass: the caster's depth from the light into a ``map_size`` x ``map_size`` depth texture. The
   light's frustum is fitted to the caster's bounding sphere (only the caster casts; a ground point whose
   light-space position falls outside the map is lit): a perspective frustum for a point light, an
   orthographic box for a directional one. Slope-scaled bias: ``glPolygonOffset(slope_bias,
   constant_bias)`` while drawing the depth.
2. camera pass: the ground (and the occluder) again with GL_LEQUAL depth; each fragment is projected into
   the map and compared (``sampler2DShadow``: 2x2 hardware comparison, then ``pcf`` x ``pcf`` taps one
   texel apart = percentage-closer filtering). The ground adds ``weight x (1 - visibility)`` to the mask,
   the occluder ``visibility x`` its Phong term.

The result is approximate by construction: the map's texels are finite (aliasing, jagged edges), the bias
shifts the shadow away from the contact (peter-panning) or lets it self-shadow (acne), and PCF blurs the
edge. ``arshadow bench`` measures how far from the exact shadow it lands at each map size.
"""

from __future__ import annotations

import math
import time
import weakref
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from .._check import check_finite, check_shape
from ..errors import UsageError
from ..renderer.request import LightPass, RendererBase, RenderRequest, RenderResult
from . import glraw as G
from .context import current
from .resources import CasterBuffers, GroundBuffer, program, set_uniforms, uniform

if TYPE_CHECKING:  # annotations only: the context is handed in (arshadow.gl.context makes it)
    import moderngl

    from ..geometry.caster import ShadowCaster

__all__ = ["ShadowMapRenderer", "light_view_projection", "MAP_SIZES"]

#: map sizes the benchmark sweeps (the renderer accepts any size up to GL_MAX_TEXTURE_SIZE)
MAP_SIZES = (512, 1024, 2048, 4096, 8192)


def _f32(m: npt.ArrayLike) -> bytes:
    """A (4, 4) matrix as float32 bytes, column-major (GLSL)."""
    return np.asarray(m, np.float64).T.astype(np.float32).tobytes()


def _look_at(
    eye: npt.ArrayLike, target: npt.ArrayLike, up_hint: tuple[float, float, float] = (0.0, 0.0, 1.0)
) -> np.ndarray:
    """OpenGL view matrix ``(4, 4)`` (camera looks down -z) from ``eye`` towards ``target``."""
    eye = np.asarray(eye, np.float64)
    f = np.asarray(target, np.float64) - eye
    f /= np.linalg.norm(f)
    up = np.asarray(up_hint, np.float64)
    if abs(f @ up) > 0.99:
        up = np.array([0.0, 1.0, 0.0])
    s = np.cross(f, up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def light_view_projection(light_h: npt.ArrayLike, bounds: npt.ArrayLike) -> np.ndarray:
    """Light ``clip_from_world (4, 4) float64`` whose frustum encloses the bounding sphere of ``bounds``.

    Parameters
    ----------
    light_h : (4,) float64
        ``(x, y, z, 1)`` point light or ``(dx, dy, dz, 0)`` direction towards the light (world frame).
    bounds : (2, 3) float64
        Caster bounding box ``[min, max]`` (world frame).

    Returns
    -------
    (4, 4) float64
        Perspective (point light; the cone tangent to the sphere, near/far planes at its front and back)
        or orthographic (directional light) projection times the light's view matrix.

    Raises
    ------
    UsageError
        A point light inside the caster's bounding sphere (one map cannot see the whole caster).
    """
    h = np.asarray(light_h, np.float64).reshape(4)
    b = np.asarray(bounds, np.float64).reshape(2, 3)
    c = 0.5 * (b[0] + b[1])
    r = max(0.5 * float(np.linalg.norm(b[1] - b[0])), 1e-9)
    if h[3] == 0.0:
        d = h[:3] / np.linalg.norm(h[:3])
        view = _look_at(c + 2.0 * r * d, c)
        n, f = r, 3.0 * r
        proj = np.array([[1 / r, 0, 0, 0], [0, 1 / r, 0, 0], [0, 0, -2 / (f - n), -(f + n) / (f - n)], [0, 0, 0, 1]])
        ortho: np.ndarray = proj @ view
        return ortho
    L = h[:3] / h[3]
    dist = float(np.linalg.norm(c - L))
    if dist <= r * 1.0001:
        raise UsageError("shadow map: the point light is inside the caster's bounding sphere")
    half = math.asin(r / dist)
    t = 1.0 / math.tan(half)
    n, f = dist - r, dist + r
    n = max(n, 1e-4 * dist)
    proj = np.array([[t, 0, 0, 0], [0, t, 0, 0], [0, 0, -(f + n) / (f - n), -2 * f * n / (f - n)], [0, 0, -1, 0]])
    persp: np.ndarray = proj @ _look_at(L, c)
    return persp


class ShadowMapRenderer(RendererBase):
    """Hard (PCF-filtered) shadows of one caster on the ground z = 0 with a shadow map per light.

    Parameters
    ----------
    ctx : moderngl.Context
        From :func:`arshadow.gl.context.create_context` (not created here).
    map_size : int
        Side of the square depth map, texels (512 ... 8192).
    pcf : int
        Percentage-closer filtering kernel side (odd; 1 = the hardware's 2x2 comparison only).
    slope_bias, constant_bias : float
        ``glPolygonOffset(factor, units)`` of the depth pass (slope-scaled bias).
    shader_bias : float
        Extra constant bias subtracted from the fragment's light-space depth ([0, 1] depth units).
    max_width, max_height : int
        Largest canvas accepted.
    crease_deg : float
        Smoothing angle of the occluder's shading normals.
    """

    # the baseline's map settings (size, PCF kernel, three biases), each swept by name by arshadow bench
    @current
    def __init__(  # noqa: PLR0913
        self,
        ctx: moderngl.Context,
        *,
        map_size: int = 2048,
        pcf: int = 3,
        slope_bias: float = 2.0,
        constant_bias: float = 4.0,
        shader_bias: float = 0.0,
        max_width: int = 4096,
        max_height: int = 4096,
        crease_deg: float = 40.0,
        samples: int = 0,
    ) -> None:
        self.ctx = ctx
        self.gl = G.load()
        limit = int(ctx.info.get("GL_MAX_TEXTURE_SIZE", 8192))
        if not (16 <= int(map_size) <= limit):
            raise UsageError(f"shadow map size {map_size} outside 16..{limit} (GL_MAX_TEXTURE_SIZE)")
        if int(pcf) < 1 or int(pcf) % 2 == 0:
            raise UsageError(f"pcf kernel must be an odd number >= 1, got {pcf}")
        if int(samples) not in (0, 1):
            raise UsageError("the shadow-map baseline renders without MSAA (samples=0)")
        self.map_size, self.pcf = int(map_size), int(pcf)
        self.slope_bias, self.constant_bias, self.shader_bias = (
            float(slope_bias),
            float(constant_bias),
            float(shader_bias),
        )
        self.max_width, self.max_height = int(max_width), int(max_height)
        self.crease_deg = float(crease_deg)
        self.samples = 0
        #: what renders (the GL renderer string): part of the compose path's key (no GPU layers: numpy compose)
        self.backend = str((ctx.info or {}).get("GL_RENDERER", "?"))
        self.prog_depth = program(ctx, "common.vert", "volume.frag")
        self.prog_occ = program(ctx, "shadowmap_occluder.vert", "shadowmap.frag")
        self.prog_ground = program(ctx, "shadowmap_ground.vert", "shadowmap.frag")
        self._ground = GroundBuffer(ctx, self.prog_ground)
        # moderngl rebinds "the last framebuffer used" after creating one, and that may be a framebuffer
        # another renderer has since deleted (GL_INVALID_OPERATION): bind the default one first, and leave
        # it bound after every render and at release
        self._default_fbo = ctx.screen if ctx.screen is not None else ctx.detect_framebuffer(0)
        self._default_fbo.use()
        self.depth_tex = ctx.depth_texture((self.map_size, self.map_size))
        self.depth_tex.compare_func = "<="
        self.depth_tex.repeat_x = self.depth_tex.repeat_y = False
        self.depth_tex.filter = (ctx.LINEAR, ctx.LINEAR)
        self.depth_fbo = ctx.framebuffer(depth_attachment=self.depth_tex)
        self._fbo: moderngl.Framebuffer | None = None
        self._rbs: list[moderngl.Renderbuffer] = []  # the attachments of _fbo
        self._size = (0, 0)
        self._caster: tuple[weakref.ref[ShadowCaster] | None, tuple[float, ...] | None, CasterBuffers | None] = (
            None,
            None,
            None,
        )  # (weakref, key, CasterBuffers)
        self._released = False

    def __enter__(self) -> ShadowMapRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    @current
    def release(self) -> None:
        """Free the GL objects this renderer made (programs stay cached on the context)."""
        if self._released:
            return
        self._default_fbo.use()
        self._ground.release()
        objs: list[moderngl.Framebuffer | moderngl.Texture | moderngl.Renderbuffer] = [self.depth_fbo, self.depth_tex]
        if self._fbo is not None:
            objs += [self._fbo, *self._rbs]
        for o in objs:
            o.release()
        if self._caster[2] is not None:
            self._caster[2].release()
        self._caster = (None, None, None)
        self._released = True

    def _buffers(self, caster: ShadowCaster, occluder_color: npt.ArrayLike | None) -> CasterBuffers:
        ckey = None if occluder_color is None else tuple(float(c) for c in np.ravel(occluder_color)[:3])
        ref, key, bufs = self._caster
        if ref is not None and bufs is not None and ref() is caster and key == ckey:  # bufs: set with ref
            return bufs
        if bufs is not None:
            bufs.release()
        # world coordinates (local=False): the shadow map's matrices and shading work in the world frame
        bufs = CasterBuffers(
            self.ctx, self.prog_occ, self.prog_occ, self.prog_depth, caster, ckey, self.crease_deg, local=False
        )
        self._caster = (weakref.ref(caster), ckey, bufs)
        return bufs

    def _targets(self, width: int, height: int) -> moderngl.Framebuffer:
        fbo = self._fbo
        if fbo is None or self._size[0] < width or self._size[1] < height:
            if fbo is not None:
                fbo.release()
                for rb in self._rbs:
                    rb.release()
            w, h = max(width, self._size[0]), max(height, self._size[1])
            ctx = self.ctx
            self._default_fbo.use()
            self._rbs = [
                ctx.renderbuffer((w, h), 4, dtype="f4"),
                ctx.renderbuffer((w, h), 2, dtype="f4"),
                ctx.depth_renderbuffer((w, h)),
            ]
            fbo = self._fbo = ctx.framebuffer(color_attachments=self._rbs[:2], depth_attachment=self._rbs[2])
            self._size = (w, h)
        return fbo

    @current
    def render(self, request: RenderRequest) -> RenderResult:
        """Render one frame (or canvas) of a :class:`arshadow.renderer.request.RenderRequest`, as
        :meth:`arshadow.gl.stencil.ShadowRenderer.render` (the passes' volumes and modes are ignored).

        Returns
        -------
        RenderResult
            ``mask`` is the PCF-filtered blocked weight at ground pixels not covered by the occluder;
            ``timings_ms`` has ``upload``, ``draw`` (depth maps + camera passes), ``readback``, ``total``.
        """
        t0 = time.perf_counter()
        if self._released:
            raise UsageError("this ShadowMapRenderer has been released")
        width, height = int(request.width), int(request.height)
        if not (0 < width <= self.max_width and 0 < height <= self.max_height):
            raise UsageError(f"canvas {width}x{height} outside 1..{self.max_width} x 1..{self.max_height}")
        proj = check_finite(check_shape(request.projection, "4,4", "projection"), "projection")
        view = check_finite(check_shape(request.view, "4,4", "view"), "view")
        passes, caster, draw_occluder = list(request.passes), request.caster, bool(request.draw_occluder)
        ctx = self.ctx
        mvp = proj @ view
        eye = -view[:3, :3].T @ view[:3, 3]
        bufs = self._buffers(caster, request.shading.color)
        self._ground.set(request.ground_size)
        set_uniforms((self.prog_occ,), request.shading.uniforms())
        fbo = self._targets(width, height)
        bounds = np.asarray(caster.bounds, np.float64)
        t1 = time.perf_counter()
        self._base_pass(fbo, mvp, (width, height), bufs, draw_occluder)
        # -- per light: depth map, then the ground and the occluder again with the map
        for p in passes:
            self._light_pass(fbo, (width, height), bufs, p, (bounds, eye), draw_occluder)
        ctx.enable_only(ctx.NOTHING)
        ctx.depth_func = "<"
        ctx.front_face = "ccw"
        ctx.finish()
        t2 = time.perf_counter()
        c0 = np.frombuffer(
            fbo.read(viewport=(0, 0, width, height), components=4, attachment=0, dtype="f4"), np.float32
        ).reshape(height, width, 4)[::-1]
        c1 = np.frombuffer(
            fbo.read(viewport=(0, 0, width, height), components=2, attachment=1, dtype="f4"), np.float32
        ).reshape(height, width, 2)[::-1]
        self._default_fbo.use()
        mask = np.clip(c1[..., 0], 0.0, 1.0)
        gcov = np.ascontiguousarray(c1[..., 1])
        t3 = time.perf_counter()
        return RenderResult(
            mask=mask,
            color=np.ascontiguousarray(c0[..., :3]),
            alpha=np.ascontiguousarray(c0[..., 3]),
            ground=gcov > 0.5,
            ground_coverage=gcov,
            timings_ms={
                "upload": (t1 - t0) * 1e3,
                "draw": (t2 - t1) * 1e3,
                "readback": (t3 - t2) * 1e3,
                "total": (t3 - t0) * 1e3,
            },
        )

    def _base_pass(
        self,
        fbo: moderngl.Framebuffer,
        mvp: np.ndarray,
        size: tuple[int, int],
        bufs: CasterBuffers,
        draw_occluder: bool,
    ) -> None:
        """Clear; the occluder (ambient, coverage) and the ground (coverage) of the ``size = (width,
        height)`` canvas (the shading's uniforms: written by ``render``)."""
        ctx, (width, height) = self.ctx, size
        fbo.use()
        fbo.viewport = (0, 0, width, height)
        ctx.scissor = (0, 0, width, height)
        ctx.front_face = "cw" if np.linalg.det(mvp) > 0 else "ccw"
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0, viewport=(0, 0, width, height))
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        for prog in (self.prog_occ, self.prog_ground):
            uniform(prog, "u_mvp").write(_f32(mvp))
            uniform(prog, "u_light_vp").write(_f32(np.eye(4)))
            uniform(prog, "u_pass").value = 0
        uniform(self.prog_occ, "u_is_ground").value = 0
        uniform(self.prog_ground, "u_is_ground").value = 1
        ctx.cull_face = "back"
        if draw_occluder:
            ctx.enable_only(ctx.DEPTH_TEST | self._cull(bufs))
            bufs.vao.render(ctx.TRIANGLES, vertices=bufs.n_indices)
            ctx.enable_only(ctx.DEPTH_TEST)
        self._ground.render(ctx)

    def _cull(self, bufs: CasterBuffers) -> int:
        """Closed meshes: back faces are never visible (the CULL_FACE flag, or 0)."""
        return self.ctx.CULL_FACE if bufs.cull else 0

    def _light_pass(
        self,
        fbo: moderngl.Framebuffer,
        size: tuple[int, int],
        bufs: CasterBuffers,
        p: LightPass,
        bounds_eye: tuple[np.ndarray, np.ndarray],
        draw_occluder: bool,
    ) -> None:
        """One light: the caster's depth from the light into the map, then the ground (its blocked weight)
        and the occluder (its lit Phong term) again, compared against the map. ``size``: ``(width,
        height)``; ``bounds_eye``: the caster's bounds and the camera centre."""
        ctx, gl, (width, height), (bounds, eye) = self.ctx, self.gl, size, bounds_eye
        w = float(p.weight)
        if not (math.isfinite(w) and w >= 0):
            raise UsageError(f"light weight must be finite and >= 0, got {p.weight}")
        lh = np.asarray(p.light_h, np.float64)
        if lh[3] != 0:
            lh = lh / lh[3]
        lvp = light_view_projection(lh, bounds)
        self.depth_fbo.use()
        self.depth_fbo.clear(depth=1.0)
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        gl.glEnable(G.GL_POLYGON_OFFSET_FILL)
        gl.glPolygonOffset(self.slope_bias, self.constant_bias)
        uniform(self.prog_depth, "u_mvp").write(_f32(lvp))
        bufs.planar_vao.render(ctx.TRIANGLES, vertices=bufs.n_indices)
        gl.glDisable(G.GL_POLYGON_OFFSET_FILL)

        fbo.use()
        fbo.viewport = (0, 0, width, height)
        ctx.enable_only(ctx.DEPTH_TEST | ctx.BLEND)
        ctx.blend_func = ctx.ONE, ctx.ONE
        ctx.depth_func = "<="
        gl.glDepthMask(G.GL_FALSE)
        self.depth_tex.use(location=0)
        for prog in (self.prog_ground, self.prog_occ):
            uniform(prog, "u_light_vp").write(_f32(lvp))
            uniform(prog, "u_pass").value = 1
            uniform(prog, "u_map").value = 0
            uniform(prog, "u_pcf").value = self.pcf
            uniform(prog, "u_texel").value = 1.0 / self.map_size
            uniform(prog, "u_bias").value = self.shader_bias
        uniform(self.prog_ground, "u_weight").value = w
        self._ground.render(ctx)
        if draw_occluder:
            ctx.enable_only(ctx.DEPTH_TEST | ctx.BLEND | self._cull(bufs))
            po = self.prog_occ
            uniform(po, "u_light").value = tuple(float(x) for x in lh)
            uniform(po, "u_light_color").value = tuple(float(x) * w for x in np.asarray(p.color, np.float64)[:3])
            uniform(po, "u_eye").value = tuple(float(x) for x in eye)  # the shading's uniforms: written by render
            bufs.vao.render(ctx.TRIANGLES, vertices=bufs.n_indices)
        gl.glDepthMask(G.GL_TRUE)
