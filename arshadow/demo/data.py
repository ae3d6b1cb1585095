"""Where the bundled sample data is: the repository root in a checkout, the package's copy when installed.

The demo's inputs (``samples/``: photos, meshes, ``scenes.json``, ``light_probe.json``; ``calib/``: the calibrations they name)
live at the repository root; the wheel ships them as ``arshadow/demo_data/samples`` and
``arshadow/demo_data/calib`` (``setup.py``), so that ``arshadow demo`` and ``arshadow bench`` run the same
from an installed wheel as from a checkout. Paths in ``scenes.json`` are relative to :func:`data_root`.

>>> root = data_root()
>>> (root / "samples" / "scenes.json").is_file() and (root / "calib" / "synth_1280x720.yml").is_file()
True
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["data_root", "samples_dir"]

_PACKAGE = Path(__file__).resolve().parents[1]  # arshadow/ (this module is arshadow/demo/data.py)


def data_root() -> Path:
    """The folder holding ``samples/`` and ``calib/``: the checkout's root when arshadow runs from a checkout
    (``samples/scenes.json`` beside the package), else the copy installed with the package."""
    checkout = _PACKAGE.parent
    if (checkout / "samples" / "scenes.json").is_file() and (checkout / "calib").is_dir():
        return checkout
    return _PACKAGE / "demo_data"


def samples_dir() -> Path:
    """``data_root() / "samples"``: the sample photos, ``meshes/`` and ``scenes.json``."""
    return data_root() / "samples"
