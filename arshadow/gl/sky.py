"""GPU side of sky occlusion: the ground occlusion map as a texture, drawn over the visible ground.

:class:`GroundSkyPass` holds one :class:`arshadow.shading.sky.GroundOcclusion` (computed once per scene in
the ground frame) as an ``R32F`` texture and the map's square on z = 0. Each frame it is drawn with the
frame's matrix into the mask target's ``b`` channel as ``1 - V`` (the share of the sky the object hides),
where the stencil says the sample sees the ground and not the occluder: the ground occlusion map projected
per frame, coverage-weighted like the shadow mask. Nothing here creates a context or imports moderngl.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from . import glraw as G
from .resources import program, uniform

if TYPE_CHECKING:
    import moderngl

    from ..geometry.caster import ShadowCaster
    from ..shading.sky import GroundGrid, GroundOcclusion
    from .glraw import GL

__all__ = ["GLGroundRaster", "GLItemBuffer", "GroundSkyPass"]

#: GL_CLIP_DISTANCE0: the ground raster clips faces at z = 0
_CLIP_DISTANCE0 = 0x3000
#: width of the faces' value texture (GLGroundRaster: one texel per face, gl_PrimitiveID)
_VALUES_W = 4096
#: sky directions drawn side by side per batch (ground_accum.frag's TILES)
_TILES = 16


class GroundSkyPass:
    """The ground occlusion map of one scene on the GPU (made by the renderer on first use).

    Parameters
    ----------
    ctx : moderngl.Context
    occlusion : arshadow.shading.sky.GroundOcclusion
    """

    def __init__(self, ctx: moderngl.Context, occlusion: GroundOcclusion) -> None:
        self.occlusion = occlusion
        self.prog = program(ctx, "sky_ground.vert", "sky_ground.frag")
        vis = np.asarray(occlusion.visibility, dtype=np.float32)
        h, w = vis.shape
        refl = occlusion.bounce if occlusion.bounce is not None else np.zeros_like(vis)
        data = np.ascontiguousarray(np.dstack([vis, np.asarray(refl, np.float32)]))
        self.tex = ctx.texture((w, h), 2, data.tobytes(), dtype="f4")
        self.tex.repeat_x = self.tex.repeat_y = False  # clamp to edge: the border's value at the edge
        self.tex.filter = (ctx.LINEAR, ctx.LINEAR)
        x0, y0, x1, y1 = occlusion.extent
        self.corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)
        self.vbo = ctx.buffer(reserve=6 * 6 * 4, dynamic=True)
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "4f 2f", "in_pos", "in_st")])
        self._origin: np.ndarray | None = None

    def _upload(self, origin: np.ndarray) -> None:
        """The square's vertices relative to the caster's local origin (float32 near the object)."""
        if self._origin is not None and np.array_equal(self._origin, origin):
            return
        st = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)
        data = np.zeros((6, 6), np.float32)
        for k, i in enumerate((0, 1, 2, 0, 2, 3)):
            data[k, :2] = self.corners[i] - origin[:2]
            data[k, 2] = -origin[2]
            data[k, 3] = 1.0
            data[k, 4:] = st[i]
        self.vbo.write(data.tobytes())
        self._origin = np.array(origin, np.float64)

    def draw(  # noqa: PLR0913 (the context, its raw GL, the frame's matrix and origin, two stencil bits)
        self, ctx: moderngl.Context, gl: GL, mvp_bytes: bytes, origin: np.ndarray, ground_bit: int, occluder_bit: int
    ) -> None:
        """Add ``1 - V`` into the mask target's ``b`` (and the object's reflected light, the map's ``bounce``,
        into its ``a``) where the stencil has the ground bit and not the occluder bit (depth test off: the
        stencil already says the ground is the visible surface)."""
        self._upload(np.asarray(origin, np.float64))
        ctx.enable_only(ctx.BLEND)
        ctx.blend_func = ctx.ONE, ctx.ONE
        gl.glDepthMask(G.GL_FALSE)
        gl.glColorMask(1, 1, 1, 1)
        gl.glEnable(G.GL_STENCIL_TEST)
        gl.glStencilMask(0)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
        gl.glStencilFunc(G.GL_EQUAL, ground_bit, ground_bit | occluder_bit)
        gl.draw_buffer_list([None, 1])
        uniform(self.prog, "u_mvp").write(mvp_bytes)
        self.tex.use(location=0)
        uniform(self.prog, "u_vis").value = 0
        self.vao.render(ctx.TRIANGLES, vertices=6)
        gl.draw_buffers(2)
        gl.glDepthMask(G.GL_TRUE)

    def release(self) -> None:
        for o in (self.vao, self.vbo, self.tex):
            o.release()


class GLItemBuffer:
    """:func:`arshadow.shading.raster.item_buffer` drawn by the GPU: the triangles' indices z-buffered into
    an ``R32I`` texture (``gl_PrimitiveID + 1``; 0 = none) and read back. Same pixel convention (pixel
    ``(i, j)`` centre at ``(j + 0.5, i + 0.5)``, row 0 = the array's first row), same nearest-to-the-source
    rule (largest depth wins).

    Parameters
    ----------
    ctx : moderngl.Context
    res : int
        Side of the square buffer in pixels.
    """

    def __init__(self, ctx: moderngl.Context, res: int) -> None:
        self.ctx, self.res = ctx, int(res)
        self.prog = program(ctx, "item.vert", "item.frag")
        self.tex = ctx.texture((self.res, self.res), 1, dtype="i4")
        self.depth = ctx.depth_renderbuffer((self.res, self.res))
        # moderngl rebinds "its" current framebuffer after making one: that may be a renderer target
        # released since (raw GL), which fails with GL_INVALID_OPERATION; bind the default one first
        ctx.detect_framebuffer(0).use()
        self.fbo = ctx.framebuffer(color_attachments=[self.tex], depth_attachment=self.depth)
        self._cap = 0
        self.vbo: moderngl.Buffer | None = None
        self.ibo: moderngl.Buffer | None = None
        self.vao: moderngl.VertexArray | None = None

    def _buffers(self, n: int, m: int) -> tuple[moderngl.Buffer, moderngl.Buffer, moderngl.VertexArray]:
        """The vertex, index and vertex-array objects, grown to ``n`` vertices and ``m`` triangles."""
        vbo, ibo, vao = self.vbo, self.ibo, self.vao
        if vbo is None or ibo is None or vao is None or n * 12 > vbo.size or m * 12 > ibo.size:
            for o in (vao, vbo, ibo):
                if o is not None:
                    o.release()
            vbo = self.vbo = self.ctx.buffer(reserve=max(n * 12, 64) * 2, dynamic=True)
            ibo = self.ibo = self.ctx.buffer(reserve=max(m * 12, 64) * 2, dynamic=True)
            vao = self.vao = self.ctx.vertex_array(self.prog, [(vbo, "3f", "in_pos")], index_buffer=ibo)
        return vbo, ibo, vao

    def __call__(self, xy: np.ndarray, depth: np.ndarray, f: np.ndarray, res: int) -> np.ndarray:
        """``(res, res) int32``: :func:`arshadow.shading.raster.item_buffer`'s result, drawn here."""
        if int(res) != self.res:
            raise ValueError(f"GLItemBuffer made for {self.res} px, asked for {res}")
        ctx = self.ctx
        out = np.full((self.res, self.res), -1, np.int32)
        if len(f) == 0:
            return out
        d0, d1 = float(depth.min()), float(depth.max())
        half = max(0.5 * (d1 - d0), 1e-30)
        pos = np.empty((len(xy), 3), np.float32)
        pos[:, :2] = np.asarray(xy, np.float64) / self.res * 2.0 - 1.0
        pos[:, 2] = -(np.asarray(depth, np.float64) - 0.5 * (d0 + d1)) / half * 0.99  # nearer the source: smaller z
        vbo, ibo, vao = self._buffers(len(pos), len(f))
        vbo.write(pos.tobytes())
        ibo.write(np.ascontiguousarray(f, np.int32).tobytes())
        self.fbo.use()
        self.fbo.viewport = (0, 0, self.res, self.res)
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        vao.render(ctx.TRIANGLES, vertices=3 * len(f))
        ids = np.frombuffer(self.tex.read(), np.int32).reshape(self.res, self.res)
        ctx.enable_only(ctx.NOTHING)
        return ids - 1

    def release(self) -> None:
        for o in (self.vao, self.vbo, self.ibo, self.fbo, self.depth, self.tex):
            if o is not None:
                o.release()


class GLGroundRaster:
    """:class:`arshadow.shading.sky.GroundRaster` drawn by the GPU: per sky direction the faces projected
    along it onto the texel grid (exact coverage at texel centres, GL's fill rule: no outward bias, so no
    sub-texels), the nearest face's value kept by the depth test, added with the direction's weight into two
    float sums; one read-back per map. Same sums as :func:`arshadow.shading.sky.ground_raster_cpu` (which
    fills 3 x 3 sub-texels: its shadows reach up to a third of a texel further out).

    Parameters
    ----------
    ctx : moderngl.Context
    """

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self._res = 0
        self._objs: list[
            Any
        ] = []  # moderngl objects, made on first use (a renderer that never draws sky occlusion makes none)
        self.acc_vao: moderngl.VertexArray | None = None

    def _targets(self, res: int) -> moderngl.VertexArray:
        """The programs (first use) and the ``res x res`` scratch and sums targets (remade for a new size);
        returns the sums pass's vertex array."""
        ctx = self.ctx
        if self.acc_vao is None:
            self.prog = program(ctx, "ground_raster.vert", "ground_raster.frag")
            self.acc_prog = program(ctx, "fullscreen.vert", "ground_accum.frag")
            self.acc_vao = ctx.vertex_array(self.acc_prog, [])
        if res == self._res:
            return self.acc_vao
        for o in self._objs:
            o.release()
        ctx.detect_framebuffer(0).use()  # see GLItemBuffer: moderngl rebinds "its" current framebuffer
        self.scratch = ctx.texture((_TILES * res, res), 2, dtype="f4")
        self.scratch.filter = (ctx.NEAREST, ctx.NEAREST)
        self.depth = ctx.depth_renderbuffer((_TILES * res, res))
        self.scratch_fbo = ctx.framebuffer(color_attachments=[self.scratch], depth_attachment=self.depth)
        self.sums = ctx.texture((res, res), 2, dtype="f4")
        self.sums_fbo = ctx.framebuffer(color_attachments=[self.sums])
        self._objs = [self.scratch_fbo, self.sums_fbo, self.depth, self.scratch, self.sums]
        self._res = res
        return self.acc_vao

    def __call__(
        self,
        caster: ShadowCaster,
        dirs: np.ndarray,
        weights: np.ndarray,
        grid: GroundGrid,
        face_values: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """``(open, bounce)`` ``(res, res) float64`` sums (:class:`arshadow.shading.sky.GroundRaster`)."""
        ctx, res = self.ctx, int(grid.res)
        ctx.__enter__()
        acc_vao = self._targets(res)
        size = grid.texel * res
        cx, cy = grid.x0 + 0.5 * size, grid.y0 + 0.5 * size
        m = len(caster.faces)
        vals = np.zeros(_VALUES_W * -(-m // _VALUES_W), np.float32)
        if face_values is not None:
            vals[:m] = np.asarray(face_values, np.float64)
        values = ctx.texture((_VALUES_W, len(vals) // _VALUES_W), 1, vals.tobytes(), dtype="f4")
        values.filter = (ctx.NEAREST, ctx.NEAREST)
        vbo = ctx.buffer(np.ascontiguousarray(caster.vertices - [cx, cy, 0.0], np.float32).tobytes())
        ibo = ctx.buffer(np.ascontiguousarray(caster.faces, np.int32).tobytes())
        vao = ctx.vertex_array(self.prog, [(vbo, "3f", "in_pos")], index_buffer=ibo)
        zmax = max(float(caster.vertices[:, 2].max()), 1e-9)
        below = float(caster.vertices[:, 2].min()) < 0.0
        uniform(self.prog, "u_grid").value = (-0.5 * size, -0.5 * size, size)
        uniform(self.prog, "u_values").value = 1
        values.use(location=1)
        self.scratch.use(location=0)
        uniform(self.acc_prog, "u_scratch").value = 0
        self.sums_fbo.use()
        self.sums_fbo.clear(0.0, 0.0, 0.0, 0.0)
        # the faces turned towards the ground project clockwise seen from above: a closed mesh above the
        # ground culls the others (the first face a ground point meets along d is one of them); an open mesh,
        # or a closed one reaching below the ground, draws every face (ground points inside the solid meet
        # a face turned away first; the depth test still finds the entry face for the points outside it)
        draw = ctx.DEPTH_TEST | (ctx.CULL_FACE if caster.is_closed and not below else 0)
        ctx.front_face = "cw"
        if below:
            ctx.enable_direct(_CLIP_DISTANCE0)
        uniform(self.acc_prog, "u_res").value = res
        dirs, weights = np.asarray(dirs, np.float64), np.asarray(weights, np.float64)
        try:
            for s0 in range(0, len(dirs), _TILES):  # a batch of directions side by side, then one sum pass
                self.scratch_fbo.use()
                self.scratch_fbo.viewport = (0, 0, _TILES * res, res)
                self.scratch_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
                ctx.enable_only(draw)
                ctx.depth_func = "<"
                for k, d in enumerate(dirs[s0 : s0 + _TILES]):
                    self.scratch_fbo.viewport = (k * res, 0, res, res)
                    uniform(self.prog, "u_dir").value = tuple(float(x) for x in d)
                    uniform(self.prog, "u_tmax").value = 1.001 * zmax / float(d[2])
                    vao.render(ctx.TRIANGLES)
                w = np.zeros(_TILES)
                w[: len(weights[s0 : s0 + _TILES])] = weights[s0 : s0 + _TILES]
                self.sums_fbo.use()
                ctx.enable_only(ctx.BLEND)
                ctx.blend_func = ctx.ONE, ctx.ONE
                uniform(self.acc_prog, "u_weight").value = tuple(float(x) for x in w)
                acc_vao.render(ctx.TRIANGLES, vertices=3)
            sums = np.frombuffer(self.sums.read(), np.float32).reshape(res, res, 2).astype(np.float64)
        finally:
            if below:
                ctx.disable_direct(_CLIP_DISTANCE0)
            ctx.front_face = "ccw"
            ctx.enable_only(ctx.NOTHING)
            for o in (vao, vbo, ibo, values):
                o.release()
        return sums[..., 0], (sums[..., 1] if face_values is not None else None)

    def release(self) -> None:
        for o in (*self._objs, self.acc_vao):
            if o is not None:
                o.release()
        self._objs, self._res, self.acc_vao = [], 0, None
