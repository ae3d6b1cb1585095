"""Reading images and writing every output file atomically.

Every output goes to a temporary file in the target folder and is renamed into place
(:func:`atomic_path`), so an interrupted run leaves the old file or the new one, never a truncated one.
Inputs are never modified.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import re
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

import cv2
import numpy as np

from .errors import ImageError, write_error

#: the photo extensions arshadow recognises (OpenCV's image readers): folders are listed by them, ``batch``
#: tells photos from videos by them, ``--keep-format`` keeps them
IMAGE_EXTENSIONS = frozenset(
    {
        ".png",
        ".jpg",
        ".jpeg",
        ".jpe",
        ".bmp",
        ".dib",
        ".tif",
        ".tiff",
        ".webp",
        ".ppm",
        ".pgm",
        ".pnm",
        ".pbm",
        ".pxm",
        ".pfm",
        ".jp2",
        ".exr",
        ".hdr",
        ".pic",
        ".sr",
        ".ras",
        ".avif",
    }
)


def read_image(path: Path | str) -> np.ndarray:
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
    if p.is_dir():
        raise ImageError(f"{p}: folder contains no image files")
    if not p.is_file():
        if any(c in str(p) for c in "*?["):
            raise ImageError(f"{p}: no file matches this pattern")
        raise ImageError(f"{p}: no such image file")
    try:
        data = np.fromfile(str(p), dtype=np.uint8)
    except OSError as exc:
        raise ImageError(f"{p}: cannot read ({exc.strerror or exc})") from None
    if data.size == 0:
        raise ImageError(f"{p}: empty file (0 bytes)")
    if data[:8].tobytes() == b"\x89PNG\r\n\x1a\n" and b"IEND" not in data[-16:].tobytes():
        # libpng would print its own complaint straight to stderr: say it once, ourselves
        raise ImageError(f"{p}: truncated or corrupt PNG (no IEND chunk at the end)")
    try:
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:  # e.g. a header announcing more pixels than OpenCV allows
        raise ImageError(f"{p}: cannot decode image ({str(exc).strip().splitlines()[-1][:120]})") from None
    if img is None or img.size == 0:
        raise ImageError(f"{p}: cannot decode image (corrupt, truncated or unsupported format)")
    return to_bgr8(img, name=str(p))


def exif_orientation(path: Path | str) -> int:
    """The EXIF orientation tag (1..8) of a JPEG or TIFF file; 1 (as stored) when there is none.

    arshadow processes a photo in its stored (sensor) orientation, the one the calibration describes, and
    turns the outputs upright with :func:`apply_orientation` (so portrait phone photos come out as a viewer
    shows them; the outputs carry no EXIF).
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 17)
    except OSError:
        return 1
    return _orientation_from_bytes(head)


def _orientation_from_bytes(b: bytes) -> int:
    import struct

    tiff = None
    if b[:2] == b"\xff\xd8":  # JPEG: walk the segments to APP1 "Exif\0\0"
        i = 2
        while i + 4 <= len(b) and b[i] == 0xFF:
            marker = b[i + 1]
            if marker in (0xD9, 0xDA):  # end of image / start of scan: no EXIF before the pixels
                break
            size = struct.unpack(">H", b[i + 2 : i + 4])[0]
            if marker == 0xE1 and b[i + 4 : i + 10] == b"Exif\0\0":
                tiff = b[i + 10 : i + 2 + size]
                break
            i += 2 + size
    elif b[:4] in (b"II*\0", b"MM\0*"):
        tiff = b
    if not tiff or len(tiff) < 8 or tiff[:2] not in (b"II", b"MM"):
        return 1
    e = "<" if tiff[:2] == b"II" else ">"
    try:
        ifd = struct.unpack(e + "I", tiff[4:8])[0]
        n = struct.unpack(e + "H", tiff[ifd : ifd + 2])[0]
        for k in range(n):
            off = ifd + 2 + 12 * k
            tag, typ = struct.unpack(e + "HH", tiff[off : off + 4])
            if tag == 0x0112 and typ == 3:
                val = struct.unpack(e + "H", tiff[off + 8 : off + 10])[0]
                return int(val) if 1 <= val <= 8 else 1
    except struct.error:
        return 1
    return 1


def apply_orientation(img: np.ndarray, orientation: int) -> np.ndarray:
    """Turn a stored image ``(H, W, ...)`` upright for EXIF ``orientation`` 1..8 (what viewers do)."""
    o = int(orientation)
    if o == 2:
        return img[:, ::-1]
    if o == 3:
        return img[::-1, ::-1]
    if o == 4:
        return img[::-1]
    if o == 5:
        return img.swapaxes(0, 1)
    if o == 6:
        return img.swapaxes(0, 1)[:, ::-1]
    if o == 7:
        return img.swapaxes(0, 1)[::-1, ::-1]
    if o == 8:
        return img.swapaxes(0, 1)[::-1]
    return img


def resolved_path(p: Path | str) -> str:
    """``p`` with links and ``..`` resolved (as given when that fails): compare outputs with the user's
    inputs, which must never be replaced (``{resolved_path(i) for i in inputs}``, built once per run)."""
    try:
        return str(Path(p).resolve())
    except OSError:
        return str(p)


def unique_stems(inputs: Iterable[Path | str], default: str = "image") -> list[str]:
    """An output stem per input: ``photo``, ``photo_2``, ... when names collide (case-insensitively); an
    image-sequence pattern ``frames/img_%04d.png`` gives ``img``, ``frames/%04d.png`` gives ``frames``.

    >>> unique_stems(["a/x.jpg", "b/X.png", "seq/img_%04d.png", "frames/%04d.png"])
    ['x', 'X_2', 'img', 'frames']
    """
    seen: dict[str, int] = {}
    out: list[str] = []
    for inp in inputs:
        p = Path(str(inp))
        stem = re.sub(r"%0?\d*d", "", p.stem).replace("%", "").strip("_.- ") or p.parent.name or default
        n = seen.get(stem.lower(), 0) + 1
        seen[stem.lower()] = n
        out.append(stem if n == 1 else f"{stem}_{n}")
    return out


class InputGuard:
    """The overwrite guard: outputs never replace one of the user's inputs.

    >>> g = InputGuard(["in/a.png"])
    >>> g.clash(["out/a.png", "in/a.png"])
    'in/a.png'
    """

    def __init__(self, inputs: Iterable[Path | str]) -> None:
        self._given = {resolved_path(str(i)) for i in inputs}

    def clash(self, outputs: Iterable[Path | str | None]) -> str | None:
        """The first of ``outputs`` (paths or None) that is an input, else None."""
        return next((str(p) for p in outputs if p is not None and resolved_path(p) in self._given), None)

    def check(self, outputs: Iterable[Path | str | None]) -> None:
        """Raise :class:`ImageError` naming the first output that would replace an input."""
        p = self.clash(outputs)
        if p is not None:
            raise ImageError(f"{p}: output would overwrite an input; choose another -o folder")


def check_output_folder(path: Path | str, what: str = "-o") -> Path:
    """Make sure ``path`` is (or can be created as) a writable folder, before any work is done.

    Raises
    ------
    UsageError
        The path is a file, lies under a file, cannot be created or is not writable.
    """
    from .errors import UsageError

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise UsageError(f"{what} {p}: exists and is not a folder")
    try:
        p.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".arshadow-probe.", dir=p)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UsageError(f"{what} {p}: cannot write there ({exc.strerror or exc})") from None
    return p


def check_output_file(path: Path | str, what: str) -> Path:
    """Make sure a file can be written at ``path`` (not a folder, its folder writable), before any work."""
    from .errors import UsageError

    p = Path(path)
    if p.is_dir():
        raise UsageError(f"{what} {p}: is a folder, give a file name")
    check_output_folder(p.parent if str(p.parent) else Path("."), f"{what} {p}: folder")
    return p


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
def atomic_path(target: Path | str) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; rename it onto ``target`` only if the block succeeds.

    The temporary name keeps ``target``'s extension so that writers choosing a format by extension
    (``cv2.imwrite``) work on it.
    """
    target = Path(target)
    make_folder(target.parent)
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


#: how often :func:`make_folder` recreates a path whose parent another process removed meanwhile
MAKE_FOLDER_TRIES = 50


def make_folder(path: str | Path) -> Path:
    """Create the folder ``path`` and its parents (existing ones are fine); returns it as a Path.

    Tolerates a parent removed by another process between the creation of that parent and of its child
    (a shared folder such as ``OUT/.arshadow-chunks`` that another task removes when it looks empty, see
    :func:`remove_empty_folder`): the whole path is created again, up to :data:`MAKE_FOLDER_TRIES` times.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> make_folder(d / "a" / "b").is_dir()
    True
    """
    p = Path(path)
    for _ in range(MAKE_FOLDER_TRIES - 1):
        try:
            os.makedirs(p, exist_ok=True)
            return p
        except FileNotFoundError:  # a parent made by this call was removed before its child was made
            continue
    os.makedirs(p, exist_ok=True)
    return p


def remove_empty_folder(path: str | Path) -> bool:
    """Remove the folder ``path`` if it is empty, in one system call (``rmdir``); True when removed.

    A folder that is not empty (another task created something in it meanwhile) or already gone is left
    as it is: no check-then-remove window in which another task's sub-folder could be lost.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> (d / "x").mkdir()
    >>> remove_empty_folder(d), remove_empty_folder(d / "x"), remove_empty_folder(d / "x")
    (False, True, False)
    """
    try:
        os.rmdir(path)
    except OSError as exc:
        if exc.errno in (errno.ENOENT, errno.ENOTEMPTY, errno.EEXIST):
            return False
        raise
    return True


def clean_temporaries(folder: Path | str, stem: str | None = None) -> int:
    """Remove the temporary files and folders an interrupted run (``kill -9``) left in ``folder``.

    They are :func:`atomic_path`'s ``.NAME.XXXX.tmp.EXT`` (and folders ``.NAME.XXXX.tmp``); with ``stem``
    only those of the outputs ``<stem>.*`` (another run's temporaries in the same folder are left alone).
    Returns how many were removed.
    """
    import shutil

    d = Path(folder)
    if not d.is_dir():
        return 0
    n = 0
    for p in d.iterdir():
        name = p.name
        if not (name.startswith(".") and ".tmp" in name):
            continue
        if stem is not None and not name.startswith(f".{stem}."):
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                p.unlink()
        n += 1
    return n


def output_mode(folder: bool = False) -> int:
    """The mode of an output file (``0o666``) or folder (``0o777``) less the process's umask: what a plain
    ``open`` / ``mkdir`` would give (``mkstemp`` / ``mkdtemp`` give owner-only 0600 / 0700)."""
    return (0o777 if folder else 0o666) & ~_umask()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_image(path: Path | str, image: np.ndarray, params: Sequence[int] | None = None) -> Path:
    """Write ``image`` atomically; the format follows ``path``'s extension. Returns the path."""
    path = Path(path)
    ok, buf = cv2.imencode(path.suffix or ".png", image, params or [])
    if not ok:
        raise ImageError(f"{path}: cannot encode image as {path.suffix}")
    return write_bytes(path, buf)


def write_bytes(path: Path | str, data: bytes | np.ndarray) -> Path:
    """Write ``data`` (bytes, or an array's buffer) atomically to ``path``."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            _write_file(tmp, data)
    except OSError as exc:  # disk full, permissions, a file where a folder should be...
        raise write_error(f"{path}: cannot write ({exc.strerror or exc}); nothing written", exc) from None
    return path


def _write_file(path: Path, data: bytes | np.ndarray) -> None:
    with open(path, "wb") as fh:
        fh.write(data.data.cast("B") if not isinstance(data, bytes) else data)


def write_json(path: Path | str, obj: object) -> Path:
    """Write ``obj`` as indented JSON atomically (NaN is refused: JSON has none)."""
    return write_bytes(path, (json.dumps(obj, indent=1, allow_nan=False) + "\n").encode())
