"""Video layers (the compositing-layers work): ``arshadow video --layers`` writes per-frame layers that rebuild the frames.

Ground truth: each decoded input frame composited again by a Session at the pose the engine reports for
it (``<stem>.frames.jsonl``); the layer videos, decoded independently with PyAV, recombine with the decoded
input frame (float64 sRGB formula of tests/test_layers.py) within one 8-bit level of that composite.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from layer_checks import linear, maxdiff, recombine
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
    "--place",
    "0.03,0,0",
    "--rotate",
    "0,0,20",
    "--light",
    "point:-0.1,0.15,0.4",
    "--no-exposure",
]
# no exposure match: the video's is smoothed over frames (and held on a blank frame), which a re-render of
# one frame by a fresh session cannot reproduce (tests/test_exposure_match.py tests the match itself)
JOB = {
    "calib": str(CALIB),
    "marker_length": 0.05,
    "model": "box:0.04,0.03,0.06",
    "place": [0.03, 0, 0],
    "rotate": [0, 0, 20],
    "lights": ["point:-0.1,0.15,0.4"],
    "no_exposure": True,
}


def _cli(*argv):
    from arshadow.cli import main

    return main([str(a) for a in argv])


@pytest.fixture(scope="module")
def clip(tmp_path_factory, gl_ctx):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import camera_path

    poses = camera_path(5, radius=0.45, height=(0.3, 0.4), sweep_deg=20.0, start_deg=-110.0)
    return make_clip(tmp_path_factory.mktemp("clip") / "clip.mp4", Intrinsics.from_file(CALIB), poses, blank=(2,))


def _decode(path, fmt):
    with av.open(str(path)) as c:
        return [f.to_ndarray(format=fmt) for f in c.decode(video=0)]


def test_ffv1_layer_videos_rebuild_every_frame(clip, tmp_path, gl_ctx):
    import arshadow
    from arshadow.video.avio import AvReader

    out = tmp_path / "out"
    assert _cli("video", clip, *SCENE, "-o", out, "-q", "--smooth", "0", "--layers", "--layers-format", "ffv1") == 0
    obj = _decode(out / "clip.object.mkv", "rgba64le")
    mult = _decode(out / "clip.shadow.mult.mkv", "gray16le")
    only = _decode(out / "clip.shadow.only.mkv", "rgba64le")
    lines = [json.loads(s) for s in (out / "clip.frames.jsonl").read_text().splitlines()]
    frames = [
        cv2.cvtColor(f.image, cv2.COLOR_YUV2BGR_I420) if f.format == "yuv420p" else f.image
        for f in AvReader(clip, raw=True)
    ]
    assert len(obj) == len(mult) == len(only) == len(lines) == len(frames) == 5
    assert lines[2]["status"] == "held"  # the blank frame: the engine holds the last pose
    assert [ln["status"] for ln in lines].count("ok") >= 3
    # the video's own scene (a video: track_roi; its outline is a video's, auto: off without sky occlusion)
    with arshadow.Session(arshadow.scene_from_dict({**JOB, "track_roi": True}), context=gl_ctx) as s:
        for k, ln in enumerate(lines):
            if ln["rvec"] is None:
                assert np.all(obj[k] == 0) and np.all(mult[k] == 65535)  # nothing drawn
                continue
            m = np.eye(4)
            m[:3, :3] = cv2.Rodrigues(np.asarray(ln["rvec"], float))[0]
            m[:3, 3] = ln["tvec"]
            comp = s.render(frames[k], m).composite
            a = obj[k][..., 3] / 65535.0
            o = np.dstack([linear(obj[k][..., :3] / 257.0) * a[..., None], a])
            assert np.count_nonzero(a > 0.5) > 200 or ln["status"] == "held"
            assert maxdiff(recombine(frames[k], o, mult[k] / 65535.0), comp) <= 1
            assert maxdiff(recombine(frames[k], o, only[k][..., 3] / 65535.0, over=True), comp) <= 1


def test_prores_4444_layers_have_alpha(clip, tmp_path):
    out = tmp_path / "out"
    assert _cli("video", clip, *SCENE, "-o", out, "-q", "--layers", "--max-frames", "2") == 0
    with av.open(str(out / "clip.object.mov")) as c:
        st = c.streams.video[0]
        assert st.codec_context.name == "prores" and "a" in st.codec_context.format.name.split("p")[0]
        fr = next(c.decode(video=0)).to_ndarray(format="rgba64le")
    assert np.count_nonzero(fr[..., 3] > 60000) > 200 and np.count_nonzero(fr[..., 3] < 1000) > 1000


def test_missing_layer_codec_is_exit_2_before_any_work(clip, tmp_path, monkeypatch, capsys):
    from arshadow.export import layervideo

    monkeypatch.setitem(layervideo.VIDEO_LAYER_FORMATS, "prores", ("no_such_encoder", "mov", "rgba", "gray"))
    out = tmp_path / "out"
    assert _cli("video", clip, *SCENE, "-o", out, "--layers") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no_such_encoder" in err[0]
    assert not out.exists() or not any(out.iterdir())


def test_png_sequence_layers_undistorted(clip, tmp_path):
    out = tmp_path / "out"
    assert (
        _cli(
            "video",
            clip,
            *SCENE,
            "-o",
            out,
            "-q",
            "--layers-undistorted",
            "--layers-format",
            "png",
            "--max-frames",
            "2",
        )
        == 0
    )
    seq = sorted(p.name for p in (out / "clip.layers").iterdir())
    assert len(seq) == 12 and "undistorted.object.000001.png" in seq and "shadow.mult.000000.png" in seq
    assert (out / "clip.stmap.png").is_file()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporaries left


def test_layer_file_over_an_input_video_is_exit_2(clip, tmp_path, capsys):
    d = tmp_path / "in"
    d.mkdir()
    (d / "c.mp4").write_bytes(Path(clip).read_bytes())
    (d / "c.object.mov").write_bytes(b"not really a video, but an input")
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    assert _cli("video", d / "c.mp4", d / "c.object.mov", *SCENE, "-o", d, "--layers") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "would overwrite an input" in err[0] and "c.object.mov" in err[0]
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before


def test_batch_layers_for_photos_and_videos(clip, tmp_path, gl_ctx):
    import cv2 as _cv2

    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    job = tmp_path / "job.json"
    job.write_text(json.dumps(JOB))
    photo = tmp_path / "shot.png"
    intr = Intrinsics.from_file(CALIB)
    _cv2.imwrite(
        str(photo),
        render_marker_photo(intr, look_at_pose([0.1, -0.3, 0.35], [0, 0, 0]), marker_length=0.05, seed=9).image,
    )
    out = tmp_path / "out"
    assert (
        _cli(
            "batch",
            photo,
            clip,
            "--config",
            job,
            "-o",
            out,
            "-q",
            "--layers",
            "--layers-format",
            "ffv1",
            "--max-frames",
            "2",
        )
        == 0
    )
    names = {p.name for p in out.iterdir()}
    assert {"shot.object.png", "shot.shadow.mult.png", "shot.shadow.only.png"} <= names  # photos: 16-bit PNG
    assert {"clip.object.mkv", "clip.shadow.mult.mkv", "clip.shadow.only.mkv"} <= names
    rec = json.loads((out / "batch.json").read_text())
    outs = [o for it in rec["items"] for o in it["outputs"]]
    assert any(o.endswith("shot.object.png") for o in outs) and any(o.endswith("clip.object.mkv") for o in outs)
