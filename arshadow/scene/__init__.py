"""The scene a user describes, as frozen picklable data: the spec and its builders (:mod:`.spec`), render options (:mod:`.options`), the time-lapse (:mod:`.timelapse`) and the sanity gates (:mod:`.sanity`). ``arshadow.scene`` re-exports :mod:`.spec`'s names."""

from .spec import *  # noqa: F403
from .spec import __all__  # noqa: F401
