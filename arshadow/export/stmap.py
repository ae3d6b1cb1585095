"""ST-maps: how the undistorted (pinhole) layers land on the distorted photo, as compositors apply it.

An ST-map (Nuke's ``STMap`` node, Fusion's ``Texture``, After Effects' "ST Map" effects) is an image of the
*output* (distorted photo) size whose red and green channels give, per pixel, the normalised position to
sample in the *input* (undistorted) image. For distorted pixel centre ``(u, v)`` (CONVENTIONS.md: (0, 0) the
centre of the top-left pixel) whose ray the pinhole camera images at ``(u', v')``
(:func:`arshadow.compose.lens.undistort_map`, OpenCV's model inverted)::

    s = (u' + 0.5) / W          t = 1 - (v' + 0.5) / H          (t up: Nuke's convention)

Pixels whose undistortion does not exist get ``(-1, -1)`` (outside the input: transparent). Written as a
float32 EXR (``R``, ``G``, ``B`` = 0) or, without OpenEXR, a 16-bit PNG (``s``, ``t`` scaled to 0..65535,
~0.02 px steps at 1280 px).

>>> import numpy as np
>>> from arshadow.camera import Intrinsics
>>> st = stmap(Intrinsics(100.0, 100.0, 1.5, 1.0, 4, 3, np.zeros(0)))
>>> st[0, 0].tolist(), st[2, 3].tolist()
([0.125, 0.8333333134651184], [0.875, 0.1666666716337204])
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ..compose.lens import INVALID, undistort_map
from ..io import write_image

if TYPE_CHECKING:
    from ..camera.model import Intrinsics

__all__ = ["stmap", "stmap_to_pixels", "write_stmap"]


def stmap(intrinsics: Intrinsics, maps: Sequence[np.ndarray] | None = None) -> np.ndarray:
    """``(H, W, 2) float32`` ST-map of a calibration (``maps``: its ``(map_x, map_y)`` if already computed,
    e.g. :attr:`arshadow.compose.lens.LensWarp.maps`)."""
    W, H = int(intrinsics.width), int(intrinsics.height)
    if maps is None:
        if intrinsics.has_distortion:
            maps = undistort_map(intrinsics)
        else:
            maps = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    mx, my = (np.asarray(m, np.float64) for m in maps)
    st = np.empty((H, W, 2), np.float32)
    st[..., 0] = (mx + 0.5) / W
    st[..., 1] = 1.0 - (my + 0.5) / H
    st[(mx <= INVALID / 2) | (my <= INVALID / 2)] = -1.0
    return st


def stmap_to_pixels(st: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """``(map_x, map_y)`` float32 pixel coordinates of an ST-map (for ``cv2.remap``)."""
    st = np.asarray(st, np.float64)
    return ((st[..., 0] * width - 0.5).astype(np.float32), ((1.0 - st[..., 1]) * height - 0.5).astype(np.float32))


def write_stmap(path: Path | str, st: np.ndarray) -> Path:
    """Write an ST-map: ``.exr`` float32 (R = s, G = t, B = 0) or ``.png`` 16-bit (atomically)."""
    p = Path(path)
    rgb = np.zeros(st.shape[:2] + (3,), np.float32)
    rgb[..., :2] = st
    if p.suffix.lower() == ".exr":
        from .layerfiles import write_exr

        return write_exr(p, rgb, dtype=np.float32)
    img = np.clip(np.rint(rgb * 65535.0), 0, 65535).astype(np.uint16)[..., ::-1]  # OpenCV: BGR
    return write_image(p, np.ascontiguousarray(img), [cv2.IMWRITE_PNG_COMPRESSION, 1])
