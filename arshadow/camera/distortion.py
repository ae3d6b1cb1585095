"""OpenCV's lens distortion model as plain functions over numpy arrays (no OpenCV call).

Normalised image coordinates ``(n, 2) float64`` (``x = X / Z``, ``y = Y / Z`` in the camera frame) are
distorted (:func:`distort_normalized`) and undistorted (:func:`undistort_normalized`, Newton's method with
the analytic Jacobian) with OpenCV's coefficients ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]])``.
:class:`arshadow.camera.Intrinsics` applies them to pixels.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from .._check import check_shape

__all__ = ["DIST_LENGTHS", "distort_normalized", "undistort_normalized"]

#: distortion vector lengths OpenCV accepts
DIST_LENGTHS = (0, 4, 5, 8, 12, 14)


def _full14(dist: npt.ArrayLike) -> np.ndarray:
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


def _distort_core(x: np.ndarray, y: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


def _distort_core_jac(
    x: np.ndarray, y: np.ndarray, d: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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


def distort_normalized(xy: npt.ArrayLike, dist: npt.ArrayLike) -> np.ndarray:
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


def undistort_normalized(
    xy_d: npt.ArrayLike, dist: npt.ArrayLike, *, tol: float = 1e-12, max_iter: int = 50
) -> np.ndarray:
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
    x, y, done, it = _newton_whole(tx.copy(), ty.copy(), tx, ty, d, tol, min(max_iter, 12))
    _newton_stragglers(x, y, tx, ty, d, done, tol, max_iter - it)
    out = np.stack([x, y], axis=1)
    out[~done] = np.nan
    return out


def _newton_whole(
    x: np.ndarray, y: np.ndarray, tx: np.ndarray, ty: np.ndarray, d: np.ndarray, tol: float, iters: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Phase 1 of :func:`undistort_normalized`: whole-array Newton with per-point backtracking (no fancy
    indexing: fast for image maps). Returns ``(x, y, done, it)``, ``it`` the index of the last iteration."""
    n = x.size
    done = np.zeros(n, dtype=bool)
    px, py = x.copy(), y.copy()  # last accepted iterate
    prev = np.full(n, np.inf)
    it = 0
    for it in range(iters):  # noqa: B007 - `it` counts the iterations spent, used below
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
    return x, y, done, it


def _newton_stragglers(
    x: np.ndarray,
    y: np.ndarray,
    tx: np.ndarray,
    ty: np.ndarray,
    d: np.ndarray,
    done: np.ndarray,
    tol: float,
    iters: int,
) -> None:
    """Phase 2 of :func:`undistort_normalized`: the few points not ``done``, by index, with a damped step;
    updates ``x``, ``y`` and ``done`` in place (points beyond the model's fold stay not done)."""
    active = np.flatnonzero(~done)
    for _ in range(iters):
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
