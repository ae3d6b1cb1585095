"""arshadow: put a virtual object and its exact hard shadow into photos of a printed ArUco marker.

Pipeline: marker detection and pose (:mod:`arshadow.tracking`) -> occluder in the marker's world frame
(:mod:`arshadow.geometry.mesh`) -> silhouette (:mod:`arshadow.geometry.silhouette`) -> shadow volume
(:mod:`arshadow.geometry.volume`) -> stencil rendering (:mod:`arshadow.gl`) -> compositing
(:mod:`arshadow.compose.composite`).

Python API (docs/architecture.md, README "Python")::

    import arshadow
    spec = arshadow.scene_from_dict({...})            # or arshadow.load_scene("job.yml")
    with arshadow.Session(spec) as s:
        result = s.process(image_bgr)                 # arshadow.FrameResult

:class:`Session`, :class:`SceneSpec`, :func:`scene_from_dict`, :func:`load_scene`, :func:`render_photo`,
:func:`process_video` (videos: :class:`EngineOptions` in, :class:`VideoRun` out), :class:`RenderOptions`,
:class:`FrameResult`, :class:`FramePlan` and the :mod:`arshadow.synth` module (known-truth photos) are
loaded on first access.

Nothing here imports OpenGL; only :mod:`arshadow.gl` does, and only when it is used.
"""

__version__ = "0.1.0"  # the one version string (pyproject.toml reads it: [tool.setuptools.dynamic])

import importlib  # noqa: E402
from typing import TYPE_CHECKING, Any  # noqa: E402

from .errors import (  # noqa: E402
    ArshadowError,
    CalibrationError,
    EstimateError,
    GLContextError,
    ImageError,
    LightError,
    MarkerNotFoundError,
    MeshError,
    ShapeError,
    UsageError,
)

if TYPE_CHECKING:  # the lazily loaded names, for type checkers (py.typed)
    from . import synth
    from .estimate import LightEstimate, estimate_light
    from .frame.session import FrameResult, Session, render_photo
    from .plan.planner import FramePlan, plan_frame
    from .scene.spec import ModelSpec, RenderOptions, SceneSpec, TrackerSpec, load_scene, scene_from_dict
    from .video.api import VideoRun, process_video
    from .video.engine import EngineOptions

_LAZY = {
    "Session": "frame.session",
    "FrameResult": "frame.session",
    "render_photo": "frame.session",
    "SceneSpec": "scene",
    "TrackerSpec": "scene",
    "ModelSpec": "scene",
    "RenderOptions": "scene",
    "scene_from_dict": "scene",
    "load_scene": "scene",
    "FramePlan": "plan",
    "plan_frame": "plan",
    "estimate_light": "estimate",
    "LightEstimate": "estimate",
    "process_video": "video.api",
    "VideoRun": "video.api",
    "EngineOptions": "video.engine",
}


def __getattr__(name: str) -> Any:
    """The API names and ``synth``, imported on first use (``import arshadow`` stays light)."""
    if name == "synth":
        return importlib.import_module(".synth", __name__)
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'arshadow' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{mod}", __name__), name)


# written out (not *_LAZY) so that linters and type checkers see the lazy names as exported
__all__ = [
    "__version__",
    "Session",
    "FrameResult",
    "render_photo",
    "SceneSpec",
    "TrackerSpec",
    "ModelSpec",
    "RenderOptions",
    "scene_from_dict",
    "load_scene",
    "FramePlan",
    "plan_frame",
    "estimate_light",
    "LightEstimate",
    "process_video",
    "VideoRun",
    "EngineOptions",
    "synth",
    "ArshadowError",
    "CalibrationError",
    "EstimateError",
    "GLContextError",
    "ImageError",
    "LightError",
    "MarkerNotFoundError",
    "MeshError",
    "ShapeError",
    "UsageError",
]
