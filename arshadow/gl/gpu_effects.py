"""Camera effects in the shader compose path: the photo's blur of the warped layers and its sensor noise.

:class:`arshadow.gl.gpu_compose.GpuCompositor` applies the frame's ``Look.camera``
(:class:`arshadow.frame.effects.CameraEffects`) as the numpy path applies it around
:func:`arshadow.compose.composite.composite` (:mod:`arshadow.frame.numpy_compose`):

- **blur**: ``compose.frag`` first writes the warped layers over the region (the ROI grown by the blur's
  reach, zeros outside the ROI) into two ``RGBA32F`` textures (colour + coverage, mask + sky occlusion);
  :class:`LayerBlur` convolves them with the Gaussian ``cv2.GaussianBlur`` applies to ``float32`` layers
  (``CameraEffects.blur_kernel``; ``blur.frag``: along rows, then along columns, zero beyond the region as
  ``BORDER_CONSTANT``), and
  ``compose.frag`` composites the blurred layers. The same float32 operations as OpenCV's separable filter
  up to the order of the sums: the composite agrees with the numpy path's within one 8-bit level;
- **noise**: ``compose.frag`` adds ``N(0, 1) * sigma(level) * coverage`` to each composited code, ``sigma``
  looked up per channel in the measured table (:attr:`arshadow.frame.effects.CameraEffects.noise_table`,
  a ``RGB32F`` texture), rounded half to even and clipped, as :func:`arshadow.frame.effects.add_noise` does.
  The normal numbers come from a hash of the photo pixel, the channel and the photo's seed
  (``CameraEffects.noise_seed``; Box-Muller),
  not from numpy's generator: the two paths' noise is alike in distribution, not in value.

Nothing here imports moderngl (the objects come from the context handed in).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..errors import ShapeError
from .resources import program, uniform

if TYPE_CHECKING:  # annotations only (see above)
    import moderngl

__all__ = ["LayerBlur", "NoiseTexture"]


class LayerBlur:
    """The region-sized float textures of the blur (grown, never shrunk) and its two passes.

    Parameters
    ----------
    ctx : moderngl.Context
    """

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.prog = program(ctx, "fullscreen.vert", "blur.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        self._size = (0, 0)
        self._tex: list[moderngl.Texture] = []  # warped colour, mask; pass-1 colour, mask
        self._fbos: list[moderngl.Framebuffer] = []  # (warped pair), (pass-1 pair)
        self._kernel: moderngl.Texture | None = None
        self._kernel_data = b""

    def target(self, width: int, height: int) -> moderngl.Framebuffer:
        """The framebuffer the warped layers are written into (two ``RGBA32F`` attachments holding a
        ``width`` x ``height`` region from texel (0, 0)); the blur's result comes back there too."""
        if width > self._size[0] or height > self._size[1]:
            self._free_textures()
            w, h = max(width, self._size[0]), max(height, self._size[1])
            for _ in range(4):
                t = self.ctx.texture((w, h), 4, dtype="f4")
                t.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
                self._tex.append(t)
            self.ctx.detect_framebuffer(0).use()  # as GpuCompositor: moderngl rebinds its current framebuffer
            self._fbos = [self.ctx.framebuffer(color_attachments=self._tex[i : i + 2]) for i in (0, 2)]
            self._size = (w, h)
        return self._fbos[0]

    def run(self, kernel: np.ndarray, width: int, height: int) -> tuple[moderngl.Texture, moderngl.Texture]:
        """Blur the ``width`` x ``height`` region of :meth:`target`'s textures by ``kernel`` (odd length,
        symmetric): along rows into the second pair, along columns back; returns ``(colour, mask)``."""
        k = np.ascontiguousarray(kernel, np.float32).ravel()
        if k.size % 2 != 1:
            raise ShapeError("the blur kernel must have an odd length", actual_shape=k.shape)
        self._upload_kernel(k)
        assert self._kernel is not None  # made by _upload_kernel
        prog = self.prog
        uniform(prog, "u_src0").value = 0
        uniform(prog, "u_src1").value = 1
        uniform(prog, "u_kernel").value = 2
        uniform(prog, "u_radius").value = k.size // 2
        uniform(prog, "u_size").value = (int(width), int(height))
        self._kernel.use(2)
        self.ctx.enable_only(self.ctx.NOTHING)
        for src, dst, direction in ((0, 1, (1, 0)), (2, 0, (0, 1))):
            uniform(prog, "u_dir").value = direction
            self._tex[src].use(0)
            self._tex[src + 1].use(1)
            fbo = self._fbos[dst]
            fbo.use()
            fbo.viewport = (0, 0, int(width), int(height))
            self.vao.render(self.ctx.TRIANGLES, vertices=3)
        return self._tex[0], self._tex[1]

    def _upload_kernel(self, k: np.ndarray) -> None:
        data = k.tobytes()
        if data == self._kernel_data and self._kernel is not None:
            return
        if self._kernel is not None:
            self._kernel.release()
        self._kernel = self.ctx.texture((k.size, 1), 1, data=data, dtype="f4")
        self._kernel.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        self._kernel_data = data

    def _free_textures(self) -> None:
        for f in self._fbos:
            f.release()
        for t in self._tex:
            t.release()
        self._fbos, self._tex = [], []
        self._size = (0, 0)

    def release(self) -> None:
        self._free_textures()
        if self._kernel is not None:
            self._kernel.release()
            self._kernel = None
        self.vao.release()


class NoiseTexture:
    """The noise table of the frame's camera effects as a ``RGB32F`` 256 x 1 texture (uploaded when the table
    changes: once per scene)."""

    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.tex: moderngl.Texture | None = None
        self._table: np.ndarray | None = None

    def use(self, table: np.ndarray, location: int) -> None:
        """Bind ``table`` ``(1, 256, 3) float32`` (sigma per code, B, G, R) to texture unit ``location``."""
        if table is not self._table or self.tex is None:
            t = np.ascontiguousarray(table, np.float32)
            if t.shape != (1, 256, 3):
                raise ShapeError(
                    "the noise table must be (1, 256, 3)", actual_shape=t.shape, expected_shape=(1, 256, 3)
                )
            if self.tex is not None:
                self.tex.release()
            self.tex = self.ctx.texture((256, 1), 3, data=t.tobytes(), dtype="f4", alignment=4)
            self.tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
            self._table = table
        self.tex.use(location)

    def release(self) -> None:
        if self.tex is not None:
            self.tex.release()
            self.tex = None
