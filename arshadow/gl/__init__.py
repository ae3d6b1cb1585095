"""OpenGL side of arshadow: the only package that imports moderngl.

- :mod:`arshadow.gl.context`: ``create_context(backend=None)``, ``gl_info(ctx)``.
- :mod:`arshadow.gl.stencil`: ``ShadowRenderer`` (stencil shadow volumes offscreen, one method per pass),
  an :class:`arshadow.renderer.request.Renderer`; ``LightPass`` and ``RenderResult`` (defined, GL-free, in
  :mod:`arshadow.renderer.request`) are re-exported there.
- :mod:`arshadow.gl.resources`: shader programs, caster/volume buffers, framebuffers, the ground plane.
- :mod:`arshadow.gl.shadowmap`: the shadow-map baseline renderer; :mod:`arshadow.gl.gpu_compose`: the
  GPU compositor; :mod:`arshadow.gl.layers`: GPU-resident results.
- :mod:`arshadow.gl.glraw`: ctypes bindings for the raw GL calls moderngl lacks (stencil, renderbuffers).

Importing this package creates no context and loads no GL library; ``create_context`` does, when called.
"""

__all__ = ["context", "glraw", "renderer", "resources", "stencil"]
