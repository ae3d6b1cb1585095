"""The video engine (arshadow/video/engine.py, avio.py, temporal.py) and ``arshadow batch`` (batch.py).

Short 640x360 clips made by tests/video_clips.py (true poses from the generator); the long judged runs
are in tests/benchmarks/bench_video_engine.py.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from video_clips import BOX_JOB, BOX_SCENE, make_clip

av = pytest.importorskip("av")

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_640x360.yml"
SCENE = BOX_SCENE
JOB = {
    **BOX_JOB,
    "refine": "edge",
}


def _intr():
    from arshadow.camera.model import Intrinsics

    return Intrinsics.from_file(CALIB)


def _poses(n):
    from arshadow.synth.markers import camera_path

    return camera_path(n, radius=0.5, height=(0.3, 0.42), sweep_deg=30.0, start_deg=-110.0)


def _cli(*argv):
    from arshadow.cli import main

    return main([str(a) for a in argv])


def _frames(path, raw=False):
    from arshadow.video.avio import AvReader

    return [f.image for f in AvReader(path, raw=raw)]


def _lines(path):
    return [json.loads(s) for s in Path(path).read_text().splitlines()]


# --------------------------------------------------------------------------------------------------
def test_pose_stream_smooths_without_lag_and_holds_then_releases():
    """Unit test of PoseStream on synthetic poses: a steady pan with noise comes out less noisy and not
    behind; a gap is held for ``hold_frames`` and then passed through."""
    from arshadow.synth.markers import pan_path
    from arshadow.transforms import matrix_from_rvec_tvec, rotation_error_deg, rvec_tvec_from_matrix
    from arshadow.video.temporal import PoseStream

    rng = np.random.default_rng(3)
    truth = pan_path(80, deg_per_frame=0.5)

    class P:  # the two attributes PoseStream reads of a MarkerPose
        def __init__(self, m):
            self.cam_from_world, self.alternative, self.n_points, self.reprojection_error_px = m, None, 4, 0.1

    noisy = []
    for m in truth:
        r, t = rvec_tvec_from_matrix(m)
        noisy.append(matrix_from_rvec_tvec(r + rng.normal(0, 0.002, 3), t + rng.normal(0, 0.001, 3)))
    gap = set(range(50, 70))
    ps = PoseStream(fps=25.0, lag=4, window=10, hold_frames=5)
    out = []
    for i, m in enumerate(noisy):
        out += ps.push(i, None if i in gap else P(m), i / 25.0)
    out += ps.flush()
    assert [d.payload for d in out] == list(range(80))
    st = [d.status for d in out]
    assert st[50:55] == ["held"] * 5 and st[55:70] == ["no_marker"] * 15 and st[70] == "ok"
    assert np.allclose(out[52].cam_from_marker, out[49].cam_from_marker)
    ok = [i for i in range(80) if i not in gap]
    e_raw = [rotation_error_deg(noisy[i][:3, :3], truth[i][:3, :3]) for i in ok]
    e_sm = [rotation_error_deg(out[i].cam_from_marker[:3, :3], truth[i][:3, :3]) for i in ok]
    assert np.median(e_sm) < 0.6 * np.median(e_raw)
    # lag: a world point's image under the smoothed poses is not behind its true image (steady pan)
    from video_clips import jitter_and_lag

    intr = _intr()
    pt = np.array([[0.1, 0.05, 0.0]])
    c_true = [intr.project(pt, truth[i])[0] for i in ok]
    c_sm = [intr.project(pt, out[i].cam_from_marker)[0] for i in ok]
    c_raw = [intr.project(pt, noisy[i])[0] for i in ok]
    j_sm, lag = jitter_and_lag(c_sm[:45], c_true[:45])
    j_raw, _ = jitter_and_lag(c_raw[:45], c_true[:45])
    assert abs(lag) < 0.1 and j_raw > 3 * j_sm, (lag, j_raw, j_sm)


def test_i420_roi_conversion_in_place_equals_the_copy():
    """Written into the decoded frame itself (``out=yuv``: the engine's path), the result is the new array
    of the copying call (checked against OpenCV's whole-frame conversion in the test below) and ``yuv``
    is that result."""
    from arshadow.video.framejob import i420_with_roi as _i420_with_roi

    rng = np.random.default_rng(4)
    H, W = 72, 128
    for roi in [(11, 7, 31, 19), (0, 0, W, H), (W - 1, H - 1, 5, 5), (-10, -10, 30, 31), (50, 30, 0, 10), None]:
        yuv = rng.integers(0, 256, (H * 3 // 2, W), np.uint8)
        bgr = rng.integers(0, 256, (H, W, 3), np.uint8)
        ref = _i420_with_roi(yuv, bgr, roi)
        buf = yuv.copy()
        got = _i420_with_roi(buf, bgr, roi, out=buf)
        assert got is buf and np.array_equal(got, ref)
        other = np.zeros_like(yuv)
        assert _i420_with_roi(yuv, bgr, roi, out=other) is other and np.array_equal(other, ref)


def test_i420_roi_conversion_changes_only_the_even_aligned_roi():
    """The encoder's frame: inside the ROI (widened to even pixels) exactly OpenCV's whole-frame BGR -> I420,
    outside it the decoded planes untouched."""
    import cv2

    from arshadow.video.framejob import i420_with_roi as _i420_with_roi

    rng = np.random.default_rng(3)
    H, W = 72, 128
    yuv = rng.integers(0, 256, (H * 3 // 2, W), np.uint8)
    for roi in [(11, 7, 31, 19), (0, 0, W, H), (W - 1, H - 1, 5, 5), (-10, -10, 30, 31), (50, 30, 0, 10)]:
        bgr = rng.integers(0, 256, (H, W, 3), np.uint8)  # differs from yuv everywhere
        got = _i420_with_roi(yuv, bgr, roi)
        full = cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_I420)
        x0, y0, w, h = roi
        x1, y1 = min(W, x0 + w), min(H, y0 + h)
        x0, y0 = max(0, x0), max(0, y0)
        inside = np.zeros((H, W), bool)
        if w > 0 and h > 0:
            inside[y0 - y0 % 2 : y1 + y1 % 2, x0 - x0 % 2 : x1 + x1 % 2] = True
        chroma = inside[::2, ::2].ravel()
        for a, b, m in (
            (got[:H], full[:H], inside),
            (got[H:].ravel()[: H * W // 4], full[H:].ravel()[: H * W // 4], chroma),
            (got[H:].ravel()[H * W // 4 :], full[H:].ravel()[H * W // 4 :], chroma),
        ):
            assert np.array_equal(a[m], b[m])
        assert np.array_equal(got[:H][~inside], yuv[:H][~inside])
        assert np.array_equal(got[H:].ravel()[: H * W // 4][~chroma], yuv[H:].ravel()[: H * W // 4][~chroma])
        assert np.array_equal(got[H:].ravel()[H * W // 4 :][~chroma], yuv[H:].ravel()[H * W // 4 :][~chroma])


@pytest.mark.gl
def test_marker_absent_30_frames_held_then_passed_through_untouched(tmp_path, gl_ctx):
    n, gap = 45, range(5, 35)
    clip = make_clip(tmp_path / "gap.mkv", _intr(), _poses(n), blank=set(gap), codec="ffv1", noise=1.0)
    out = tmp_path / "out"
    rc = _cli("video", clip, *SCENE, "-o", out, "--format", "mkv", "--hold", "12", "-q", "--save-mask")
    assert rc == 0
    lines = _lines(out / "gap.frames.jsonl")
    assert [ln["frame"] for ln in lines] == list(range(n))
    st = [ln["status"] for ln in lines]
    assert st[:5] == ["ok"] * 5 and st[5:17] == ["held"] * 12 and st[17:35] == ["no_marker"] * 18
    assert st[35:] == ["ok"] * 10
    for ln in lines:
        assert {"frame", "time_s", "status", "marker_ids", "rvec", "tvec", "raw", "mode", "timings_ms"} <= set(ln)
        assert (ln["raw"] is None) == (ln["status"] != "ok")
    # held frames render the last pose; released frames are the input, bit for bit (lossless yuv420p)
    assert lines[10]["rvec"] == lines[4]["rvec"]
    ins, outs = _frames(clip, raw=True), _frames(out / "gap.mkv", raw=True)
    masks = _frames(out / "gap.shadow.mkv")
    assert len(outs) == n == len(masks)
    for i in range(17, 35):
        assert np.array_equal(ins[i], outs[i]) and not masks[i].any()
    assert masks[10].any() and not np.array_equal(ins[10], outs[10])
    assert (out / "gap.sheet.jpg").exists()


@pytest.mark.gl
def test_corrupt_frames_are_skipped_reported_and_exit_1(tmp_path, gl_ctx, capsys):
    n = 12
    clip = make_clip(tmp_path / "c.avi", _intr(), _poses(n), codec="mjpeg", noise=1.0)
    # overwrite the middle of two frames' JPEG data with garbage
    c = av.open(str(clip))
    pos = [p.pos for p in c.demux(video=0) if p.pos is not None and p.size]
    sizes = [p.size for p in av.open(str(clip)).demux(video=0) if p.pos is not None and p.size]
    c.close()
    data = bytearray(clip.read_bytes())
    for k in (4, 8):  # two frames' JPEG data zeroed: undecodable packets
        data[pos[k] : pos[k] + sizes[k]] = b"\x00" * sizes[k]
    clip.write_bytes(bytes(data))
    assert len(sizes) == n
    out = tmp_path / "out"
    rc = _cli("video", clip, *SCENE, "-o", out, "--report", out / "r.json", "-q")
    err = capsys.readouterr().err
    assert rc == 1
    v = json.loads((out / "r.json").read_text())["videos"][0]
    assert v["status"] == "damaged" and v["decode_errors"] == 2 and "damaged packet" in err
    assert not v["truncated"] and v["frames"] == n - 2 and v["frames_ok"] == n - 2
    assert len(_frames(out / "c.mp4")) == v["frames"]


@pytest.mark.gl
def test_truncated_video_warns_and_exits_1_but_writes_what_it_read(tmp_path, gl_ctx, capsys):
    n = 20
    clip = make_clip(tmp_path / "t.mp4", _intr(), _poses(n), noise=1.0)
    data = clip.read_bytes()
    clip.write_bytes(data[: int(len(data) * 0.6)])
    out = tmp_path / "out"
    rc = _cli("video", clip, *SCENE, "-o", out, "--report", out / "r.json", "-q")
    err = capsys.readouterr().err
    assert rc == 1 and "warning" in err and "ends early" in err
    v = json.loads((out / "r.json").read_text())["videos"][0]
    assert v["truncated"] and v["status"] == "damaged" and 0 < v["frames"] < n
    assert len(_frames(out / "t.mp4")) == v["frames"]


@pytest.mark.gl
def test_phone_rotation_is_kept_and_named_when_the_calibration_is_turned(tmp_path, gl_ctx, capsys):
    """A video stored sideways with a display rotation (a phone filmed upright) is tracked on its stored
    frames and written with the same rotation; a calibration of the turned (displayed) size fails with
    one line naming the rotation."""
    import cv2

    from arshadow.video.avio import AvReader

    clip = make_clip(tmp_path / "r.mp4", _intr(), _poses(6), noise=1.0, rotation=90)
    assert AvReader(clip).rotation == 90
    out = tmp_path / "out"
    assert _cli("video", clip, *SCENE, "-o", out, "-q") == 0
    assert AvReader(out / "r.mp4").rotation == 90
    # in chunks (the parts are joined by packet copy), the same
    clip2 = make_clip(tmp_path / "r2.mp4", _intr(), _poses(40), noise=1.0, rotation=270, gop=10)
    assert _cli("video", clip2, *SCENE, "-o", out, "-q", "--jobs", "2") == 0
    assert AvReader(out / "r2.mp4").rotation == 270
    # the same camera, calibrated in the displayed (portrait) orientation
    intr = _intr()
    K = intr.K.copy()
    K[[0, 1]] = K[[1, 0]]
    K[:, [0, 1]] = K[:, [1, 0]]
    turned = tmp_path / "portrait.yml"
    fs = cv2.FileStorage(str(turned), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", intr.height)
    fs.write("image_height", intr.width)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", np.zeros((5, 1)))
    fs.release()
    scene = [a if a != str(CALIB) else str(turned) for a in map(str, SCENE)]
    capsys.readouterr()
    rc = _cli("video", clip, *scene, "-o", tmp_path / "o2", "-q")
    err = capsys.readouterr().err
    assert rc != 0 and "shown turned by 90 degrees" in err and f"stored {intr.width}x{intr.height}" in err


@pytest.mark.gl
def test_exposure_match_reads_the_paper_outside_the_roi(tmp_path, gl_ctx, monkeypatch):
    """yuv420p frames are converted to BGR only inside the plan's ROI; an object placed away from the
    marker leaves the paper outside it, and the exposure match read zeros there (a black object). The
    paper measured by the engine must equal the measurement on the whole frame converted the same way."""
    import cv2

    from arshadow.estimate import match
    from arshadow.estimate.exposure import measure_exposure
    from arshadow.video.avio import AvReader

    seen = []
    gain = match.ExposureMatch.gain

    def spy(self, image, intr, cfm, mid, geometry, pfw=None, in_frame=True):
        g, rep = gain(self, image, intr, cfm, mid, geometry, pfw, in_frame)
        seen.append((np.array(cfm), intr, rep.get("paper_rgb")))
        return g, rep

    monkeypatch.setattr(match.ExposureMatch, "gain", spy)
    clip = make_clip(tmp_path / "c.mp4", _intr(), _poses(8), noise=1.0)
    # the scene's box moved 0.2 m away from the marker (the last --place wins)
    assert _cli("video", clip, *SCENE, "--place", "0.2,0.1,0", "-o", tmp_path / "o", "-q") == 0
    frames = [f.image for f in AvReader(clip, raw=True)]
    assert len(seen) == len(frames) and all(f.shape[0] == _intr().height * 3 // 2 for f in frames)
    for (cfm, intr, paper), yuv in zip(seen, frames, strict=True):
        truth = measure_exposure(cv2.cvtColor(yuv, cv2.COLOR_YUV2BGR_I420), intr, cfm, 0.05, "DICT_6X6_250", 0)
        assert paper is not None and np.allclose(paper, truth.paper_rgb, atol=1e-6), (paper, truth.paper_rgb)


@pytest.mark.gl
def test_exposure_match_holds_while_the_marker_is_hidden(tmp_path, gl_ctx):
    """Frames rendered with a held pose (the marker hidden) must not measure the paper where the pose says
    it is: the floor there made the object four times darker, and the first frame after the marker came
    back too. Truth: the clip's exposure never changes (one camera gain for every frame of make_clip), so
    every composited frame's gain is the tracked frames' gain, the held ones exactly the last one's."""
    clip = make_clip(tmp_path / "h.mp4", _intr(), _poses(16), noise=1.0, blank=(6, 7, 8))
    rep = tmp_path / "r.json"
    assert _cli("video", clip, *SCENE, "-o", tmp_path / "o", "-q", "--report", rep) == 0
    items = json.loads(rep.read_text())["images"]
    status = [it["status"] for it in items]
    assert status[6:9] == ["held"] * 3 and status.count("ok") == 13, status
    gains = np.array([it["exposure"]["gain"] for it in items])
    assert np.all(np.abs(gains / np.median(gains, axis=0) - 1) < 0.03), gains
    assert np.array_equal(gains[6:9], np.repeat(gains[5:6], 3, axis=0))
    assert all(items[i]["exposure"].get("held") for i in (6, 7, 8))
    assert all("paper_rgb" not in items[i]["exposure"] for i in (6, 7, 8))


@pytest.mark.gl
def test_h264_output_keeps_size_rate_and_audio(tmp_path, gl_ctx):
    clip = make_clip(tmp_path / "a.mp4", _intr(), _poses(10), noise=1.0, fps=30, audio=True)
    out = tmp_path / "out"
    assert _cli("video", clip, *SCENE, "-o", out, "-q", "--crf", "23") == 0
    with av.open(str(out / "a.mp4")) as c:
        vs = c.streams.video[0]
        assert vs.codec_context.name == "h264" and (vs.width, vs.height) == (640, 360)
        assert float(vs.average_rate) == pytest.approx(30.0)
        assert c.streams.audio and c.streams.audio[0].codec_context.name == "aac"
    assert len(_frames(out / "a.mp4")) == 10


def _write_job(tmp_path):
    p = tmp_path / "job.json"
    p.write_text(json.dumps(JOB))
    return p


def _batch_inputs(tmp_path, n_videos=3, frames=16):
    from arshadow.io import write_image
    from arshadow.synth.markers import render_marker_photo

    ins = [make_clip(tmp_path / f"v{k}.mp4", _intr(), _poses(frames), noise=1.0, seed=10 * k) for k in range(n_videos)]
    ph = render_marker_photo(_intr(), _poses(3)[1], marker_length=0.05, noise_sigma=1.0, seed=5)
    ins.append(write_image(tmp_path / "p0.png", ph.image))
    return ins


@pytest.mark.gl
def test_batch_kill9_mid_run_then_rerun_completes_everything(tmp_path):
    frames = 16
    ins = _batch_inputs(tmp_path, frames=frames)
    job = _write_job(tmp_path)
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "arshadow",
        "batch",
        *map(str, ins),
        "--config",
        str(job),
        "-o",
        str(out),
        "-q",
        "--save-mask",
    ]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rec = out / ".arshadow-batch"
    t0 = time.time()
    # kill while the second video is being written (its temporary file exists), after the first is done
    while time.time() - t0 < 120:
        done = list(rec.glob("*.json")) if rec.exists() else []
        tmps = [p for p in out.glob(".v1.*")] if out.exists() else []
        if done and tmps:
            break
        if proc.poll() is not None:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the batch finished before it could be killed: make the inputs longer"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / "v1.mp4").exists()  # never half-written
    assert [p.name for p in rec.glob("*.json")] == ["v0.json"]
    rc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    assert rc.returncode == 0, rc.stderr
    summary = json.loads((out / "batch.json").read_text())
    assert [it["status"] for it in summary["items"]] == ["ok"] * 4
    assert [it["skipped"] for it in summary["items"]] == [True, False, False, False]
    for k in range(3):
        assert len(_frames(out / f"v{k}.mp4")) == frames
        assert len(_lines(out / f"v{k}.frames.jsonl")) == frames
        assert len(_frames(out / f"v{k}.shadow.mkv")) == frames
    import cv2

    assert cv2.imread(str(out / "p0.png")).shape == (360, 640, 3)
    assert not [p for p in out.iterdir() if ".tmp" in p.name]


@pytest.mark.gl
def test_batch_on_dask_localcluster_equals_local(tmp_path):
    distributed = pytest.importorskip("distributed")
    from arshadow.scene.spec import scene_from_dict
    from arshadow.video.batch import run_batch
    from arshadow.video.engine import EngineOptions

    ins = _batch_inputs(tmp_path, n_videos=2, frames=8)
    # one compose path for every process: with `auto` each process times the numpy and shader paths on its
    # first frame, and the two may differ by one 8-bit level (docs/planner.md)
    spec = scene_from_dict({**JOB, "compose": "cpu"})
    opts = EngineOptions(codec="ffv1", fmt="mkv", mask="mkv", contact_sheet=0)
    local = run_batch(spec, ins, tmp_path / "local", opts, save_mask=True)
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl,
        distributed.Client(cl) as client,
    ):
        remote = run_batch(spec, ins, tmp_path / "dask", opts, save_mask=True, client=client)
    assert [it["status"] for it in local["items"]] == [it["status"] for it in remote["items"]] == ["ok"] * 3
    for k in range(2):
        a, b = _lines(tmp_path / "local" / f"v{k}.frames.jsonl"), _lines(tmp_path / "dask" / f"v{k}.frames.jsonl")
        for la, lb in zip(a, b, strict=True):
            la.pop("timings_ms"), lb.pop("timings_ms")
        assert a == b
        for name in (f"v{k}.mkv", f"v{k}.shadow.mkv"):
            fa, fb = _frames(tmp_path / "local" / name, raw=True), _frames(tmp_path / "dask" / name, raw=True)
            assert len(fa) == len(fb) == 8 and all(np.array_equal(x, y) for x, y in zip(fa, fb, strict=True))
    assert (tmp_path / "local" / "p0.png").read_bytes() == (tmp_path / "dask" / "p0.png").read_bytes()


@pytest.mark.gl
def test_yuv420p_frames_take_back_all_the_camera_blur_writes(tmp_path, gl_ctx, monkeypatch):
    """With camera effects on and no motion blur, the compositor writes the ROI grown by the camera blur's
    reach (the object's and its shadow's blurred edges spill past the ROI's 2 px margin). A yuv420p frame
    must be converted and written back over all of that region: the ROI alone dropped the spill."""
    from arshadow.frame import execute
    from arshadow.video import framejob

    touched, written, rois = [], [], []
    real_touched, real_back = execute._touched, framejob.i420_with_roi

    def spy_touched(frame):
        rois.append(tuple(frame.plan.roi))
        touched.append(tuple(real_touched(frame)))
        return touched[-1]

    def spy_back(img, bgr, roi, out=None):
        written.append(tuple(int(v) for v in roi))
        return real_back(img, bgr, roi, out=out)

    monkeypatch.setattr(execute, "_touched", spy_touched)
    monkeypatch.setattr(framejob, "i420_with_roi", spy_back)
    clip = make_clip(tmp_path / "c.mp4", _intr(), _poses(4), noise=1.0)  # H.264: yuv420p frames
    out = tmp_path / "o"
    argv = ("--format", "mkv", "-q", "--camera-effects", "on", "--motion-blur", "off")
    assert _cli("video", clip, *SCENE, "-o", out, *argv) == 0
    assert len(touched) == len(written) == len(rois) == 4
    for t, w, r in zip(touched, written, rois, strict=True):
        assert t[0] < r[0] and t[2] > r[2]  # the camera's blur reaches past the ROI
        assert w[0] <= t[0] and w[1] <= t[1] and w[0] + w[2] >= t[0] + t[2] and w[1] + w[3] >= t[1] + t[3], (w, t)


@pytest.mark.gl
def test_video_camera_effects_are_measured_on_the_whole_frame_and_applied(tmp_path, gl_ctx):
    """--camera-effects on in a video: the blur and the noise are measured once, on the whole of the first
    tracked frame, and applied. Before: the video's smoothed pose carried no tracked marker to measure on, so
    nothing was applied (the frames equalled --camera-effects off), and a yuv420p frame converted inside the
    ROI only would have shown the measurement a black floor. Truth: make_clip's blur (0.8 px, before H.264)
    and its floor, a mid grey."""
    clip = make_clip(tmp_path / "c.mp4", _intr(), _poses(3), noise=2.0)
    frames, reports = {}, {}
    for ce in ("off", "on"):
        rep = tmp_path / f"{ce}.json"
        argv = ("--format", "mkv", "-q", "--camera-effects", ce, "--motion-blur", "off", "--report", rep)
        assert _cli("video", clip, *SCENE, "-o", tmp_path / ce, *argv) == 0
        frames[ce], reports[ce] = _frames(tmp_path / ce / "c.mkv"), json.loads(rep.read_text())
    effects = [im["plan"]["camera_effects"] for im in reports["on"]["images"]]
    assert all(e == effects[0] for e in effects)  # measured once
    assert 0.3 <= effects[0]["blur_sigma_px"] <= 1.2, effects[0]
    assert effects[0]["noise"] and all(max(n["level"]) > 50 for n in effects[0]["noise"]), effects[0]
    assert any(not np.array_equal(a, b) for a, b in zip(frames["on"], frames["off"], strict=True))
    assert all("camera_effects" not in im["plan"] for im in reports["off"]["images"])
