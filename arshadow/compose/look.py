"""How the rendered layers meet the photo: :class:`Look`, the compositing side's one value per frame.

The executor (:mod:`arshadow.frame.execute`) builds one per frame from the options and the frame's measured
exposure gain, and hands it to whichever compositor runs (the numpy
:func:`arshadow.compose.composite.composite` or the shader :class:`arshadow.gl.gpu_compose.GpuCompositor`); it is
to the composite what :class:`arshadow.renderer.request.Shading` is to the renderer. A new compositing setting
(a camera effect measured from the photo, say) is a field here, read in :meth:`Look.from_options` or
measured per frame, and used by both compositors.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..frame.effects import CameraEffects
    from ..frame.motion import MotionBlur
    from ..scene.options import RenderOptions

__all__ = ["Look"]


@dataclass(frozen=True)
class Look:
    """How the layers are composited into the photo.

    Attributes
    ----------
    opacity : float in [0, 1]
        How dark a fully blocked ground pixel gets (``1 - opacity`` of its light is kept).
    shadow_color : (3,) linear RGB
        Tint of a full shadow (black: plain darkening).
    draw_occluder : bool
        Composite the shaded object over the shadow.
    color_gain : (3,) float32 linear RGB or None
        Per-channel gain on the object's rendered colour (the marker paper's exposure match,
        :mod:`arshadow.estimate.match`); None: none.

    Examples
    --------
    >>> from arshadow.scene.options import RenderOptions
    >>> Look.from_options(RenderOptions(opacity=0.5), color_gain=(1.0, 0.9, 0.8)).color_gain.dtype
    dtype('float32')
    """

    opacity: float = 0.7
    shadow_color: tuple = (0.0, 0.0, 0.0)
    draw_occluder: bool = True
    color_gain: np.ndarray | None = None
    #: the photo's measured blur and noise applied to the inserted layers (:mod:`arshadow.frame.effects`,
    #: ``--camera-effects on``; both compositors: the shader one in :mod:`arshadow.gl.gpu_effects`), None: none
    camera: CameraEffects | None = None
    #: a video frame's motion blur of the inserted layers (:mod:`arshadow.frame.motion`, ``--motion-blur``;
    #: the numpy compositor only: a frame whose blur is applied is composited by it), None: none
    motion: MotionBlur | None = None

    @classmethod
    def from_options(cls, options: RenderOptions, color_gain: Sequence[float] | np.ndarray | None = None) -> Look:
        """The look ``options`` ask for, with this frame's exposure gain (None: none)."""
        gain = None if color_gain is None else np.asarray(color_gain, np.float32).reshape(3)
        return cls(
            opacity=options.opacity,
            shadow_color=options.shadow_color,
            draw_occluder=options.draw_occluder,
            color_gain=gain,
        )
