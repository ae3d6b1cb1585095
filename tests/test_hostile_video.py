"""Hostile input for ``arshadow video`` and ``arshadow batch`` (the stress suite, the video side of
tests/test_hostile_inputs.py): every kind gets one clear line naming the file or value, the exit status of
CONVENTIONS.md (1: some inputs failed, the rest processed; 2: bad usage / configuration, before any
decoding), no traceback, nothing half-written, inputs never modified.

Tiny synthetic clips (tests/video_clips.py: 2-12 frames, 640x360). The module prints how many kinds it
tried and how many behaved (``python -m pytest -q -s tests/test_hostile_video.py``).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import pytest
from cli_run import run_cli
from video_clips import make_clip

av = pytest.importorskip("av")
pytestmark = pytest.mark.gl

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_640x360.yml"
SCENE = [
    "--calib",
    str(CALIB),
    "--marker-length",
    "0.05",
    "--model",
    "box:0.04,0.03,0.06",
    "--light",
    "point:-0.1,0.15,0.4",
]
JOB = {"calib": str(CALIB), "marker_length": 0.05, "model": "box:0.04,0.03,0.06", "lights": ["point:-0.1,0.15,0.4"]}
TALLY: dict[str, list] = {"config (exit 2)": [], "per input (exit 1)": [], "accepted": [], "interrupted": []}


def _lines(text):
    """The non-empty stderr lines, without the sanity gates ('s)'s flagged-pose warnings (these small, soft synthetic clips
    have every pose flagged; those lines are tested in tests/test_user_reports.py)."""
    flagged = re.compile(
        r"arshadow (video|batch): warning: .*(: \d+ of \d+ frames have a flagged pose \(|: flagged pose: )"
    )
    return [ln for ln in text.splitlines() if ln.strip() and not flagged.match(ln)]


def _md5(p):
    return hashlib.md5(Path(p).read_bytes()).hexdigest()


def _temporaries(d):
    return [p.name for p in Path(d).rglob(".*") if ".tmp" in p.name]


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    """Good clips of 2, 6 and 12 frames, a photo, and the damaged and hostile files made from them."""
    from arshadow.camera.model import Intrinsics
    from arshadow.io import write_image
    from arshadow.synth.markers import camera_path, render_marker_photo
    from arshadow.video.avio import AvReader

    d = tmp_path_factory.mktemp("clips")
    intr = Intrinsics.from_file(CALIB)
    poses = camera_path(12, radius=0.5, height=(0.3, 0.42), sweep_deg=10.0, start_deg=-110.0)
    make_clip(d / "good.mp4", intr, poses[:6], noise=1.0)
    make_clip(d / "g12.mp4", intr, poses, noise=1.0)
    make_clip(d / "two.mp4", intr, poses[:2], noise=1.0)
    write_image(d / "photo.png", render_marker_photo(intr, poses[0], marker_length=0.05, noise_sigma=1.0).image)
    data = (d / "g12.mp4").read_bytes()
    (d / "truncated.mp4").write_bytes(data[: len(data) // 2])  # cut in the middle of a frame
    (d / "header_only.mp4").write_bytes(data[:1500])  # a valid header, no frame data: 0 decodable frames
    with av.open(str(d / "g12.mp4")) as c:
        pk = [(p.pos, p.size) for p in c.demux(video=0) if p.size]
    bad = bytearray(data)
    pos, size = pk[4]
    bad[pos + 10 : pos + size] = b"\xff" * (size - 10)  # frame 4's slice data destroyed
    (d / "corrupt_mid.mp4").write_bytes(bytes(bad))
    (d / "zero.mp4").write_bytes(b"")
    (d / "text.mp4").write_text("hello, I am a text file\n")
    (d / "junk.xyz").write_bytes(b"\x00garbage" * 200)
    (d / "clip.xyz").write_bytes((d / "good.mp4").read_bytes())  # a real video with an unknown extension
    (d / "folder.mp4").mkdir()
    (d / "sub").mkdir()
    (d / "sub" / "good.mp4").write_bytes((d / "good.mp4").read_bytes())  # the same stem as good.mp4
    (d / "seq").mkdir()
    for i, f in enumerate(AvReader(d / "good.mp4")):
        if i != 3:  # frame 3 missing
            cv2.imwrite(str(d / "seq" / f"f{i:03d}.png"), f.image)
    return d


# ------------------------------------------------------------------------------------ per input
#: name -> (needle of its one error line, or None for an input that is processed) ; "!" marks a warning
VIDEO_INPUTS = {
    "good.mp4": None,
    "zero.mp4": "empty file",
    "text.mp4": "cannot open as a video (Invalid data found when processing input)",
    "truncated.mp4": "!the video ends early",
    "header_only.mp4": "no decodable frame",
    "corrupt_mid.mp4": "!1 damaged packet(s) could not be decoded",
    "seq/f%03d.png": "!image",
    "seq/x%03d.png": "no file matches this image-sequence pattern",
    "junk.xyz": "cannot open as a video",
    "clip.xyz": None,
    "folder.mp4": "is a folder, not a video",
    "missing.mp4": "no such video file",
    "sub/good.mp4": None,
}


def test_bad_videos_in_one_run(clips, tmp_path, capsys):
    """Every bad video: one line naming it (damaged ones: a warning, their decoded frames written); the good
    ones around them are processed (two inputs with one stem: clip, clip_2); exit 1; no temporaries (a
    stale one, as ``kill -9`` leaves, is cleaned); the report has one entry per video."""
    out = tmp_path / "out"
    out.mkdir()
    (out / ".good.k9x1.tmp.mp4").write_bytes(b"left by kill -9")
    (out / ".good.shadow.k9x2.tmp").mkdir()
    code, so, se = run_cli(
        capsys,
        "video",
        *[clips / n for n in VIDEO_INPUTS],
        *SCENE,
        "-o",
        out,
        "-q",
        "--report",
        tmp_path / "r.json",
        "--save-mask",
        "png",
    )
    lines = _lines(se)
    assert "Traceback" not in se
    rep = {v["input"]: v for v in json.loads((tmp_path / "r.json").read_text())["videos"]}
    for name, needle in VIDEO_INPUTS.items():
        mine = [ln for ln in lines if str(clips / name) in ln]
        v = rep[str(clips / name)]
        if needle is None:
            ok = not mine and v["status"] == "ok"
            TALLY["accepted"].append((name, ok))
        elif needle.startswith("!"):  # damaged: warned, exit 1, the frames decoded are written
            ok = (
                len(mine) >= 1
                and all(ln.startswith("arshadow video: warning:") for ln in mine)
                and needle[1:] in mine[-1 if "damaged" in needle else 0]
                and v["status"] == "damaged"
                and v["frames"] > 0
            )
            ok = ok and len(list(av.open(v["output"]).decode(video=0))) == v["frames"]
            TALLY["per input (exit 1)"].append((name, ok))
        else:
            ok = (
                len(mine) == 1
                and mine[0].startswith("arshadow video: error:")
                and needle in mine[0]
                and v["status"] == "error"
            )
            TALLY["per input (exit 1)"].append((name, ok))
        assert ok, (name, mine, v.get("status"))
    assert code == 1
    assert len(lines) == sum(n is not None for n in VIDEO_INPUTS.values()) + 1  # truncated: 2 warnings
    assert rep[str(clips / "truncated.mp4")]["frames"] == 3  # all the decodable frames (were 1: threading)
    assert rep[str(clips / "corrupt_mid.mp4")]["frames"] == 11
    seq = rep[str(clips / "seq/f%03d.png")]
    assert seq["frames"] == 3 and "f003.png is missing" in seq["warnings"][0]
    assert {"good.mp4", "good_2.mp4", "clip.mp4", "truncated.mp4", "corrupt_mid.mp4", "f.mp4"} <= {
        p.name for p in out.iterdir()
    }
    for stem in ("good", "good_2"):
        assert len(list((out / f"{stem}.shadow").iterdir())) == 6
    assert not [p for p in out.iterdir() if p.stem in ("zero", "text", "header_only", "junk", "folder", "missing")]
    assert _temporaries(out) == []


def test_bad_inputs_in_one_batch(clips, tmp_path, capsys):
    """The same through ``arshadow batch`` (photos among them; patterns and unknown extensions classified by
    content: a video named .xyz is processed as a video, a text file named .png fails as a photo)."""
    job = tmp_path / "job.json"
    job.write_text(json.dumps(JOB))
    (tmp_path / "text.png").write_text("not a png\n")
    names = [
        "good.mp4",
        "zero.mp4",
        "text.mp4",
        "truncated.mp4",
        "header_only.mp4",
        "corrupt_mid.mp4",
        "seq/f%03d.png",
        "junk.xyz",
        "clip.xyz",
        "folder.mp4",
        "missing.mp4",
        "photo.png",
    ]
    inputs = [clips / n for n in names] + [tmp_path / "text.png"]
    out = tmp_path / "out"
    code, so, se = run_cli(capsys, "batch", *inputs, "--config", job, "-o", out, "-q", "--contact-sheet", "0")
    assert "Traceback" not in se and code == 1
    summary = json.loads((out / "batch.json").read_text())
    status = {Path(it["input"]).name: it["status"] for it in summary["items"]}
    expect = {
        "good.mp4": "ok",
        "zero.mp4": "error",
        "text.mp4": "error",
        "truncated.mp4": "damaged",
        "header_only.mp4": "error",
        "corrupt_mid.mp4": "damaged",
        "f%03d.png": "damaged",
        "junk.xyz": "error",
        "clip.xyz": "ok",
        "folder.mp4": "error",
        "missing.mp4": "error",
        "photo.png": "ok",
        "text.png": "error",
    }
    lines = _lines(se)
    for n, st in expect.items():
        mine = [ln for ln in lines if n in ln]
        ok = status[n] == st and len(mine) == (st != "ok")
        TALLY["per input (exit 1)" if st != "ok" else "accepted"].append(("batch " + n, ok))
        assert ok, (n, status[n], mine)
    assert {it["kind"] for it in summary["items"] if Path(it["input"]).name in ("clip.xyz", "f%03d.png")} == {"video"}
    assert _temporaries(out) == []


def test_output_never_overwrites_an_input(clips, tmp_path, capsys):
    """``-o`` the inputs' own folder: each input whose output would replace it (or another input) is refused
    with one line, exit 1, the inputs byte for byte unchanged (batch used to overwrite them)."""
    d = tmp_path / "in"
    d.mkdir()
    for n in ("good.mp4", "photo.png"):
        (d / n).write_bytes((clips / n).read_bytes())
    before = {n: _md5(d / n) for n in ("good.mp4", "photo.png")}
    job = tmp_path / "job.json"
    job.write_text(json.dumps(JOB))
    code, _, se = run_cli(capsys, "video", d / "good.mp4", clips / "two.mp4", *SCENE, "-o", d, "-q")
    ok_v = (
        code == 1
        and _lines(se) == [ln for ln in _lines(se) if "would overwrite an input" in ln]
        and len(_lines(se)) == 1
        and (d / "two.mp4").is_file()
    )
    code, _, se = run_cli(
        capsys, "batch", d / "good.mp4", d / "photo.png", "--config", job, "-o", d, "-q", "--contact-sheet", "0"
    )
    ok_b = code == 1 and len(_lines(se)) == 2 and all("would overwrite an input" in ln for ln in _lines(se))
    unchanged = {n: _md5(d / n) for n in before} == before
    TALLY["per input (exit 1)"] += [
        ("video -o = input folder", ok_v and unchanged),
        ("batch -o = input folder", ok_b and unchanged),
    ]
    assert ok_v and ok_b and unchanged, se


# ------------------------------------------------------------------------------------ configuration
VIDEO_CONFIG = [  # (kind, extra args, needle)
    ("o_is_file", ["-o", "{file}"], "exists and is not a folder"),
    ("o_under_file", ["-o", "/dev/null/out"], "-o /dev/null/out: cannot write there"),
    ("o_unwritable", ["-o", "/proc/arshadow_out"], "-o /proc/arshadow_out: cannot write there"),
    ("report_under_file", ["--report", "/dev/null/r.json"], "--report /dev/null/r.json"),
    ("report_is_folder", ["--report", "{dir}"], "is a folder"),
    ("crf_99", ["--crf", "99"], "--crf 99.0: must be 0..51"),
    ("crf_nan", ["--crf", "nan"], "--crf nan"),
    ("codec_nonsense", ["--codec", "nonsense"], "invalid choice: 'nonsense'"),
    ("format_webm", ["--format", "webm"], "invalid choice: 'webm'"),
    ("preset_nonsense", ["--preset", "nonsense"], "--preset nonsense: use one of"),
    ("hold_negative", ["--hold", "-1"], "--hold -1: must be >= 0"),
    ("smooth_negative", ["--smooth", "-2"], "--smooth -2: must be >= 0"),
    ("contact_sheet_negative", ["--contact-sheet", "-1"], "--contact-sheet -1"),
    ("pose_lag_negative", ["--pose-lag", "-1"], "--pose-lag -1"),
    ("max_frames_0", ["--max-frames", "0"], "--max-frames 0: must be >= 1"),
    ("max_frames_negative", ["--max-frames", "-3"], "--max-frames -3"),
    ("max_frames_float", ["--max-frames", "2.5"], "invalid int value: '2.5'"),
    ("save_mask_gif", ["--save-mask", "gif"], "invalid choice: 'gif'"),
    ("time_lapse_garbage", ["--time-lapse", "garbage"], "--time-lapse START 'garbage'"),
    ("time_lapse_speed_text", ["--time-lapse", "2024-06-21T06:00+02:00,abc"], "SPEED 'abc' is not a number"),
    ("time_lapse_speed_negative", ["--time-lapse", "2024-06-21T06:00+02:00,-5"], "SPEED must be a positive"),
    ("time_lapse_no_sun", ["--time-lapse", "2024-06-21T06:00+02:00"], "needs a sun light"),
    ("recompute_negative", ["--recompute-deg", "-1"], "--recompute-deg -1"),
]


@pytest.mark.parametrize("kind, extra, needle", VIDEO_CONFIG, ids=[c[0] for c in VIDEO_CONFIG])
def test_video_bad_configuration(tmp_path, capsys, kind, extra, needle):
    """Exit 2, one line, before any video is opened (the input does not exist: had it been read, its own
    error would show) and nothing written."""
    (tmp_path / "afile").write_text("x")
    extra = [a.replace("{file}", str(tmp_path / "afile")).replace("{dir}", str(tmp_path)) for a in extra]
    args = ["-o", tmp_path / "out", *SCENE, *extra]
    code, _, se = run_cli(capsys, "video", tmp_path / "never_opened.mp4", *args)
    lines = _lines(se)
    ok = code == 2 and len(lines) == 1 and needle in lines[0] and "never_opened" not in se and "Traceback" not in se
    TALLY["config (exit 2)"].append(("video " + kind, ok))
    assert ok, (code, se)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


SCENE_FILES = {  # name -> (content, needle)
    "malformed.yml": ("calib: [unclosed\n  - : :\n", "line 2, column 5"),
    "binary.yml": (b"\xff\xfe\x00garbage", "not UTF-8"),
    "list.yml": ("- 1\n- 2\n", "mapping of scene keys"),
    "empty.yml": ("", "mapping of scene keys"),
    "truncated.json": ('{"calib": 1,', "JSONDecodeError"),
    "marker_length_text.json": ({**JOB, "marker_length": "five centimetres"}, "marker_length 'five centimetres'"),
    "marker_id_float.json": ({**JOB, "marker_id": 2.5}, "marker_id 2.5: expected a whole number"),
    "bool_as_text.json": ({**JOB, "roi": "no"}, "roi 'no': expected true or false"),
    "lights_numbers.json": ({**JOB, "lights": [1, 2]}, "lights 1"),
    "model_number.json": ({**JOB, "model": 42}, "model 42"),
    "place_text.json": ({**JOB, "place": "hello"}, "place"),
    "unknown_key.json": ({**JOB, "colour": "200,0,0"}, "unknown scene key(s) 'colour'"),
    "missing_model.json": ({k: v for k, v in JOB.items() if k != "model"}, "needs 'model'"),
    "calib_missing.json": ({**JOB, "calib": "nope.yml"}, "no such calibration file"),
    "light_unquoted.yml": (
        f"calib: {CALIB}\nmarker_length: 0.05\nmodel: box:0.04,0.03,0.06\nlights: [point:-0.1,0.15,0.4]\n",
        "(in YAML, quote it)",
    ),
}

BATCH_CONFIG = [  # (kind, config file (name in SCENE_FILES or a path), extra args, needle)
    ("config_missing", "nope.yml", [], "nope.yml: cannot read the scene file"),
    ("config_folder", "{dir}", [], "cannot read the scene file"),
    *[(n.split(".")[0], n, [], v[1]) for n, v in SCENE_FILES.items()],
    ("o_under_file", "good.json", ["-o", "/dev/null/out"], "-o /dev/null/out: cannot write there"),
    ("o_unwritable", "good.json", ["-o", "/proc/arshadow_out"], "-o /proc/arshadow_out"),
    ("crf_99", "good.json", ["--crf", "99"], "--crf 99.0"),
    ("dask_local_0", "good.json", ["--dask", "local:0"], "--dask local:0: use local or local:N"),
    ("dask_local_text", "good.json", ["--dask", "local:two"], "--dask local:two"),
    ("dask_garbage", "good.json", ["--dask", "garbage"], "--dask garbage: give a scheduler address"),
    ("dask_unreachable", "good.json", ["--dask", "tcp://127.0.0.1:9"], "cannot reach the scheduler within 1 s"),
]


@pytest.mark.parametrize("kind, config, extra, needle", BATCH_CONFIG, ids=[c[0] for c in BATCH_CONFIG])
def test_batch_bad_configuration(tmp_path, capsys, monkeypatch, kind, config, extra, needle):
    """Exit 2, one line naming the file / value, before any input is read, nothing written; a wrong Dask
    address fails within the (here 1 s) connection timeout instead of hanging."""
    if kind.startswith("dask"):
        pytest.importorskip("distributed")
        monkeypatch.setattr("arshadow.cli.batch.DASK_CONNECT_TIMEOUT_S", 1)
    (tmp_path / "good.json").write_text(json.dumps(JOB))
    for n, (content, _) in SCENE_FILES.items():
        p = tmp_path / n
        if isinstance(content, dict):
            p.write_text(json.dumps(content))
        else:
            p.write_bytes(content if isinstance(content, bytes) else content.encode())
    cfg = str(tmp_path) if config == "{dir}" else str(tmp_path / config)
    args = ["--config", cfg, "-o", tmp_path / "out", "-q", *extra]
    t0 = time.perf_counter()
    code, _, se = run_cli(capsys, "batch", tmp_path / "never_opened.mp4", *args)
    lines = _lines(se)
    ok = (
        code == 2
        and len(lines) == 1
        and needle in lines[0]
        and "never_opened" not in se
        and "Traceback" not in se
        and time.perf_counter() - t0 < 20
    )
    TALLY["config (exit 2)"].append(("batch " + kind, ok))
    assert ok, (code, se)
    assert not (tmp_path / "out").exists() or not [p for p in (tmp_path / "out").rglob("*") if p.is_file()]


# ------------------------------------------------------------------------------------ disk full, interrupts
def _env():
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def test_disk_full_while_encoding(clips, tmp_path):
    """Writes fail part-way through the first video (simulated: RLIMIT_FSIZE, so FFmpeg's own writes fail
    with EFBIG): one line naming the output, none of that video's files left (not its frames report either),
    no temporaries, and the next video (small enough) is still written."""

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (90_000, 90_000))

    out = tmp_path / "out"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "arshadow",
            "video",
            str(clips / "g12.mp4"),
            str(clips / "two.mp4"),
            *SCENE,
            "-o",
            str(out),
            "-q",
            "--contact-sheet",
            "0",
        ],
        preexec_fn=limit,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    lines = _lines(r.stderr)
    ok = (
        r.returncode == 1
        and len(lines) == 1
        and "g12.mp4: cannot write (File too large); nothing written" in lines[0]
        and sorted(p.name for p in out.iterdir()) == ["two.frames.jsonl", "two.mp4"]
    )
    TALLY["per input (exit 1)"].append(("disk_full", ok))
    assert ok, (r.returncode, r.stderr, sorted(p.name for p in out.iterdir()))


def test_keyboard_interrupt_mid_video_leaves_nothing(clips, tmp_path, capsys, monkeypatch):
    """Ctrl-C while frames are being rendered and encoded: exit 130, one line, no output or temporary file."""
    from arshadow.video import engine

    real = engine.SessionBackend.render
    calls = []

    def render(self, *a, **k):
        calls.append(1)
        if len(calls) == 8:
            raise KeyboardInterrupt
        return real(self, *a, **k)

    monkeypatch.setattr(engine.SessionBackend, "render", render)
    out = tmp_path / "out"
    code, _, se = run_cli(capsys, "video", clips / "g12.mp4", *SCENE, "-o", out, "-q", "--save-mask")
    ok = code == 130 and len(_lines(se)) == 1 and "interrupted" in se and not any(out.iterdir())
    TALLY["interrupted"].append(("KeyboardInterrupt", ok))
    assert ok, (code, se, list(out.iterdir()))


def test_sigterm_mid_video_leaves_nothing_and_rerun_completes(clips, tmp_path):
    """SIGTERM (``kill``) while the video is being encoded: exit 143, its temporaries removed, no output;
    the same command again writes everything."""
    long = tmp_path / "long.mp4"
    with av.open(str(clips / "g12.mp4")) as src, av.open(str(long), "w") as dst:  # 12 frames x 4, packets copied
        vin = src.streams.video[0]
        vout = dst.add_stream_from_template(vin)
        pk = [p for p in src.demux(vin) if p.dts is not None]
        step = pk[1].pts - pk[0].pts
        for k in range(4):
            for p in pk:
                p.stream = vout
                p.pts += 12 * step * (k > 0)
                p.dts += 12 * step * (k > 0)
                dst.mux(p)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "arshadow", "video", str(long), *SCENE, "-o", str(out), "-q", "--save-mask"]
    proc = subprocess.Popen(cmd, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    t0 = time.time()
    while time.time() - t0 < 120 and proc.poll() is None:
        if out.exists() and any(p.name.startswith(".long.") and p.name.endswith(".tmp.mp4") for p in out.iterdir()):
            break
        time.sleep(0.01)
    assert proc.poll() is None, "the run ended before it could be stopped"
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=120)[1]
    ok = proc.returncode == 143 and "interrupted (SIGTERM)" in err and "Traceback" not in err and not any(out.iterdir())
    TALLY["interrupted"].append(("SIGTERM", ok))
    assert ok, (proc.returncode, err, list(out.iterdir()))
    r = subprocess.run(cmd, env=_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert len(list(av.open(str(out / "long.mp4")).decode(video=0))) == 48


def test_report_counts():
    """Print the tally (run last in this module)."""
    total = sum(len(v) for v in TALLY.values())
    print(f"\nvideo/batch hostile-input kinds tried: {total}")
    for k, v in TALLY.items():
        print(f"  {k}: {len(v)} tried, {sum(ok for _, ok in v)} behaved")
    if total:
        assert all(ok for v in TALLY.values() for _, ok in v)
