"""Camera-track export (the compositing-layers work): the exported camera reprojects the detected marker corners.

The files are parsed independently of the writer: glTF with pygltflib (and trimesh loads it), JSON with
json, CSV with csv. The camera pose is rebuilt from the parsed glTF node hierarchy and animation (root
rotation, keyed translation + quaternion, the glTF camera's -z view axis), the intrinsics from the glTF
camera (yfov, aspect) and its ``extras`` (principal point, distortion); the marker corners are projected
with ``cv2.projectPoints`` and compared with the corners the tracker detected in the photos.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from arshadow.camera.model import Intrinsics
from arshadow.export.track import (
    CameraTrack,
    TrackFrame,
    track_from_frames_jsonl,
    track_from_items,
    write_track,
)

ROOT = Path(__file__).resolve().parents[1]
L = 0.05
CORNERS = np.array([[-L / 2, L / 2, 0], [L / 2, L / 2, 0], [L / 2, -L / 2, 0], [-L / 2, -L / 2, 0]])


def _quat_to_R(q):
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _trs(t, q):
    m = np.eye(4)
    m[:3, :3] = _quat_to_R(q)
    m[:3, 3] = t
    return m


def _read_accessor(g, idx):
    acc = g.accessors[idx]
    view = g.bufferViews[acc.bufferView]
    data = g.binary_blob()
    n = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc.type]
    dt = {5126: np.float32, 5125: np.uint32}[acc.componentType]
    a = np.frombuffer(data, dt, count=acc.count * n, offset=view.byteOffset + (acc.byteOffset or 0))
    return a.reshape(acc.count, n) if n > 1 else a


def _gltf_projections(path):
    """{time: (4, 2) projected marker corners} from a .glb parsed by pygltflib."""
    pygltflib = pytest.importorskip("pygltflib")
    g = pygltflib.GLTF2().load(str(path))
    root = g.nodes[g.scenes[g.scene].nodes[0]]
    root_m = _trs(root.translation or [0, 0, 0], root.rotation or [0, 0, 0, 1])
    cam_node_i = next(i for i, n in enumerate(g.nodes) if n.camera is not None)
    assert cam_node_i in root.children
    cam = g.cameras[g.nodes[cam_node_i].camera]
    ex = cam.extras["opencv"]
    W, H = ex["width"], ex["height"]
    fy = H / (2 * np.tan(cam.perspective.yfov / 2))
    fx = W / (2 * cam.perspective.aspectRatio * np.tan(cam.perspective.yfov / 2))
    K = np.array([[fx, 0, ex["cx"]], [0, fy, ex["cy"]], [0, 0, 1]])
    dist = np.asarray(ex["dist"], float)
    anim = g.animations[0]
    by_path = {}
    for ch in anim.channels:
        assert ch.target.node == cam_node_i
        s = anim.samplers[ch.sampler]
        by_path[ch.target.path] = (_read_accessor(g, s.input), _read_accessor(g, s.output))
    times, tr = by_path["translation"]
    _, rot = by_path["rotation"]
    out = {}
    pts_gltf = root_m @ np.c_[CORNERS, np.ones(4)].T  # marker corners in glTF world
    for t, tt, q in zip(times, tr, rot, strict=True):
        world_from_cam_gl = root_m @ _trs(tt, q / np.linalg.norm(q))
        cam_gl = np.linalg.inv(world_from_cam_gl) @ pts_gltf
        cam_cv = (np.diag([1, -1, -1]) @ cam_gl[:3]).T
        uv, _ = cv2.projectPoints(cam_cv, np.zeros(3), np.zeros(3), K, dist)
        out[round(float(t), 4)] = uv.reshape(4, 2)
    return out


@pytest.mark.gl
@pytest.mark.parametrize("calib", ["synth_1280x720.yml", "synth_1280x720_k1.yml"])
def test_gltf_camera_reprojects_the_detected_corners(gl_ctx, tmp_path, calib):
    import arshadow
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    intr = Intrinsics.from_file(str(ROOT / "calib" / calib))
    scene = arshadow.scene_from_dict(
        {
            "calib": str(ROOT / "calib" / calib),
            "marker_length": L,
            "model": "box:0.04,0.04,0.06",
            "lights": ["point:0.1,0.1,0.4"],
        }
    )
    eyes = ([0.1, -0.3, 0.4], [-0.2, -0.25, 0.3], [0.05, 0.3, 0.35], [0.3, 0.05, 0.25])
    items, detected = [], []
    with arshadow.Session(scene, context=gl_ctx) as s:
        for k, eye in enumerate(eyes):
            img = render_marker_photo(intr, look_at_pose(eye, [0, 0, 0]), marker_length=L, seed=k).image
            pose = s.track(img)
            res = s.render(img, pose)
            items.append(res.item)
            detected.append(np.asarray(pose.corners, float).reshape(-1, 2)[:4])
    items.append({"status": "no_marker", "rvec": None, "tvec": None})  # a lost photo
    track = track_from_items(items, intr, fps=2.0)
    glb = write_track(
        tmp_path / "t.glb", track, caster=s.scene.caster, ground_size=0.5, lost="absent", interpolation="STEP"
    )
    proj = _gltf_projections(glb)
    assert len(proj) == len(eyes)  # the lost photo has no key
    for k in range(len(eyes)):
        err = np.linalg.norm(proj[round(k / 2.0, 4)] - detected[k], axis=1)
        assert err.max() < 0.5, (k, err)
    # the file loads in a second reader, with the two meshes
    trimesh = pytest.importorskip("trimesh")
    sc = trimesh.load(str(glb), force="scene")
    assert len(sc.geometry) == 2
    # the embedded .gltf is the same document
    gl = write_track(tmp_path / "t.gltf", track, caster=s.scene.caster, lost="absent")
    assert json.loads(gl.read_text())["buffers"][0]["uri"].startswith("data:application/octet-stream;base64,")


def _lost_track(intr):
    from arshadow.synth.markers import look_at_pose

    poses = [look_at_pose([0.1 * np.cos(a), 0.3 * np.sin(a) - 0.1, 0.4], [0, 0, 0]) for a in np.linspace(0, 1, 6)]
    status = ["lost", "tracked", "tracked", "lost", "held", "tracked"]
    frames = [TrackFrame(i, i / 30.0, st, None if st == "lost" else poses[i]) for i, st in enumerate(status)]
    return CameraTrack.from_intrinsics(intr, frames, "clip"), poses


def test_json_and_csv_state_both_conventions_and_key_lost_frames(tmp_path):
    intr = Intrinsics.from_file(str(ROOT / "calib" / "synth_1280x720.yml"))
    track, poses = _lost_track(intr)
    held = json.loads(write_track(tmp_path / "h.json", track, lost="held").read_text())
    absent = json.loads(write_track(tmp_path / "a.json", track, lost="absent").read_text())
    assert {"opencv", "opengl", "world", "time_s"} <= set(held["conventions"])
    fh, fa = held["frames"], absent["frames"]
    assert [f["keyed"] for f in fa] == [False, True, True, False, True, True]
    assert [f["keyed"] for f in fh] == [False, True, True, True, True, True]  # nothing to hold before frame 1
    assert fh[3]["status"] == "lost" and fh[3]["opencv"]["tvec"] == pytest.approx(poses[2][:3, 3].tolist())
    assert fa[3]["opencv"] is None and fh[1]["time_s"] == pytest.approx(1 / 30)
    for f in fh[1:3]:
        m = np.array(f["opencv"]["cam_from_world"])
        g = np.array(f["opengl"]["world_from_camera"])
        assert np.allclose(m, poses[f["frame"]])
        # the OpenGL camera looks down -z: the marker origin is in front of it (negative z in camera space)
        assert (np.linalg.inv(g) @ [0, 0, 0, 1])[2] < 0
        assert np.allclose(g[:3, 3], f["opengl"]["position"])
        assert np.allclose(_quat_to_R(f["opengl"]["quaternion_xyzw"]), g[:3, :3], atol=1e-9)
    with write_track(tmp_path / "x.csv", track, lost="absent").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6 and rows[0]["tvec_x"] == "" and rows[1]["status"] == "tracked"
    assert float(rows[2]["tvec_z"]) == pytest.approx(poses[2][2, 3])


def test_frames_jsonl_of_a_video(tmp_path):
    intr = Intrinsics.from_file(str(ROOT / "calib" / "synth_1280x720.yml"))
    rv = [0.1, 0.2, 0.3]
    lines = [
        {"frame": 0, "time_s": 0.0, "status": "no_marker", "rvec": None, "tvec": None, "raw": None},
        {"frame": 1, "time_s": 0.04, "status": "ok", "rvec": rv, "tvec": [0, 0, 0.4], "raw": {"rvec": rv}},
        {"frame": 2, "time_s": 0.08, "status": "ok", "rvec": rv, "tvec": [0, 0, 0.41], "raw": None},
        {"frame": 3, "time_s": 0.12, "status": "held", "rvec": rv, "tvec": [0, 0, 0.41], "raw": None},
    ]
    p = tmp_path / "clip.frames.jsonl"
    p.write_text("".join(json.dumps(d) + "\n" for d in lines))
    tr = track_from_frames_jsonl(p, intr)
    assert [f.status for f in tr.frames] == ["lost", "tracked", "held", "held"] and tr.name == "clip"
    assert tr.frames[2].cam_from_world[2, 3] == pytest.approx(0.41)


def test_ground_scene_exports_the_camera_in_the_ground_frame():
    """With ``--ground wall:0.3`` the occluder stands in the ground frame, so the exported camera must be
    ``cam_from_marker @ marker_from_ground``: the ground's origin and up axis land where the marker pose puts
    the plane's point and normal (given in the marker frame by the spec), not at the marker's own origin."""
    from arshadow.geometry.ground import parse_ground
    from arshadow.synth.markers import look_at_pose
    from arshadow.transforms import rvec_tvec_from_matrix

    intr = Intrinsics.from_file(str(ROOT / "calib" / "synth_1280x720.yml"))
    cam_from_marker = look_at_pose([0.1, -0.6, 0.2], [0.0, -0.3, 0.0])
    rvec, tvec = rvec_tvec_from_matrix(cam_from_marker)
    item = {"status": "ok", "rvec": list(rvec), "tvec": list(tvec), "ground": "wall:0.3"}
    g = parse_ground("wall:0.3")
    (frame,) = track_from_items([item], intr).frames
    cam_from_ground = frame.cam_from_world
    origin = cam_from_marker @ np.r_[np.asarray(g.point, float), 1.0]
    np.testing.assert_allclose(cam_from_ground @ [0, 0, 0, 1.0], origin, atol=1e-12)
    np.testing.assert_allclose(
        cam_from_ground[:3, :3] @ [0, 0, 1.0], cam_from_marker[:3, :3] @ np.asarray(g.normal, float), atol=1e-12
    )
    (plain,) = track_from_items([dict(item, ground=None)], intr).frames  # no ground: the marker frame
    np.testing.assert_allclose(plain.cam_from_world, cam_from_marker, atol=1e-9)
