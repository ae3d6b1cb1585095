"""Camera-track export: the per-frame camera in the marker (ground) frame, for 3D and compositing tools.

Formats (docs/export.md):

- **glTF 2.0** (``.glb`` binary or ``.gltf`` JSON with the buffer embedded): one scene whose root node
  ``marker_frame`` turns arshadow's z-up marker frame into glTF's y-up (a -90 degree rotation about x:
  marker ``(x, y, z)`` -> glTF ``(x, z, -y)``; Blender's importer turns it back, so the marker lies on
  Blender's ground with its z up). Under it: the ``camera`` node (a perspective camera, animated: one
  translation + rotation key per tracked frame, at the frame's time in seconds), the ``occluder`` mesh and
  the ``ground`` proxy (a square at z = 0). The camera's full OpenCV calibration (K, distortion, size),
  which glTF cannot express (principal point, distortion), is in ``cameras[0].extras``.
- **JSON**: intrinsics and, per frame, ``time_s``, ``status`` and the camera in both conventions:
  ``opencv`` (``rvec``/``tvec``/``cam_from_world``: marker -> camera, camera x right, y down, z forward)
  and ``opengl`` (``world_from_camera``: the camera's pose in the marker frame, camera x right, y up,
  looking down -z; its ``position`` and ``quaternion_xyzw``).
- **CSV**: one row per frame, the same numbers flat (header row; columns in :data:`CSV_COLUMNS`).

Marker-lost frames (no marker in the frame) are ``held`` (keyed with the last tracked pose, as the
compositor rendered them) or ``absent`` (no key; empty pose fields), as the caller asks. Frames whose
pose the video engine held itself (status ``held``) are keyed with that pose.
"""

from __future__ import annotations

import base64
import csv
import io
import json
import math
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import numpy.typing as npt

from ..errors import UsageError
from ..geometry.ground import parse_ground
from ..io import write_bytes

if TYPE_CHECKING:
    from ..camera.model import Intrinsics
    from ..frame.report import ReportItem
    from ..geometry.caster import ShadowCaster

__all__ = [
    "CSV_COLUMNS",
    "GLTF_FROM_MARKER",
    "CameraTrack",
    "TrackFrame",
    "gl_world_from_camera",
    "quat_from_matrix",
    "track_from_frames_jsonl",
    "track_from_items",
    "write_track",
]

#: 4x4: glTF's y-up frame from arshadow's z-up marker frame (the root node's rotation)
GLTF_FROM_MARKER = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], np.float64)
#: OpenCV camera axes -> OpenGL camera axes (and back): diag(1, -1, -1)
_CV_GL = np.diag([1.0, -1.0, -1.0, 1.0])
CSV_COLUMNS = (
    "frame",
    "time_s",
    "status",
    "keyed",
    "rvec_x",
    "rvec_y",
    "rvec_z",
    "tvec_x",
    "tvec_y",
    "tvec_z",
    "gl_px",
    "gl_py",
    "gl_pz",
    "gl_qx",
    "gl_qy",
    "gl_qz",
    "gl_qw",
)


@dataclass
class TrackFrame:
    """One frame: ``status`` ``tracked`` | ``held`` (the engine held the last pose) | ``lost`` (no marker);
    ``cam_from_world`` (4, 4) float64 or None (lost and not held)."""

    frame: int
    time_s: float
    status: str
    cam_from_world: np.ndarray | None


@dataclass
class CameraTrack:
    """A camera track: the calibration and the frames (in order)."""

    K: np.ndarray
    dist: np.ndarray
    width: int
    height: int
    frames: list[TrackFrame] = field(default_factory=list)
    name: str = ""

    @classmethod
    def from_intrinsics(cls, intr: Intrinsics, frames: Iterable[TrackFrame] = (), name: str = "") -> CameraTrack:
        return cls(
            np.asarray(intr.K, np.float64),
            np.asarray(intr.dist, np.float64).ravel(),
            int(intr.width),
            int(intr.height),
            list(frames),
            name,
        )

    def keyed(self, lost: str = "held") -> list[tuple[TrackFrame, np.ndarray]]:
        """``[(TrackFrame, cam_from_world)]`` of the frames with a key: tracked, held, and with
        ``lost="held"`` the lost ones with the last pose before them (none before the first tracked one)."""
        if lost not in ("held", "absent"):
            raise UsageError(f"lost frames: expected 'held' or 'absent', got {lost!r}")
        out: list[tuple[TrackFrame, np.ndarray]] = []
        last: np.ndarray | None = None
        for f in self.frames:
            m = f.cam_from_world
            if m is not None and f.status != "lost":
                last = m
                out.append((f, m))
            elif lost == "held":
                held = m if m is not None else last
                if held is not None:  # none before the first tracked frame
                    out.append((f, held))
        return out


def gl_world_from_camera(cam_from_world: npt.ArrayLike) -> np.ndarray:
    """(4, 4): the OpenGL camera's pose in the marker frame (x right, y up, looking down -z)."""
    m = np.asarray(cam_from_world, np.float64)
    inv = np.eye(4)
    inv[:3, :3] = m[:3, :3].T
    inv[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return inv @ _CV_GL


def quat_from_matrix(R: npt.ArrayLike) -> np.ndarray:
    """(4,) float64 ``(x, y, z, w)`` unit quaternion of a 3x3 rotation, ``w >= 0``.

    >>> quat_from_matrix(np.diag([1.0, -1.0, -1.0])).round(6).tolist()
    [1.0, 0.0, 0.0, 0.0]
    """
    R = np.asarray(R, np.float64)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + R[i, i] - R[j, j] - R[k, k], 1e-300))
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    qa = np.asarray(q, np.float64)
    qa /= np.linalg.norm(qa)
    return -qa if qa[3] < 0 else qa


def _matrix(rvec: npt.ArrayLike, tvec: npt.ArrayLike, ground: str | None = None) -> np.ndarray:
    """(4, 4) float64 ``cam_from_world`` of a report's marker pose; with a ``ground`` spec (``--ground``) the
    world is the ground frame (``cam_from_marker @ marker_from_ground``), where the occluder was placed."""
    m = np.eye(4)
    m[:3, :3] = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3))[0]
    m[:3, 3] = np.asarray(tvec, np.float64).reshape(3)
    return m if not ground else m @ parse_ground(ground).marker_from_ground


def track_from_frames_jsonl(path: str | Path, intr: Intrinsics, name: str = "") -> CameraTrack:
    """The track of a video from ``arshadow video``'s ``<stem>.frames.jsonl`` (the pose each frame was
    rendered with; status ``held`` (or ``raw`` null) = held by the engine; ``no_marker`` = lost)."""
    frames: list[TrackFrame] = []
    p = Path(path)
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(f"{p}: cannot read the frames report ({exc})") from None
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            d = json.loads(line)
            ok = d.get("status") in ("ok", "held") and d.get("rvec") is not None
            m = _matrix(d["rvec"], d["tvec"], d.get("ground")) if ok else None
            status = "lost" if not ok else ("tracked" if d.get("raw") is not None and d["status"] == "ok" else "held")
            frames.append(TrackFrame(int(d["frame"]), float(d["time_s"]), status, m))
        except (ValueError, KeyError, TypeError) as exc:
            raise UsageError(f"{p}:{n}: not a frames report line ({exc})") from None
    return CameraTrack.from_intrinsics(intr, frames, name or p.name.split(".")[0])


def track_from_items(
    items: Iterable[ReportItem | dict[str, Any]], intr: Intrinsics, name: str = "photos", fps: float = 1.0
) -> CameraTrack:
    """The track of a photo set from report items (:class:`arshadow.frame.report.ReportItem` or their dicts):
    photo ``i`` at ``i / fps`` seconds; a photo without a pose is lost."""
    frames: list[TrackFrame] = []
    for i, it in enumerate(items):
        d = it if isinstance(it, dict) else it.to_dict()
        ok = d.get("status") == "ok" and d.get("rvec") is not None
        frames.append(
            TrackFrame(
                i,
                i / float(fps),
                "tracked" if ok else "lost",
                _matrix(d["rvec"], d["tvec"], d.get("ground")) if ok else None,
            )
        )
    return CameraTrack.from_intrinsics(intr, frames, name)


# ------------------------------------------------------------------------------------------- JSON / CSV
def _frame_record(f: TrackFrame, m: np.ndarray | None, keyed: bool) -> dict[str, Any]:
    rec: dict[str, Any] = {
        "frame": f.frame,
        "time_s": f.time_s,
        "status": f.status,
        "keyed": keyed,
        "opencv": None,
        "opengl": None,
    }
    if m is not None:
        rvec = cv2.Rodrigues(m[:3, :3])[0].ravel()
        g = gl_world_from_camera(m)
        rec["opencv"] = {"rvec": rvec.tolist(), "tvec": m[:3, 3].tolist(), "cam_from_world": m.tolist()}
        rec["opengl"] = {
            "world_from_camera": g.tolist(),
            "position": g[:3, 3].tolist(),
            "quaternion_xyzw": quat_from_matrix(g[:3, :3]).tolist(),
        }
    return rec


def _records(track: CameraTrack, lost: str) -> list[dict[str, Any]]:
    keyed = {id(f): m for f, m in track.keyed(lost)}
    return [_frame_record(f, keyed.get(id(f)), id(f) in keyed) for f in track.frames]


def _intrinsics_dict(track: CameraTrack) -> dict[str, Any]:
    K = track.K
    return {
        "width": track.width,
        "height": track.height,
        "K": K.tolist(),
        "dist": track.dist.tolist(),
        "fx": float(K[0, 0]),
        "fy": float(K[1, 1]),
        "cx": float(K[0, 2]),
        "cy": float(K[1, 2]),
        "yfov_rad": 2.0 * math.atan(track.height / (2.0 * K[1, 1])),
        "pixels": "(u, v), (0, 0) the centre of the top-left pixel (CONVENTIONS.md)",
    }


def track_json(track: CameraTrack, lost: str = "held") -> dict[str, Any]:
    """The JSON document of a track (conventions stated in it)."""
    from .. import __version__

    return {
        "arshadow": __version__,
        "name": track.name,
        "lost_frames": lost,
        "conventions": {
            "world": "marker frame: origin at the marker centre, x right, y up the print, z out of it; "
            "ground z = 0; metres",
            "opencv": "cam_from_world maps marker-frame points to the OpenCV camera (x right, y down, z "
            "forward): X_cam = R X_world + t, (rvec, tvec) as cv2.solvePnP",
            "opengl": "world_from_camera is the camera's pose in the marker frame with OpenGL camera axes "
            "(x right, y up, looking down -z) = inverse(cam_from_world) @ diag(1, -1, -1, 1)",
            "time_s": "presentation time of the frame in seconds (photo sets: index / fps)",
        },
        "intrinsics": _intrinsics_dict(track),
        "frames": _records(track, lost),
    }


def track_csv(track: CameraTrack, lost: str = "held") -> str:
    """The CSV text of a track (:data:`CSV_COLUMNS`; empty pose fields where a frame has no key)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for r in _records(track, lost):
        pose = [""] * 13
        if r["opencv"] is not None:
            o, g = r["opencv"], r["opengl"]
            pose = [repr(float(v)) for v in (*o["rvec"], *o["tvec"], *g["position"], *g["quaternion_xyzw"])]
        w.writerow([r["frame"], repr(r["time_s"]), r["status"], int(r["keyed"]), *pose])
    return buf.getvalue()


# ------------------------------------------------------------------------------------------- glTF
class _Bin:
    """The glTF binary buffer, its bufferViews and accessors."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict[str, int]] = []
        self.accessors: list[dict[str, Any]] = []

    def add(self, arr: np.ndarray, ctype: str, target: int | None = None, minmax: bool = False) -> int:
        arr = np.ascontiguousarray(arr)
        comp = {np.dtype(np.float32): 5126, np.dtype(np.uint32): 5125}[arr.dtype]
        while len(self.data) % 4:
            self.data.append(0)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": arr.nbytes}
        if target is not None:
            view["target"] = target
        self.data += arr.tobytes()
        self.views.append(view)
        count = arr.shape[0] if ctype != "SCALAR" or arr.ndim == 1 else arr.size
        acc: dict[str, Any] = {
            "bufferView": len(self.views) - 1,
            "componentType": comp,
            "count": int(count),
            "type": ctype,
        }
        if minmax:
            flat = arr.reshape(int(count), -1)
            acc["min"] = [float(v) for v in flat.min(axis=0)]
            acc["max"] = [float(v) for v in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _mesh(b: _Bin, verts: npt.ArrayLike, faces: npt.ArrayLike, name: str, color: int) -> dict[str, Any]:
    pos = b.add(np.asarray(verts, np.float32), "VEC3", target=34962, minmax=True)
    idx = b.add(np.asarray(faces, np.uint32).ravel(), "SCALAR", target=34963)
    return {"name": name, "primitives": [{"attributes": {"POSITION": pos}, "indices": idx, "material": color}]}


def track_gltf(
    track: CameraTrack,
    *,
    caster: ShadowCaster | None = None,
    ground_size: float = 1.0,
    lost: str = "held",
    interpolation: str = "LINEAR",
    pivot: npt.ArrayLike | None = None,
) -> tuple[dict[str, Any], bytes]:
    """The glTF document (dict) and its binary buffer.

    ``caster``: the occluder (:class:`arshadow.geometry.mesh.ShadowCaster`, world frame) or None;
    ``pivot``: ``(3,)`` its placed position, world frame (``--place``): the occluder node's translation,
    its vertices relative to it (None: the marker's origin);
    ``ground_size``: side of the proxy ground square (metres); ``interpolation``: ``LINEAR`` (video) or
    ``STEP`` (photo sets: the photos are unrelated).
    """
    from .. import __version__

    b = _Bin()
    keys = track.keyed(lost)
    K = track.K
    yfov = 2.0 * math.atan(track.height / (2.0 * K[1, 1]))
    # glTF's aspectRatio is tan(xfov/2) / tan(yfov/2): W fy / (H fx) keeps fx != fy exact
    aspect = (track.width * K[1, 1]) / (track.height * K[0, 0])
    cam = {
        "type": "perspective",
        "name": "arshadow_camera",
        "perspective": {"yfov": yfov, "aspectRatio": aspect, "znear": 0.01},
        "extras": {"opencv": _intrinsics_dict(track)},
    }
    materials = [
        {"name": "occluder", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0]}, "doubleSided": True},
        {
            "name": "shadow_catcher",
            "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]},
            "extras": {"arshadow": "proxy ground z = 0: use it as a shadow catcher"},
        },
    ]
    cam_node = {"name": "camera", "camera": 0}
    if keys:
        g0 = gl_world_from_camera(keys[0][1])
        cam_node.update(translation=g0[:3, 3].tolist(), rotation=quat_from_matrix(g0[:3, :3]).tolist())
    root = {
        "name": "marker_frame",
        "rotation": [-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)],
        "children": [1],
        "extras": {"arshadow": "marker frame (z up) -> glTF (y up)"},
    }
    nodes: list[dict[str, Any]] = [root, cam_node]
    meshes = []
    s = float(ground_size) / 2.0
    ground = np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]], np.float64)
    meshes.append(_mesh(b, ground, [[0, 1, 2], [0, 2, 3]], "ground", 1))
    nodes.append({"name": "ground", "mesh": 0})
    nodes[0]["children"].append(2)
    if caster is not None:
        at = np.zeros(3) if pivot is None else np.asarray(pivot, np.float64).reshape(3)
        meshes.append(_mesh(b, np.asarray(caster.vertices, np.float64) - at, caster.faces, "occluder", 0))
        nodes.append({"name": "occluder", "mesh": 1, **({"translation": at.tolist()} if at.any() else {})})
        nodes[0]["children"].append(3)
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": f"arshadow {__version__}"},
        "extras": {
            "arshadow": {
                "name": track.name,
                "lost_frames": lost,
                "frames_keyed": len(keys),
                "frames": len(track.frames),
            }
        },
        "scene": 0,
        "scenes": [{"name": track.name or "arshadow", "nodes": [0]}],
        "nodes": nodes,
        "cameras": [cam],
        "meshes": meshes,
        "materials": materials,
    }
    if keys:
        times = np.array([f.time_s for f, _ in keys], np.float32)
        gs = [gl_world_from_camera(m) for _, m in keys]
        tr = np.array([g[:3, 3] for g in gs], np.float32)
        q = np.array([quat_from_matrix(g[:3, :3]) for g in gs], np.float64)
        for i in range(1, len(q)):  # shortest path between keys
            if np.dot(q[i], q[i - 1]) < 0:
                q[i] = -q[i]
        t_acc = b.add(times, "SCALAR", minmax=True)
        doc["animations"] = [
            {
                "name": "camera_track",
                "samplers": [
                    {"input": t_acc, "output": b.add(tr, "VEC3"), "interpolation": interpolation},
                    {"input": t_acc, "output": b.add(q.astype(np.float32), "VEC4"), "interpolation": interpolation},
                ],
                "channels": [
                    {"sampler": 0, "target": {"node": 1, "path": "translation"}},
                    {"sampler": 1, "target": {"node": 1, "path": "rotation"}},
                ],
            }
        ]
    while len(b.data) % 4:
        b.data.append(0)
    doc["buffers"] = [{"byteLength": len(b.data)}]
    doc["bufferViews"], doc["accessors"] = b.views, b.accessors
    return doc, bytes(b.data)


def _glb(doc: dict[str, Any], data: bytes) -> bytes:
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + 8 + len(data)
    return (
        struct.pack("<III", 0x46546C67, 2, total)
        + struct.pack("<II", len(js), 0x4E4F534A)
        + js
        + struct.pack("<II", len(data), 0x004E4942)
        + data
    )


def write_track(
    path: str | Path,
    track: CameraTrack,
    *,
    caster: ShadowCaster | None = None,
    ground_size: float = 1.0,
    lost: str = "held",
    interpolation: str = "LINEAR",
    pivot: npt.ArrayLike | None = None,
) -> Path:
    """Write a track by ``path``'s extension: ``.glb``, ``.gltf`` (buffer embedded), ``.json`` or ``.csv``
    (atomically); ``pivot``: the occluder's placed position (:func:`track_gltf`)."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext in (".glb", ".gltf"):
        doc, data = track_gltf(
            track, caster=caster, ground_size=ground_size, lost=lost, interpolation=interpolation, pivot=pivot
        )
        if ext == ".glb":
            return write_bytes(p, _glb(doc, data))
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
        return write_bytes(p, (json.dumps(doc, indent=1) + "\n").encode())
    if ext == ".json":
        return write_bytes(p, (json.dumps(track_json(track, lost), indent=1, allow_nan=False) + "\n").encode())
    if ext == ".csv":
        return write_bytes(p, track_csv(track, lost).encode())
    raise UsageError(f"{p}: unknown track format {ext!r} (expected .glb, .gltf, .json or .csv)")
