"""The photo loop (arshadow/photos.py) shared by render, batch and demo; the session's plan -> render path;
the time-lapse of the scene spec; the one stems / guard / contact-sheet helpers (the façade work)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from image_files import with_exif_orientation

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_1280x720.yml"
JOB = {"calib": str(CALIB), "marker_length": 0.05, "model": "box:0.04,0.03,0.05", "lights": ["point:-0.1,0.1,0.4"]}


def _photo(seed=3, eye=(0.15, -0.3, 0.3)):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    intr = Intrinsics.from_file(CALIB)
    pose = look_at_pose(list(eye), [0.0, 0.0, 0.0])
    return render_marker_photo(intr, pose, marker_length=0.05, seed=seed).image, pose


@pytest.mark.gl
def test_batch_honours_exif_orientation_as_render_does(tmp_path, capsys, gl_ctx):
    """`batch` re-implemented the photo loop without EXIF orientation: a rotated JPEG came out sideways.
    Both commands now go through arshadow.photos: the tagged photo's outputs are the untagged photo's
    outputs turned 90 degrees (the independent reference), and render and batch write the same bytes."""
    from arshadow.cli import main

    img, _ = _photo()
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])
    d = tmp_path / "in"
    d.mkdir()
    (d / "plain.jpg").write_bytes(buf.tobytes())
    (d / "portrait.jpg").write_bytes(with_exif_orientation(buf.tobytes(), 6))
    job = tmp_path / "job.json"
    job.write_text(json.dumps(JOB))
    assert (
        main(
            [
                "batch",
                str(d / "plain.jpg"),
                str(d / "portrait.jpg"),
                "--config",
                str(job),
                "-o",
                str(tmp_path / "b"),
                "--save-mask",
                "-q",
            ]
        )
        == 0
    ), capsys.readouterr().err
    assert (
        main(
            [
                "render",
                str(d),
                "--calib",
                str(CALIB),
                "--marker-length",
                "0.05",
                "--model",
                JOB["model"],
                "--light",
                JOB["lights"][0],
                "-o",
                str(tmp_path / "r"),
                "--save-mask",
                "-q",
            ]
        )
        == 0
    )
    for kind in ("", ".shadow"):
        plain = cv2.imread(str(tmp_path / "b" / f"plain{kind}.png"), cv2.IMREAD_UNCHANGED)
        portrait = cv2.imread(str(tmp_path / "b" / f"portrait{kind}.png"), cv2.IMREAD_UNCHANGED)
        assert portrait.shape[:2] == (1280, 720)
        assert np.array_equal(portrait, cv2.rotate(plain, cv2.ROTATE_90_CLOCKWISE))
        for stem in ("plain", "portrait"):
            a = (tmp_path / "b" / f"{stem}{kind}.png").read_bytes()
            assert a == (tmp_path / "r" / f"{stem}{kind}.png").read_bytes(), (stem, kind)
    summary = json.loads((tmp_path / "b" / "batch.json").read_text())
    item = next(r for r in summary["items"] if r["stem"] == "portrait")["item"]
    assert item["output"] == str(tmp_path / "b" / "portrait.png") and item["status"] == "ok"


@pytest.mark.gl
def test_photo_loop_records_failures_and_goes_on(tmp_path, gl_ctx):
    """A missing file, a photo without the marker and an output that would replace an input each fail
    alone (status and error recorded); the good photo is still rendered."""
    from arshadow.frame.session import Session
    from arshadow.io import InputGuard
    from arshadow.photos import PhotoJob, photo_jobs, render_photos

    img, _ = _photo()
    good = tmp_path / "good.png"
    cv2.imwrite(str(good), img)
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((720, 1280, 3), 128, np.uint8))
    jobs = photo_jobs([str(tmp_path / "missing.png"), str(blank), str(good)], tmp_path / "out", save_mask=True)
    jobs.append(PhotoJob(str(good), good))  # its output is its own input
    seen = []
    with Session({**JOB}, context=gl_ctx) as s:
        items = render_photos(s, jobs, on_done=lambda job, item, res, err: seen.append((item.status, err)))
    assert [i.status for i in items] == ["error", "no_marker", "ok", "error"]
    assert "overwrite an input" in items[3].error and good.read_bytes() == cv2.imencode(".png", img)[1].tobytes()
    assert all((err is None) == (st == "ok") for st, err in seen) and len(seen) == 4
    assert items[2].output == str(tmp_path / "out" / "good.png") and (tmp_path / "out" / "good.shadow.png").is_file()
    assert all("total" in i.timings_ms for i in items)
    assert InputGuard([good]).clash([tmp_path / "x.png", good]) == str(good)


@pytest.mark.gl
def test_render_of_a_plan_equals_render_at_the_pose(gl_ctx):
    """Session.plan then Session.render(plan=...) is the same frame as Session.render(pose): the plan is
    the whole of the per-frame decisions, the compose path among them."""
    from arshadow.errors import UsageError
    from arshadow.frame.session import Session

    img, pose = _photo()
    with Session({**JOB, "compose": "cpu"}, context=gl_ctx) as s:
        a = s.render(img, pose)
        plan = s.plan(pose, img.shape[1], img.shape[0])
        assert plan.compose is None  # decided at render time (it depends on the output buffers)
        b = s.render(img, plan=plan)
        assert plan.compose == "cpu" and plan.decisions[-1].reason == "forced cpu"
        with pytest.raises(UsageError, match="plan is for"):
            s.render(img[:360, :640], plan=plan)
        with pytest.raises(UsageError, match="a pose or a plan"):
            s.render(img)
    assert np.array_equal(a.composite, b.composite) and np.array_equal(a.mask, b.mask)
    assert a.item.to_dict().keys() == b.item.to_dict().keys() and a.item.roi == b.item.roi
    assert b.timings.total > 0 and b.timings_ms["total"] == round(b.timings.total, 3)


def test_time_lapse_is_part_of_the_scene_spec():
    """--time-lapse used to be built in cli/video.py, bypassing SceneSpec: now a job file or a dict has it,
    the spec pickles with it, and the session starts with the sun at the start time."""
    import pickle

    from arshadow.errors import UsageError
    from arshadow.frame.session import Session
    from arshadow.lights.spec import parse_light, parse_sun_track
    from arshadow.scene.spec import scene_from_dict

    sun = "sun:48,11,2021-06-21T09:00+02:00,0@0.5"
    d = {**JOB, "lights": ["point:0.1,0.1,0.4", sun], "time_lapse": "2021-06-21T12:00+02:00,600", "recompute_deg": 0.2}
    spec = scene_from_dict(d)
    assert pickle.loads(pickle.dumps(spec)) == spec and spec.time_lapse.speed == 600.0
    s = Session(spec)
    assert len(s.sun_tracks) == 1 and s.time_lapse[1] == 600.0
    ref = parse_sun_track(sun, recompute_deg=0.2)
    frame = ref.update(s.time_lapse[0])
    want = [parse_light("point:0.1,0.1,0.4").homogeneous, ref.light(frame).homogeneous]
    assert np.allclose([ls.light_h for ls in s.geometry.lights], want)
    later = s.set_time(s.time_lapse[0].replace(hour=13))
    assert later[0].recompute  # an hour later the sun moved far more than 0.2 degrees
    with pytest.raises(UsageError, match="needs a sun light"):
        scene_from_dict({**JOB, "time_lapse": "2021-06-21T12:00+02:00"})
    with pytest.raises(UsageError, match="SPEED must be a positive"):
        scene_from_dict({**d, "time_lapse": "2021-06-21T12:00+02:00,-1"})
    with pytest.raises(UsageError, match="recompute-deg"):
        scene_from_dict({**d, "recompute_deg": -1})


def test_one_contact_sheet_layout():
    """The demo's and the video's sheets are one function: tiles at gap + k * (size + gap), background
    elsewhere (positions computed here by hand)."""
    from arshadow.photos import contact_sheet

    tiles = [np.full((3, 5, 3), 10 * (k + 1), np.uint8) for k in range(5)]
    sheet = contact_sheet(tiles, columns=2, gap=4, background=32)
    assert sheet.shape == (3 * 3 + 4 * 4, 2 * 5 + 3 * 4, 3)
    for k in range(5):
        r, c = divmod(k, 2)
        y, x = 4 + r * 7, 4 + c * 9
        assert (sheet[y : y + 3, x : x + 5] == 10 * (k + 1)).all()
    mask = np.ones(sheet.shape[:2], bool)
    for k in range(5):
        r, c = divmod(k, 2)
        mask[4 + r * 7 : 7 + r * 7, 4 + c * 9 : 9 + c * 9] = False
    assert (sheet[mask] == 32).all()


def test_one_stem_and_extension_list():
    """render and batch named outputs with two stem rules and two extension lists that disagreed."""
    from arshadow.io import IMAGE_EXTENSIONS, unique_stems
    from arshadow.photos import photo_jobs
    from arshadow.video.batch import plan_batch

    inputs = ["a/shot.jpe", "b/SHOT.png", "c/clip.mp4"]
    assert unique_stems(inputs) == ["shot", "SHOT_2", "clip"]
    assert [j.output.name for j in photo_jobs(inputs[:2], Path("o"), keep_format=True)] == ["shot.jpe", "SHOT_2.png"]
    assert [(b.kind, b.stem) for b in plan_batch(inputs)] == [("photo", "shot"), ("photo", "SHOT_2"), ("video", "clip")]
    assert {".jpe", ".dib", ".pic", ".pfm"} <= IMAGE_EXTENSIONS
