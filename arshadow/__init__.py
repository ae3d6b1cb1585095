"""arshadow: put a virtual object and its exact hard shadow into photos of a printed ArUco marker.

Pipeline: marker detection and pose (:mod:`arshadow.marker`) -> occluder in the marker's world frame
(:mod:`arshadow.mesh`) -> silhouette (:mod:`arshadow.silhouette`) -> shadow volume
(:mod:`arshadow.volume`) -> stencil rendering (:mod:`arshadow.gl`) -> compositing
(:mod:`arshadow.composite`).

Nothing here imports OpenGL; only :mod:`arshadow.gl` does, and only when it is used.
"""

__version__ = "0.1.0"

from .errors import (  # noqa: E402
    ArshadowError,
    CalibrationError,
    GLContextError,
    ImageError,
    LightError,
    MarkerNotFoundError,
    MeshError,
    ShapeError,
    UsageError,
)

__all__ = [
    "__version__",
    "ArshadowError",
    "CalibrationError",
    "GLContextError",
    "ImageError",
    "LightError",
    "MarkerNotFoundError",
    "MeshError",
    "ShapeError",
    "UsageError",
]
