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
