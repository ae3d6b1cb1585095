"""The camera model: pinhole intrinsics + OpenCV lens distortion, and the exact OpenGL projection.

Conventions (CONVENTIONS.md): pixel ``(0, 0)`` is the *centre* of the top-left pixel; the camera frame is
OpenCV's (x right, y down, z forward); OpenGL eye space is ``X_gl = diag(1, -1, -1) @ X_cam``; the
distortion model is OpenCV's (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]).

:class:`Intrinsics` is a thin frozen object over plain functions kept in their own modules: the
distortion model in :mod:`arshadow.camera.distortion` (:func:`distort_normalized`, :func:`undistort_normalized`,
re-exported here) and OpenCV FileStorage reading/writing in :mod:`arshadow.camera.cvstorage`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from .._check import check_finite, check_shape
from ..errors import CalibrationError
from .cvstorage import open_storage, read_matrix, read_positive_int, write_storage
from .distortion import DIST_LENGTHS, distort_normalized, undistort_normalized

__all__ = [
    "Intrinsics",
    "distort_normalized",
    "undistort_normalized",
    "DIST_LENGTHS",
    "open_storage",
    "write_storage",
]

#: keys of an OpenCV calibration file (the ones OpenCV's calibration sample writes)
KEY_K, KEY_DIST, KEY_W, KEY_H = "camera_matrix", "distortion_coefficients", "image_width", "image_height"


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

    def __post_init__(self) -> None:
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
    def _key(self) -> tuple[float, float, float, float, int, int, tuple[float, ...]]:
        return (self.fx, self.fy, self.cx, self.cy, self.width, self.height, tuple(self.dist.tolist()))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Intrinsics) and self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        return (
            f"Intrinsics(fx={self.fx:.6g}, fy={self.fy:.6g}, cx={self.cx:.6g}, cy={self.cy:.6g}, "
            f"width={self.width}, height={self.height}, dist={np.round(self.dist, 6).tolist()})"
        )

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
    def from_K(cls, K: npt.ArrayLike, width: int, height: int, dist: npt.ArrayLike = ()) -> Intrinsics:  # noqa: N802
        """Build from a (3, 3) camera matrix (skew must be zero)."""
        K = check_shape(np.asarray(K, dtype=np.float64), "3,3", "camera matrix")
        if abs(K[0, 1]) > 1e-9 * max(1.0, abs(K[0, 0])):
            raise CalibrationError(f"camera matrix has a skew term ({K[0, 1]}); not supported")
        if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0.0:
            raise CalibrationError(f"not a camera matrix (last row {K[2].tolist()})")
        return cls(K[0, 0], K[1, 1], K[0, 2], K[1, 2], width, height, np.asarray(dist, dtype=np.float64))

    # -- files ---------------------------------------------------------------------------------------
    @classmethod
    def from_file(cls, path: Path | str) -> Intrinsics:
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
            K = read_matrix(knode, KEY_K, p)
            if K.size != 9:
                raise CalibrationError(f"{p}: '{KEY_K}' must be 3x3, got {K.size} values")
            K = K.reshape(3, 3)
            model = fs.getNode("distortion_model")
            if not model.empty() and model.isString():
                m = model.string().strip().lower()
                if m not in ("plumb_bob", "rational_polynomial", ""):
                    raise CalibrationError(f"{p}: distortion_model '{m}' is not OpenCV's standard model")
            dnode = fs.getNode(KEY_DIST)
            dist = np.zeros(0) if dnode.empty() else read_matrix(dnode, KEY_DIST, p).ravel()
            w = read_positive_int(fs, KEY_W, p)
            h = read_positive_int(fs, KEY_H, p)
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

    def to_file(self, path: Path | str, **extra: object) -> Path:
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
        return Intrinsics(
            self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5, width, height, self.dist
        )

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
                f"(and is not the same aspect ratio)"
            )
        return self.scaled(width, height), True

    # -- projection ----------------------------------------------------------------------------------
    def project(
        self, points_world: npt.ArrayLike, cam_from_world: npt.ArrayLike | None = None, distort: bool = True
    ) -> np.ndarray:
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
        uv: np.ndarray = np.empty_like(xy)
        uv[:, 0] = self.fx * xy[:, 0] + self.cx
        uv[:, 1] = self.fy * xy[:, 1] + self.cy
        uv[bad] = np.nan
        return uv

    def distort_pixels(self, uv_pinhole: npt.ArrayLike) -> np.ndarray:
        """Pinhole pixel coordinates -> where the distorted camera images them, (n, 2) -> (n, 2)."""
        uv = check_shape(uv_pinhole, "N,2", "uv_pinhole").astype(np.float64)
        if not self.has_distortion:
            return uv.copy()
        xy = np.stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy], axis=1)
        xy = distort_normalized(xy, self.dist)
        return np.stack([xy[:, 0] * self.fx + self.cx, xy[:, 1] * self.fy + self.cy], axis=1)

    def undistort_pixels(self, uv: npt.ArrayLike) -> np.ndarray:
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
    def gl_projection(
        self, znear: float, zfar: float | None = None, canvas: Sequence[float] | None = None
    ) -> np.ndarray:
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
