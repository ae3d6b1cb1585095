"""GPU side of sky occlusion: the ground occlusion map as a texture, drawn over the visible ground.

:class:`GroundSkyPass` holds one :class:`arshadow.shading.sky.GroundOcclusion` (computed once per scene in
the ground frame) as an ``R32F`` texture and the map's square on z = 0. Each frame it is drawn with the
frame's matrix into the mask target's ``b`` channel as ``1 - V`` (the share of the sky the object hides),
where the stencil says the sample sees the ground and not the occluder: the ground occlusion map projected
per frame, coverage-weighted like the shadow mask. Nothing here creates a context or imports moderngl.
"""

from __future__ import annotations

import numpy as np

from . import glraw as G
from .resources import program

__all__ = ["GroundSkyPass"]


class GroundSkyPass:
    """The ground occlusion map of one scene on the GPU (made by the renderer on first use).

    Parameters
    ----------
    ctx : moderngl.Context
    occlusion : arshadow.shading.sky.GroundOcclusion
    """

    def __init__(self, ctx, occlusion):
        self.occlusion = occlusion
        self.prog = program(ctx, "sky_ground.vert", "sky_ground.frag")
        vis = np.ascontiguousarray(occlusion.visibility, dtype=np.float32)
        h, w = vis.shape
        self.tex = ctx.texture((w, h), 1, vis.tobytes(), dtype="f4")
        self.tex.repeat_x = self.tex.repeat_y = False  # clamp to edge: the border's value at the edge
        self.tex.filter = (ctx.LINEAR, ctx.LINEAR)
        x0, y0, x1, y1 = occlusion.extent
        self.corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)
        self.vbo = ctx.buffer(reserve=6 * 6 * 4, dynamic=True)
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "4f 2f", "in_pos", "in_st")])
        self._origin = None

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

    def draw(self, ctx, gl, mvp_bytes: bytes, origin: np.ndarray, ground_bit: int, occluder_bit: int) -> None:
        """Add ``1 - V`` into the mask target's ``b`` where the stencil has the ground bit and not the
        occluder bit (depth test off: the stencil already says the ground is the visible surface)."""
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
        self.prog["u_mvp"].write(mvp_bytes)
        self.tex.use(location=0)
        self.prog["u_vis"].value = 0
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

    def __init__(self, ctx, res: int):
        self.ctx, self.res = ctx, int(res)
        self.prog = program(ctx, "item.vert", "item.frag")
        self.tex = ctx.texture((self.res, self.res), 1, dtype="i4")
        self.depth = ctx.depth_renderbuffer((self.res, self.res))
        # moderngl rebinds "its" current framebuffer after making one: that may be a renderer target
        # released since (raw GL), which fails with GL_INVALID_OPERATION; bind the default one first
        ctx.detect_framebuffer(0).use()
        self.fbo = ctx.framebuffer(color_attachments=[self.tex], depth_attachment=self.depth)
        self._cap = 0
        self.vbo = self.ibo = self.vao = None

    def _buffers(self, n: int, m: int) -> None:
        if self.vbo is None or n * 12 > self.vbo.size or m * 12 > self.ibo.size:
            for o in (self.vao, self.vbo, self.ibo):
                if o is not None:
                    o.release()
            self.vbo = self.ctx.buffer(reserve=max(n * 12, 64) * 2, dynamic=True)
            self.ibo = self.ctx.buffer(reserve=max(m * 12, 64) * 2, dynamic=True)
            self.vao = self.ctx.vertex_array(self.prog, [(self.vbo, "3f", "in_pos")], index_buffer=self.ibo)

    def __call__(self, xy: np.ndarray, depth: np.ndarray, f: np.ndarray, res: int) -> np.ndarray:
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
        self._buffers(len(pos), len(f))
        self.vbo.write(pos.tobytes())
        self.ibo.write(np.ascontiguousarray(f, np.int32).tobytes())
        self.fbo.use()
        self.fbo.viewport = (0, 0, self.res, self.res)
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable_only(ctx.DEPTH_TEST)
        ctx.depth_func = "<"
        self.vao.render(ctx.TRIANGLES, vertices=3 * len(f))
        ids = np.frombuffer(self.tex.read(), np.int32).reshape(self.res, self.res)
        ctx.enable_only(ctx.NOTHING)
        return ids - 1

    def release(self) -> None:
        for o in (self.vao, self.vbo, self.ibo, self.fbo, self.depth, self.tex):
            if o is not None:
                o.release()
