"""The camera model: pinhole intrinsics + OpenCV lens distortion, and the exact OpenGL projection.

Conventions (CONVENTIONS.md): pixel ``(0, 0)`` is the *centre* of the top-left pixel; the camera frame is
OpenCV's (x right, y down, z forward); OpenGL eye space is ``X_gl = diag(1, -1, -1) @ X_cam``; the
distortion model is OpenCV's (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]).

Plain functions over numpy arrays come first (:func:`distort_normalized`,
:func:`undistort_normalized`); :class:`Intrinsics` is the thin frozen object on top.
"""

from __future__ import annotations

import contextlib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ._check import check_finite, check_shape
from .errors import CalibrationError

__all__ = [
    "Intrinsics",
    "distort_normalized",
    "undistort_normalized",
    "DIST_LENGTHS",
]

#: distortion vector lengths OpenCV accepts
DIST_LENGTHS = (0, 4, 5, 8, 12, 14)

#: keys of an OpenCV calibration file (the ones OpenCV's calibration sample writes)
KEY_K, KEY_DIST, KEY_W, KEY_H = "camera_matrix", "distortion_coefficients", "image_width", "image_height"


# ---------------------------------------------------------------------------------------------------
# distortion model, plain functions
# ---------------------------------------------------------------------------------------------------
def _full14(dist) -> np.ndarray:
    d = np.zeros(14)
    dist = np.asarray(dist, dtype=np.float64).ravel()
    d[: dist.size] = dist
    return d


def _tilt_matrix(tau_x: float, tau_y: float) -> np.ndarray:
    """OpenCV's ``computeTiltProjectionMatrix`` (Scheimpflug sensor tilt), (3, 3) float64."""
    cx, sx, cy, sy = math.cos(tau_x), math.sin(tau_x), math.cos(tau_y), math.sin(tau_y)
    rot_x = np.array([[1, 0, 0], [0, cx, sx], [0, -sx, cx]], dtype=np.float64)
    rot_y = np.array([[cy, 0, -sy], [0, 1, 0], [sy, 0, cy]], dtype=np.float64)
    rxy = rot_y @ rot_x
    proj_z = np.array([[rxy[2, 2], 0, -rxy[0, 2]], [0, rxy[2, 2], -rxy[1, 2]], [0, 0, 1]], dtype=np.float64)
    return proj_z @ rxy


def _distort_core(x, y, d):
    """Radial (rational) + tangential + thin-prism part, without tilt. Returns xd, yd."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d[:12]
    r2 = x * x + y * y
    r4 = r2 * r2
    r6 = r4 * r2
    g = (1.0 + k1 * r2 + k2 * r4 + k3 * r6) / (1.0 + k4 * r2 + k5 * r4 + k6 * r6)
    xy2 = 2.0 * x * y
    xd = x * g + p1 * xy2 + p2 * (r2 + 2.0 * x * x) + s1 * r2 + s2 * r4
    yd = y * g + p1 * (r2 + 2.0 * y * y) + p2 * xy2 + s3 * r2 + s4 * r4
    return xd, yd


def _distort_core_jac(x, y, d):
    """Values and analytic Jacobian of :func:`_distort_core`: (xd, yd, j00, j01, j10, j11).

    Terms whose coefficients are all zero are skipped (the common 5-coefficient case is ~2x faster).
    """
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d[:12]
    x2 = x * x
    y2 = y * y
    r2 = x2 + y2
    r4 = r2 * r2
    a = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    da = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    if k4 or k5 or k6:
        b = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
        db = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
        g = a / b
        dg = (da * b - a * db) / (b * b)  # dg / d(r2)
    else:
        g, dg = a, da
    xy = x * y
    dg2xy = 2.0 * xy * dg
    xd = x * g
    yd = y * g
    j00 = g + 2.0 * x2 * dg
    j11 = g + 2.0 * y2 * dg
    j01 = dg2xy
    j10 = dg2xy.copy()
    if p1 or p2:
        xd += 2.0 * p1 * xy + p2 * (r2 + 2.0 * x2)
        yd += p1 * (r2 + 2.0 * y2) + 2.0 * p2 * xy
        t = 2.0 * p1 * x + 2.0 * p2 * y
        j00 += 2.0 * p1 * y + 6.0 * p2 * x
        j11 += 6.0 * p1 * y + 2.0 * p2 * x
        j01 += t
        j10 += t
    if s1 or s2 or s3 or s4:
        xd += s1 * r2 + s2 * r4
        yd += s3 * r2 + s4 * r4
        px = s1 + 2.0 * s2 * r2
        py = s3 + 2.0 * s4 * r2
        j00 += 2.0 * x * px
        j01 += 2.0 * y * px
        j10 += 2.0 * x * py
        j11 += 2.0 * y * py
    return xd, yd, j00, j01, j10, j11


def distort_normalized(xy, dist) -> np.ndarray:
    """Apply OpenCV's lens distortion to normalized image coordinates.

    Parameters
    ----------
    xy : (n, 2) float64
        Ideal (pinhole) normalized coordinates ``(X/Z, Y/Z)`` in the OpenCV camera frame.
    dist : (k,) float64
        OpenCV distortion coefficients, ``k`` in :data:`DIST_LENGTHS`.

    Returns
    -------
    (n, 2) float64
        Distorted normalized coordinates (multiply by fx, fy and add cx, cy for pixels).

    Examples
    --------
    >>> distort_normalized([[0.1, 0.0]], [-0.2, 0, 0, 0]).round(6).tolist()
    [[0.0998, 0.0]]
    """
    xy = check_shape(xy, "N,2", "xy").astype(np.float64)
    d = _full14(dist)
    xd, yd = _distort_core(xy[:, 0], xy[:, 1], d)
    if d[12] != 0.0 or d[13] != 0.0:
        m = _tilt_matrix(d[12], d[13])
        w = m[2, 0] * xd + m[2, 1] * yd + m[2, 2]
        xd, yd = (m[0, 0] * xd + m[0, 1] * yd + m[0, 2]) / w, (m[1, 0] * xd + m[1, 1] * yd + m[1, 2]) / w
    return np.stack([xd, yd], axis=1)


def undistort_normalized(xy_d, dist, *, tol=1e-12, max_iter=50) -> np.ndarray:
    """Exact inverse of :func:`distort_normalized` by damped Newton iteration (vectorised).

    Parameters
    ----------
    xy_d : (n, 2) float64
        Distorted normalized coordinates.
    dist : (k,) float64
        OpenCV distortion coefficients.
    tol : float
        Convergence threshold on the residual in normalized units (1e-12 ~ 1e-9 px at f = 1000).
    max_iter : int
        Iteration limit. Points that do not converge (outside the region where the distortion model is
        invertible, e.g. beyond the fold of a strong barrel distortion) come back as NaN.

    Returns
    -------
    (n, 2) float64
        Ideal normalized coordinates ``xy`` with ``distort_normalized(xy) == xy_d``.

    Examples
    --------
    >>> d = [-0.25, 0.05, 0.001, -0.002, 0.0]
    >>> xy = undistort_normalized(distort_normalized([[0.3, -0.2]], d), d)
    >>> bool(np.allclose(xy, [[0.3, -0.2]], atol=1e-12))
    True
    """
    xy_d = check_shape(xy_d, "N,2", "xy_d").astype(np.float64)
    d = _full14(dist)
    tx, ty = xy_d[:, 0].copy(), xy_d[:, 1].copy()
    if d[12] != 0.0 or d[13] != 0.0:  # the tilt is a homography: invert it exactly first
        m = np.linalg.inv(_tilt_matrix(d[12], d[13]))
        w = m[2, 0] * tx + m[2, 1] * ty + m[2, 2]
        tx, ty = (m[0, 0] * tx + m[0, 1] * ty + m[0, 2]) / w, (m[1, 0] * tx + m[1, 1] * ty + m[1, 2]) / w
    if not np.any(d[:12]):
        return np.stack([tx, ty], axis=1)
    x, y = tx.copy(), ty.copy()
    n = x.size
    done = np.zeros(n, dtype=bool)
    # phase 1: whole-array Newton with per-point backtracking (no fancy indexing: fast for image maps)
    px, py = x.copy(), y.copy()  # last accepted iterate
    prev = np.full(n, np.inf)
    it = 0
    for it in range(min(max_iter, 12)):  # noqa: B007 - `it` counts the iterations spent, used below
        xd, yd, j00, j01, j10, j11 = _distort_core_jac(x, y, d)
        ex, ey = xd - tx, yd - ty
        res = np.hypot(ex, ey)
        worse = ~(res <= prev)  # includes NaN
        done = res < tol
        if done.all():
            break
        det = j00 * j11 - j01 * j10
        det[np.abs(det) < 1e-300] = 1e-300
        nx = x - (j11 * ex - j01 * ey) / det
        ny = y - (-j10 * ex + j00 * ey) / det
        if worse.any():  # backtrack these points halfway to their last accepted iterate
            nx = np.where(worse, 0.5 * (x + px), nx)
            ny = np.where(worse, 0.5 * (y + py), ny)
            res = np.where(worse, prev, res)
            x = np.where(worse, px, x)
            y = np.where(worse, py, y)
        px, py, prev = x, y, res
        x, y = np.where(done, x, nx), np.where(done, y, ny)
    # phase 2: the few stragglers, by index (points beyond the model's fold end as NaN)
    active = np.flatnonzero(~done)
    for _ in range(max_iter - it):
        if active.size == 0:
            break
        xa, ya = x[active], y[active]
        xd, yd, j00, j01, j10, j11 = _distort_core_jac(xa, ya, d)
        ex, ey = xd - tx[active], yd - ty[active]
        res = np.hypot(ex, ey)
        conv = res < tol
        done[active[conv]] = True
        keep = ~conv
        active, xa, ya, ex, ey, res = active[keep], xa[keep], ya[keep], ex[keep], ey[keep], res[keep]
        j00, j01, j10, j11 = j00[keep], j01[keep], j10[keep], j11[keep]
        if active.size == 0:
            break
        det = j00 * j11 - j01 * j10
        det = np.where(np.abs(det) < 1e-300, 1e-300, det)
        sx = (j11 * ex - j01 * ey) / det
        sy = (-j10 * ex + j00 * ey) / det
        step = np.ones_like(sx)
        nx, ny = xa - sx, ya - sy
        for _ in range(8):  # damping: halve the step where it does not reduce the residual
            xd2, yd2 = _distort_core(nx, ny, d)
            worse = ~(np.hypot(xd2 - tx[active], yd2 - ty[active]) <= res)
            if not np.any(worse):
                break
            step = np.where(worse, step * 0.5, step)
            nx, ny = xa - step * sx, ya - step * sy
        x[active], y[active] = nx, ny
    out = np.stack([x, y], axis=1)
    out[~done] = np.nan
    return out


# ---------------------------------------------------------------------------------------------------
# file helpers
# ---------------------------------------------------------------------------------------------------
@contextlib.contextmanager
def open_storage(path, what: str, error=CalibrationError):
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
def write_storage(path, what: str, error=CalibrationError):
    """Open an OpenCV FileStorage for writing ``path`` atomically (format from the extension)."""
    from .io import atomic_path

    p = Path(path)
    with atomic_path(p) as tmp:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise error(f"{p}: cannot write {what}")
        try:
            yield fs
        finally:
            fs.release()


def _node_array(node, name: str, path) -> np.ndarray:
    """Read an OpenCV matrix node, a ROS-style {rows, cols, data} map, or a plain sequence."""
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


def _read_int(fs, key, path) -> int:
    node = fs.getNode(key)
    if node.empty():
        raise CalibrationError(f"{path}: missing key '{key}'")
    if not (node.isInt() or node.isReal()):
        raise CalibrationError(f"{path}: key '{key}' is not a number")
    v = node.real()
    if not math.isfinite(v) or v != int(v) or v <= 0:
        raise CalibrationError(f"{path}: key '{key}' must be a positive integer, got {v}")
    return int(v)


# ---------------------------------------------------------------------------------------------------
# Intrinsics
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Intrinsics:
    """Pinhole intrinsics + OpenCV distortion for one image size.

    Parameters
    ----------
    fx, fy : float
        Focal lengths in pixels (> 0).
    cx, cy : float
        Principal point in pixels (pixel-centre convention: (0, 0) is the centre of the top-left pixel).
    width, height : int
        Image size in pixels the calibration belongs to.
    dist : (k,) float64
        OpenCV distortion coefficients, ``k`` in (0, 4, 5, 8, 12, 14); stored read-only.

    Examples
    --------
    >>> cam = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    >>> cam.project([[0.0, 0.0, 1.0]], np.eye(4)).tolist()
    [[639.5, 359.5]]
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    dist: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self):
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise CalibrationError(f"{name} must be a number, got {v!r}") from None
            if not math.isfinite(v):
                raise CalibrationError(f"{name} is not finite ({v})")
            object.__setattr__(self, name, v)
        if self.fx <= 0 or self.fy <= 0:
            raise CalibrationError(f"focal lengths must be positive (fx={self.fx}, fy={self.fy})")
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, float) and v.is_integer():
                v = int(v)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v <= 0:
                raise CalibrationError(f"image {name} must be a positive integer, got {v!r}")
            object.__setattr__(self, name, int(v))
        d = np.array(self.dist if self.dist is not None else [], dtype=np.float64).ravel()
        if d.size not in DIST_LENGTHS:
            raise CalibrationError(f"distortion must have 0, 4, 5, 8, 12 or 14 coefficients, got {d.size}")
        if not np.all(np.isfinite(d)):
            raise CalibrationError("distortion coefficients contain NaN or inf")
        d.setflags(write=False)
        object.__setattr__(self, "dist", d)

    # -- value semantics ---------------------------------------------------------------------------
    def _key(self):
        return (self.fx, self.fy, self.cx, self.cy, self.width, self.height, tuple(self.dist.tolist()))

    def __eq__(self, other):
        return isinstance(other, Intrinsics) and self._key() == other._key()

    def __hash__(self):
        return hash(self._key())

    def __repr__(self):
        return (f"Intrinsics(fx={self.fx:.6g}, fy={self.fy:.6g}, cx={self.cx:.6g}, cy={self.cy:.6g}, "
                f"width={self.width}, height={self.height}, dist={np.round(self.dist, 6).tolist()})")

    # -- basic properties --------------------------------------------------------------------------
    @property
    def K(self) -> np.ndarray:  # noqa: N802 (the usual name)
        """(3, 3) float64 camera matrix (a fresh copy)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)``."""
        return (self.width, self.height)

    @property
    def has_distortion(self) -> bool:
        """True when any distortion coefficient is non-zero."""
        return bool(np.any(self.dist != 0.0))

    @property
    def dist_cv(self) -> np.ndarray:
        """Distortion as OpenCV functions want it: (k,) float64, or (5,) zeros when empty (a copy)."""
        return self.dist.copy() if self.dist.size else np.zeros(5)

    @classmethod
    def from_K(cls, K, width, height, dist=()):  # noqa: N802
        """Build from a (3, 3) camera matrix (skew must be zero)."""
        K = check_shape(np.asarray(K, dtype=np.float64), "3,3", "camera matrix")
        if abs(K[0, 1]) > 1e-9 * max(1.0, abs(K[0, 0])):
            raise CalibrationError(f"camera matrix has a skew term ({K[0, 1]}); not supported")
        if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0.0:
            raise CalibrationError(f"not a camera matrix (last row {K[2].tolist()})")
        return cls(K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height, np.asarray(dist, dtype=np.float64))

    # -- files ---------------------------------------------------------------------------------------
    @classmethod
    def from_file(cls, path) -> Intrinsics:
        """Read an OpenCV FileStorage calibration (YAML/XML/JSON) or a ROS ``camera_info`` YAML.

        Keys: ``camera_matrix`` (3x3), ``distortion_coefficients`` (1xN or Nx1, optional = none),
        ``image_width``, ``image_height``. Matrices may be ``!!opencv-matrix`` nodes or plain
        ``{rows, cols, data}`` maps (ROS, OpenCV's older samples). ROS ``distortion_model`` must be
        ``plumb_bob`` or ``rational_polynomial`` when present.

        Raises
        ------
        CalibrationError
            Missing/unreadable file, missing key, non-finite or non-positive focal length, bad size.
        """
        p = Path(path)
        with open_storage(p, "calibration file") as fs:
            knode = fs.getNode(KEY_K)
            if knode.empty():
                raise CalibrationError(f"{p}: missing key '{KEY_K}'")
            K = _node_array(knode, KEY_K, p)
            if K.size != 9:
                raise CalibrationError(f"{p}: '{KEY_K}' must be 3x3, got {K.size} values")
            K = K.reshape(3, 3)
            model = fs.getNode("distortion_model")
            if not model.empty() and model.isString():
                m = model.string().strip().lower()
                if m not in ("plumb_bob", "rational_polynomial", ""):
                    raise CalibrationError(f"{p}: distortion_model '{m}' is not OpenCV's standard model")
            dnode = fs.getNode(KEY_DIST)
            dist = np.zeros(0) if dnode.empty() else _node_array(dnode, KEY_DIST, p).ravel()
            w = _read_int(fs, KEY_W, p)
            h = _read_int(fs, KEY_H, p)
        if not np.all(np.isfinite(K)):
            raise CalibrationError(f"{p}: '{KEY_K}' contains NaN or inf")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibrationError(f"{p}: focal lengths must be positive (fx={K[0, 0]}, fy={K[1, 1]})")
        # ROS files carry 0 for unused trailing coefficients; OpenCV lengths only
        if dist.size not in DIST_LENGTHS:
            padded = next((n for n in DIST_LENGTHS if n >= dist.size), None)
            if padded is None:
                raise CalibrationError(f"{p}: {dist.size} distortion coefficients (at most 14)")
            dist = np.concatenate([dist, np.zeros(padded - dist.size)])
        try:
            return cls.from_K(K, w, h, dist)
        except CalibrationError as exc:
            raise CalibrationError(f"{p}: {exc}") from None

    def to_file(self, path, **extra) -> Path:
        """Write an OpenCV FileStorage calibration (format from the extension: .yml/.yaml/.xml/.json).

        ``extra`` keys are written too: numbers, strings, lists of strings, or arrays (as matrices), e.g.
        ``rms=0.39, per_view_errors=np.array([...])``. The file is written atomically.
        """
        p = Path(path)
        if p.suffix.lower() not in (".yml", ".yaml", ".xml", ".json"):
            raise CalibrationError(f"{p}: calibration files must end in .yml, .yaml, .xml or .json")
        with write_storage(p, "calibration file") as fs:
            fs.write(KEY_W, int(self.width))
            fs.write(KEY_H, int(self.height))
            fs.write(KEY_K, self.K)
            fs.write(KEY_DIST, self.dist.reshape(1, -1) if self.dist.size else np.zeros((1, 5)))
            for k, v in extra.items():
                if v is None:
                    continue
                if isinstance(v, (bool, np.bool_)):
                    fs.write(k, int(v))
                elif isinstance(v, (int, np.integer)):
                    fs.write(k, int(v))
                elif isinstance(v, (float, np.floating)):
                    fs.write(k, float(v))
                elif isinstance(v, str):
                    fs.write(k, v)
                elif isinstance(v, (list, tuple)) and all(isinstance(x, str) for x in v):
                    fs.startWriteStruct(k, cv2.FileNode_SEQ)
                    for x in v:
                        fs.write("", x)
                    fs.endWriteStruct()
                else:
                    arr = np.asarray(v, dtype=np.float64)
                    fs.write(k, arr.reshape(-1, 1) if arr.ndim == 1 else arr)
        return p

    # -- resolution ----------------------------------------------------------------------------------
    def scaled(self, width: int, height: int) -> Intrinsics:
        """The same camera at another resolution (pixel-centre exact: ``u' + 0.5 = s (u + 0.5)``).

        Examples
        --------
        >>> Intrinsics(1000, 1000, 639.5, 359.5, 1280, 720).scaled(640, 360).cx
        319.5
        """
        sx, sy = width / self.width, height / self.height
        return Intrinsics(self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5,
                          width, height, self.dist)

    def for_image(self, width: int, height: int) -> tuple[Intrinsics, bool]:
        """Intrinsics for an image of ``width x height``: ``(intrinsics, was_scaled)``.

        Raises
        ------
        CalibrationError
            The image's aspect ratio differs from the calibration's (by more than one pixel).
        """
        width, height = int(width), int(height)
        if (width, height) == (self.width, self.height):
            return self, False
        if width <= 0 or height <= 0 or abs(width * self.height / self.width - height) > 1.0:
            raise CalibrationError(
                f"image size {width}x{height} does not match the calibration's {self.width}x{self.height} "
                f"(and is not the same aspect ratio)")
        return self.scaled(width, height), True

    # -- projection ----------------------------------------------------------------------------------
    def project(self, points_world, cam_from_world=None, distort: bool = True) -> np.ndarray:
        """Project world points to pixels.

        Parameters
        ----------
        points_world : (n, 3) float64
            Points in the world frame.
        cam_from_world : (4, 4) float64, optional
            World -> OpenCV camera transform (identity when omitted: points in the camera frame).
        distort : bool
            Apply the lens distortion (True: where the real camera images them; False: pinhole).

        Returns
        -------
        (n, 2) float64
            Pixel coordinates (pixel-centre convention); NaN for points with camera z <= 0.
        """
        p = check_finite(check_shape(points_world, "N,3", "points_world"), "points_world")
        if cam_from_world is not None:
            m = check_shape(np.asarray(cam_from_world, dtype=np.float64), "4,4", "cam_from_world")
            p = p @ m[:3, :3].T + m[:3, 3]
        z = p[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = p[:, :2] / z[:, None]
        bad = ~(z > 0)
        xy[bad] = 0.0
        if distort and self.has_distortion:
            xy = distort_normalized(xy, self.dist)
        uv = np.empty_like(xy)
        uv[:, 0] = self.fx * xy[:, 0] + self.cx
        uv[:, 1] = self.fy * xy[:, 1] + self.cy
        uv[bad] = np.nan
        return uv

    def distort_pixels(self, uv_pinhole) -> np.ndarray:
        """Pinhole pixel coordinates -> where the distorted camera images them, (n, 2) -> (n, 2)."""
        uv = check_shape(uv_pinhole, "N,2", "uv_pinhole").astype(np.float64)
        if not self.has_distortion:
            return uv.copy()
        xy = np.stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy], axis=1)
        xy = distort_normalized(xy, self.dist)
        return np.stack([xy[:, 0] * self.fx + self.cx, xy[:, 1] * self.fy + self.cy], axis=1)

    def undistort_pixels(self, uv) -> np.ndarray:
        """Distorted pixel coordinates -> pinhole pixel coordinates (exact inverse, < 1e-6 px).

        Parameters
        ----------
        uv : (n, 2) float64
            Pixels of the real (distorted) image.

        Returns
        -------
        (n, 2) float64
            Where an ideal pinhole camera with the same K images the same rays. NaN where the
            distortion model cannot be inverted (beyond its fold; never inside a sane calibration's image).

        Examples
        --------
        >>> cam = Intrinsics(1000, 1000, 639.5, 359.5, 1280, 720, np.array([-0.25, 0.0, 0.0, 0.0]))
        >>> uv = cam.project([[0.3, 0.2, 1.0]], np.eye(4))
        >>> bool(np.allclose(cam.undistort_pixels(uv), cam.project([[0.3, 0.2, 1.0]], None, distort=False)))
        True
        """
        uv = check_shape(uv, "N,2", "uv").astype(np.float64)
        if not self.has_distortion:
            return uv.copy()
        xy = np.stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy], axis=1)
        # 1e-6 px / f in normalized units, with a 1000x margin
        xy = undistort_normalized(xy, self.dist, tol=1e-9 / max(self.fx, self.fy))
        return np.stack([xy[:, 0] * self.fx + self.cx, xy[:, 1] * self.fy + self.cy], axis=1)

    def pixel_grid(self) -> np.ndarray:
        """(height * width, 2) float64 pixel centres, row-major."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        return np.stack([u.ravel(), v.ravel()], axis=1)

    # -- OpenGL ---------------------------------------------------------------------------------------
    def gl_projection(self, znear: float, zfar: float | None = None, canvas=None) -> np.ndarray:
        """OpenGL clip-from-eye matrix of this (pinhole) camera, exact to the pixel-centre convention.

        Eye coordinates are OpenGL's: ``X_gl = diag(1, -1, -1) @ X_cam``. A camera point imaged at
        OpenCV pixel ``(u, v)`` (without distortion) lands at ``x_ndc = 2(u - u0 + 0.5)/w - 1``,
        ``y_ndc = 1 - 2(v - v0 + 0.5)/h`` — the centre of that pixel in a ``w x h`` viewport showing the
        pixel rectangle ``[u0, u0 + w) x [v0, v0 + h)``.

        Parameters
        ----------
        znear : float
            Near plane distance (> 0, metres).
        zfar : float or None
            Far plane distance (> znear), or None for an infinite far plane (depth ``1 - 2 znear / d``
            stays inside [-1, 1) for every point beyond the near plane).
        canvas : (u0, v0, w, h), optional
            The pixel sub-rectangle to render (u0, v0 may be negative or beyond the image); default
            ``(0, 0, width, height)``.

        Returns
        -------
        (4, 4) float64
            ``clip_from_gl_eye`` for column vectors (``clip = M @ (x, y, z, 1)``). GLSL matrices are
            column-major: upload ``M.T.astype('f4').tobytes()``.
        """
        znear = float(znear)
        if not (math.isfinite(znear) and znear > 0):
            raise CalibrationError(f"znear must be positive and finite, got {znear}")
        if zfar is not None:
            zfar = float(zfar)
            if not (math.isfinite(zfar) and zfar > znear):
                raise CalibrationError(f"zfar must be finite and > znear ({znear}), got {zfar}")
        if canvas is None:
            u0, v0, w, h = 0.0, 0.0, float(self.width), float(self.height)
        else:
            u0, v0, w, h = (float(c) for c in canvas)
            if not (w > 0 and h > 0 and all(math.isfinite(c) for c in (u0, v0, w, h))):
                raise CalibrationError(f"canvas must be (u0, v0, w > 0, h > 0), got {tuple(canvas)}")
        m = np.zeros((4, 4))
        m[0, 0] = 2.0 * self.fx / w
        m[0, 2] = 1.0 - 2.0 * (self.cx - u0 + 0.5) / w
        m[1, 1] = 2.0 * self.fy / h
        m[1, 2] = 2.0 * (self.cy - v0 + 0.5) / h - 1.0
        if zfar is None:
            m[2, 2] = -1.0
            m[2, 3] = -2.0 * znear
        else:
            m[2, 2] = -(zfar + znear) / (zfar - znear)
            m[2, 3] = -2.0 * zfar * znear / (zfar - znear)
        m[3, 2] = -1.0
        return m
