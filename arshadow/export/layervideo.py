"""Video layers: the object and shadow layers of every frame, as videos with alpha or as image sequences.

Formats (``--layers-format`` of ``arshadow video`` / ``batch``; docs/export.md):

``prores``
    QuickTime ``.mov``, ProRes 4444 (``prores_ks``, 10-bit 4:4:4 with alpha; visually lossless, not exact):
    ``<stem>.object.mov`` and ``<stem>.shadow.only.mov`` with alpha, ``<stem>.shadow.mult.mov`` grey.
``ffv1``
    Matroska ``.mkv``, FFV1 (lossless): 16-bit RGBA (``rgba64le``) and 16-bit grey (``gray16le``): the
    same numbers as the 16-bit PNG layers.
``png`` / ``exr``
    A folder ``<stem>.layers/`` with ``object.NNNNNN.png`` ... per frame (:mod:`.layerfiles`).

Colour as the image layers: the object's colour is sRGB-encoded with **straight** alpha in the videos and
PNGs (what these codecs and readers expect), premultiplied linear in EXR; the multiply pass holds the linear
factor. The lens distortion is applied (the layers sit on the photo's pixels); ``undistorted=True`` also
writes the pinhole (undistorted) layers and the ST-map that distorts them (:mod:`.stmap`).

Every file is written to a temporary name and renamed into place by :meth:`LayerSink.close`;
:meth:`LayerSink.abort` removes them.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import UsageError
from ..io import output_mode
from .layerfiles import LAYER_NAMES, check_layer_format, layer_arrays, write_layers

if TYPE_CHECKING:
    from ..compose.layers import Layers

__all__ = ["VIDEO_LAYER_FORMATS", "LayerSink", "check_video_layer_format", "video_layer_paths"]

#: format -> (codec, container extension, RGBA pixel format, grey pixel format)
VIDEO_LAYER_FORMATS = {
    "prores": ("prores_ks", "mov", "yuva444p10le", "yuv444p10le"),
    "ffv1": ("ffv1", "mkv", "rgba64le", "gray16le"),
    "png": None,
    "exr": None,
}


def check_video_layer_format(fmt: str, what: str = "--layers-format") -> str:
    """Check that ``fmt``'s encoder or writer is available (before any work); returns ``fmt``.

    Raises
    ------
    UsageError
        Unknown format, an FFmpeg build without the codec, or no OpenEXR writer: one line.
    """
    if fmt not in VIDEO_LAYER_FORMATS:
        raise UsageError(f"{what} {fmt!r}: expected one of {', '.join(VIDEO_LAYER_FORMATS)}")
    spec = VIDEO_LAYER_FORMATS[fmt]
    if spec is None:
        return check_layer_format(fmt, what)
    import av  # the video engine's own dependency

    try:
        av.codec.Codec(spec[0], "w")
    except Exception:  # noqa: BLE001  (PyAV raises its own UnknownCodecError, version-dependent)
        raise UsageError(f"{what} {fmt}: this FFmpeg build has no {spec[0]} encoder (try {what} ffv1 or png)") from None
    return fmt


def video_layer_paths(outdir: Path | str, stem: str, fmt: str, undistorted: bool = False) -> dict[str, Path]:
    """``{name: Path}``: one video per layer, or the sequence folder ``<stem>.layers`` (key ``folder``); with
    ``undistorted`` also the ``undistorted.<name>`` videos and the ``stmap`` (``<stem>.stmap.exr`` with
    ``exr``, else 16-bit PNG)."""
    spec = VIDEO_LAYER_FORMATS[fmt]
    d = Path(outdir)
    if spec is None:
        out = {"folder": d / f"{stem}.layers"}
    else:
        names = list(LAYER_NAMES) + ([f"undistorted.{n}" for n in LAYER_NAMES] if undistorted else [])
        out = {n: d / f"{stem}.{n}.{spec[1]}" for n in names}
    if undistorted:
        out["stmap"] = d / f"{stem}.stmap.{'exr' if fmt == 'exr' else 'png'}"
    return out


def _u16(arr: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(arr, np.float64) * 65535.0), 0, 65535).astype(np.uint16)


class LayerSink:
    """Writes one video's layers frame by frame.

    Parameters
    ----------
    paths : dict
        :func:`video_layer_paths`.
    fmt : str
        A :data:`VIDEO_LAYER_FORMATS` key.
    rate : fractions.Fraction or float
        Frame rate.
    size : (W, H)
    stmap : (H, W, 2) float32, optional
        The ST-map of the undistorted layers (:func:`arshadow.export.stmap.stmap`), written by :meth:`close`.
    """

    def __init__(
        self,
        paths: dict[str, Path],
        fmt: str,
        rate: Fraction | float,
        size: tuple[int, int],
        stmap: np.ndarray | None = None,
    ) -> None:
        self.paths, self.fmt, self.rate = dict(paths), fmt, rate
        self.W, self.H = int(size[0]), int(size[1])
        self.n = 0
        self.stmap = stmap
        self._tmp: dict[str, Path] = {}
        self._streams: dict[str, tuple[Any, Any]] = {}
        spec = VIDEO_LAYER_FORMATS[fmt]
        if spec is None:
            target = Path(self.paths["folder"])
            target.parent.mkdir(parents=True, exist_ok=True)
            self._tmp["folder"] = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
            return
        import av  # the video engine's own dependency

        codec, ext, rgba_fmt, grey_fmt = spec
        for name in [n for n in self.paths if n not in ("folder", "stmap")]:
            target = Path(self.paths[name])
            target.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".tmp.{ext}", dir=target.parent)
            os.close(fd)
            self._tmp[name] = Path(tmp)
            c = av.open(tmp, "w")
            s: Any = c.add_stream(codec, rate=rate if isinstance(rate, Fraction | int) else _fraction(rate))
            s.width, s.height = self.W, self.H
            s.pix_fmt = grey_fmt if name.endswith("shadow.mult") else rgba_fmt
            if codec == "prores_ks":
                s.options = {"profile": "4444"}
            self._streams[name] = (c, s)

    def write(self, layers: Layers | None) -> None:
        """Add one frame (``layers``: :class:`arshadow.compose.layers.Layers`, or None: nothing drawn)."""
        if layers is None:
            from ..compose.layers import layers_from_warped

            layers = layers_from_warped(None, None, (0, 0, 0, 0), (self.H, self.W), opacity=0.0)
        if "folder" in self._tmp:
            fmt = self.fmt
            d = self._tmp["folder"]
            names = list(LAYER_NAMES) + ([f"undistorted.{n}" for n in LAYER_NAMES] if self.stmap is not None else [])
            write_layers({n: d / f"{n}.{self.n:06d}.{fmt}" for n in names}, layers, fmt)
            self.n += 1
            return
        import av  # the video engine's own dependency

        from ..compose.composite import linear_to_srgb

        arrays = layer_arrays(layers)
        for name, (c, s) in self._streams.items():
            arr = arrays[name]
            if name.endswith("shadow.mult"):
                if arr.ndim == 3:  # a coloured tint: the grey video holds the mean (docs/export.md)
                    arr = arr.mean(axis=2)
                frame = av.VideoFrame.from_ndarray(_u16(arr), format="gray16le")
            else:
                if name.endswith("object"):  # straight alpha, sRGB-encoded colour
                    a = arr[..., 3:4]
                    straight = np.divide(arr[..., :3], a, out=np.zeros_like(arr[..., :3]), where=a > 0)
                    arr = np.concatenate([linear_to_srgb(straight), a], axis=2)
                frame = av.VideoFrame.from_ndarray(_u16(arr), format="rgba64le")
            for pkt in s.encode(frame):
                c.mux(pkt)
        self.n += 1

    def close(self) -> dict[str, Path]:
        """Finish the files and rename them into place; returns the paths written."""
        for c, s in self._streams.values():
            for pkt in s.encode():
                c.mux(pkt)
            c.close()
        self._streams.clear()
        if self.stmap is not None:
            from .stmap import write_stmap

            write_stmap(self.paths["stmap"], self.stmap)
        for name, tmp in self._tmp.items():
            target = Path(self.paths[name])
            os.chmod(tmp, output_mode(folder=tmp.is_dir()))  # mkstemp / mkdtemp: owner-only
            if tmp.is_dir():
                if target.exists():
                    shutil.rmtree(target)
                tmp.rename(target)
            else:
                tmp.replace(target)
        self._tmp.clear()
        return self.paths

    def abort(self) -> None:
        """Remove the temporary files (after a failure)."""
        for c, _s in self._streams.values():
            with contextlib.suppress(Exception):
                c.close()
        self._streams.clear()
        for tmp in self._tmp.values():
            if tmp.is_dir():
                shutil.rmtree(tmp, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    tmp.unlink()
        self._tmp.clear()


def _fraction(rate: float) -> Fraction:
    """A float frame rate (an image sequence's) as the fraction PyAV takes (29.97 -> 2997/100)."""
    return Fraction(rate).limit_denominator(1_000_000)
