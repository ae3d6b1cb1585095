"""What a new user hit (the trust fixes): each test fails on the code before the fix.

Ground truth is independent of the code under test: file modes from ``os.stat``, a glTF read by its own
parser (pygltflib), placements computed by hand from the box's dimensions, warnings by their text.
"""

from __future__ import annotations

import json
import os
import stat
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_1280x720.yml"


def _cli(capsys, *argv):
    from arshadow.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# ----------------------------------------------------------------------------- flagged-pose warning
def test_flag_reasons_with_numbers_are_grouped():
    """Reasons that differ only in their numbers ('reprojection error 35.2 px ...') are one kind."""
    from arshadow.scene.sanity import FlagTally

    t = FlagTally()
    for k, e in enumerate([35.2, 164.0, 80.5, 41.0]):
        t.add(k, [f"reprojection error {e:.1f} px, far above the 4.0 px the detected corners allow (...)"])
    t.add(9, ["small marker: 20.1 px across, under the 30 px a pose can be trusted at"])
    line = t.summary(10, "frames")
    assert "reprojection error (4)" in line and "small marker (1)" in line
    assert "35.2" not in line and len(line) < 200


# ----------------------------------------------------------------------------- layer file modes
@pytest.mark.parametrize("fmt", ["ffv1", "png"])
def test_video_layer_files_are_written_0644(tmp_path, fmt):
    """Every other output is 0666 less the umask (0644 under the usual 022); the layer videos (mkstemp)
    and the PNG-sequence folder (mkdtemp) were owner-only."""
    pytest.importorskip("av")
    from arshadow.export.layerfiles import LAYER_NAMES
    from arshadow.export.layervideo import LayerSink

    old = os.umask(0o022)
    try:
        if fmt == "png":
            paths = {"folder": tmp_path / "clip.layers"}
        else:
            paths = {n: tmp_path / f"clip.{n}.mkv" for n in LAYER_NAMES}
        sink = LayerSink(paths, fmt, Fraction(25), (64, 48))
        sink.write(None)
        sink.close()
    finally:
        os.umask(old)
    for p in paths.values():
        mode = stat.S_IMODE(os.stat(p).st_mode)
        assert mode == (0o755 if Path(p).is_dir() else 0o644), (p, oct(mode))


# ----------------------------------------------------------------------------- FrameResult repr
def test_frame_result_repr_is_short():
    """``print(result)`` names the size, status, camera and timings; it does not dump the arrays."""
    from arshadow.frame.report import ReportItem, StageTimings
    from arshadow.frame.result import FrameResult

    m = np.eye(4)
    m[:3, 3] = [0.0, 0.0, 0.5]  # the camera 0.5 m from the marker, by construction
    res = FrameResult(
        np.zeros((720, 1280, 3), np.uint8),
        np.zeros((720, 1280), np.uint8),
        None,
        m,
        ReportItem(input="x.jpg", status="ok"),
        StageTimings(detect=1.25, total=10.5),
    )
    text = repr(res)
    assert len(text) < 240 and "\n" not in text, text
    assert "1280x720" in text and "0.500 m" in text and "10.5 ms" in text and "array" not in text


# ----------------------------------------------------------------------------- export-track placement
def _y_up_obj(path, w=0.04, h=0.10, d=0.02):
    """A box ``w`` (x) by ``h`` (y, up) by ``d`` (z) with its base centred on the origin, as Blender's
    OBJ export writes a standing object (Y-up)."""
    vs = [(x, y, z) for x in (-w / 2, w / 2) for y in (0.0, h) for z in (-d / 2, d / 2)]
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    path.write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in vs) + "".join("f " + " ".join(map(str, f)) + "\n" for f in faces)
    )
    return path


def _frames_jsonl(path):
    rv, lines = [0.1, 0.2, 0.3], []
    for i in range(3):
        lines.append({"frame": i, "time_s": i / 25, "status": "ok", "rvec": rv, "tvec": [0, 0, 0.4], "raw": None})
    path.write_text("".join(json.dumps(d) + "\n" for d in lines))
    return path


def test_export_track_places_the_occluder_as_render_does(tmp_path, capsys):
    """``--up y`` and ``--drop-to-ground`` are accepted as by render; the occluder node's translation is
    its --place (the pivot), and node + mesh put the box standing upright there: its height (0.10 m) along
    world z, its base on the ground."""
    pygltflib = pytest.importorskip("pygltflib")
    obj = _y_up_obj(tmp_path / "tower.obj")
    src = _frames_jsonl(tmp_path / "clip.frames.jsonl")
    out = tmp_path / "clip.glb"
    code, _, err = _cli(
        capsys,
        "export-track",
        src,
        "--calib",
        CALIB,
        "--model",
        obj,
        "--up",
        "y",
        "--drop-to-ground",
        "--place",
        "0.1,0.05,0",
        "-o",
        out,
    )
    assert code == 0, err
    g = pygltflib.GLTF2().load(str(out))
    node = next(n for n in g.nodes if n.name == "occluder")
    assert node.translation == pytest.approx([0.1, 0.05, 0.0])
    prim = g.meshes[node.mesh].primitives[0]
    acc = g.accessors[prim.attributes.POSITION]
    view = g.bufferViews[acc.bufferView]
    v = np.frombuffer(g.binary_blob(), np.float32, acc.count * 3, view.byteOffset + (acc.byteOffset or 0))
    world = v.reshape(-1, 3) + np.asarray(node.translation)  # the node is a child of the marker frame
    assert world.min(axis=0) == pytest.approx([0.08, 0.04, 0.0], abs=1e-6)
    assert world.max(axis=0) == pytest.approx([0.12, 0.06, 0.10], abs=1e-6)


# ----------------------------------------------------------------------------- object out of view
KNOT_SCENE = [
    "--calib",
    CALIB,
    "--marker-length",
    "0.05",
    "--model",
    ROOT / "samples" / "meshes" / "knot.ply",
    "--light",
    "point:-0.12,0.2,0.42",
]


@pytest.mark.gl
def test_an_object_out_of_view_in_every_photo_is_warned(tmp_path, capsys):
    """``--place 3,0,0`` (a cm/m slip): the knot is 3 m beside a marker seen from ~0.6 m, outside the
    view (its distance alone puts it beyond the frame's ~50 degree field); exit 0 with a warning that says
    so and names the placement."""
    photo = ROOT / "samples" / "knot_point.jpg"
    code, _, err = _cli(capsys, "render", photo, *KNOT_SCENE, "--place", "3,0,0", "-o", tmp_path / "o", "-q")
    assert code == 0
    warn = [ln for ln in err.splitlines() if "outside the view" in ln]
    assert len(warn) == 1 and "every photo" in warn[0] and "--place 3,0,0" in warn[0], err
    code, _, err = _cli(capsys, "render", photo, *KNOT_SCENE, "--place", "0.1,0.05,0", "-o", tmp_path / "p", "-q")
    assert code == 0 and "outside the view" not in err


# ----------------------------------------------------------------------------- own outputs on re-render
@pytest.mark.gl
def test_rerendering_a_folder_skips_arshadows_own_outputs(tmp_path, capsys):
    """``render DIR -o DIR --save-mask`` twice: the second run renders the one photo again (no
    ``*.shadow.png`` taken as a photo, no ``knot_point_2.png``) and says in one line what it skipped."""
    d = tmp_path / "shots"
    d.mkdir()
    (d / "knot_point.jpg").write_bytes((ROOT / "samples" / "knot_point.jpg").read_bytes())
    scene = [*KNOT_SCENE, "--place", "0.1,0.05,0", "--save-mask"]
    assert _cli(capsys, "render", d, *scene, "-o", d, "-q")[0] == 0
    assert sorted(p.name for p in d.iterdir()) == ["knot_point.jpg", "knot_point.png", "knot_point.shadow.png"]
    code, _, err = _cli(capsys, "render", d, *scene, "-o", d, "-q")
    assert code == 0, err
    assert sorted(p.name for p in d.iterdir()) == ["knot_point.jpg", "knot_point.png", "knot_point.shadow.png"]
    lines = [ln for ln in err.splitlines() if "skipped" in ln]
    assert len(lines) == 1 and "2 of arshadow's own outputs" in lines[0], err


# ----------------------------------------------------------------------------- video, wrong dictionary
@pytest.mark.gl
@pytest.mark.parametrize("jobs", ["1", "2"])
def test_video_with_the_wrong_dictionary_names_the_one_there(tmp_path, capsys, jobs):
    """samples/video/orbit.mp4 shows DICT_6X6_250 marker 0 (its orbit.json): with --dictionary DICT_4X4_50
    the warning names the dictionary family that is there, as a photo's message does."""
    pytest.importorskip("av")
    clip = ROOT / "samples" / "video" / "orbit.mp4"
    code, _, err = _cli(
        capsys,
        "video",
        clip,
        "--calib",
        ROOT / "calib" / "synth_640x360.yml",
        "--marker-length",
        "0.05",
        "--dictionary",
        "DICT_4X4_50",
        "--model",
        "box:0.04,0.04,0.06",
        "--light",
        "point:0,0,1",
        "--max-frames",
        "20",
        "--contact-sheet",
        "0",
        "--jobs",
        jobs,
        "-q",
        "-o",
        tmp_path,
    )
    line = next((ln for ln in err.splitlines() if "found in none of the" in ln), "")
    # the family's smallest dictionary holding the ids found (as for photos): DICT_6X6_50 holds id 0
    assert "other dictionaries: DICT_6X6_" in line and " ids 0 " in line and "give --dictionary" in line, err


# ----------------------------------------------------------------------------- scaled calibration, once
@pytest.mark.gl
@pytest.mark.parametrize("jobs", ["1", "2"])
def test_scaled_calibration_note_once_per_run_and_says_video(tmp_path, jobs):
    """Two 640x360 videos with the 1280x720 calibration (same aspect: K scaled): ``arshadow batch`` says
    so once in the run (it said it per video, and per chunk worker with --jobs), and says "video"."""
    import subprocess
    import sys

    import yaml
    from dask_cluster import make_clips

    clips = make_clips(tmp_path / "clips", n_videos=2, n=24, gop=12)
    job = tmp_path / "job.yml"
    job.write_text(
        yaml.safe_dump(
            {
                "calib": str(CALIB),
                "marker_length": 0.05,
                "model": "box:0.04,0.03,0.06",
                "place": [0.05, 0, 0],
                "lights": ["point:-0.1,0.15,0.4"],
                "compose": "cpu",
            }
        )
    )
    cmd = [sys.executable, "-m", "arshadow", "batch", *map(str, clips), "--config", str(job), "-o", str(tmp_path / "o")]
    cmd += ["--contact-sheet", "0", "--jobs", jobs, "-q"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert r.returncode == 0, r.stderr
    notes = [ln for ln in r.stderr.splitlines() if "the calibration is for 1280x720" in ln]
    assert len(notes) == 1, r.stderr
    assert "the video is 640x360" in notes[0]


# ----------------------------------------------------------------------------- --ground wall:300
@pytest.mark.gl
def test_a_far_ground_is_one_units_warning_not_two(tmp_path):
    """``--ground wall:300`` (mm for m): its own warning names the slip; the camera is ~0.6 m from the
    marker, so no second "the camera is 299.6 m from the marker ... wrong units" warning."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "arshadow", "render", str(ROOT / "samples" / "knot_point.jpg"), *map(str, KNOT_SCENE)]
    cmd += ["--place", "0.1,0.05,0", "--ground", "wall:300", "-o", str(tmp_path), "-q"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert r.returncode == 0, r.stderr
    assert "--ground wall:300" in r.stderr and "300 mm would be wall:0.3" in r.stderr
    assert "the camera is" not in r.stderr and "wrong units" not in r.stderr, r.stderr


# ----------------------------------------------------------------------------- a Y-up OBJ
def test_a_y_up_obj_read_z_up_suggests_up_y(tmp_path, caplog):
    """A standing 10 cm tower written Y-up (as Blender exports OBJ), given without --up: it lies on its
    back half under the ground; the warning suggests --up y (not --drop-to-ground). With --up y: none."""
    from arshadow.scene.spec import scene_from_dict

    obj = _y_up_obj(tmp_path / "tower.obj")
    job = {"calib": str(CALIB), "marker_length": 0.05, "model": str(obj), "lights": ["point:0,0,1"]}
    with caplog.at_level("WARNING"):
        scene_from_dict(job).build()
    said = [r.getMessage() for r in caplog.records if "below the ground" in r.getMessage()]
    assert len(said) == 1 and "--up y" in said[0] and "--drop-to-ground" not in said[0], said
    caplog.clear()
    with caplog.at_level("WARNING"):
        scene_from_dict({**job, "up": "y"}).build()
    assert not [r for r in caplog.records if "below the ground" in r.getMessage()]
    caplog.clear()
    with caplog.at_level("WARNING"):  # a Z-up model centred on its origin: still --drop-to-ground
        scene_from_dict({**job, "model": "box:0.02,0.02,0.1", "place": [0, 0, -0.05]}).build()
    said = [r.getMessage() for r in caplog.records if "below the ground" in r.getMessage()]
    assert len(said) == 1 and "--drop-to-ground" in said[0]


# ----------------------------------------------------------------------------- README
def test_readme_places_the_knot_tells_where_the_wheel_meshes_are_and_gives_one_suite_time():
    """The README's knot render places it beside the marker (--place), prints the folder of the meshes
    shipped in the package with a command that works (run here: it names a folder holding knot.ply), and
    states one suite time."""
    import re
    import subprocess
    import sys

    text = (ROOT / "README.md").read_text()
    commands = re.findall(r"arshadow render (?:[^\n]*\\\n)*[^\n]*", text)  # with its continuation lines
    knot = [c for c in commands if "samples/meshes/knot.ply" in c]
    assert knot and all("--place" in c for c in knot), knot
    cmd = re.search(
        r'python3 -c "(from arshadow.demo.data import samples_dir; print\(samples_dir\(\) / .meshes.\))"', text
    )
    assert cmd is not None
    r = subprocess.run([sys.executable, "-c", cmd.group(1)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and (Path(r.stdout.strip()) / "knot.ply").is_file(), r.stderr
    times = re.findall(r"(?:the tests|suite)[^\n]*?[~ ](\d+) min", text)  # the suite's time, wherever given
    assert len(set(times)) == 1, times
