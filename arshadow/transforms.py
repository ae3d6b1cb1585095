"""Rigid transforms and the one place where OpenCV and OpenGL axes meet.

Frames (see CONVENTIONS.md): world = marker frame (z up, out of the printed face); camera = OpenCV's
(x right, y down, z forward); ``X_cam = R @ X_world + t`` with ``(rvec, tvec)`` from ``cv2.solvePnP``
(that transform is called ``cam_from_world``). OpenGL eye space is ``CV_TO_GL @ X_cam``.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from ._check import check_finite, check_shape

#: (4, 4) float64: OpenCV camera frame -> OpenGL eye frame (flip y and z).
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


def matrix_from_rvec_tvec(rvec: npt.ArrayLike, tvec: npt.ArrayLike) -> np.ndarray:
    """Build ``cam_from_world`` from a Rodrigues vector and a translation.

    Parameters
    ----------
    rvec : (3,) float64
        Rodrigues rotation vector (world -> camera), as ``cv2.solvePnP`` returns it.
    tvec : (3,) float64
        Translation (world -> camera), metres.

    Returns
    -------
    (4, 4) float64
        ``cam_from_world``.

    Examples
    --------
    >>> matrix_from_rvec_tvec([0, 0, 0], [0, 0, 1])[:3, 3].tolist()
    [0.0, 0.0, 1.0]
    """
    rvec = check_finite(check_shape(np.ravel(rvec), "3", "rvec"), "rvec")
    tvec = check_finite(check_shape(np.ravel(tvec), "3", "tvec"), "tvec")
    m = np.eye(4)
    m[:3, :3] = cv2.Rodrigues(rvec.reshape(3, 1))[0]
    m[:3, 3] = tvec
    return m


def rvec_tvec_from_matrix(m: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`matrix_from_rvec_tvec`: ``(4, 4)`` -> ``((3,) rvec, (3,) tvec)`` float64."""
    m = check_shape(m, "4,4", "transform").astype(np.float64)
    rvec = cv2.Rodrigues(m[:3, :3])[0].ravel()
    return rvec, m[:3, 3].copy()


def invert_rigid(m: npt.ArrayLike) -> np.ndarray:
    """Invert a rigid ``(4, 4)`` transform exactly (``R.T``, ``-R.T @ t``)."""
    m = check_shape(m, "4,4", "transform").astype(np.float64)
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


def transform_points(m: npt.ArrayLike, points: npt.ArrayLike) -> np.ndarray:
    """Apply a ``(4, 4)`` transform to ``(n, 3)`` points; returns ``(n, 3)`` float64."""
    p = check_shape(points, "N,3", "points").astype(np.float64)
    m = np.asarray(m, dtype=np.float64)
    out: np.ndarray = p @ m[:3, :3].T + m[:3, 3]
    return out


def rotation_error_deg(r_a: npt.ArrayLike, r_b: npt.ArrayLike) -> float:
    """Angle in degrees of the rotation ``R_a @ R_b.T``.

    Parameters
    ----------
    r_a, r_b : (3,) Rodrigues vectors, (3, 3) rotations or (4, 4) rigid transforms (rotation part used)

    ``atan2`` of the skew and symmetric parts keeps full precision near 0 and 180 degrees, where
    ``arccos((trace - 1) / 2)`` loses digits.

    Examples
    --------
    >>> rotation_error_deg(np.eye(3), np.diag([1.0, -1.0, -1.0]))
    180.0
    """

    def as_mat(r: npt.ArrayLike) -> np.ndarray:
        r = np.asarray(r, dtype=np.float64)
        return cv2.Rodrigues(r.reshape(3, 1))[0] if r.size == 3 else r[:3, :3]

    d = as_mat(r_a) @ as_mat(r_b).T
    c = (np.trace(d) - 1.0) / 2.0
    s = 0.5 * np.sqrt((d[2, 1] - d[1, 2]) ** 2 + (d[0, 2] - d[2, 0]) ** 2 + (d[1, 0] - d[0, 1]) ** 2)
    return float(np.degrees(np.arctan2(s, c)))


#: rotation angle (radians) above which :func:`rotation_vectors` takes ``cv2.Rodrigues`` per matrix: near
#: pi the antisymmetric part of ``R`` no longer carries the axis accurately
NEAR_PI_RAD = 2.5


def rotation_vectors(R: npt.ArrayLike) -> np.ndarray:
    """Rotation vectors (axis x angle, radians) of a stack of rotation matrices: ``cv2.Rodrigues`` of each,
    vectorised (the video pose smoothing takes 21 a frame; one call each cost 0.1 ms).

    The angle is ``atan2(|v|, (trace - 1) / 2)`` with ``v`` the antisymmetric part's vector (``sin`` of the
    angle times the axis), accurate at small angles; matrices turned by more than :data:`NEAR_PI_RAD` go
    through ``cv2.Rodrigues`` one by one.

    Parameters
    ----------
    R : (n, 3, 3) float64
        Rotation matrices.

    Returns
    -------
    (n, 3) float64

    Examples
    --------
    >>> Rz = cv2.Rodrigues(np.array([0.0, 0.0, 0.3]))[0]
    >>> rotation_vectors(np.stack([Rz, np.eye(3)])).round(12).tolist()
    [[0.0, 0.0, 0.3], [0.0, 0.0, 0.0]]
    """
    R = np.asarray(R, np.float64).reshape(-1, 3, 3)
    v = 0.5 * np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], axis=1)
    s = np.linalg.norm(v, axis=1)
    c = 0.5 * (R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2] - 1.0)
    theta = np.arctan2(s, c)
    scale = np.divide(theta, s, out=np.ones_like(theta), where=s > 1e-300)
    out: np.ndarray = v * scale[:, None]
    for i in np.flatnonzero(theta > NEAR_PI_RAD):
        out[i] = cv2.Rodrigues(np.ascontiguousarray(R[i]))[0].ravel()
    return out
