"""Writing compositing layers (:class:`arshadow.compose.layers.Layers`) as files compositors read.

Per photo or frame, three files (docs/export.md):

``<stem>.object.<ext>``
    The object. EXR: premultiplied RGBA, linear, half float (EXR's own convention). PNG: 16-bit RGBA with
    **straight** alpha and sRGB-encoded colour (PNG's own convention: a PNG reader un-premultiplies
    nothing); ``object_linear_premultiplied = srgb_to_linear(rgb) * a``.
``<stem>.shadow.mult.<ext>``
    The multiply pass (the linear factor the composite applies to the plate). EXR: channel ``Y`` (or
    ``R,G,B`` with a coloured tint), half float. PNG: 16-bit grey (or RGB) holding the **linear** factor
    (read it as raw / linear data, not as sRGB).
``<stem>.shadow.only.<ext>``
    Black with alpha (16-bit PNG RGBA or half-float EXR RGBA): over the plate, then the object over it.

Formats: ``png`` (16-bit PNG, OpenCV) and ``exr`` (the optional ``OpenEXR`` package: ``pip install
'arshadow[exr]'``). :func:`check_layer_format` says what is missing before any work.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from ..compose.composite import linear_to_srgb
from ..compose.layers import Layers, shadow_only_alpha
from ..errors import UsageError
from ..io import InputGuard, atomic_path, write_image

__all__ = [
    "IMAGE_FORMATS",
    "LAYER_NAMES",
    "check_layer_format",
    "layer_arrays",
    "layer_paths",
    "refuse_overwrite",
    "write_exr",
    "write_layers",
]

#: the image formats of photo / frame layers
IMAGE_FORMATS = ("png", "exr")
#: the layer files' name parts
LAYER_NAMES = ("object", "shadow.mult", "shadow.only")


def check_layer_format(fmt: str, what: str = "--layers-format") -> str:
    """Check that the writer of ``fmt`` is available; returns ``fmt``.

    Raises
    ------
    UsageError
        An unknown format, or ``exr`` without the OpenEXR package (one line naming the fix).
    """
    if fmt not in IMAGE_FORMATS:
        raise UsageError(f"{what} {fmt!r}: expected one of {', '.join(IMAGE_FORMATS)}")
    if fmt == "exr":
        try:
            import OpenEXR  # noqa: F401  (optional extra: only checked when EXR layers are asked for)
        except ImportError:
            raise UsageError(
                f"{what} exr: no OpenEXR writer (pip install 'arshadow[exr]', or use {what} png)"
            ) from None
    return fmt


def layer_paths(outdir: Path | str, stem: str, fmt: str, undistorted: bool = False) -> dict[str, Path]:
    """``{name: Path}`` of one photo's layer files (:data:`LAYER_NAMES`; with ``undistorted`` also
    ``undistorted.<name>`` and the ``stmap``) in ``outdir``."""
    names = list(LAYER_NAMES) + ([f"undistorted.{n}" for n in LAYER_NAMES] if undistorted else [])
    out = {n: Path(outdir) / f"{stem}.{n}.{fmt}" for n in names}
    if undistorted:
        out["stmap"] = Path(outdir) / f"{stem}.stmap.{fmt}"
    return out


def refuse_overwrite(paths: Iterable[Path | str], inputs: Iterable[Path | str], what: str = "--layers") -> None:
    """A usage error (before any work) when one of the layer files ``paths`` would replace one of ``inputs``."""
    p = InputGuard(inputs).clash(paths)  # the one overwrite guard (arshadow.io)
    if p is not None:
        raise UsageError(f"{what}: {p} would overwrite an input; choose another -o folder")


def layer_arrays(layers: Layers) -> dict[str, np.ndarray]:
    """Photo-sized float32 arrays, RGB(A) order: ``object`` (H, W, 4) premultiplied linear, ``shadow.mult``
    (H, W) or (H, W, 3), ``shadow.only`` (H, W, 4) black with alpha; and ``undistorted.<name>`` of
    ``layers.undistorted`` when there is one."""
    obj, sh = layers.full()
    only = np.zeros_like(obj)
    only[..., 3] = shadow_only_alpha(sh, obj[..., 3])
    out = {"object": obj, "shadow.mult": sh, "shadow.only": only}
    if layers.undistorted is not None:
        out.update({f"undistorted.{k}": v for k, v in layer_arrays(layers.undistorted).items()})
    return out


def write_exr(path: Path | str, arr: np.ndarray, dtype: npt.DTypeLike = np.float16) -> Path:
    """Write ``(H, W)`` (channel Y), ``(H, W, 3)`` (RGB) or ``(H, W, 4)`` (RGBA) as EXR (half float by default;
    ``dtype=np.float32`` for full float), atomically."""
    import OpenEXR  # optional extra (checked by check_layer_format before any work)

    a = np.ascontiguousarray(arr, dtype)
    name = "Y" if a.ndim == 2 else ("RGB" if a.shape[2] == 3 else "RGBA")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path) as tmp:
        OpenEXR.File(header, {name: a}).write(str(tmp))
    return Path(path)


def _png16(arr: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(arr, np.float64) * 65535.0), 0, 65535).astype(np.uint16)


def write_layers(
    paths: dict[str, Path], layers: Layers, fmt: str, orient: Callable[[np.ndarray], np.ndarray] | None = None
) -> dict[str, Path]:
    """Write one frame's layers to ``paths`` (:func:`layer_paths`) in ``fmt``; returns ``paths``.

    ``orient``: a function applied to every photo-sized array before writing (EXIF orientation).
    """
    arrays = layer_arrays(layers)
    for name, arr in arrays.items():
        if name not in paths:
            continue
        if orient is not None and not name.startswith("undistorted."):  # the pinhole ones: the stored frame
            arr = orient(arr)
        if fmt == "exr":
            write_exr(paths[name], arr)
            continue
        if name.endswith("object"):  # PNG: straight alpha, sRGB-encoded colour
            a = arr[..., 3:4]
            straight = np.divide(arr[..., :3], a, out=np.zeros_like(arr[..., :3]), where=a > 0)
            arr = np.concatenate([linear_to_srgb(straight), a], axis=2)
        img = _png16(arr)
        if img.ndim == 3:  # OpenCV writes BGR(A)
            img = img[..., [2, 1, 0, 3]] if img.shape[2] == 4 else img[..., ::-1]
        # fast zlib level: 16-bit layers are large and mostly flat; level 1 writes them ~4x faster than the default
        write_image(paths[name], np.ascontiguousarray(img), [cv2.IMWRITE_PNG_COMPRESSION, 1])
    return paths
