"""Camera poses for synthetic photos and videos: :func:`look_at_pose`, :func:`random_pose` (a random pose
that keeps given points in view), :func:`camera_path` (an orbit) and :func:`pan_path` (a steady pan).

Every pose is a ``cam_from_world`` (4, 4) float64 in OpenCV camera axes (x right, y down, z forward) with the
world = the marker's frame (CONVENTIONS.md). They are the ground truth of :mod:`arshadow.synth`'s photos,
which re-exports them.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import ArrayLike

from .._check import check_finite, check_shape
from ..camera.model import Intrinsics
from ..errors import UsageError

__all__ = ["camera_path", "look_at_pose", "pan_path", "random_pose"]


def look_at_pose(eye_world: ArrayLike, target_world: ArrayLike, up: ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """``cam_from_world`` of an OpenCV camera at ``eye`` looking at ``target``, ``up`` appearing upwards.

    Parameters
    ----------
    eye_world, target_world : (3,) float64
        Camera centre and the point it looks at (world frame, metres).
    up : (3,) float64
        World direction that should point up in the image. When the view direction is parallel to it
        (looking straight down at the marker), world +y is used instead (the marker's top edge up).

    Returns
    -------
    (4, 4) float64
        ``cam_from_world`` (x right, y down, z forward).

    Examples
    --------
    >>> m = look_at_pose([0, 0, 1], [0, 0, 0])
    >>> m[:3, 3].tolist(), m[2, :3].tolist()
    ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0])
    """
    eye = check_finite(check_shape(np.ravel(eye_world), "3", "eye_world"), "eye_world")
    target = check_finite(check_shape(np.ravel(target_world), "3", "target_world"), "target_world")
    up = check_finite(check_shape(np.ravel(up), "3", "up"), "up")
    z = target - eye
    nz = np.linalg.norm(z)
    if nz < 1e-12:
        raise UsageError("look_at_pose: eye and target coincide")
    z = z / nz
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9 * max(1.0, float(np.linalg.norm(up))):
        x = np.cross(z, np.array([0.0, 1.0, 0.0]))
        if np.linalg.norm(x) < 1e-9:
            x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, :3] = np.stack([x, y, z])
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def _rot_a_to_b(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    s, c = np.linalg.norm(v), float(a @ b)
    if s < 1e-15:
        return np.eye(3)
    return np.asarray(cv2.Rodrigues((v / s * math.atan2(s, c)).reshape(3, 1))[0])


def random_pose(
    rng: np.random.Generator,
    intrinsics: Intrinsics,
    *,
    distance: tuple[float, float] = (0.3, 0.8),
    tilt_deg: tuple[float, float] = (0.0, 70.0),
    roll_deg: tuple[float, float] = (-180.0, 180.0),
    keep_in_view: ArrayLike | None = None,
    margin_px: float = 10.0,
    max_tries: int = 200,
    target: ArrayLike = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """A random ``cam_from_world`` looking at ``target`` (default the world origin), placed anywhere in
    the image.

    Parameters
    ----------
    rng : np.random.Generator
    intrinsics : Intrinsics
    distance : (float, float)
        Camera-to-target distance range, metres (uniform).
    tilt_deg : (float, float)
        Angle between the line of sight (camera -> target) and the marker normal (+z), degrees,
        uniform in the angle.
    roll_deg : (float, float)
        Rotation of the camera about its optical axis.
    keep_in_view : (n, 3) float64, optional
        World points that must project inside the (distorted) image with ``margin_px`` to spare
        (e.g. the paper corners).

    Returns
    -------
    (4, 4) float64
    """
    K = intrinsics.K
    target = check_finite(check_shape(np.ravel(target), "3", "target"), "target").astype(np.float64)
    pts = None if keep_in_view is None else check_shape(keep_in_view, "N,3", "keep_in_view").astype(float)
    for attempt in range(max_tries):
        d = rng.uniform(*distance)
        tilt = math.radians(rng.uniform(*tilt_deg))
        az = rng.uniform(0.0, 2.0 * math.pi)
        eye = target + d * np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), math.cos(tilt)])
        m = look_at_pose(eye, target)
        roll = math.radians(rng.uniform(*roll_deg))
        rz = np.array([[math.cos(roll), -math.sin(roll), 0], [math.sin(roll), math.cos(roll), 0], [0, 0, 1]])
        # aim the optical axis so that the origin lands at a random pixel (shrinking towards the centre
        # when the points to keep in view do not fit)
        shrink = max(0.0, 1.0 - attempt / (0.7 * max_tries))
        u = intrinsics.cx + shrink * rng.uniform(-0.42, 0.42) * intrinsics.width
        v = intrinsics.cy + shrink * rng.uniform(-0.42, 0.42) * intrinsics.height
        ray = np.linalg.solve(K, np.array([u, v, 1.0]))
        rc = _rot_a_to_b(ray, np.array([0.0, 0.0, 1.0])).T  # camera turns so that +z_old -> ray
        pose = np.eye(4)
        pose[:3, :3] = rc @ rz @ m[:3, :3]
        pose[:3, 3] = rc @ rz @ m[:3, 3]
        if pts is None:
            return pose
        uv = intrinsics.project(pts, pose)  # NaN for points behind the camera
        pin = intrinsics.project(pts, pose, distort=False)
        if (
            np.all(np.isfinite(uv))
            and np.all(uv >= margin_px)
            and np.all(uv[:, 0] <= intrinsics.width - 1 - margin_px)
            and np.all(uv[:, 1] <= intrinsics.height - 1 - margin_px)
            # guard against the distortion model's fold: the pinhole position must be sane too
            and np.all(np.abs(pin[:, 0] - intrinsics.cx) < 2.0 * intrinsics.width)
            and np.all(np.abs(pin[:, 1] - intrinsics.cy) < 2.0 * intrinsics.height)
        ):
            return pose
    raise UsageError("random_pose: could not keep the points in view; widen the distance range")


def camera_path(
    n: int,
    *,
    radius: float = 0.55,
    height: tuple[float, float] = (0.3, 0.5),
    sweep_deg: float = 120.0,
    start_deg: float = -90.0,
    target_wobble: float = 0.02,
    phase: float = 0.0,
) -> np.ndarray:
    """A smooth camera path around the origin: ``(n, 4, 4)`` float64 ``cam_from_world`` per frame.

    The eye moves on an arc of ``sweep_deg`` degrees at horizontal distance ``radius`` from the origin,
    its height oscillating smoothly within ``height``; it looks at a target that wobbles by
    ``target_wobble`` metres around the origin (hand-held feel). Consecutive frames differ by a small,
    smooth motion, as in a video.
    """
    if n < 1:
        raise UsageError("camera_path needs n >= 1 frames")
    t = np.linspace(0.0, 1.0, n)
    ang = np.radians(start_deg + sweep_deg * (3 * t**2 - 2 * t**3))  # ease in / out
    h = height[0] + (height[1] - height[0]) * 0.5 * (1 - np.cos(2 * np.pi * (t + phase)))
    out = np.empty((n, 4, 4))
    for i in range(n):
        eye = np.array([radius * math.cos(ang[i]), radius * math.sin(ang[i]), h[i]])
        tgt = target_wobble * np.array([math.sin(5.1 * t[i] + phase), math.cos(3.7 * t[i] + 1.3 * phase), 0.0])
        out[i] = look_at_pose(eye, tgt)
    return out


def pan_path(
    n: int,
    *,
    eye: ArrayLike = (0.05, -0.5, 0.4),
    target: ArrayLike = (-0.06, 0.0, 0.0),
    deg_per_frame: float = 0.25,
    axis: ArrayLike = (0.0, 0.0, 1.0),
) -> np.ndarray:
    """A steady pan: ``(n, 4, 4)`` float64 ``cam_from_world``, the camera fixed at ``eye`` turning about
    ``axis`` (world, through the eye) at a constant ``deg_per_frame``, starting by looking at ``target``.

    With a constant angular velocity and a fixed camera centre every pixel moves at a near-constant
    speed: the test case for the lag of a pose filter.
    """
    if n < 1:
        raise UsageError("pan_path needs n >= 1 frames")
    p0 = look_at_pose(eye, target)
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    c = np.asarray(eye, np.float64)
    out = np.empty((n, 4, 4))
    for i in range(n):
        th = math.radians(deg_per_frame * i)
        R = cv2.Rodrigues(a * th)[0]  # world rotation of the camera about the axis through the eye
        rot = p0[:3, :3] @ R.T
        out[i] = np.eye(4)
        out[i, :3, :3] = rot
        out[i, :3, 3] = -rot @ c
    return out
