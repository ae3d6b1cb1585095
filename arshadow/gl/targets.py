"""Raw-GL render targets of the stencil renderer: :class:`RenderTarget` (colour renderbuffers and a
D24S8 depth-stencil buffer wrapped by moderngl) and :class:`FrameTargets` (the main multisampled target, the
supersampled / resolved canvases and the textures a frame reads back or keeps on the GPU, made once per size).

Nothing here creates a context or imports moderngl (the objects come from the context handed in).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from ..errors import GLContextError
from . import glraw as G
from .layers import TextureTarget

if TYPE_CHECKING:  # annotations only (see above)
    import moderngl

__all__ = ["FrameTargets", "RenderTarget"]


class RenderTarget:
    """A raw-GL framebuffer: colour renderbuffers (+ optional D24S8), wrapped by moderngl."""

    def __init__(
        self,
        ctx: moderngl.Context,
        gl: G.GL,
        width: int,
        height: int,
        samples: int,
        color_formats: Sequence[int],
        depth_stencil: bool,
    ) -> None:
        self.gl = gl
        self.width, self.height, self.samples = int(width), int(height), int(samples)
        self.fbo = gl.gen_framebuffer()
        self.rbs: list[int] = []
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, self.fbo)
        formats = list(color_formats) + ([G.GL_DEPTH24_STENCIL8] if depth_stencil else [])
        for i, fmt in enumerate(formats):
            rb = gl.gen_renderbuffer()
            gl.glBindRenderbuffer(G.GL_RENDERBUFFER, rb)
            if self.samples:
                gl.glRenderbufferStorageMultisample(G.GL_RENDERBUFFER, self.samples, fmt, self.width, self.height)
            else:
                gl.glRenderbufferStorage(G.GL_RENDERBUFFER, fmt, self.width, self.height)
            att = G.GL_DEPTH_STENCIL_ATTACHMENT if fmt == G.GL_DEPTH24_STENCIL8 else G.GL_COLOR_ATTACHMENT0 + i
            gl.glFramebufferRenderbuffer(G.GL_FRAMEBUFFER, att, G.GL_RENDERBUFFER, rb)
            self.rbs.append(rb)
        gl.glBindRenderbuffer(G.GL_RENDERBUFFER, 0)
        #: samples the driver actually allocated (llvmpipe rounds 2 up to 4)
        self.actual_samples = gl.renderbuffer_param(self.rbs[0], G.GL_RENDERBUFFER_SAMPLES) if self.samples else 0
        status = gl.glCheckFramebufferStatus(G.GL_FRAMEBUFFER)
        self.stencil_bits = (
            gl.attachment_param(G.GL_STENCIL_ATTACHMENT, G.GL_FRAMEBUFFER_ATTACHMENT_STENCIL_SIZE)
            if depth_stencil
            else 0
        )
        self.depth_bits = (
            gl.attachment_param(G.GL_DEPTH_ATTACHMENT, G.GL_FRAMEBUFFER_ATTACHMENT_DEPTH_SIZE) if depth_stencil else 0
        )
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, 0)
        if status != G.GL_FRAMEBUFFER_COMPLETE:
            self.release()
            raise GLContextError(
                f"offscreen framebuffer {self.width}x{self.height} (samples={self.samples}) is incomplete: "
                f"{G.framebuffer_status_name(status)}"
            )
        self.n_color = len(color_formats)
        self.mgl = ctx.detect_framebuffer(self.fbo)

    def release(self) -> None:
        gl = self.gl
        if self.fbo:
            gl.delete_framebuffer(self.fbo)
            self.fbo = 0
        for rb in self.rbs:
            gl.delete_renderbuffer(rb)
        self.rbs = []


def _made(target: RenderTarget | None) -> RenderTarget:
    """``target``, which :meth:`FrameTargets.ensure` has made (for the size asked)."""
    assert target is not None, "ensure() first"
    return target


class FrameTargets:
    """The framebuffers of a renderer: the main target (MSAA and/or supersampled, with depth/stencil), the
    single-sample targets it is resolved/downsampled into, and the texture target of GPU-resident
    results. All are grown (never shrunk) to the largest canvas asked for.

    Parameters
    ----------
    ctx : moderngl.Context
    gl : arshadow.gl.glraw.GL
        The raw GL functions (:func:`arshadow.gl.glraw.load`).
    samples : int
        MSAA samples of the main target (0 = none).
    supersample : int
        1, 2 or 4: the main target is this many times the canvas size.
    """

    #: colour 0: occluder colour + coverage; colour 1: shadow mask, ground coverage
    FORMATS: tuple[int, int] = (G.GL_RGBA16F, G.GL_RG16F)
    #: with sky occlusion (:meth:`ensure` ``sky=True``): colour 1 gains the sky occlusion (b)
    SKY_FORMATS: tuple[int, int] = (G.GL_RGBA16F, G.GL_RGBA16F)

    def __init__(self, ctx: moderngl.Context, gl: G.GL, samples: int, supersample: int) -> None:
        self.ctx, self.gl = ctx, gl
        self.samples, self.supersample = int(samples), int(supersample)
        #: render target (MSAA and/or supersampled)
        self.main: RenderTarget | None = None
        #: single-sample canvas-size target (when main is MSAA/supersampled)
        self.resolve: RenderTarget | None = None
        #: intermediate for supersample 4
        self.half: RenderTarget | None = None
        #: single-sample supersampled size (MSAA + supersampling)
        self.ss_resolve: RenderTarget | None = None
        #: GPU-resident result
        self.tex: TextureTarget | None = None

    def ensure(self, width: int, height: int, sky: bool = False) -> None:
        """Grow the targets to hold a ``width`` x ``height`` canvas; ``sky``: with the sky-occlusion channel
        (the targets are remade with it on the first frame that needs it, and keep it)."""
        if sky and self.FORMATS != self.SKY_FORMATS:
            self.release()
            self.FORMATS = self.SKY_FORMATS
        s = self.supersample
        need_w, need_h = width * s, height * s
        main = self.main
        if main is None or main.width < need_w or main.height < need_h:
            w = max(need_w, main.width if main else 0)
            h = max(need_h, main.height if main else 0)
            for t in (self.main, self.resolve, self.half):
                if t is not None:
                    t.release()
            self.main = self.resolve = self.half = None
            self.main = RenderTarget(self.ctx, self.gl, w, h, self.samples, self.FORMATS, True)
            if self.samples or s > 1:
                self.resolve = RenderTarget(self.ctx, self.gl, w // s, h // s, 0, self.FORMATS, False)
            if s == 4:
                self.half = RenderTarget(self.ctx, self.gl, w // 2, h // 2, 0, self.FORMATS, False)

    def resolve_canvas(self, width: int, height: int) -> RenderTarget:
        """MSAA resolve / supersampling downsample (glBlitFramebuffer) of the canvas into a single-sample
        canvas-size target; returns it (the main target itself when there is nothing to resolve)."""
        s = self.supersample
        rw, rh = width * s, height * s
        src = _made(self.main)
        if self.samples:
            dst = _made(self.resolve) if s == 1 else self._main_resolve_ss()
            self.blit(src, dst, rw, rh, rw, rh, G.GL_NEAREST)
            src = dst
        if s == 4:
            half = _made(self.half)
            self.blit(src, half, rw, rh, rw // 2, rh // 2, G.GL_LINEAR)
            src = half
            rw, rh = rw // 2, rh // 2
        if s > 1:
            resolve = _made(self.resolve)
            self.blit(src, resolve, rw, rh, width, height, G.GL_LINEAR)
            src = resolve
        return src

    def texture(self, width: int, height: int) -> TextureTarget:
        """Single-sample ``RGBA16F`` + ``RGBA16F`` textures (grown, never shrunk) for GPU-resident results."""
        t = self.tex
        if t is None or t.width < width or t.height < height:
            w, h = max(width, t.width if t else 0), max(height, t.height if t else 0)
            if t is not None:
                t.release()
            t = self.tex = TextureTarget(self.ctx, w, h, mask_components=4 if self.FORMATS == self.SKY_FORMATS else 2)
        return t

    def _main_resolve_ss(self) -> RenderTarget:
        """Single-sample target of the supersampled size (MSAA + supersampling)."""
        t, main = self.ss_resolve, self.main
        assert main is not None, "ensure() first"
        if t is None or t.width < main.width or t.height < main.height:
            if t is not None:
                t.release()
            t = RenderTarget(self.ctx, self.gl, main.width, main.height, 0, self.FORMATS, False)
            self.ss_resolve = t
        return t

    def blit(
        self,
        src: RenderTarget | TextureTarget,
        dst: RenderTarget | TextureTarget,
        sw: int,
        sh: int,
        dw: int,
        dh: int,
        filt: int,
    ) -> None:
        """Copy both colour attachments of ``src`` (``sw`` x ``sh``) into ``dst`` (``dw`` x ``dh``)."""
        gl = self.gl
        gl.glDisable(G.GL_SCISSOR_TEST)
        gl.glBindFramebuffer(G.GL_READ_FRAMEBUFFER, src.fbo)
        gl.glBindFramebuffer(G.GL_DRAW_FRAMEBUFFER, dst.fbo)
        for i in range(2):
            gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0 + i)
            gl.draw_buffers(2, only=i)
            gl.glBlitFramebuffer(0, 0, sw, sh, 0, 0, dw, dh, G.GL_COLOR_BUFFER_BIT, filt)
        gl.draw_buffers(2)
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, 0)

    def release(self) -> None:
        for t in (self.main, self.resolve, self.half, self.ss_resolve, self.tex):
            if t is not None:
                t.release()
        self.main = self.resolve = self.half = self.ss_resolve = self.tex = None
