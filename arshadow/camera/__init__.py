"""The camera: pinhole intrinsics and lens distortion (:mod:`.model`, :mod:`.distortion`) and OpenCV FileStorage files (:mod:`.cvstorage`). ``arshadow.camera`` re-exports :mod:`.model`'s names."""

from .model import *  # noqa: F403
from .model import __all__  # noqa: F401
