"""Synthetic data with known truth: photos of a marker or board (:mod:`.markers`), photos lit by a known light (:mod:`.lit`), camera poses (:mod:`.poses`). ``arshadow.synth`` re-exports :mod:`.markers`'s names."""

from .markers import *  # noqa: F403
from .markers import __all__  # noqa: F401
