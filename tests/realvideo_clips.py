"""The shared real clips of the ArUco library and what stock OpenCV finds in them (the real-footage tests' reference)."""

from __future__ import annotations

import csv
from pathlib import Path

import av
import cv2
import numpy as np

#: clip -> (folder, video file, target marker id, marker side m)
CLIPS = {
    "chessboard": ("aruco_chessboard_paroj", "chessboard.avi", 32, 0.034),
    "single": ("aruco_single_paroj", "video.avi", 101, 0.05),
}


def stock_detections(folder: Path) -> dict:
    """frame -> set of ids stock OpenCV found (the shared ``detections.csv``)."""
    with open(folder / "detections.csv") as fh:
        return {int(r["frame"]): set(map(int, r["ids"].split())) for r in csv.DictReader(fh)}


def rot(rvec):
    return cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]


def angle(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1.0) / 2.0, -1.0, 1.0))))


def jumps(rots) -> list:
    """Indices whose rotation is more than 5 deg from both neighbours *and* off the path between them
    (the neighbours closer to each other than to it): a spike, not steady fast motion (the 5-fps clip
    turns 6-8 deg per frame at times, as every one of its six markers shows)."""
    out = []
    for i in range(1, len(rots) - 1):
        if any(r is None for r in rots[i - 1 : i + 2]):
            continue
        a, b = angle(rots[i], rots[i - 1]), angle(rots[i], rots[i + 1])
        if a > 5.0 and b > 5.0 and angle(rots[i - 1], rots[i + 1]) < max(a, b):
            out.append(i)
    return out


def literal_jumps(rots) -> list:
    """The issue's words: frames whose rotation is more than 5 deg from both neighbours."""
    return [
        i
        for i in range(1, len(rots) - 1)
        if all(r is not None for r in rots[i - 1 : i + 2])
        and angle(rots[i], rots[i - 1]) > 5.0
        and angle(rots[i], rots[i + 1]) > 5.0
    ]


def stock_rotations(folder: Path, video: str, length: float) -> list:
    """Per frame, ``{id: (3, 3) rotation}`` of every marker stock OpenCV finds on the decoded colour frames,
    each posed on its own by ``cv2.solvePnP(SOLVEPNP_IPPE_SQUARE)`` with the shared intrinsics (no
    arshadow code)."""
    fs = cv2.FileStorage(str(folder / "intrinsics.yml"), cv2.FILE_STORAGE_READ)
    K, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    fs.release()
    h = length / 2
    obj = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], np.float64)
    det = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_ARUCO_ORIGINAL))
    out = []
    with av.open(str(folder / video)) as c:
        for fr in c.decode(video=0):
            corners, ids, _ = det.detectMarkers(fr.to_ndarray(format="bgr24"))
            rots = {}
            for cc, i in zip(corners, [] if ids is None else ids.ravel().tolist(), strict=True):
                ok, rvec, _ = cv2.solvePnP(
                    obj, cc.reshape(4, 2).astype(np.float64), K, dist, flags=cv2.SOLVEPNP_IPPE_SQUARE
                )
                if ok:
                    rots[int(i)] = rot(rvec)
            out.append(rots)
    return out
