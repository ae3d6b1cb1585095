"""GPU-resident render results: the renderer's layers kept in textures (``ShadowRenderer.render_gpu``).

Kept apart from :mod:`arshadow.gl.stencil` so that the compose path (:mod:`arshadow.gl.gpu_compose`) and the
renderer share these two small types without importing each other.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # annotations only: the objects come from the context handed in
    import moderngl

__all__ = ["GpuLayers", "TextureTarget"]


class TextureTarget:
    """Texture-backed single-sample framebuffer (colour 0 ``RGBA16F``, colour 1 ``RG16F``, ``RGBA16F`` with sky occlusion): the blit
    destination of ``render_gpu()``, sampled by :mod:`arshadow.gl.gpu_compose`."""

    def __init__(self, ctx: moderngl.Context, width: int, height: int, mask_components: int = 2) -> None:
        self.width, self.height = int(width), int(height)
        self.color_tex = ctx.texture((self.width, self.height), 4, dtype="f2")
        self.mask_tex = ctx.texture((self.width, self.height), int(mask_components), dtype="f2")
        for t in (self.color_tex, self.mask_tex):
            t.filter = (ctx.NEAREST, ctx.NEAREST)
        self.mgl = ctx.framebuffer(color_attachments=[self.color_tex, self.mask_tex])
        self.fbo = self.mgl.glo

    def release(self) -> None:
        for o in (self.mgl, self.color_tex, self.mask_tex):
            o.release()


@dataclass
class GpuLayers:
    """What ``ShadowRenderer.render_gpu()`` returns: the frame's layers left on the GPU.

    Attributes
    ----------
    color_tex : moderngl.Texture
        ``RGBA16F``: rgb = premultiplied linear occluder colour, a = coverage (as :class:`RenderResult`).
    mask_tex : moderngl.Texture
        ``RG16F``: r = blocked weight (not yet clipped to [0, 1]), g = ground coverage; ``RGBA16F`` once the
        renderer has drawn sky occlusion: b = the share of the sky the object hides from the visible ground
        (not yet clipped to [-1, 1]; meaningful only when ``sky`` is True).
    width, height : int
        The canvas occupies texels ``[0, width) x [0, height)``, OpenGL's bottom-up rows (texel row 0 is
        the canvas's BOTTOM row); the textures may be larger (grown, never shrunk). Valid until the next
        render.
    timings_ms : dict
        ``upload``, ``draw`` (commands issued; not waited for), ``readback`` (0), ``total``.
    premultiplied : bool
        The colour is premultiplied by the coverage (the renderers' convention).
    sky : bool
        This frame drew its sky occlusion into ``mask_tex``'s b channel (``RenderResult.sky_occlusion`` of the
        same request): the shader compositor darkens the ground by it (:mod:`arshadow.gl.gpu_compose`).
    bleed : (3,) float or None
        Colour bleeding (``SkyShading.bleed`` when ``SkyShading.colored``): ``mask_tex``'s a channel holds
        the object's reflected light, the sky channel is ``b - a * bleed`` per colour channel.
    """

    color_tex: moderngl.Texture
    mask_tex: moderngl.Texture
    width: int
    height: int
    timings_ms: dict[str, float] = field(default_factory=dict)
    premultiplied: bool = True
    sky: bool = False
    bleed: tuple | None = None
