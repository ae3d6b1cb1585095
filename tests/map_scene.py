"""A synthetic clip of loose markers with known poses (the marker-map work: the marker map's truth).

Six markers (DICT_6X6_250, ids 3, 5, 8, 12, 17, 21, side :data:`LENGTH`) lie scattered on the ground, some
tilted a few degrees (paper curls); a camera pans across them so that markers leave and enter the view, and
a skin-coloured blob (a hand) covers the reference marker (id 3) for a stretch of frames. Every frame is
rendered independently of arshadow's tracking code: each marker's print (OpenCV's own marker image on white
paper) is warped by the exact plane homography ``K [r1 r2 t]`` at 2 x 2 supersampling and box-filtered, then
blur and noise. The truth is the generating pose (world_from_marker per marker, cam_from_world per frame).
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from arshadow.camera.model import Intrinsics
from arshadow.synth.poses import look_at_pose

IDS = (3, 5, 8, 12, 17, 21)
LENGTH = 0.06
DICTIONARY = "DICT_6X6_250"
#: (x, y, yaw deg, tilt about x deg, tilt about y deg) per marker, world frame (ground z = 0)
LAYOUT = {
    3: (0.0, 0.0, 0.0, 0.0, 0.0),
    5: (0.17, 0.04, 20.0, 3.0, 0.0),
    8: (-0.16, 0.08, -15.0, 0.0, -2.5),
    12: (0.05, 0.19, 40.0, 0.0, 0.0),
    17: (0.34, 0.12, -30.0, -2.0, 2.0),
    21: (-0.33, -0.02, 75.0, 0.0, 4.0),
}
#: the hand covers the reference marker in these frames (fraction of the clip)
OCCLUDED = (0.42, 0.62)


def intrinsics() -> Intrinsics:
    """640 x 480, no distortion (the ground truth of the camera model is the rendering's)."""
    return Intrinsics(560.0, 560.0, 319.5, 239.5, 640, 480)


def world_from_marker() -> dict:
    """id -> (4, 4) float64 marker pose in the world (ground) frame; z of each centre lifts its tilted
    paper so that it rests on the ground."""
    out = {}
    for i, (x, y, yaw, tx, ty) in LAYOUT.items():
        R = cv2.Rodrigues(np.radians([0.0, 0.0, yaw]))[0] @ cv2.Rodrigues(np.radians([tx, ty, 0.0]))[0]
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = (x, y, 0.5 * LENGTH * math.sin(math.radians(max(abs(tx), abs(ty)))))
        out[i] = T
    return out


def camera_poses(n: int) -> np.ndarray:
    """(n, 4, 4) cam_from_world: the eye slides along x from -0.3 to 0.3 m, 0.42-0.5 m high, 0.45 m back,
    looking at a target that slides from -0.22 to 0.22 m (the outer markers leave and enter the view)."""
    out = np.empty((n, 4, 4))
    for k, s in enumerate(np.linspace(-1.0, 1.0, n)):
        eye = (0.3 * s, -0.45 + 0.05 * math.sin(3 * s), 0.46 + 0.04 * math.cos(2.3 * s))
        out[k] = look_at_pose(eye, (0.22 * s, 0.07, 0.0))
    return out


def _print_texture(marker_id: int, px: int = 16) -> tuple[np.ndarray, float]:
    """The marker on white paper (a margin of one cell): (S, S) uint8 and the paper side / marker side."""
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_6X6_250)
    m = cv2.aruco.generateImageMarker(d, marker_id, 8 * px)
    tex = cv2.copyMakeBorder(m, px * 2, px * 2, px * 2, px * 2, cv2.BORDER_CONSTANT, value=235)
    tex = np.where(tex < 128, 22, 235).astype(np.uint8)
    return tex, 12.0 / 8.0


def render_frame(intr, cam_from_world, poses: dict, hand=None, rng=None) -> np.ndarray:
    """One (H, W, 3) uint8 BGR frame: a grey floor, every marker print, an optional hand polygon
    ``hand (k, 2)`` (pixels), blur 0.6 px and noise 2 grey levels."""
    W, H, s = intr.width, intr.height, 2
    K2 = intr.K.copy()
    K2[:2, :2] *= s
    K2[0, 2], K2[1, 2] = s * (intr.cx + 0.5) - 0.5, s * (intr.cy + 0.5) - 0.5
    img = np.full((H * s, W * s), 118.0, np.float32)
    for i, wm in poses.items():
        cm = cam_from_world @ wm
        if cm[2, 3] <= 0:
            continue
        tex, paper = _print_texture(i)
        S, Lp = tex.shape[0], LENGTH * paper
        A = np.array([[Lp / S, 0, -Lp / 2 + 0.5 * Lp / S], [0, -Lp / S, Lp / 2 - 0.5 * Lp / S], [0, 0, 1]])
        Hm = K2 @ np.column_stack([cm[:3, 0], cm[:3, 1], cm[:3, 3]]) @ A
        warped = cv2.warpPerspective(tex.astype(np.float32), Hm, (W * s, H * s), flags=cv2.INTER_LINEAR)
        alpha = cv2.warpPerspective(np.ones_like(tex, np.float32), Hm, (W * s, H * s), flags=cv2.INTER_LINEAR)
        img = warped + (1.0 - alpha) * img
    img = cv2.resize(img, (W, H), interpolation=cv2.INTER_AREA)
    bgr = np.repeat(img[:, :, None], 3, axis=2)
    if hand is not None:
        cv2.fillPoly(bgr, [np.round(hand * 16).astype(np.int32)], (120.0, 150.0, 200.0), cv2.LINE_AA, shift=4)
    bgr = cv2.GaussianBlur(bgr, (0, 0), 0.6)
    rng = np.random.default_rng(0) if rng is None else rng
    bgr = bgr + rng.normal(0.0, 2.0, bgr.shape)
    return np.clip(np.round(bgr), 0, 255).astype(np.uint8)


def make_scene(n: int = 80, seed: int = 0) -> dict:
    """The clip's frames and truth: ``frames`` (list of BGR uint8), ``cam_from_world`` (n, 4, 4),
    ``world_from_marker`` {id: (4, 4)}, ``occluded`` (n,) bool (the hand covers marker 3), ``intrinsics``."""
    intr = intrinsics()
    poses = world_from_marker()
    cams = camera_poses(n)
    rng = np.random.default_rng(seed)
    occ = np.zeros(n, bool)
    occ[int(OCCLUDED[0] * n) : int(OCCLUDED[1] * n)] = True
    frames = []
    ref_pts = np.array([[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]], float) * LENGTH * 0.9
    for k in range(n):
        hand = None
        if occ[k]:
            c = intr.project((poses[3][:3, :3] @ ref_pts.T).T + poses[3][:3, 3], cams[k])
            ctr, r = c.mean(axis=0), 0.9 * np.ptp(c, axis=0).max()
            a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
            hand = ctr + np.column_stack([r * np.cos(a), 0.8 * r * np.sin(a)]) + [0.3 * r, 0.5 * r]
        frames.append(render_frame(intr, cams[k], poses, hand, rng))
    return {"frames": frames, "cam_from_world": cams, "world_from_marker": poses, "occluded": occ, "intrinsics": intr}


def write_frames(frames, folder) -> list:
    """Write the frames as lossless PNGs ``folder/f0000.png ...``; returns the paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for k, f in enumerate(frames):
        p = folder / f"f{k:04d}.png"
        cv2.imwrite(str(p), f)
        out.append(p)
    return out
