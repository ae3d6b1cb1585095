"""GPU side of sky occlusion: the ground occlusion map as a texture, read over the visible ground.

:class:`GroundSkyMap` holds one :class:`arshadow.shading.sky.GroundOcclusion` (computed once per scene in
the ground frame) as an ``RG32F`` texture. Each frame the ground pass (``ground.frag``, which finds every
visible ground sample's point on z = 0) reads it into the mask target's ``b`` channel as ``1 - V`` (the
share of the sky the object hides) and its reflected-light part into ``a``: the map projected per frame,
coverage-weighted like the shadow mask. (Until 2026-11-28 a separate pass drew the map's square with
additive blending where the stencil said the ground was visible: the same values, one pass more, 0.6-1.0 ms
a frame on llvmpipe.) :class:`GLGroundRaster` and :class:`GLItemBuffer` make the maps' shadows and item
buffers on the GPU. Nothing here creates a context or imports moderngl.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .resources import program, uniform

if TYPE_CHECKING:
    import moderngl

    from ..geometry.caster import ShadowCaster
    from ..shading.sky import GroundGrid, GroundOcclusion

__all__ = ["GLGroundRaster", "GLItemBuffer", "GroundSkyMap"]

#: GL_CLIP_DISTANCE0: the ground raster clips faces at z = 0
_CLIP_DISTANCE0 = 0x3000
#: width of the faces' value texture (GLGroundRaster: one texel per face, gl_PrimitiveID)
_VALUES_W = 4096
#: sky directions drawn side by side per batch (ground_accum.frag's TILES)
_TILES = 16


class GroundSkyMap:
    """The ground occlusion map of one scene on the GPU (made by the renderer on first use): an ``RG32F``
    texture of the sky visibility and its reflected-light part, read by the ground pass
    (``ground.frag``) at each visible ground point.

    Parameters
    ----------
    ctx : moderngl.Context
    occlusion : arshadow.shading.sky.GroundOcclusion
    """

    def __init__(self, ctx: moderngl.Context, occlusion: GroundOcclusion) -> None:
        self.occlusion = occlusion
        vis = np.asarray(occlusion.visibility, dtype=np.float32)
        h, w = vis.shape
        refl = occlusion.bounce if occlusion.bounce is not None else np.zeros_like(vis)
        data = np.ascontiguousarray(np.dstack([vis, np.asarray(refl, np.float32)]))
        self.tex = ctx.texture((w, h), 2, data.tobytes(), dtype="f4")
        self.tex.repeat_x = self.tex.repeat_y = False  # clamp to edge: the border's value at the edge
        self.tex.filter = (ctx.LINEAR, ctx.LINEAR)

    def bind(self, prog: moderngl.Program, origin: np.ndarray, unit: int = 0) -> None:
        """Give the ground program ``prog`` the map on texture ``unit`` and its square relative to the local
        ``origin (3,)`` (the frame the ground's vertices are in), ``u_sky`` on."""
        x0, y0, x1, y1 = self.occlusion.extent
        o = np.asarray(origin, np.float64)
        uniform(prog, "u_sky").value = True
        uniform(prog, "u_vis_rect").value = (float(x0 - o[0]), float(y0 - o[1]), float(x1 - x0), float(y1 - y0))
        self.tex.use(location=unit)
        uniform(prog, "u_vis").value = unit

    def release(self) -> None:
        self.tex.release()


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
