"""The planner, without GL: a frame's plan and its decisions (:mod:`.planner`), the scene's camera-independent geometry and the region of interest (:mod:`.scene_geometry`), the rules (:mod:`.rules`). ``arshadow.plan`` re-exports :mod:`.planner`'s names."""

from .planner import *  # noqa: F403
from .planner import __all__  # noqa: F401
