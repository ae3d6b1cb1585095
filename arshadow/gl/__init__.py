"""OpenGL side of arshadow: the only package that imports moderngl.

- :mod:`arshadow.gl.context`: ``create_context(backend=None)``, ``gl_info(ctx)``.
- :mod:`arshadow.gl.renderer`: ``ShadowRenderer`` (stencil shadow volumes offscreen), an
  :class:`arshadow.render_api.Renderer`; ``LightPass`` and ``RenderResult`` (defined, GL-free, in
  :mod:`arshadow.render_api`) are re-exported there.
- :mod:`arshadow.gl.glraw`: ctypes bindings for the raw GL calls moderngl lacks (stencil, renderbuffers).

Importing this package creates no context and loads no GL library; ``create_context`` does, when called.
"""

__all__ = ["context", "renderer", "glraw"]
