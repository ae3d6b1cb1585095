"""Bundle adjustment of a marker map: every marker pose and camera pose, fitted to the detected corners.

Frames: the map's frame is the reference marker's (its pose is fixed to the identity, which fixes the gauge);
``ref_from_marker`` (4, 4) places a marker's corners (its own marker frame, :func:`marker_object_points`)
in the map; ``cam_from_ref`` (4, 4) is a frame's camera pose (OpenCV camera). The corners are compared in
*normalised pinhole* coordinates (undistorted once, before the fit: the lens model stays out of the loop)
scaled by the focal lengths, so a residual is in pixels.

The solver is :func:`scipy.optimize.least_squares` (trust region, robust soft-L1 loss, its Jacobian by finite
differences over the sparse structure given by ``jac_sparsity``: an observation's 8 residuals depend only
on its marker's 6 and its frame's 6 parameters).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

__all__ = ["BundleResult", "bundle_adjust", "rodrigues_many", "project_normalised"]

#: scale of the robust loss, pixels (a corner detected to a fraction of a pixel is an inlier). Soft-L1, not
#: Huber: on the real six-marker clip scipy's trust region with Huber had not converged after 200
#: evaluations (3.2 s); soft-L1 converges in 13 (0.25 s) to the same map (inter-marker distances within
#: 0.2 mm)
LOSS_SCALE_PX = 1.0


def rodrigues_many(rvecs: np.ndarray) -> np.ndarray:
    """Rotation matrices of ``rvecs (n, 3)`` float64 axis-angle vectors: ``(n, 3, 3)`` float64.

    >>> import cv2
    >>> r = np.array([[0.1, -0.2, 0.3], [0.0, 0.0, 0.0]])
    >>> bool(np.allclose(rodrigues_many(r)[0], cv2.Rodrigues(r[0])[0]))
    True
    """
    r = np.asarray(rvecs, np.float64).reshape(-1, 3)
    th = np.linalg.norm(r, axis=1)
    small = th < 1e-12
    k = r / np.where(small, 1.0, th)[:, None]
    kx, ky, kz = k[:, 0], k[:, 1], k[:, 2]
    z = np.zeros_like(kx)
    K = np.stack([np.stack([z, -kz, ky], 1), np.stack([kz, z, -kx], 1), np.stack([-ky, kx, z], 1)], 1)
    s, c = np.sin(th)[:, None, None], (1.0 - np.cos(th))[:, None, None]
    R = np.eye(3) + s * K + c * (K @ K)
    R[small] = np.eye(3)
    out: np.ndarray = R
    return out


def project_normalised(
    marker_rt: np.ndarray, cam_rt: np.ndarray, local: np.ndarray, obs_marker: np.ndarray, obs_frame: np.ndarray
) -> np.ndarray:
    """Normalised pinhole coordinates of every observed corner: ``(n, 4, 2)`` float64.

    Parameters
    ----------
    marker_rt : (m, 6) float64
        ``ref_from_marker`` per marker as (rvec, tvec).
    cam_rt : (f, 6) float64
        ``cam_from_ref`` per frame as (rvec, tvec).
    local : (m, 4, 3) float64
        Each marker's corners in its own frame.
    obs_marker, obs_frame : (n,) int
        Marker and frame index of each observation.
    """
    Rm, Rc = rodrigues_many(marker_rt[:, :3]), rodrigues_many(cam_rt[:, :3])
    ref = np.einsum("mij,mkj->mki", Rm, local) + marker_rt[:, None, 3:]  # (m, 4, 3) in the map
    p = np.einsum("nij,nkj->nki", Rc[obs_frame], ref[obs_marker]) + cam_rt[obs_frame, None, 3:]
    z = np.where(np.abs(p[..., 2]) < 1e-9, 1e-9, p[..., 2])
    uv: np.ndarray = p[..., :2] / z[..., None]
    return uv


@dataclass
class BundleResult:
    """What :func:`bundle_adjust` returns: the fitted poses and the (non-robust) residuals.

    Attributes
    ----------
    marker_rt : (m, 6) float64
        ``ref_from_marker`` (rvec, tvec) per marker (the reference's is zero).
    cam_rt : (f, 6) float64
        ``cam_from_ref`` (rvec, tvec) per frame.
    residual_px : (n,) float64
        RMS corner reprojection error of each observation, pixels.
    nfev : int
        Function evaluations spent.
    """

    marker_rt: np.ndarray
    cam_rt: np.ndarray
    residual_px: np.ndarray
    nfev: int


def _sparsity(
    n_obs: int, n_free_markers: int, n_frames: int, obs_free: np.ndarray, obs_frame: np.ndarray
) -> Any:  # a scipy.sparse CSR matrix
    """(8 n, 6 m' + 6 f) 0/1 structure: rows of an observation, columns of its marker and its frame."""
    rows, cols = [], []
    r = np.arange(n_obs)[:, None] * 8 + np.arange(8)[None, :]  # (n, 8)
    fc = 6 * n_free_markers + obs_frame[:, None] * 6 + np.arange(6)[None, :]  # (n, 6)
    rows.append(np.repeat(r, 6, axis=1).ravel())
    cols.append(np.tile(fc, (1, 8)).ravel())
    has = obs_free >= 0
    mc = obs_free[has, None] * 6 + np.arange(6)[None, :]
    rows.append(np.repeat(r[has], 6, axis=1).ravel())
    cols.append(np.tile(mc, (1, 8)).ravel())
    rr, cc = np.concatenate(rows), np.concatenate(cols)
    shape = (8 * n_obs, 6 * (n_free_markers + n_frames))
    return coo_matrix((np.ones(rr.size, np.int8), (rr, cc)), shape=shape).tocsr()


def bundle_adjust(  # noqa: PLR0913 -- the sparse problem's arrays, as least_squares takes them
    marker_rt: np.ndarray,
    cam_rt: np.ndarray,
    local: np.ndarray,
    obs_marker: np.ndarray,
    obs_frame: np.ndarray,
    obs_norm: np.ndarray,
    focal: np.ndarray,
    ref_index: int,
    max_nfev: int = 60,
) -> BundleResult:
    """Fit every marker pose (but the reference's) and every camera pose to the observed corners.

    Parameters
    ----------
    marker_rt : (m, 6) float64
        Initial ``ref_from_marker`` (rvec, tvec); row ``ref_index`` is held at zero.
    cam_rt : (f, 6) float64
        Initial ``cam_from_ref`` per frame.
    local : (m, 4, 3) float64
        Corners of each marker in its own frame (metres: the scale of the map).
    obs_marker, obs_frame : (n,) int
    obs_norm : (n, 4, 2) float64
        Observed corners, normalised pinhole coordinates (undistorted).
    focal : (2,) float64
        (fx, fy): normalised residuals times these are pixels.
    ref_index : int
    max_nfev : int
        Bound on the solver's function evaluations.

    Returns
    -------
    BundleResult
    """
    marker_rt = np.asarray(marker_rt, np.float64).copy()
    m, f, n = len(marker_rt), len(cam_rt), len(obs_marker)
    free = np.array([i for i in range(m) if i != ref_index], int)
    free_of = -np.ones(m, int)
    free_of[free] = np.arange(len(free))
    obs_free = free_of[obs_marker]
    fxy = np.asarray(focal, np.float64)

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mr = marker_rt.copy()
        mr[free] = x[: 6 * len(free)].reshape(-1, 6)
        return mr, x[6 * len(free) :].reshape(f, 6)

    def fun(x: np.ndarray) -> np.ndarray:
        mr, cr = unpack(x)
        uv = project_normalised(mr, cr, local, obs_marker, obs_frame)
        res: np.ndarray = ((uv - obs_norm) * fxy).ravel()
        return res

    x0 = np.concatenate([marker_rt[free].ravel(), np.asarray(cam_rt, np.float64).ravel()])
    sp = _sparsity(n, len(free), f, obs_free, obs_frame)
    sol = least_squares(
        fun,
        x0,
        jac_sparsity=sp,
        method="trf",
        loss="soft_l1",
        f_scale=LOSS_SCALE_PX,
        x_scale="jac",
        max_nfev=max_nfev,
        xtol=1e-8,
        ftol=1e-6,
    )
    mr, cr = unpack(sol.x)
    res = fun(sol.x).reshape(n, 8)
    return BundleResult(mr, cr, np.sqrt(np.mean(res**2, axis=1)), int(sol.nfev))
