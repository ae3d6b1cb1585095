"""Marker maps (the marker-map work): loose markers learned into a rigid map, checked against the generating poses.

The clip (tests/map_scene.py) is rendered from known marker and camera poses by plain OpenCV warps, never
by arshadow's tracking code; the truth of every figure below is those poses.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from conftest import TOL
from map_scene import IDS, LENGTH, make_scene, write_frames

from arshadow.cli import main
from arshadow.errors import MarkerNotFoundError, UsageError
from arshadow.tracking.board import load_board
from arshadow.tracking.dictionary import marker_object_points
from arshadow.tracking.mapio import write_map
from arshadow.tracking.mapping import Observations, learn_map
from arshadow.tracking.tracker import MarkerTracker
from arshadow.transforms import invert_rigid, rotation_error_deg

REF = min(IDS)


@pytest.fixture(scope="module")
def scene():
    return make_scene(60)


@pytest.fixture(scope="module")
def observations(scene):
    tr = MarkerTracker(scene["intrinsics"], marker_length=LENGTH, refine="edge")
    return Observations.from_detections([tr.detect(f) for f in scene["frames"]], (640, 480))


@pytest.fixture(scope="module")
def learned(scene, observations):
    return learn_map(observations, scene["intrinsics"], LENGTH)


def map_errors(mmap, scene) -> np.ndarray:
    """(k, 2) per non-reference marker: position error (mm) and rotation error (deg) against the truth."""
    W = scene["world_from_marker"]
    out = []
    for i, est in mmap.ref_from_marker.items():
        if i == mmap.reference_id:
            continue
        tru = invert_rigid(W[mmap.reference_id]) @ W[i]
        out.append((1e3 * np.linalg.norm(tru[:3, 3] - est[:3, 3]), rotation_error_deg(tru[:3, :3], est[:3, :3])))
    return np.asarray(out)


def test_learned_map_matches_the_generating_poses(scene, learned):
    """All six markers mapped in the reference's frame; median within 1 mm / 0.2 deg of the truth."""
    assert learned.reference_id == REF and sorted(learned.corners) == sorted(IDS)
    assert np.allclose(learned.corners[REF], marker_object_points(LENGTH))
    e = map_errors(learned, scene)
    print("map error mm", e[:, 0].round(3), "deg", e[:, 1].round(3))
    assert np.median(e[:, 0]) <= TOL.map_marker_median_mm
    assert np.median(e[:, 1]) <= TOL.map_marker_median_deg
    assert all(learned.frames_seen[i] >= 2 for i in IDS) and learned.rms_total_px < 0.5


def test_camera_rotation_with_the_map_beats_one_marker(scene, learned):
    """On the frames where the reference marker is visible, the camera's rotation error against the map is
    at most half that of tracking the reference marker alone (median over the frames)."""
    intr, W = scene["intrinsics"], scene["world_from_marker"]
    single = MarkerTracker(intr, marker_length=LENGTH, marker_id=REF, refine="edge")
    mapped = MarkerTracker(intr, board=learned.board(), refine="edge")
    e_single, e_map = [], []
    for k, f in enumerate(scene["frames"]):
        truth = scene["cam_from_world"][k] @ W[REF]
        try:
            p1 = single.estimate(f)
        except MarkerNotFoundError:
            continue
        p2 = mapped.estimate(f)
        e_single.append(rotation_error_deg(p1.cam_from_world[:3, :3], truth[:3, :3]))
        e_map.append(rotation_error_deg(p2.cam_from_world[:3, :3], truth[:3, :3]))
    print(f"rotation error median: single {np.median(e_single):.3f} deg, map {np.median(e_map):.3f} deg")
    assert len(e_single) >= 30
    assert np.median(e_map) <= TOL.map_vs_single_rot_ratio * np.median(e_single)


def test_frames_with_the_reference_hidden_are_tracked(scene, learned):
    """Every frame where the hand hides the reference marker and another marker is seen gets a pose
    against the map, as accurate as the synthetic tolerance of one marker."""
    intr, W = scene["intrinsics"], scene["world_from_marker"]
    mapped = MarkerTracker(intr, board=learned.board(), refine="edge")
    probe = MarkerTracker(intr, marker_length=LENGTH)
    hidden = 0
    for k in np.flatnonzero(scene["occluded"]):
        ids = set(probe.detect(scene["frames"][k]).ids.tolist())
        if REF in ids or not ids:
            continue
        hidden += 1
        pose = mapped.estimate(scene["frames"][k])
        assert REF not in pose.marker_ids and set(pose.marker_ids) == ids
        truth = scene["cam_from_world"][k] @ W[REF]
        assert rotation_error_deg(pose.cam_from_world[:3, :3], truth[:3, :3]) < TOL.synth_rot_median_deg
        assert np.linalg.norm(pose.cam_from_world[:3, 3] - truth[:3, 3]) < 1e-3
    assert hidden >= 5


def test_outliers_are_rejected(scene, observations):
    """A marker seen once, a false id with random corners (in two frames), a repeated id and a corner set
    15 px off are rejected, each with its reason, and the map stays within tolerance."""
    o = observations
    rng = np.random.default_rng(1)
    fr, ids, cs = [o.frame], [o.ids], [o.corners]
    quad = np.array([[0, 0], [40, 0], [40, 40], [0, 40]], float)
    fr.append(np.array([5])), ids.append(np.array([40])), cs.append((quad + 200)[None])
    for f in (10, 20):  # a false id 30 in two frames, somewhere random
        fr.append(np.array([f])), ids.append(np.array([30])), cs.append((quad + rng.uniform(50, 400, 2))[None])
    k = int(np.flatnonzero((o.ids == 12) & (o.frame == 25))[0])
    fr.append(np.array([25])), ids.append(np.array([12])), cs.append(o.corners[k : k + 1] + 30.0)
    shifted = o.corners.copy()
    j = int(np.flatnonzero((o.ids == 8) & (o.frame == 30))[0])
    shifted[j] += 15.0
    cs[0] = shifted
    bad = Observations(np.concatenate(fr), np.concatenate(ids), np.concatenate(cs), o.n_frames, o.image_size)
    mmap = learn_map(bad, scene["intrinsics"], LENGTH)
    text = "\n".join(mmap.rejected)
    assert "marker 40 seen in one frame only" in text
    assert "marker 30 not connected" in text
    assert "marker 12 seen twice in frame 25" in text
    assert "marker 8 in frame 30" in text
    assert sorted(mmap.corners) == sorted(IDS)
    e = map_errors(mmap, scene)
    assert np.median(e[:, 0]) <= TOL.map_marker_median_mm and np.median(e[:, 1]) <= TOL.map_marker_median_deg


def test_reference_and_lengths(scene, observations):
    """``reference_id`` sets the map's frame; a per-id length; an unseen reference is an error."""
    m = learn_map(observations, scene["intrinsics"], {None: LENGTH, 12: LENGTH}, reference_id=12)
    assert m.reference_id == 12 and np.allclose(m.corners[12], marker_object_points(LENGTH))
    W = scene["world_from_marker"]
    tru = invert_rigid(W[12]) @ W[REF]
    assert np.linalg.norm(m.ref_from_marker[REF][:3, 3] - tru[:3, 3]) < 1e-3
    with pytest.raises(MarkerNotFoundError, match="reference marker 99"):
        learn_map(observations, scene["intrinsics"], LENGTH, reference_id=99)
    with pytest.raises(UsageError, match="no marker length for id"):
        learn_map(observations, scene["intrinsics"], {12: LENGTH})


def test_map_file_is_a_board_file_with_residuals(tmp_path, learned):
    p = write_map(learned, tmp_path / "map.yml")
    b = load_board(p)
    assert b.kind == "markers" and sorted(b.marker_ids) == sorted(IDS) and b.dictionary == "DICT_6X6_250"
    for i in IDS:
        assert np.allclose(b.markers[i], learned.corners[i], atol=1e-12)
    fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    m0 = fs.getNode("markers").at(0)
    assert m0.getNode("rms_px").real() >= 0 and m0.getNode("frames_seen").real() >= 2
    assert int(fs.getNode("map").getNode("reference_id").real()) == REF
    fs.release()


@pytest.fixture(scope="module")
def frames_on_disk(scene, tmp_path_factory):
    d = tmp_path_factory.mktemp("mapclip")
    calib = d / "cam.yml"
    scene["intrinsics"].to_file(calib)
    return write_frames(scene["frames"], d / "frames"), calib


def test_cli_map(frames_on_disk, tmp_path, capsys):
    paths, calib = frames_on_disk
    out = tmp_path / "map.yml"
    argv = ["map", *map(str, paths), "--calib", str(calib), "--marker-length", "0.06", f"{REF}=0.06", "-o", str(out)]
    assert main(argv) == 0
    assert "map of 6 markers (reference 3)" in capsys.readouterr().err
    assert sorted(load_board(out).marker_ids) == sorted(IDS)
    assert main(["map", str(paths[0]), "--calib", str(calib), "--marker-length", "x=1", "-o", str(out)]) == 2
    assert main(["map", str(paths[0]), "--calib", str(calib), "--marker-length", "0.06", "-o", str(out)]) == 1


@pytest.mark.gl
def test_render_with_map_auto_tracks_the_hidden_reference(scene, frames_on_disk, tmp_path):
    """``render --map auto``: the map learned from the photos (written to OUT/map.yml), every photo with a
    marker rendered, those where the reference is hidden too; the report names the markers used."""
    paths, calib = frames_on_disk
    out = tmp_path / "out"
    argv = ["render", *map(str, paths[::2]), "--calib", str(calib), "--marker-length", "0.06", "--map", "auto"]
    argv += ["--model", "box:0.02,0.02,0.02", "--light", "point:0.1,0.1,0.5", "-o", str(out), "--quiet"]
    argv += ["--report", str(tmp_path / "r.json")]
    assert main(argv) == 0
    assert sorted(load_board(out / "map.yml").marker_ids) == sorted(IDS)
    rep = json.loads((tmp_path / "r.json").read_text())
    items = rep["images"]
    assert rep["map"]["reference_id"] == REF and rep["map"]["rms_px"] < 0.5 and len(rep["map"]["markers"]) == 6
    assert all(it["status"] == "ok" for it in items)
    hidden = [it for it in items if REF not in it["marker_ids"]]
    assert hidden and all(len(it["marker_ids"]) >= 1 for it in hidden)
    bad = ["render", str(paths[0]), "--calib", str(calib), "--map", "auto", "--model", "box:0.02,0.02,0.02"]
    assert main([*bad, "--light", "point:0,0,1", "-o", str(tmp_path / "o2")]) == 2  # no marker length


@pytest.fixture(scope="module")
def clip_on_disk(scene, frames_on_disk):
    from video_clips import CvClipWriter

    _, calib = frames_on_disk
    path = calib.parent / "clip.mkv"  # FFV1: lossless
    with CvClipWriter(path, 25, (640, 480)) as w:
        for f in scene["frames"]:
            w.write(f)
    return path, calib


def video_records(clip, calib, out, *tracker_args) -> list:
    argv = ["video", str(clip), "--calib", str(calib), *tracker_args, "--model", "box:0.02,0.02,0.02"]
    argv += ["--light", "point:0.1,0.1,0.5", "--contact-sheet", "0", "--quiet", "-o", str(out)]
    assert main(argv) == 0
    with open(next(out.glob("*.frames.jsonl"))) as fh:
        return [json.loads(line) for line in fh]


@pytest.mark.gl
def test_video_with_map_tracks_frames_where_the_reference_is_hidden(scene, clip_on_disk, tmp_path):
    """``video --map auto``: the hand's frames, held or lost with the reference marker alone, are tracked
    against the map (the report names the markers used and the map's reprojection error), and the camera
    rotation there is as good as elsewhere."""
    clip, calib = clip_on_disk
    one = video_records(clip, calib, tmp_path / "one", "--marker-length", "0.06", "--marker-id", str(REF))
    mapped = video_records(clip, calib, tmp_path / "map", "--marker-length", "0.06", "--map", "auto")
    occ = np.flatnonzero(scene["occluded"])
    assert sum(one[k]["status"] != "ok" for k in occ) >= 5  # the reference alone: held or lost
    assert all(r["status"] == "ok" for r in mapped)
    W = scene["world_from_marker"]
    for k in occ:
        r = mapped[k]
        assert REF not in r["marker_ids"] and len(r["marker_ids"]) >= 2 and r["reprojection_error_px"] < 1.0
        R = cv2.Rodrigues(np.asarray(r["rvec"], float))[0]
        assert rotation_error_deg(R, (scene["cam_from_world"][k] @ W[REF])[:3, :3]) < TOL.synth_rot_median_deg


@pytest.mark.gl
def test_batch_with_map_auto(scene, frames_on_disk, tmp_path):
    """``batch --map auto``: the scene file's marker length scales the map learned from the inputs."""
    paths, calib = frames_on_disk
    job = tmp_path / "job.yml"
    job.write_text(f"calib: {calib}\nmarker_length: 0.06\nmodel: box:0.02,0.02,0.02\nlights: ['point:0.1,0.1,0.5']\n")
    use = [str(paths[k]) for k in range(0, len(paths), 3)]
    assert main(["batch", *use, "-c", str(job), "--map", "auto", "-o", str(tmp_path / "out"), "-q"]) == 0
    assert sorted(load_board(tmp_path / "out" / "map.yml").marker_ids) == sorted(IDS)
    items = json.loads((tmp_path / "out" / "batch.json").read_text())["items"]
    assert len(items) == len(use) and all(it["status"] == "ok" for it in items)
    occ = [str(paths[k]) for k in np.flatnonzero(scene["occluded"]) if str(paths[k]) in use]
    assert occ and all(REF not in it["item"]["marker_ids"] for it in items if it["input"] in occ)


def test_map_option_usage_errors(frames_on_disk, learned, tmp_path, capsys):
    """``--map`` with ``--board``, a missing map file: one usage error each (exit 2), before any work."""
    paths, calib = frames_on_disk
    mfile = write_map(learned, tmp_path / "m.yml")
    base = ["render", str(paths[0]), "--calib", str(calib), "--model", "box:0.02,0.02,0.02"]
    base += ["--light", "point:0,0,1", "-o", str(tmp_path / "o")]
    assert main([*base, "--board", str(mfile), "--map", str(mfile)]) == 2
    assert "either --map or --board" in capsys.readouterr().err
    assert main([*base, "--map", str(tmp_path / "nope.yml")]) == 2
    assert "no such map file" in capsys.readouterr().err


def test_one_marker_is_a_map_of_one(scene, observations):
    """Frames that only ever see one marker give a map of that marker alone (no adjustment), which tracks
    like the marker itself."""
    o = observations
    k = o.ids == 12
    m = learn_map(Observations(o.frame[k], o.ids[k], o.corners[k], o.n_frames, o.image_size), scene["intrinsics"], 0.06)
    assert m.reference_id == 12 and list(m.corners) == [12] and m.frames_used == 0
    assert np.allclose(m.corners[12], marker_object_points(LENGTH)) and m.rms_total_px < 0.5
