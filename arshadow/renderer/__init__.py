"""The render seam, without GL: what the executor hands a renderer (:class:`RenderRequest` with its :class:`Shading`) and what it gets back, and the :class:`Renderer` protocol that ``arshadow.gl`` implements (:mod:`.request`). ``arshadow.renderer`` re-exports its names."""

from .request import *  # noqa: F403
from .request import __all__  # noqa: F401
