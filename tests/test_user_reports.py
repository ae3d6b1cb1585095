"""Problems a new user met (the stress suite, "Also found when tried as a new user would"), each pinned by a test.
The others of that list are in tests/test_hostile_inputs.py (Latin-1 OBJ, output paths checked first,
wrong-units / camera-inside / sun-below-horizon warnings, --board with --dictionary, --aa 3, empty folder,
--calib DIR) and tests/test_stress_render.py (the light seam where the object meets its shadow)."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from datetime import datetime, timedelta, timezone
from pathlib import Path

import cv2
import numpy as np
import pytest
from image_files import with_exif_orientation

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_1280x720.yml"


@pytest.mark.parametrize("orientation", range(1, 9))
@pytest.mark.parametrize("big_endian", [False, True])
def test_exif_orientation_matches_opencv(tmp_path, orientation, big_endian):
    """io.exif_orientation + io.apply_orientation turn a photo upright exactly as OpenCV's own EXIF-aware
    decoder (IMREAD_COLOR) does: the independent reference."""
    from arshadow.io import apply_orientation, exif_orientation, read_image

    rng = np.random.default_rng(orientation)
    img = (rng.random((24, 40, 3)) * 255).astype(np.uint8)
    img = cv2.resize(img, (80, 48), interpolation=cv2.INTER_NEAREST)  # smooth enough for JPEG
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 100])
    p = tmp_path / "o.jpg"
    p.write_bytes(with_exif_orientation(buf.tobytes(), orientation, big_endian))
    assert exif_orientation(p) == orientation
    stored = read_image(p)  # as stored: the calibration's frame
    assert stored.shape == (48, 80, 3)
    ref = cv2.imdecode(np.fromfile(str(p), np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(np.ascontiguousarray(apply_orientation(stored, orientation)), ref)


def test_exif_orientation_absent_or_garbage(tmp_path):
    from arshadow.io import exif_orientation

    p = tmp_path / "a.png"
    cv2.imwrite(str(p), np.zeros((4, 4, 3), np.uint8))
    assert exif_orientation(p) == 1
    q = tmp_path / "b.jpg"
    q.write_bytes(b"\xff\xd8\xff\xe1\x00\x10Exif\0\0II*\0\xff\xff\xff\xff" + b"\0" * 40)
    assert exif_orientation(q) == 1
    assert exif_orientation(tmp_path / "missing.jpg") == 1


@pytest.mark.gl
def test_render_honours_exif_orientation(tmp_path, capsys, gl_ctx):
    """A landscape sensor photo tagged 'rotate 90 CW' (a phone held upright): rendered in the stored
    orientation (where the calibration applies), written upright: the output is the untagged photo's
    output turned the same way."""
    from arshadow.camera.model import Intrinsics
    from arshadow.cli import main
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    intr = Intrinsics.from_file(CALIB)
    img = render_marker_photo(intr, look_at_pose([0.15, -0.3, 0.3], [0.0, 0.0, 0.0]), marker_length=0.05, seed=3).image
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])
    d = tmp_path / "in"
    d.mkdir()
    (d / "plain.jpg").write_bytes(buf.tobytes())
    (d / "portrait.jpg").write_bytes(with_exif_orientation(buf.tobytes(), 6))
    args = [
        "render",
        str(d),
        "--calib",
        str(CALIB),
        "--marker-length",
        "0.05",
        "--model",
        "box:0.04,0.03,0.05",
        "--light",
        "point:-0.1,0.1,0.4",
        "-o",
        str(tmp_path / "o"),
        "--save-mask",
        "-q",
    ]
    assert main(args) == 0, capsys.readouterr().err
    plain = cv2.imread(str(tmp_path / "o" / "plain.png"), cv2.IMREAD_UNCHANGED)
    portrait = cv2.imread(str(tmp_path / "o" / "portrait.png"), cv2.IMREAD_UNCHANGED)
    assert portrait.shape == (1280, 720, 3)
    assert np.array_equal(portrait, cv2.rotate(plain, cv2.ROTATE_90_CLOCKWISE))
    pm = cv2.imread(str(tmp_path / "o" / "portrait.shadow.png"), 0)
    assert np.array_equal(
        pm, cv2.rotate(cv2.imread(str(tmp_path / "o" / "plain.shadow.png"), 0), cv2.ROTATE_90_CLOCKWISE)
    )


def test_marker_id_help_is_the_same_in_render_and_pose():
    """`render` said "the first found", `pose` "the lowest id found" (the tracker takes the lowest)."""
    from arshadow.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    helps = {
        name: next(a.help for a in sub[name]._actions if "--marker-id" in a.option_strings)
        for name in ("render", "pose")
    }
    assert helps["render"] == helps["pose"] and "lowest id" in helps["render"]
    dicts = {
        name: next(a.help for a in sub[name]._actions if "--dictionary" in a.option_strings)
        for name in ("render", "pose")
    }
    assert dicts["render"] == dicts["pose"]


def test_board_with_conflicting_dictionary_is_refused():
    from arshadow.camera.model import Intrinsics
    from arshadow.errors import UsageError
    from arshadow.tracking.tracker import MarkerTracker

    intr = Intrinsics.from_file(CALIB)
    board = ROOT / "calib" / "gridboard_5x7.yml"
    with pytest.raises(UsageError, match="conflicts with the board"):
        MarkerTracker(intr, dictionary="DICT_4X4_50", board=board)
    assert MarkerTracker(intr, dictionary="DICT_6X6_250", board=board).board is not None  # agreeing: fine
    assert MarkerTracker(intr, board=board).board is not None


def test_aa_only_documented_values():
    from arshadow.errors import UsageError
    from arshadow.scene.spec import RenderOptions

    for ok in (0, 2, 4):
        RenderOptions(aa=ok).check()
    for bad in (1, 3, 8, -2):
        with pytest.raises(UsageError, match=f"--aa {bad}"):
            RenderOptions(aa=bad).check()


# ==================================================================================================
# the sanity gates: plausible mistakes that gave silent wrong output. Each case asserts the message (not only the
# exit status).
# ==================================================================================================

KNOT = ROOT / "samples" / "meshes" / "knot.ply"


def _scene(**kw):
    from arshadow.scene.spec import scene_from_dict

    d = {"calib": str(CALIB), "marker_length": 0.05, "model": "box:0.04,0.04,0.06", "lights": ["point:0.1,0.1,0.4"]}
    d.update(kw)
    return scene_from_dict(d)


def _warnings_of_build(caplog, **kw) -> list[str]:
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        _scene(**kw).build()
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


@pytest.mark.parametrize("length, unit, fix", [(50, "millimetres", "0.05"), (14.5, "centimetres", "0.145")])
def test_marker_length_in_wrong_units_names_the_unit(caplog, length, unit, fix):
    """``--marker-length 50`` (mm) or ``14.5`` (cm): the warning names the probable unit and the value to give
    (also on the API path: the check is in SceneSpec.build), and the object is then far smaller than the
    marker (a second warning)."""
    msgs = _warnings_of_build(caplog, marker_length=length)
    first = next(m for m in msgs if m.startswith(f"--marker-length {length:g}"))
    assert f"probably {unit} (then give --marker-length {fix};" in first
    assert any("1/" in m and "of the" in m and "marker" in m and "Wrong units?" in m for m in msgs), msgs
    assert not _warnings_of_build(caplog, marker_length=0.05)  # the right length: silent


def test_board_file_in_millimetres_warns_when_the_scene_loads(caplog, tmp_path):
    """A grid board written in millimetres (marker_length 40, separation 10): the scene build warns that the
    board file is probably in millimetres, naming the metre value; the same board in metres is silent."""
    text = (ROOT / "calib" / "gridboard_5x7.yml").read_text()
    mm = tmp_path / "board_mm.yml"
    mm.write_text(
        text.replace("marker_length: 0.04", "marker_length: 40").replace(
            "marker_separation: 0.01", "marker_separation: 10"
        )
    )
    msgs = _warnings_of_build(caplog, marker_length=None, board=str(mm))
    assert any("probably in millimetres" in m and "0.04" in m for m in msgs), msgs
    assert not any(
        "millimetres" in m
        for m in _warnings_of_build(caplog, marker_length=None, board=str(ROOT / "calib" / "gridboard_5x7.yml"))
    )


def test_camera_tens_of_metres_away_is_a_unit_warning_once():
    """The per-frame check (O(1)): a camera 574 m from the marker (what a 50 m marker gives) is said once per
    run, naming the unit mistake; a camera 0.5 m away is silent."""
    from arshadow.geometry.mesh import load_occluder
    from arshadow.scene.sanity import FrameChecks
    from arshadow.synth.markers import look_at_pose

    checks = FrameChecks(load_occluder("box:0.04,0.04,0.06"), marker_length=50.0)
    far = look_at_pose([0.0, -344.4, 459.2], [0.0, 0.0, 0.0])  # |eye| = 574 m
    msgs = checks.check(far)
    assert len(msgs) == 1 and msgs[0].startswith("the camera is 574 m from the marker")
    assert "--marker-length 50 is probably in millimetres" in msgs[0]
    assert checks.check(far) == []  # once per run
    assert FrameChecks(load_occluder("box:0.04,0.04,0.06"), 0.05).check(look_at_pose([0, -0.3, 0.4], [0, 0, 0])) == []


def test_model_below_the_ground_warns_and_drop_to_ground_fixes(caplog, tmp_path):
    """``--place 0,0,-0.03`` and a mesh centred on its origin (most exports) reach below z = 0: a warning
    with the depth and the fix; ``drop_to_ground`` stands it on the ground (checked against the box's own
    extents, built independently with trimesh)."""
    import trimesh

    msgs = _warnings_of_build(caplog, place=[0, 0, -0.03])
    assert any("reaches 0.03 m below the ground" in m and "--drop-to-ground" in m for m in msgs), msgs
    centred = tmp_path / "centred.obj"
    trimesh.creation.box(extents=[0.04, 0.05, 0.06]).export(centred)  # z from -0.03 to 0.03
    msgs = _warnings_of_build(caplog, model=str(centred))
    assert any(m.startswith("centred.obj reaches 0.03 m below the ground") for m in msgs), msgs
    assert not [m for m in _warnings_of_build(caplog, model=str(centred), drop_to_ground=True) if "below" in m]
    caster = _scene(model=str(centred), drop_to_ground=True, place=[0.1, 0, 0]).build().caster
    assert np.allclose(caster.bounds, [[0.08, -0.025, 0.0], [0.12, 0.025, 0.06]], atol=1e-9)


def test_gltf_is_y_up_by_default_and_up_option(tmp_path):
    """glTF is Y-up by specification: a GLB whose height is along its y axis stands upright by default;
    ``up: z`` keeps the file's axes; an OBJ is read Z-up unless ``up: y`` (Blender's OBJ export);
    ``--up`` with a primitive is refused."""
    import trimesh

    from arshadow.errors import MeshError

    tall = trimesh.creation.box(extents=[0.02, 0.10, 0.04])  # 10 cm along the file's y: its height (Y-up)
    tall.apply_translation([0, 0.05, 0])  # standing on the file's ground y = 0
    glb, obj = tmp_path / "tall.glb", tmp_path / "tall.obj"
    tall.export(glb)
    tall.export(obj)
    upright = _scene(model=str(glb)).build().caster
    assert np.allclose(upright.bounds[1] - upright.bounds[0], [0.02, 0.04, 0.10], atol=1e-6)
    assert abs(upright.bounds[0][2]) < 1e-6  # still on the ground
    assert np.allclose(
        np.ptp(_scene(model=str(glb), up="z").build().caster.vertices, axis=0), [0.02, 0.10, 0.04], atol=1e-6
    )
    assert np.allclose(np.ptp(_scene(model=str(obj)).build().caster.vertices, axis=0), [0.02, 0.10, 0.04], atol=1e-6)
    assert np.allclose(
        np.ptp(_scene(model=str(obj), up="y").build().caster.vertices, axis=0), [0.02, 0.04, 0.10], atol=1e-6
    )
    with pytest.raises(MeshError, match="primitives .* --up is for mesh files"):
        _scene(up="y").build()
    with pytest.raises(MeshError, match="choose z or y"):
        _scene(model=str(obj), up="x").build()


def test_light_inside_the_object_is_one_error_before_any_work(tmp_path):
    """A light inside the model: one line, exit 2, before any photo is read or written (it was one error
    per photo, exit 1)."""
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    img = render_marker_photo(
        Intrinsics.from_file(CALIB), look_at_pose([0.1, -0.3, 0.4], [0, 0, 0]), marker_length=0.05
    ).image
    for k in range(3):
        cv2.imwrite(str(tmp_path / f"p{k}.png"), img)
    out = tmp_path / "o"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "arshadow",
            "render",
            str(tmp_path / "p*.png"),
            "--calib",
            str(CALIB),
            "--marker-length",
            "0.05",
            "--model",
            "box:0.04,0.04,0.06",
            "--light",
            "point:0,0,0.03",
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "is inside the closed mesh 'box:0.04,0.04,0.06'" in lines[0], r.stderr
    assert "p0.png" not in r.stderr and not list(out.glob("*.png"))


def test_shadow_map_around_a_point_light_is_one_usage_error():
    """``--shadow-method shadowmap`` with a point light inside the model's bounding sphere failed on every
    photo; now one UsageError when the scene is built (the renderer's own condition, checked independently
    here: the light 1 cm above a 6 cm box's top is inside its bounding sphere of radius ~4.1 cm)."""
    from arshadow.errors import UsageError

    with pytest.raises(UsageError, match="--shadow-method shadowmap: the point light .* inside the bounding sphere"):
        _scene(shadow_method="shadowmap", lights=["point:0,0,0.07"]).build()
    _scene(shadow_method="shadowmap", lights=["point:0.1,0.1,0.4"]).build()  # outside: fine
    _scene(lights=["point:0,0,0.07"]).build()  # stencil volumes: fine


def test_sun_setting_during_a_time_lapse_names_the_frames():
    """The frame range of a sun below the horizon, against an independent per-frame evaluation (every frame's
    own sun_position, no sampling or bisection)."""
    from arshadow.lights.spec import parse_sun_track
    from arshadow.lights.sun import sun_position
    from arshadow.scene.sanity import sun_set_warning

    tr = parse_sun_track("sun:48.85,2.35,2026-06-21T21:30+02:00")
    start = datetime(2026, 6, 21, 21, 30, tzinfo=timezone(timedelta(hours=2)))
    n, fps, speed = 5000, 25.0, 30.0  # 100 s of video, 50 min of sun: sampled, then bisected
    # independent: the first frame whose own position is below, found by scanning every 10th frame then
    # each frame of that stretch (the sun sets once here)
    coarse = next(
        k
        for k in range(0, n, 10)
        if not sun_position(start + timedelta(seconds=k * speed / fps), 48.85, 2.35).above_horizon
    )
    first = next(
        k
        for k in range(max(0, coarse - 10), coarse + 1)
        if not sun_position(start + timedelta(seconds=k * speed / fps), 48.85, 2.35).above_horizon
    )
    msg = sun_set_warning([tr], start, speed, fps, n, label="clip.mp4")
    assert msg.startswith(f"clip.mp4: the sun is below the horizon in frames {first}-{n - 1} of {n}"), msg
    assert "those frames get no sun shadow" in msg
    assert sun_set_warning([tr], start - timedelta(hours=8), speed, fps, n) is None  # midday: silent


@pytest.mark.gl
def test_time_lapse_sunset_warns_before_any_work_and_in_the_report(tmp_path):
    """``arshadow video --time-lapse`` on the sample clip: the warning (with the frame range) comes before
    the video is processed, and the video's report warnings carry it; its range matches the per-frame
    ``above_horizon`` of the frames report."""
    out = tmp_path / "o"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "arshadow",
            "video",
            "samples/video/orbit.mp4",
            "--calib",
            "calib/synth_640x360.yml",
            "--marker-length",
            "0.05",
            "--model",
            "box:0.04,0.04,0.06",
            "--light",
            "sun:48.85,2.35,2026-06-21T21:30+02:00",
            "--time-lapse",
            "2026-06-21T21:30+02:00,1200",
            "-o",
            str(out),
            "--report",
            str(tmp_path / "r.json"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    warn = [ln for ln in r.stderr.splitlines() if "below the horizon" in ln]
    assert len(warn) == 1 and warn[0].startswith("arshadow video: warning: samples/video/orbit.mp4: the sun is")
    frames = [json.loads(ln) for ln in (out / "orbit.frames.jsonl").read_text().splitlines() if ln.strip()]
    dark = [f["frame"] for f in frames if "sun" in f and not f["sun"][0]["above_horizon"]]
    assert dark and f"frames {dark[0]}-{dark[-1]} of {len(frames)}" in warn[0], (warn, dark)
    rep = json.loads((tmp_path / "r.json").read_text())
    assert any("below the horizon" in w for w in rep["videos"][0]["warnings"])


@pytest.mark.parametrize(
    "cmd", [["info"], ["render", "--help"], ["sun", "--lat", "48", "--lon", "2", "--time", "2026-06-21T12:00+02:00"]]
)
def test_output_to_a_closed_pipe_has_no_traceback(cmd):
    """``arshadow info | head -1``: the reader closes the pipe; no BrokenPipeError traceback, exit 141
    (128 + SIGPIPE, as a shell reports a command killed by it)."""
    p = subprocess.Popen(
        [sys.executable, "-m", "arshadow", *cmd], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT
    )
    p.stdout.close()  # the reader is gone before anything is written
    err = p.stderr.read().decode()
    p.wait(timeout=120)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    # argparse's --help ignores a closed pipe itself (exit 0); our commands exit 141
    assert p.returncode == (0 if "--help" in cmd else 141), (p.returncode, err)


def test_negative_first_number_for_place_and_rotate():
    """``--place -0.05,0,0`` / ``--rotate -90,0,0`` were "expected one argument"; the help says it works."""
    from arshadow.cli import build_parser, join_negative_values

    argv = [
        "render",
        "a.jpg",
        "--calib",
        "c.yml",
        "--marker-length",
        "0.05",
        "--model",
        "box:1,1,1",
        "--light",
        "point:0,0,1",
        "--place",
        "-0.05,0,0",
        "--rotate",
        "-90,0,0",
        "-o",
        "out",
    ]
    args = build_parser().parse_args(join_negative_values(argv))
    assert args.place == (-0.05, 0.0, 0.0) and args.rotate == (-90.0, 0.0, 0.0)
    assert args.marker_length == 0.05 and args.output == "out"
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["render"]
    helps = {a.dest: a.help for a in sub._actions}
    assert "--place -0.05,0,0" in helps["place"] and "--rotate -90,0,0" in helps["rotate"]


def test_soft_samples_without_a_sized_light_warns(caplog):
    msgs = _warnings_of_build(caplog, soft_samples=16)
    assert any(
        m.startswith("--soft-samples 16: no light has a size, so the shadows stay hard")
        and "point:0.1,0.1,0.4,radius=0.02" in m
        for m in msgs
    ), msgs
    assert not _warnings_of_build(caplog, soft_samples=16, lights=["point:0.1,0.1,0.4,radius=0.02"])


def test_hex_colour_accepted():
    """``--color '#ff0000'`` was refused; it is the same scene as ``255,0,0``; a malformed one names the form."""
    from arshadow.errors import UsageError

    assert _scene(color="#ff0000") == _scene(color="255,0,0")
    caster = _scene(color="#ff0000").build().caster
    assert np.allclose(caster.colors[:, :3], [1.0, 0.0, 0.0])
    with pytest.raises(UsageError, match="#rrggbb"):
        _scene(color="#ff00")


def test_light_close_to_the_object_gets_a_slowness_notice(caplog):
    """A light 2 cm under the top of the knot (6.7 s for one photo): a notice; the sample scenes: none."""
    msgs = _warnings_of_build(
        caplog, model=str(KNOT), place=[0.1, 0.05, 0], rotate=[0, 0, 15], lights=["point:0.1,0.05,0.034"]
    )
    assert any("may take seconds" in m and "knot.ply" in m for m in msgs), msgs
    scenes = json.loads((ROOT / "samples" / "scenes.json").read_text())["scenes"]
    for sc in scenes:
        from arshadow.scene.spec import scene_from_dict

        d = {k: v for k, v in sc.items() if k not in ("photo", "title", "true_cam_from_world")}
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            scene_from_dict(d, base_dir=ROOT).build()
        assert not [r for r in caplog.records if r.levelno >= logging.WARNING], (sc["photo"], caplog.text)


def test_flagged_pose_carries_its_reason():
    """A pose flagged for a small marker carries the reason with the number (the report's ``flag_reasons``);
    a flag of ``subpix`` corners (with the default ``edge`` corners a small marker is a report note)."""
    from arshadow.camera.model import Intrinsics
    from arshadow.frame.report import ReportItem
    from arshadow.frame.session import Session
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    intr = Intrinsics.from_file(CALIB)
    img = render_marker_photo(intr, look_at_pose([0.2, -0.9, 1.2], [0, 0, 0]), marker_length=0.05, seed=2).image
    with Session(_scene(refine="subpix")) as s:
        pose = s.track(img)
    item = ReportItem(input="far.png")
    item.set_pose(pose)
    assert item.pose_flagged is True and item.to_dict()["flag_reasons"] == item.flag_reasons
    reasons = item.flag_reasons
    assert any(r.startswith("small marker: ") and "px across, under the 32 px" in r for r in reasons), reasons


def test_calibration_of_another_size_is_said_on_stderr(caplog):
    from arshadow.frame.session import Session

    with Session(_scene()) as s, caplog.at_level(logging.WARNING):
        s.hooks.calibration(640, 360)
    assert any(
        "the calibration is for 1280x720, the photo is 640x360" in r.getMessage() and "scaled by 0.5" in r.getMessage()
        for r in caplog.records
    ), caplog.text


def test_batch_json_names_outputs_and_survives_an_interruption(tmp_path, monkeypatch):
    """``batch.json`` after an interruption lists the finished and the pending items (it was missing)."""
    from arshadow.video import batch
    from arshadow.video.engine import EngineOptions

    for k in range(3):
        cv2.imwrite(str(tmp_path / f"p{k}.png"), np.zeros((8, 8, 3), np.uint8))
    calls = []

    def fake(spec, item, outdir, opts, save_mask, fp, session=None, pool=None):
        calls.append(item.input)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return {
            "input": item.input,
            "kind": item.kind,
            "stem": item.stem,
            "status": "ok",
            "error": None,
            "outputs": [],
            "warnings": [],
        }

    monkeypatch.setattr(batch, "process_item", fake)
    out = tmp_path / "o"
    with pytest.raises(KeyboardInterrupt):
        batch.run_batch(
            _scene(), [str(tmp_path / f"p{k}.png") for k in range(3)], out, EngineOptions(), session=object()
        )
    rep = json.loads((out / "batch.json").read_text())
    assert rep["interrupted"] is True
    assert [i["status"] for i in rep["items"]] == ["ok", "pending", "pending"]
    assert rep["counts"]["pending"] == 2


@pytest.mark.gl
def test_batch_json_item_output_is_not_null(tmp_path):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo
    from arshadow.video.batch import run_batch
    from arshadow.video.engine import EngineOptions

    img = render_marker_photo(
        Intrinsics.from_file(CALIB), look_at_pose([0.1, -0.3, 0.4], [0, 0, 0]), marker_length=0.05
    ).image
    cv2.imwrite(str(tmp_path / "p.png"), img)
    out = tmp_path / "o"
    run_batch(_scene(), [str(tmp_path / "p.png")], out, EngineOptions(), save_mask=True)
    it = json.loads((out / "batch.json").read_text())["items"][0]
    assert it["status"] == "ok" and it["item"]["output"] == it["outputs"][0] == str(out / "p.png")
    assert it["item"]["mask"] == it["outputs"][1] == str(out / "p.shadow.png")
    assert it["warnings"] == [] and it["item"]["flag_reasons"] == []
    # a photo whose pose is flagged (a small marker, subpix corners): done, with a warning naming the reason
    far = render_marker_photo(
        Intrinsics.from_file(CALIB), look_at_pose([0.2, -0.9, 1.2], [0, 0, 0]), marker_length=0.05, seed=2
    ).image
    cv2.imwrite(str(tmp_path / "far.png"), far)
    run_batch(_scene(refine="subpix"), [str(tmp_path / "far.png")], tmp_path / "o2", EngineOptions())
    it = json.loads((tmp_path / "o2" / "batch.json").read_text())["items"][0]
    assert it["status"] == "ok" and len(it["warnings"]) == 1
    assert (
        it["warnings"][0].startswith(f"{tmp_path / 'far.png'}: flagged pose: ")
        and "small marker: " in it["warnings"][0]
    )


def test_demo_and_render_agree_on_aa():
    from arshadow.cli import build_parser
    from arshadow.scene.options import DEFAULT_AA, RenderOptions

    sub = next(a for a in build_parser()._actions if a.dest == "command").choices
    defaults = {n: next(a.default for a in sub[n]._actions if "--aa" in a.option_strings) for n in ("render", "demo")}
    assert defaults == {"render": DEFAULT_AA, "demo": DEFAULT_AA} and RenderOptions().aa == DEFAULT_AA


def test_conventions_are_in_the_repository():
    """A clone has no ../shared: the conventions are docs/CONVENTIONS.md and nothing points outside."""
    assert (ROOT / "docs" / "CONVENTIONS.md").read_text().startswith("# arshadow conventions")
    files = [p for p in ROOT.rglob("*") if p.suffix in (".md", ".py") and ".git" not in p.parts]
    bad = [
        str(p)
        for p in files
        if "shared/CONVENTIONS" in p.read_text(errors="replace") and p.name != "test_user_reports.py"
    ]
    assert not bad, bad


@pytest.mark.gl
def test_render_says_unit_mistakes_and_flagged_poses_on_stderr(tmp_path):
    """The photo path end to end: ``--marker-length 50`` warns (unit, object size, camera distance) with
    exit 0, and a photo with a small (flagged: ``--refine subpix``) marker gets the flagged-pose summary line."""
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    intr = Intrinsics.from_file(CALIB)
    cv2.imwrite(
        str(tmp_path / "near.png"),
        render_marker_photo(intr, look_at_pose([0.1, -0.3, 0.4], [0, 0, 0]), marker_length=0.05).image,
    )
    cv2.imwrite(
        str(tmp_path / "far.png"),
        render_marker_photo(intr, look_at_pose([0.2, -0.9, 1.2], [0, 0, 0]), marker_length=0.05, seed=2).image,
    )
    base = [
        sys.executable,
        "-m",
        "arshadow",
        "render",
        "--calib",
        str(CALIB),
        "--model",
        "box:0.04,0.04,0.06",
        "--light",
        "point:0.1,0.1,0.4",
        "-q",
    ]
    r = subprocess.run(
        base + [str(tmp_path / "near.png"), "--marker-length", "50", "-o", str(tmp_path / "a")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert "--marker-length 50: a printed marker 50 m across?" in r.stderr
    assert "probably in millimetres" in r.stderr and "the camera is " in r.stderr
    r = subprocess.run(
        base
        + [str(tmp_path / "near.png"), str(tmp_path / "far.png"), "--marker-length", "0.05", "--refine", "subpix"]
        + ["-o", str(tmp_path / "b")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=False,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    line = [ln for ln in r.stderr.splitlines() if "flagged pose" in ln]
    assert len(line) == 1 and line[0].startswith("arshadow render: warning: 1 of 2 photos have a flagged pose (")
    assert "far.png" in line[0] and "small marker (1)" in line[0]
