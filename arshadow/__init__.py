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
:class:`RenderOptions`, :class:`FrameResult`, :class:`FramePlan` and the :mod:`arshadow.synth` module
(known-truth photos) are loaded on first access.

Nothing here imports OpenGL; only :mod:`arshadow.gl` does, and only when it is used.
"""

__version__ = "0.1.0"

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

_LAZY = {
    "Session": "session",
    "FrameResult": "session",
    "render_photo": "session",
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
}


def __getattr__(name):
    """The API names and ``synth``, imported on first use (``import arshadow`` stays light)."""
    import importlib

    if name == "synth":
        return importlib.import_module(".synth", __name__)
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'arshadow' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{mod}", __name__), name)


__all__ = [
    "__version__",
    *_LAZY,
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
