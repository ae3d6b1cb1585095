"""Reading images and writing every output file atomically.

Every output goes to a temporary file in the target folder and is renamed into place
(:func:`atomic_path`), so an interrupted run leaves the old file or the new one, never a truncated one.
Inputs are never modified.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np

from .errors import ImageError


def read_image(path) -> np.ndarray:
    """Read an image as 8-bit BGR, whatever OpenCV can decode.

    Grayscale becomes 3-channel, 16-bit is scaled to 8-bit, an alpha channel is dropped (composited
    over black is *not* done: the colour channels are kept as they are).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    (H, W, 3) uint8
        BGR image.

    Raises
    ------
    ImageError
        Missing, unreadable or corrupt file, or an empty image.
    """
    p = Path(path)
    if not p.is_file():
        raise ImageError(f"{p}: no such image file")
    data = np.fromfile(str(p), dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None or img.size == 0:
        raise ImageError(f"{p}: cannot decode image (corrupt or unsupported format)")
    return to_bgr8(img, name=str(p))


def to_bgr8(img: np.ndarray, name: str = "image") -> np.ndarray:
    """Convert a decoded image (gray / BGR / BGRA, 8/16-bit or float) to ``(H, W, 3) uint8`` BGR."""
    if img.dtype == np.uint16:
        img = (img.astype(np.float32) / 257.0 + 0.5).astype(np.uint8)
    elif img.dtype in (np.float32, np.float64):
        img = np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise ImageError(f"{name}: unsupported pixel type {img.dtype}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = cv2.cvtColor(img[:, :, 0], cv2.COLOR_GRAY2BGR)
    elif not (img.ndim == 3 and img.shape[2] == 3):
        raise ImageError(f"{name}: unsupported image layout {img.shape}")
    return np.ascontiguousarray(img)


@contextlib.contextmanager
def atomic_path(target):
    """Yield a temporary path beside ``target``; rename it onto ``target`` only if the block succeeds.

    The temporary name keeps ``target``'s extension so that writers choosing a format by extension
    (``cv2.imwrite``) work on it.
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}", dir=target.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes the file owner-only (0600); an output gets the usual mode (0666 less the umask)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_image(path, image: np.ndarray, params=None) -> Path:
    """Write ``image`` atomically; the format follows ``path``'s extension. Returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        ok, buf = cv2.imencode(path.suffix or ".png", image, params or [])
        if not ok:
            raise ImageError(f"{path}: cannot encode image as {path.suffix}")
        buf.tofile(str(tmp))
    return path


def write_bytes(path, data: bytes) -> Path:
    """Write ``data`` atomically to ``path``."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def write_json(path, obj) -> Path:
    """Write ``obj`` as indented JSON atomically (NaN is refused: JSON has none)."""
    return write_bytes(path, (json.dumps(obj, indent=1, allow_nan=False) + "\n").encode())
