"""Former home of the stencil renderer, kept as an alias for code written against it.

The renderer is :mod:`arshadow.gl.stencil` (:class:`~arshadow.gl.stencil.ShadowRenderer`, one method per
pass) and its GPU resources are in :mod:`arshadow.gl.resources`. ``render(readback=False)`` is now
:meth:`~arshadow.gl.stencil.ShadowRenderer.render_gpu`. New code imports from those modules.
"""

from __future__ import annotations

from ..compose.composite import srgb_to_linear
from ..render_api import LightPass, RenderResult
from .resources import ground_vertices, load_shader, local_origin
from .stencil import ShadowRenderer

__all__ = [
    "LightPass",
    "RenderResult",
    "ShadowRenderer",
    "ground_vertices",
    "load_shader",
    "local_origin",
    "srgb_to_linear",
]
