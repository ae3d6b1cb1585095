"""ArUco dictionaries: predefined names and custom dictionary files, marker bits and object points.

The marker frame (CONVENTIONS.md): origin at the marker centre, x right, y up (towards the printed top
edge), z out of the printed face; corners TL, TR, BR, BL = ``(-s/2, s/2, 0), (s/2, s/2, 0),
(s/2, -s/2, 0), (-s/2, -s/2, 0)`` (:func:`marker_object_points`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TypeAlias

import cv2
import numpy as np

from ..camera.model import open_storage
from ..errors import UsageError

__all__ = [
    "PREDEFINED_DICTIONARIES",
    "DEFAULT_DICTIONARY",
    "get_dictionary",
    "dictionary_label",
    "marker_object_points",
    "marker_bits",
]

#: what names a dictionary: a predefined name, a dictionary file, or the dictionary itself
DictionarySpec: TypeAlias = str | Path | cv2.aruco.Dictionary

#: names accepted by :func:`get_dictionary` (case-insensitive, the ``DICT_`` prefix optional)
PREDEFINED_DICTIONARIES = tuple(
    sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and not any(c.islower() for c in n))
)


def _dict_constant(name: str) -> tuple[str, int | None]:
    n = name.strip().upper()
    if not n.startswith("DICT_"):
        n = "DICT_" + n
    return n, getattr(cv2.aruco, n, None) if n in PREDEFINED_DICTIONARIES else None


#: the dictionary of single-marker mode when none is given
DEFAULT_DICTIONARY = "DICT_6X6_250"


def get_dictionary(spec: DictionarySpec, base_dir: str | Path | None = None) -> cv2.aruco.Dictionary:
    """An ArUco dictionary from a predefined name or a custom dictionary file.

    Parameters
    ----------
    spec : str, Path or cv2.aruco.Dictionary
        ``"DICT_6X6_250"`` (case-insensitive, ``DICT_`` optional), or the path of a dictionary file
        in OpenCV's format (``nmarkers``, ``markersize``, ``marker_0`` ... as written by
        ``Dictionary.writeDictionary``; YAML/XML/JSON).
    base_dir : Path, optional
        Relative dictionary paths are resolved against it (board files use their own folder).

    Raises
    ------
    UsageError
        Unknown name, or a dictionary file that is missing or unreadable.

    Examples
    --------
    >>> get_dictionary("6x6_250").markerSize
    6
    """
    if isinstance(spec, cv2.aruco.Dictionary):
        return spec
    s = str(spec)
    looks_like_file = any(s.lower().endswith(e) for e in (".yml", ".yaml", ".xml", ".json")) or "/" in s
    if not looks_like_file:
        n, const = _dict_constant(s)
        if const is None:
            raise UsageError(
                f"unknown dictionary '{s}' (use a name such as DICT_6X6_250, one of "
                f"{', '.join(PREDEFINED_DICTIONARIES)}, or a dictionary file)"
            )
        return cv2.aruco.getPredefinedDictionary(const)
    p = Path(s)
    if base_dir is not None and not p.is_absolute():
        p = Path(base_dir) / p
    with open_storage(p, "dictionary file", UsageError) as fs:
        if fs.getNode("nmarkers").empty() or fs.getNode("markersize").empty():
            raise UsageError(f"{p}: not a dictionary file (needs 'nmarkers', 'markersize', 'marker_0'...)")
        d = cv2.aruco.Dictionary()
        try:
            ok = d.readDictionary(fs.root())
        except cv2.error as exc:
            raise UsageError(f"{p}: invalid dictionary file ({str(exc).strip().splitlines()[-1][:100]})") from None
        if not ok or d.bytesList is None or len(d.bytesList) == 0:
            raise UsageError(f"{p}: invalid dictionary file")
    return d


def dictionary_label(spec: DictionarySpec) -> str:
    """A short human name for a dictionary spec (the predefined name, or the file name)."""
    if isinstance(spec, cv2.aruco.Dictionary):
        return f"custom {spec.markerSize}x{spec.markerSize} dictionary ({len(spec.bytesList)} markers)"
    s = str(spec)
    n, const = _dict_constant(s)
    return n if const is not None else Path(s).name


def marker_object_points(length: float) -> np.ndarray:
    """(4, 3) float64 marker corners TL, TR, BR, BL in the marker (world) frame, side ``length`` m.

    Examples
    --------
    >>> marker_object_points(2.0)[0].tolist()
    [-1.0, 1.0, 0.0]
    """
    h = float(length) / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def marker_bits(dictionary: DictionarySpec, marker_id: int, border_bits: int = 1) -> np.ndarray:
    """(c, c) bool, True = white cell, for ``marker_id`` including its black border (c = size + 2 border)."""
    d = get_dictionary(dictionary)
    if not 0 <= int(marker_id) < len(d.bytesList):
        raise UsageError(f"marker id {marker_id} is not in the dictionary (ids 0..{len(d.bytesList) - 1})")
    c = d.markerSize + 2 * border_bits
    return cv2.aruco.generateImageMarker(d, int(marker_id), c, borderBits=border_bits) > 127
