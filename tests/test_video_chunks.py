"""One video cut at keyframes into chunks (arshadow/video/scan.py, chunks.py, parallel.py): the chunked run
equals the sequential one.

Ground truth is the sequential run of the same code (``--jobs 1``: one process, one piece), which the
other tests check against the generating poses; here the claim is equality: the same per-frame status and
pose (the JSON Lines records, exact), the same lossless mask frames (FFV1, decoded and compared), the same
frame count and audio. Clips: tests/video_clips.py (synthetic frames, H.264 with a fixed GOP so that
keyframes fall where the test needs them; a marker-free stretch so that hold and marker loss cross a
chunk boundary).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from fractions import Fraction
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
    "compose": "cpu",
}
#: keys of a frame record that must be equal between the runs
KEYS = (
    "frame",
    "time_s",
    "status",
    "marker_ids",
    "rvec",
    "tvec",
    "raw",
    "reprojection_error_px",
    "pose_choice",
    "mode",
)


def _intr():
    from arshadow.camera.model import Intrinsics

    return Intrinsics.from_file(CALIB)


def _poses(n):
    from arshadow.synth.markers import camera_path

    return camera_path(n, radius=0.5, height=(0.3, 0.42), sweep_deg=40.0, start_deg=-110.0)


def _clip(path, n=72, gop=24, blank=range(16, 34), audio=True):
    return make_clip(path, _intr(), _poses(n), noise=1.0, seed=7, blank=set(blank), gop=gop, audio=audio)


def _cli(*argv):
    from arshadow.cli import main

    return main([str(a) for a in argv])


def _lines(path):
    return [json.loads(s) for s in Path(path).read_text().splitlines()]


def _masks(path):
    with av.open(str(path)) as c:
        return [f.to_ndarray(format="gray") for f in c.decode(video=0)]


def _video(path):
    with av.open(str(path)) as c:
        return sum(1 for _ in c.decode(video=0)), bool(c.streams.audio)


def _report(path):
    return json.loads(Path(path).read_text())["videos"][0]


def assert_same_run(a_dir, b_dir, stem, n):
    """Equal per-frame records (status, poses: exact), equal mask frames, same frame count and audio."""
    la, lb = _lines(a_dir / f"{stem}.frames.jsonl"), _lines(b_dir / f"{stem}.frames.jsonl")
    assert [d["frame"] for d in la] == [d["frame"] for d in lb] == list(range(n))
    for x, y in zip(la, lb, strict=True):
        assert {k: x.get(k) for k in KEYS} == {k: y.get(k) for k in KEYS}, f"frame {x['frame']}"
    ma, mb = _masks(a_dir / f"{stem}.shadow.mkv"), _masks(b_dir / f"{stem}.shadow.mkv")
    assert len(ma) == len(mb) == n
    assert all(np.array_equal(x, y) for x, y in zip(ma, mb, strict=True))
    assert _video(a_dir / f"{stem}.mp4") == _video(b_dir / f"{stem}.mp4")
    return la


def _run(clip, out, *extra):
    rc = _cli(
        "video", clip, *SCENE, "--compose", "cpu", "--save-mask", "-q", "-o", out, "--report", out / "r.json", *extra
    )
    return rc, _report(out / "r.json")


# --------------------------------------------------------------------------------------------------
def test_plan_cuts_at_keyframes_and_primes_from_before():
    from arshadow.video.chunks import margins, plan_chunks
    from arshadow.video.engine import EngineOptions
    from arshadow.video.scan import StreamIndex

    opts = EngineOptions()
    prime, check, tail = margins(opts)
    idx = StreamIndex(pts=list(range(600)), times=[i / 25 for i in range(600)], keyframes=list(range(0, 600, 50)))
    chunks, note = plan_chunks(idx, 600, opts, 4)
    assert note is None
    assert [c.start for c in chunks] == [0, 150, 300, 450]
    assert [c.stop for c in chunks] == [150, 300, 450, 600]
    for c in chunks[1:]:  # decoding starts at a keyframe at least `prime` frames before the chunk
        assert c.decode_from in idx.keyframes and c.start - c.decode_from >= prime
    for c in chunks[:-1]:  # and goes on `tail` frames past its end: the pose look-ahead, no more
        assert c.decode_stop == c.stop + tail
    assert tail == opts.smooth + opts.pose_lag + 2 and check == tail + opts.smooth
    one, note = plan_chunks(StreamIndex(pts=list(range(90)), times=[0.0] * 90, keyframes=[0]), 90, opts, 3)
    assert len(one) == 1 and "no keyframe after the first frame" in note
    # keyframes at 0 and 130 only (x264's scene cut): the boundary goes `prime` frames after 130, so that
    # nothing is decoded in vain, rather than at 130 (a primer decoding 80 frames from frame 0)
    idx = StreamIndex(pts=list(range(300)), times=[i / 25 for i in range(300)], keyframes=[0, 130])
    two, _ = plan_chunks(idx, 300, opts, 2)
    assert [c.start for c in two] == [0, 130 + prime] and two[1].decode_from == two[1].prime_from == 130


def assert_same_items(a_report, b_report, tol):
    """The reports' per-frame items: every key equal but the timings and the output paths; the exposure
    match's gain within ``tol.chunk_exposure_gain_rel`` (its smoothing's memory, see conftest)."""
    ia = json.loads(Path(a_report).read_text())["images"]
    ib = json.loads(Path(b_report).read_text())["images"]
    assert len(ia) == len(ib)
    for x, y in zip(ia, ib, strict=True):
        skip = {"timings_ms", "output", "mask", "exposure"}
        assert {k: v for k, v in x.items() if k not in skip} == {k: v for k, v in y.items() if k not in skip}
        assert set(x) == set(y), x["frame"]
        if "exposure" in x:
            ex, ey = x["exposure"], y["exposure"]
            assert set(ex) == set(ey) and ex.get("paper_rgb") == ey.get("paper_rgb"), x["frame"]
            if "gain" in ex:
                np.testing.assert_allclose(ey["gain"], ex["gain"], rtol=tol.chunk_exposure_gain_rel)


@pytest.mark.gl
def test_jobs2_equals_sequential(tmp_path, tol):
    clip = _clip(tmp_path / "c.mp4")
    rc1, s1 = _run(clip, tmp_path / "seq")
    rc2, s2 = _run(clip, tmp_path / "par", "--jobs", "2")
    assert rc1 == rc2 == 0
    assert "chunks" not in s1 and len(s2["chunks"]) == 2
    lines = assert_same_run(tmp_path / "seq", tmp_path / "par", "c", 72)
    assert_same_items(tmp_path / "seq" / "r.json", tmp_path / "par" / "r.json", tol)
    # the clip exercises what crosses a boundary: held frames and frames without the marker
    assert {d["status"] for d in lines} == {"ok", "held", "no_marker"}
    for k in (
        "frames",
        "frames_ok",
        "frames_held",
        "frames_no_marker",
        "swapped",
        "status",
        "audio",
        "warnings",
        "longest_gap",
        "longest_gap_start",
    ):
        seq = s1[k]
        if k == "warnings":  # they name the run's own frames file (the cluster and flags work)
            seq = [w.replace(str(tmp_path / "seq"), str(tmp_path / "par")) for w in seq]
        assert seq == s2[k], k
    assert s2["audio"] is True
    assert not (tmp_path / "par" / ".arshadow-chunks").exists() or not any(
        (tmp_path / "par" / ".arshadow-chunks").iterdir()
    )


@pytest.mark.gl
def test_jobs2_with_camera_effects_is_cut_and_equals_sequential(tmp_path, tol):
    """``--camera-effects on`` measures the blur and noise on the video's first tracked frame, which the second
    chunk does not hold: the parent measures them as the whole run does and every chunk applies them. (Each
    chunk measured its own on its primer's first tracked frame once, and the shadow mask video differed from
    ``--jobs 1``'s; then such a video was not cut.)"""
    clip = _clip(tmp_path / "c.mp4")
    cam = ("--camera-effects", "on", "--motion-blur", "off")
    rc1, s1 = _run(clip, tmp_path / "seq", *cam)
    rc2, s2 = _run(clip, tmp_path / "par", "--jobs", "2", *cam)
    assert rc1 == rc2 == 0
    assert "chunks" not in s1 and len(s2["chunks"]) == 2
    assert not any("not cut into chunks" in w for w in s2["warnings"]), s2["warnings"]
    assert_same_run(tmp_path / "seq", tmp_path / "par", "c", 72)
    assert_same_items(tmp_path / "seq" / "r.json", tmp_path / "par" / "r.json", tol)


@pytest.mark.gl
def test_jobs2_with_camera_effects_reports_a_calibration_that_does_not_fit_as_jobs1(tmp_path):
    """The parent's measurement (engine.first_camera) meets a calibration that does not fit the video first:
    the video goes to the one-piece run, which reports it as ``--jobs 1`` does, the phone's rotation hint
    included (a video stored sideways and shown turned)."""
    clip = make_clip(tmp_path / "c.mp4", _intr(), _poses(40), noise=1.0, seed=7, gop=20, rotation=90)
    cal = tmp_path / "c43.yml"  # a 4:3 calibration for a 16:9 video
    cal.write_text((ROOT / "calib" / "synth_640x360.yml").read_text().replace("image_height: 360", "image_height: 480"))
    scene = [str(cal) if str(a).endswith("synth_640x360.yml") else a for a in SCENE]
    errors = []
    for jobs in ("1", "2"):
        out = tmp_path / jobs
        rc = _cli(
            "video", clip, *scene, "-q", "-o", out, "--report", out / "r.json", "--jobs", jobs, "--camera-effects", "on"
        )
        rep = _report(out / "r.json")
        assert rc == 1 and rep["status"] == "error", rep
        errors.append(rep["error"])
    assert errors[0] == errors[1] and "shown turned by 90 degrees" in errors[0], errors


@pytest.mark.gl
def test_each_video_of_a_run_measures_its_own_camera_effects(tmp_path):
    """Two videos in one run (one session): the second's blur and noise are measured on its own first tracked
    frame, as when it runs alone (they were the first video's, kept for the session: a video's output then
    depended on the video before it)."""
    cam = ("--camera-effects", "on", "--motion-blur", "off")
    soft = make_clip(tmp_path / "soft.mp4", _intr(), _poses(10), noise=3.0, blur=1.5, seed=1)
    sharp = make_clip(tmp_path / "sharp.mp4", _intr(), _poses(10), noise=1.0, blur=0.6, seed=2)
    assert (
        _cli("video", soft, sharp, *SCENE, "-q", "-o", tmp_path / "both", "--report", tmp_path / "both.json", *cam) == 0
    )
    assert _cli("video", sharp, *SCENE, "-q", "-o", tmp_path / "one", "--report", tmp_path / "one.json", *cam) == 0

    def measured(report, stem):
        items = json.loads(Path(report).read_text())["images"]
        return [it["plan"]["camera_effects"] for it in items if Path(it["input"]).stem == stem and it.get("plan")]

    alone, in_run = measured(tmp_path / "one.json", "sharp"), measured(tmp_path / "both.json", "sharp")
    first = measured(tmp_path / "both.json", "soft")
    assert alone and in_run == alone
    assert first[0] != alone[0]  # the two videos' optics differ: the test can tell them apart


@pytest.mark.gl
@pytest.mark.slow
def test_jobs2_equals_sequential_300_frames(tmp_path, tol):
    clip = make_clip(tmp_path / "c.mp4", _intr(), _poses(300), noise=1.0, seed=7, blank=set(range(100, 130)), gop=50)
    _run(clip, tmp_path / "seq")
    _, s2 = _run(clip, tmp_path / "par", "--jobs", "2")
    assert len(s2["chunks"]) == 2
    assert_same_run(tmp_path / "seq", tmp_path / "par", "c", 300)
    assert_same_items(tmp_path / "seq" / "r.json", tmp_path / "par" / "r.json", tol)


@pytest.mark.gl
def test_no_keyframe_after_the_first_is_one_chunk_and_said(tmp_path, capsys):
    clip = _clip(tmp_path / "c.mp4", n=30, gop=1000, blank=(), audio=False)
    from arshadow.video.scan import scan_stream

    assert scan_stream(clip).keyframes == [0]
    rc, s = _run(clip, tmp_path / "par", "--jobs", "2")
    assert rc == 0 and "chunks" not in s
    err = capsys.readouterr().err
    assert "no keyframe after the first frame: processed as one chunk" in err
    assert len(_lines(tmp_path / "par" / "c.frames.jsonl")) == 30


def _vfr_clip(path, n=60):
    """H.264 with frame intervals alternating 30 and 50 ms (variable frame rate), keyframe every 15."""
    from arshadow.synth.markers import render_marker_photo

    intr = _intr()
    with av.open(str(path), "w") as c:
        s = c.add_stream("libx264", rate=25)
        s.width, s.height, s.pix_fmt = intr.width, intr.height, "yuv420p"
        s.codec_context.time_base = s.time_base = Fraction(1, 1000)
        s.options = {"crf": "18", "x264-params": "keyint=15:min-keyint=15:scenecut=0:bframes=0"}
        t = 0
        for i, pose in enumerate(_poses(n)):
            img = render_marker_photo(intr, pose, marker_length=0.05, noise_sigma=1.0, seed=i).image
            f = av.VideoFrame.from_ndarray(img, format="bgr24")
            f.pts, f.time_base = t, Fraction(1, 1000)
            t += 30 if i % 2 else 50
            for p in s.encode(f):
                c.mux(p)
        for p in s.encode(None):
            c.mux(p)
    return path


@pytest.mark.gl
def test_variable_frame_rate_chunks_keep_the_frame_times(tmp_path):
    from arshadow.video.scan import scan_stream

    clip = _vfr_clip(tmp_path / "v.mp4")
    idx = scan_stream(clip)
    assert idx.vfr and idx.problem is None and len(idx.keyframes) == 4
    assert np.allclose(np.diff(idx.times)[:4], [0.05, 0.03, 0.05, 0.03])
    _run(clip, tmp_path / "seq")
    _, s = _run(clip, tmp_path / "par", "--jobs", "3")
    assert len(s["chunks"]) == 3
    lines = assert_same_run(tmp_path / "seq", tmp_path / "par", "v", 60)
    assert [d["time_s"] for d in lines[:3]] == [0.0, 0.05, 0.08]


@pytest.mark.gl
def test_kill9_mid_video_then_rerun_redoes_only_unfinished_chunks(tmp_path):
    clip = _clip(tmp_path / "c.mp4", n=96, gop=24)
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "arshadow",
        "video",
        str(clip),
        *SCENE,
        "--compose",
        "cpu",
        "--save-mask",
        "-q",
        "-o",
        str(out),
        "--jobs",
        "3",
        "--report",
        str(out / "r.json"),
    ]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    t0 = time.time()
    store = out / ".arshadow-chunks"
    while time.time() - t0 < 180:  # kill once a chunk is recorded and before the video is joined
        recs = list(store.glob("*/c*.json")) if store.exists() else []
        if recs or proc.poll() is not None:
            break
        time.sleep(0.01)
    assert proc.poll() is None, "the run finished before it could be killed"
    os.killpg(proc.pid, signal.SIGKILL)  # the whole process group: the parent and its chunk workers
    proc.wait()
    kept = {p.name: json.loads(p.read_text())["pid"] for p in store.glob("*/c*.json")}
    assert kept and not (out / "c.mp4").exists() and not (out / "c.frames.jsonl").exists()  # nothing half-written
    rc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    assert rc.returncode == 0, rc.stderr
    s = _report(out / "r.json")
    assert s["chunks_resumed"] == len(kept) and len(s["chunks"]) == 3
    _run(clip, tmp_path / "seq")
    assert_same_run(tmp_path / "seq", out, "c", 96)
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]


def dying_chunk_task(recipe, prep, chunk):
    """A chunk task whose worker dies (hard, as when killed) on chunk 1: once when $ARSHADOW_TEST_DIE_ONCE
    names a file that does not exist yet (then created), every time when $ARSHADOW_TEST_DIE is set."""
    from arshadow.video.parallel import chunk_task

    once = os.environ.get("ARSHADOW_TEST_DIE_ONCE")
    if chunk.k == 1 and (os.environ.get("ARSHADOW_TEST_DIE") or (once and not os.path.exists(once))):
        if once:
            Path(once).touch()
        os._exit(9)
    return chunk_task(recipe, prep, chunk)


@pytest.mark.gl
def test_a_dying_worker_is_retried_or_fails_the_video_in_one_line(tmp_path, monkeypatch):
    from arshadow.errors import ImageError
    from arshadow.scene.spec import scene_from_dict
    from arshadow.video.engine import EngineOptions, video_outputs
    from arshadow.video.parallel import BackendRecipe, ChunkPool, process_video_chunked

    clip = _clip(tmp_path / "c.mp4", n=48, gop=24, blank=(), audio=False)
    recipe = BackendRecipe(scene_from_dict(JOB))
    opts = EngineOptions(mask="mkv", contact_sheet=0)
    monkeypatch.setenv("ARSHADOW_TEST_DIE_ONCE", str(tmp_path / "died"))
    pool = ChunkPool(2)
    try:
        s, _ = process_video_chunked(
            recipe,
            pool,
            clip,
            video_outputs(tmp_path / "a", "c", opts),
            opts,
            outdir=tmp_path / "a",
            stem="c",
            task=dying_chunk_task,
        )
    finally:
        pool.close()
    assert (tmp_path / "died").exists() and s["frames"] == 48 and len(s["chunks"]) == 2
    assert len(_masks(tmp_path / "a" / "c.shadow.mkv")) == 48
    monkeypatch.setenv("ARSHADOW_TEST_DIE", "1")
    pool = ChunkPool(2)
    try:
        with pytest.raises(ImageError, match=r"chunk 1 \(frames 24-47\): its worker process died twice") as e:
            process_video_chunked(
                recipe,
                pool,
                clip,
                video_outputs(tmp_path / "b", "c", opts),
                opts,
                outdir=tmp_path / "b",
                stem="c",
                task=dying_chunk_task,
            )
    finally:
        pool.close()
    assert "\n" not in str(e.value)
    assert not (tmp_path / "b" / "c.mp4").exists()


@pytest.mark.gl
def test_batch_jobs2_and_dask_localcluster_chunks_equal_local(tmp_path):
    distributed = pytest.importorskip("distributed")
    from arshadow.scene.spec import scene_from_dict
    from arshadow.video.batch import run_batch
    from arshadow.video.engine import EngineOptions

    clip = _clip(tmp_path / "c.mp4", n=72, gop=24, audio=False)
    spec = scene_from_dict(JOB)
    opts = EngineOptions(mask="mkv", contact_sheet=0)
    local = run_batch(spec, [clip], tmp_path / "local", opts, save_mask=True)
    jobs2 = run_batch(spec, [clip], tmp_path / "jobs2", opts, save_mask=True, jobs=2)  # batch --jobs 2
    assert jobs2["items"][0]["chunks"] == 2
    assert_same_run(tmp_path / "local", tmp_path / "jobs2", "c", 72)
    with (
        distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl,
        distributed.Client(cl) as client,
    ):
        remote = run_batch(spec, [clip], tmp_path / "dask", opts, save_mask=True, client=client, jobs=3)
    assert [it["status"] for it in local["items"]] == [it["status"] for it in remote["items"]] == ["ok"]
    assert remote["items"][0]["chunks"] == 3 and "chunks" not in local["items"][0]
    assert_same_run(tmp_path / "local", tmp_path / "dask", "c", 72)


def test_boundary_check_compares_the_frames_before_a_chunk_and_the_tracker_state(tmp_path):
    """first_mismatch (no GL): a chunk's primer decisions of the `check` frames before its start against
    the previous chunk's records of them, the tracker's state handed over at the boundary and the IPPE
    anchor. Any one difference (a pose, a status, a tracking window, misses in a row, an anchor less than
    a second back) redoes the chunk."""
    from arshadow.video.chunks import Chunk, ChunkStore, first_mismatch, margins
    from arshadow.video.engine import EngineOptions

    opts = EngineOptions()
    check = margins(opts)[1]
    store = ChunkStore(tmp_path, "v", "f" * 16, opts).open()
    chunks = [Chunk(0, 0, 100, 0, 128, 0), Chunk(1, 100, 200, 50, 200, 50)]

    def rec(i, tx=0.1):
        return {
            "frame": i,
            "status": "ok",
            "raw": None,
            "rvec": [0.0, 0.0, 0.0],
            "tvec": [tx, 0.0, 0.5],
            "pose_choice": "error",
        }

    store.outputs(0)["frames"].write_text("".join(json.dumps(rec(i)) + "\n" for i in range(100)))
    state = {"tracker": [None, {"window_corners": [[1.0, 2.0]], "rescue_misses": 0}], "colour_misses": 0}
    records = {
        0: {"state_out": state, "head": []},
        1: {"state_in": json.loads(json.dumps(state)), "head": [rec(i) for i in range(100 - check, 100)]},
    }
    assert first_mismatch(store, chunks, records, opts) is None
    records[1]["head"][5] = rec(100 - check + 5, tx=0.1 + 1e-12)
    assert first_mismatch(store, chunks, records, opts) == 1
    records[1]["head"][5] = rec(100 - check + 5)
    records[1]["head"][-1]["status"] = "held"
    assert first_mismatch(store, chunks, records, opts) == 1
    records[1]["head"][-1]["status"] = "ok"
    records[1]["state_in"]["tracker"][1]["rescue_misses"] = 4  # the marker gone, misses counted apart
    assert first_mismatch(store, chunks, records, opts) == 1
    records[1]["state_in"] = state
    # the IPPE branch choice's anchor: the last pose before the boundary, which may precede the compared
    # frames (the marker lost for them); compared when it is less than a second before the boundary
    from arshadow.video.scan import StreamIndex

    idx = StreamIndex(pts=list(range(200)), times=[i / 25 for i in range(200)], keyframes=[0, 50])
    old = {**rec(80), "time_s": 80 / 25}
    records[0]["anchor_out"], records[1]["anchor_in"] = old, {**old, "tvec": [0.2, 0.0, 0.5]}
    assert first_mismatch(store, chunks, records, opts, idx) == 1  # 0.8 s before frame 100: it counts
    far = {**rec(70), "time_s": 70 / 25}  # 1.2 s back: the choice does not link across that gap
    records[0]["anchor_out"], records[1]["anchor_in"] = far, None
    assert first_mismatch(store, chunks, records, opts, idx) is None
    records[0]["anchor_out"] = records[1]["anchor_in"] = None
    records[1]["head"] = records[1]["head"][1:]  # a primer too short to decide every compared frame
    assert first_mismatch(store, chunks, records, opts) == 1
    # a chunk primed from frame 0 is the sequential run: nothing to compare
    chunks[1] = Chunk(1, 100, 200, 0, 200, 0)
    assert first_mismatch(store, chunks, records, opts) is None
