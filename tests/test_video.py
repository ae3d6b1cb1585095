"""Batch AR video (arshadow/video/decode.py, avio.py, chooser.py, arshadow/cli/video.py).

- frames in / frames out: timestamps, the lossless mask container, atomic (never half-written) outputs;
- end to end on a synthetic clip made by arshadow's generator along ``synth.camera_path``: the pose is
  ESTIMATED from the decoded (lossy mp4) frames, the shadow mask read back from the mask video is compared
  with the independent per-pixel oracle (tests/image_oracle.py) at the TRUE pose of each frame;
- temporal IPPE choice: on a sequence whose frames are ambiguous, choosing by reprojection error flips
  between the two solutions; the temporal chooser does not (ground truth = the generating poses);
- ``--time-lapse``: the sun moves with the frame times, and silhouettes are recomputed exactly when the
  direction has moved more than ``--recompute-deg`` since the last recompute (counted by wrapping the
  silhouette function; the expected count is computed here from the sun's position independently);
- bad input: missing / unreadable videos give one line and exit 1 while the other videos are processed.
"""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path

import cv2
import numpy as np
import pytest
from image_oracle import ShadowOracle, iou
from video_clips import BOX_SCENE, CvClipWriter, read_frames

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_640x360.yml"
W, H = 640, 360
FPS = 25.0


# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------
def _intr():
    from arshadow.camera.model import Intrinsics

    return Intrinsics.from_file(CALIB)


def _write_clip(path, poses, *, marker_length=0.05, blank=(), noise=1.0, seed=0):
    """Synthetic clip: one render_marker_photo per pose (frames in ``blank``: plain grey, no marker)."""
    from arshadow.synth.markers import render_marker_photo

    intr = _intr()
    with CvClipWriter(path, FPS, (W, H)) as w:
        for i, pose in enumerate(poses):
            if i in blank:
                w.write(np.full((H, W, 3), 128, np.uint8))
            else:
                w.write(
                    render_marker_photo(
                        intr, pose, marker_length=marker_length, noise_sigma=noise, blur_sigma=0.6, seed=seed + i
                    ).image
                )
    return path


class _Distorted:
    """The pinhole oracle seen through the lens (points undistorted by OpenCV, converged)."""

    def __init__(self, oracle, K, dist):
        self.o, self.K, self.dist = oracle, np.asarray(K, float), np.asarray(dist, float)

    def image(self, roi):
        x0, y0, w, h = roi
        vv, uu = np.mgrid[y0 : y0 + h, x0 : x0 + w]
        pts = np.stack([uu.ravel(), vv.ravel()], 1).astype(np.float64).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
        p = cv2.undistortPoints(pts, self.K, self.dist, None, self.K, criteria=crit).reshape(-1, 2)
        m, g, o = self.o.classify(p[:, 0], p[:, 1])
        return m.reshape(h, w)


def _run_cli(*argv):
    from arshadow.cli import main

    return main([str(a) for a in argv])


# --------------------------------------------------------------------------------------------------
# reader / writer
# --------------------------------------------------------------------------------------------------
def test_reader_timestamps_and_lossless_mask_video(tmp_path):
    from arshadow.video.decode import VideoReader

    rng = np.random.default_rng(3)
    masks = [rng.integers(0, 256, (48, 64), dtype=np.uint8) for _ in range(6)]
    with CvClipWriter(tmp_path / "m.mkv", 30.0, (64, 48), color=False) as w:
        for m in masks:
            w.write(m)
    frames = list(VideoReader(tmp_path / "m.mkv"))
    assert [f.index for f in frames] == list(range(6))
    # Matroska stores timestamps in milliseconds: the decoder gives them at that resolution
    assert np.allclose([f.time_s for f in frames], np.arange(6) / 30.0, atol=1e-3)
    for f, m in zip(frames, masks, strict=True):
        assert f.image.shape == (48, 64, 3) and not f.image.flags.writeable
        assert np.array_equal(f.image[:, :, 0], m)  # FFV1: exact 8-bit values
    assert len(list(VideoReader(tmp_path / "m.mkv", max_frames=2))) == 2


def test_writer_reused_frame_keeps_every_frame_exact(tmp_path):
    """The writer refills one frame buffer per pixel format: lossless outputs (FFV1 of planar yuv420p, the
    grey mask) decode to exactly the frames written, each different, at a width whose planes are padded
    (100 px: rows of 112 and 64 bytes)."""
    from arshadow.video.avio import AvReader, AvWriter

    rng = np.random.default_rng(5)
    H, W = 48, 100
    yuv = [rng.integers(0, 256, (H * 3 // 2, W), np.uint8) for _ in range(4)]
    gray = [rng.integers(0, 256, (H, W), np.uint8) for _ in range(4)]
    with AvWriter(tmp_path / "y.mkv", 25, (W, H), codec="ffv1", pix_fmt="yuv420p") as w:
        for f in yuv:
            w.write_yuv420p(f)
    with AvWriter(tmp_path / "g.mkv", 25, (W, H), color=False) as w:
        for f in gray:
            w.write(f)
    got_y = [f.image for f in AvReader(tmp_path / "y.mkv", raw=True)]
    assert len(got_y) == 4 and all(np.array_equal(a, b) for a, b in zip(got_y, yuv, strict=True))
    import av

    with av.open(str(tmp_path / "g.mkv")) as c:
        got_g = [f.to_ndarray(format="gray") for f in c.decode(video=0)]
    assert len(got_g) == 4 and all(np.array_equal(a, b) for a, b in zip(got_g, gray, strict=True))


def test_writer_never_leaves_a_half_written_file(tmp_path):
    from arshadow.errors import ImageError
    from arshadow.video.avio import AvWriter as AtomicVideoWriter

    target = tmp_path / "out.mp4"
    target.write_bytes(b"old contents")
    with pytest.raises(RuntimeError):
        with AtomicVideoWriter(target, 25.0, (64, 48)) as w:
            for i in range(5):
                w.write(np.full((48, 64, 3), 40 * i, np.uint8))
            raise RuntimeError("interrupted mid-video")
    assert target.read_bytes() == b"old contents"  # the old file, untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.mp4"]  # no temporary left behind
    with pytest.raises(ImageError, match="expected"):  # wrong frame size: error, nothing written
        with AtomicVideoWriter(tmp_path / "b.mp4", 25.0, (64, 48)) as w:
            w.write(np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(ImageError, match="no frame"):
        with AtomicVideoWriter(tmp_path / "c.mp4", 25.0, (64, 48)):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.mp4"]


def test_reader_bad_input(tmp_path):
    from arshadow.errors import ImageError
    from arshadow.video.decode import VideoReader

    with pytest.raises(ImageError, match="no such video file"):
        VideoReader(tmp_path / "missing.mp4")
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"not a video at all " * 50)
    with pytest.raises(ImageError, match="cannot open as a video|no decodable frame"):
        VideoReader(junk)
    (tmp_path / "empty.mp4").write_bytes(b"")
    with pytest.raises(ImageError, match="empty"):
        VideoReader(tmp_path / "empty.mp4")


# --------------------------------------------------------------------------------------------------
# temporal IPPE choice (no GL)
# --------------------------------------------------------------------------------------------------
def _branch_flips(chosen, truth):
    """(wrong, flips): frames on the IPPE branch farther from the truth (branches > 5 deg apart), and
    changes of branch between consecutive frames."""
    from arshadow.transforms import rotation_error_deg as rotation_angle_deg

    br = []
    for c, t in zip(chosen, truth, strict=True):
        a = rotation_angle_deg(c.cam_from_world, t)
        b = rotation_angle_deg(c.alternative.cam_from_world, t)
        br.append(0 if abs(a - b) < 5.0 else int(a > b))
    return sum(br), sum(1 for x, y in pairwise(br) if x != y)


def test_temporal_choice_removes_ippe_flips():
    from arshadow.synth.markers import camera_path, render_marker_photo
    from arshadow.tracking.tracker import MarkerTracker
    from arshadow.video.chooser import TemporalPoseChooser

    intr = _intr()
    # small marker (4 cm at ~0.55 m: ~35 px), seen nearly face-on, noisy: many ambiguous frames
    truth = camera_path(40, radius=0.15, height=(0.5, 0.6), sweep_deg=90)
    tr = MarkerTracker(intr, marker_length=0.04, refine="subpix")  # edge corners: no flip here
    est = [
        tr.estimate(render_marker_photo(intr, p, marker_length=0.04, noise_sigma=2.0, blur_sigma=0.6, seed=i).image)
        for i, p in enumerate(truth)
    ]
    wrong0, flips0 = _branch_flips(est, truth)
    assert flips0 >= 3, "the sequence must be ambiguous for this test to mean anything"
    for lag in (0, 16):
        ch = TemporalPoseChooser(lag=lag, fps=FPS)
        out = []
        for i, p in enumerate(est):
            out += ch.push(i, p, i / FPS)
        out += ch.flush()
        assert [o.payload for o in out] == list(range(len(est)))  # in order, none lost
        wrong, flips = _branch_flips([o.pose for o in out], truth)
        assert (wrong, flips) == (0, 0), (lag, wrong, flips, wrong0, flips0)


def test_temporal_chooser_passes_frames_without_pose_and_breaks_long_gaps():
    from arshadow.video.chooser import TemporalPoseChooser

    ch = TemporalPoseChooser(lag=3, max_gap_s=0.2)
    got = []
    for i in range(5):
        got += ch.push(i, None, i / FPS)
    got += ch.flush()
    assert [c.payload for c in got] == list(range(5)) and all(c.pose is None for c in got)


# --------------------------------------------------------------------------------------------------
# end to end (GL)
# --------------------------------------------------------------------------------------------------
@pytest.mark.gl
def test_video_end_to_end_mask_iou_against_oracle(tmp_path, tol, gl_ctx):
    from arshadow.geometry.mesh import load_occluder
    from arshadow.synth.markers import camera_path

    poses = camera_path(10, radius=0.5, height=(0.3, 0.42), sweep_deg=40.0, start_deg=-110.0)
    clip = _write_clip(tmp_path / "clip.mp4", poses, blank={4})
    out = tmp_path / "out"
    rc = _run_cli(
        "video",
        clip,
        *BOX_SCENE,
        "-o",
        out,
        "--save-mask",
        "--format",
        "mkv",
        "--report",
        out / "r.json",
        "-q",
        "--hold",
        "0",
    )
    assert rc == 0
    rep = json.loads((out / "r.json").read_text())
    items = rep["images"]
    assert [it["frame"] for it in items] == list(range(10))
    assert [it["status"] for it in items] == ["ok"] * 4 + ["no_marker"] + ["ok"] * 5
    assert rep["videos"][0]["frames_no_marker"] == 1 and rep["videos"][0]["status"] == "ok"
    masks = read_frames(out / "clip.shadow.mkv")
    outs = read_frames(out / "clip.mkv")
    ins = read_frames(clip)
    assert len(masks) == len(outs) == 10
    # the frame without a marker is passed through unchanged (lossless output), with an empty mask
    assert np.array_equal(outs[4], ins[4]) and not masks[4].any()
    intr = _intr()
    caster = load_occluder("box:0.04,0.03,0.06", place=(0.05, 0.0, 0.0))
    ious = []
    for i, it in enumerate(items):
        if it["status"] != "ok":
            continue
        orc = _Distorted(
            ShadowOracle(intr.K, poses[i], caster.vertices, caster.faces, [(np.array([-0.1, 0.15, 0.4, 1.0]), 1.0)]),
            intr.K,
            intr.dist,
        )
        x0, y0, w, h = it["roi"]
        x1, y1 = min(W, x0 + w + 20), min(H, y0 + h + 20)
        x0, y0 = max(0, x0 - 20), max(0, y0 - 20)
        ref = orc.image((x0, y0, x1 - x0, y1 - y0)) >= 0.5
        got = masks[i][y0:y1, x0:x1, 0] >= 128
        assert ref.sum() > 300, (i, int(ref.sum()))
        ious.append(iou(got, ref))
    assert np.median(ious) >= tol.end_to_end_iou_median, ious
    assert min(ious) >= 0.85, ious


@pytest.mark.gl
def test_time_lapse_moves_the_sun_and_recomputes_only_past_the_angle(tmp_path, monkeypatch, gl_ctx):
    from datetime import datetime, timedelta, timezone

    import arshadow.geometry.silhouette as sil_mod
    from arshadow.lights.sun import enu_to_world, sun_position
    from arshadow.synth.markers import camera_path

    poses = camera_path(8, radius=0.5, height=(0.35, 0.4), sweep_deg=10.0, start_deg=-100.0)
    clip = _write_clip(tmp_path / "tl.mp4", poses)
    calls = []
    real = sil_mod.silhouette

    def counting(caster, light_h, *a, **k):
        calls.append(np.asarray(light_h, float).copy())
        return real(caster, light_h, *a, **k)

    monkeypatch.setattr(sil_mod, "silhouette", counting)
    lat, lon, speed, thr = 48.8566, 2.3522, 1800.0, 0.45
    start = datetime(2024, 6, 21, 9, 0, tzinfo=timezone(timedelta(hours=2)))
    out = tmp_path / "o"
    rc = _run_cli(
        "video",
        clip,
        "--calib",
        CALIB,
        "--marker-length",
        "0.05",
        "--model",
        "box:0.03,0.03,0.05",
        "--light",
        f"sun:{lat},{lon}",
        "--time-lapse",
        f"{start.isoformat()},{speed}",
        "--plan",
        "zfail",
        "--recompute-deg",
        thr,
        "-o",
        out,
        "--save-mask",
        "--report",
        out / "r.json",
        "-q",
    )
    assert rc == 0
    rep = json.loads((out / "r.json").read_text())
    # independent expectation: sun direction per frame time; greedy "moved more than thr since last"
    dirs = []
    for it in rep["images"]:
        when = start + timedelta(seconds=it["time_s"] * speed)
        p = sun_position(when, lat, lon)
        dirs.append(enu_to_world(p.enu, 0.0))

    def ang(a, b):
        return np.degrees(np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))

    expect, last = [], None
    for d in dirs:
        rec = last is None or ang(d, last) > thr
        expect.append(rec)
        if rec:
            last = d
    assert ang(dirs[0], dirs[-1]) > 2 * thr  # the sun really moves over the clip
    assert 1 < sum(expect) < len(expect)  # some frames recompute, some reuse
    assert [s["recompute"] for it in rep["images"] for s in it["sun"]] == expect
    # the silhouette was computed at those frames where the box's facing changed (the planner keeps the
    # cached silhouette of a moved light whose faces all keep their facing: docs/planner.md); the box's
    # face normals are the six axis directions, so its facing is the sign pattern of the sun direction
    want, facing = [], None
    for d, e in zip(dirs, expect, strict=True):
        f = tuple(np.sign(np.round(d, 12)))
        if e and f != facing:
            want.append(d)
            facing = f
    assert len(calls) == len(want)
    for c, d in zip(calls, want, strict=True):
        assert ang(c[:3], d) < 1e-6 and c[3] == 0.0
    # the shadow moves: masks of the first and last frame differ
    m = read_frames(out / "tl.shadow.mkv")
    assert np.count_nonzero((m[0][:, :, 0] >= 128) != (m[-1][:, :, 0] >= 128)) > 50
    assert rep["videos"][0]["recomputes"] == sum(expect)


# --------------------------------------------------------------------------------------------------
# command line: bad input
# --------------------------------------------------------------------------------------------------
def _scene(*extra):
    return [
        "--calib",
        CALIB,
        "--marker-length",
        "0.05",
        "--model",
        "box:0.03,0.03,0.05",
        "--light",
        "point:0,0.1,0.4",
        *extra,
    ]


@pytest.mark.gl
def test_cli_bad_videos_one_line_each_others_processed(tmp_path, capsys):
    from arshadow.synth.markers import camera_path

    good = _write_clip(tmp_path / "good.mp4", camera_path(3, radius=0.5, height=(0.35, 0.4), sweep_deg=5.0))
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"\x00garbage" * 200)
    out = tmp_path / "o"
    rc = _run_cli("video", tmp_path / "missing.mp4", junk, good, *_scene(), "-o", out, "--report", out / "r.json", "-q")
    assert rc == 1
    err = capsys.readouterr().err.strip().splitlines()
    # the sanity gates: the good clip's poses are flagged (a small, soft marker): beside the two errors, one warning
    # line saying so, and nothing else
    others = err[2:]
    assert len(err) == 2 + len(others) and len(others) <= 1, err
    assert all(
        ln.startswith("arshadow video: warning: ") and "good.mp4" in ln and "flagged pose" in ln for ln in others
    ), err
    assert "missing.mp4" in err[0] and "no such video file" in err[0]
    assert "junk.avi" in err[1] and "video" in err[1]
    assert "Traceback" not in "\n".join(err)
    assert (out / "good.mp4").is_file() and not (out / "junk.mp4").exists()
    rep = json.loads((out / "r.json").read_text())
    assert [v["status"] for v in rep["videos"]] == ["error", "error", "ok"]
    assert sorted(p.name for p in out.iterdir()) == [
        "good.frames.jsonl",
        "good.mp4",
        "good.sheet.jpg",
        "r.json",
    ]  # no temporaries


def test_cli_bad_usage_exit_2(tmp_path, capsys):
    out = tmp_path / "o"
    clip = tmp_path / "x.mp4"
    assert _run_cli("video", clip, *_scene("--time-lapse", "yesterday"), "-o", out) == 2
    assert "--time-lapse" in capsys.readouterr().err
    assert _run_cli("video", clip, *_scene("--time-lapse", "2024-06-21T09:00+02:00,600"), "-o", out) == 2
    assert "sun light" in capsys.readouterr().err
    assert _run_cli("video", clip, *_scene("--recompute-deg", "-1"), "-o", out) == 2
    assert not out.exists()


def test_rotation_vectors_equal_opencv_rodrigues():
    """The vectorised log map used by the pose smoothing, from 1e-9 rad to pi (the near-pi branch
    included): the generating rotation vector back, and cv2.Rodrigues's (which rounds angles below 1e-5
    rad to 0: compared from 1e-3 rad up)."""
    import cv2

    from arshadow.transforms import NEAR_PI_RAD, rotation_vectors

    rng = np.random.default_rng(3)
    mats, truth, opencv = [], [], []
    for angle in (0.0, 1e-9, 1e-6, 1e-3, 0.1, 1.0, NEAR_PI_RAD - 0.01, NEAR_PI_RAD + 0.01, 3.1, np.pi - 1e-6):
        for _ in range(20):
            axis = rng.normal(size=3)
            r = axis / np.linalg.norm(axis) * angle
            R = cv2.Rodrigues(r)[0]
            mats.append(R)
            truth.append(r)
            opencv.append(cv2.Rodrigues(R)[0].ravel() if angle >= 1e-3 else r)
    got = rotation_vectors(np.stack(mats))
    assert np.abs(got - np.array(opencv)).max() < 1e-12
    # near pi the vector is OpenCV's (r and -r are nearly the same rotation there; its sign is OpenCV's)
    below = np.linalg.norm(truth, axis=1) < NEAR_PI_RAD
    assert np.abs(got[below] - np.array(truth)[below]).max() < 1e-9


def test_exposure_smoothing_restarts_after_a_long_loss():
    """A marker lost for RESTART_AFTER frames in a row is a new shot for the exposure smoothing: the next
    measurement is taken as it is; after a shorter loss the filter goes on from where it was."""
    from arshadow.estimate.exposure import RESTART_AFTER, Exposure, ExposureSmoother

    def paper(v):
        return Exposure((v, v, v), (0.02, 0.02, 0.02), 20)

    for gap, restarted in ((RESTART_AFTER - 1, False), (RESTART_AFTER, True)):
        sm = ExposureSmoother()
        for _ in range(5):
            sm.update(paper(0.5))
        for k in range(gap):
            if k % 2:
                sm.update(None)  # a held frame (rendered, not measured)
            else:
                sm.missing()  # a frame without the marker (not rendered)
        got = sm.update(paper(0.56)).paper_rgb[0]  # 12 % brighter: below the jump rule's 15 %
        assert (got == pytest.approx(0.56, rel=1e-12)) == restarted, (gap, got)
        assert got < 0.56 or restarted
