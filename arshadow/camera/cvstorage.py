"""OpenCV FileStorage files (YAML / XML / JSON): opening with clear errors, atomic writing, reading
matrices and positive integers. Used by calibration files (:meth:`arshadow.camera.Intrinsics.from_file`)
and board files (:mod:`arshadow.tracking`).
"""

from __future__ import annotations

import contextlib
import math
import re
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from ..errors import CalibrationError
from ..io import atomic_path

__all__ = ["open_storage", "read_matrix", "read_positive_int", "write_storage"]


@contextlib.contextmanager
def open_storage(path: Path | str, what: str, error: type[Exception] = CalibrationError) -> Iterator[cv2.FileStorage]:
    """Open an OpenCV FileStorage (YAML/XML/JSON) for reading; released when the block ends.

    Every problem is one ``error`` naming the file and ``what`` it should be (``"calibration file"``,
    ``"board file"`` ...): missing, unreadable, or unparsable (quoting OpenCV's parser: file, line, what).
    """
    p = Path(path)
    if p.is_dir():
        raise error(f"{p}: is a folder, not a {what} (give the file itself)")
    if not p.is_file():
        raise error(f"{p}: no such {what}")
    if p.stat().st_size == 0:
        raise error(f"{p}: empty file, not a {what}")
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        # the Python binding may wrap OpenCV's parser error in a SystemError: report the parser's own
        inner = exc.__cause__ or exc.__context__ or exc
        text = str(inner).strip()
        where = re.search(r"in function '([^']*)'", text)  # OpenCV puts "file(line): what" there
        first = where.group(1) if where else (text.splitlines()[-1].strip() if text else "parse error")
        if "(" not in first:  # no "file(line): what": OpenCV could not even recognise the format
            raise error(f"{p}: cannot parse {what}: not OpenCV YAML, XML or JSON ({first[:80]})") from None
        raise error(f"{p}: cannot parse {what}: {first[:160]}") from None
    if not fs.isOpened():
        raise error(f"{p}: cannot open {what}")
    try:
        yield fs
    finally:
        fs.release()


@contextlib.contextmanager
def write_storage(path: Path | str, what: str, error: type[Exception] = CalibrationError) -> Iterator[cv2.FileStorage]:
    """Open an OpenCV FileStorage for writing ``path`` atomically (format from the extension)."""
    p = Path(path)
    with atomic_path(p) as tmp:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise error(f"{p}: cannot write {what}")
        try:
            yield fs
        finally:
            fs.release()


def read_matrix(node: cv2.FileNode, name: str, path: Path | str) -> np.ndarray:
    """Read an OpenCV matrix node (key ``name`` of file ``path``, for messages), a ROS-style {rows, cols, data} map, or a plain sequence."""
    if node.isMap():
        data = node.getNode("data")
        if data.empty() or not data.isSeq():
            raise CalibrationError(f"{path}: key '{name}' has no 'data' list")
        vals = [data.at(i).real() for i in range(data.size())]
        rows, cols = node.getNode("rows"), node.getNode("cols")
        arr = np.asarray(vals, dtype=np.float64)
        if not rows.empty() and not cols.empty():
            r, c = int(rows.real()), int(cols.real())
            if r * c != arr.size:
                raise CalibrationError(f"{path}: key '{name}' says {r}x{c} but holds {arr.size} values")
            arr = arr.reshape(r, c)
        return arr
    if node.isSeq():
        return np.asarray([node.at(i).real() for i in range(node.size())], dtype=np.float64)
    raise CalibrationError(f"{path}: key '{name}' is not a matrix")


def read_positive_int(fs: cv2.FileStorage, key: str, path: Path | str) -> int:
    """The positive integer under ``key`` of an open FileStorage ``fs`` (of file ``path``, for messages)."""
    node = fs.getNode(key)
    if node.empty():
        raise CalibrationError(f"{path}: missing key '{key}'")
    if not (node.isInt() or node.isReal()):
        raise CalibrationError(f"{path}: key '{key}' is not a number")
    v = node.real()
    if not math.isfinite(v) or v != int(v) or v <= 0:
        raise CalibrationError(f"{path}: key '{key}' must be a positive integer, got {v}")
    return int(v)
