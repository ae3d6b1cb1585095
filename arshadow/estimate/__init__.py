"""Measure the real light from the photos: exposure and white balance from the marker's paper, the light's
direction (or position, or the world's bearing under a known sun) and the shadow's colour from a reference
object's real shadow, by analysis by synthesis on arshadow's exact shadow geometry (docs/light.md).

Pure numpy / OpenCV / scipy; no OpenGL.
"""

from .api import estimate_light
from .exposure import Exposure, measure_exposure, smooth_exposures
from .record import LightEstimate, load_estimate, shading_gain

__all__ = [
    "Exposure",
    "LightEstimate",
    "estimate_light",
    "load_estimate",
    "measure_exposure",
    "shading_gain",
    "smooth_exposures",
]
