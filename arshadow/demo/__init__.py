"""The bundled demo: the sample photos through the photo loop (:mod:`.run`), where the bundled data is (:mod:`.data`) and the measured-look item (:mod:`.light`). ``arshadow.demo`` re-exports :mod:`.run`'s names."""

from .run import *  # noqa: F403
from .run import __all__  # noqa: F401
