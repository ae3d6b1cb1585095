"""The video entry point of the API (the layout work): ``arshadow.process_video`` is what ``arshadow video``
runs; the CLI only parses, calls it and prints. Same clip, same scene: the same frames, masks and report."""

from __future__ import annotations

import json

import numpy as np
import pytest
from video_clips import BOX_SCENE, ROOT, make_clip, read_frames

CALIB = ROOT / "calib" / "synth_640x360.yml"
SCENE = {
    "calib": str(CALIB),
    "marker_length": 0.05,
    "model": "box:0.04,0.03,0.06",
    "place": (0.05, 0.0, 0.0),
    "lights": ["point:-0.1,0.15,0.4"],
    "refine": "edge",  # arshadow video's --corner-refine default
}


def _comparable(d):
    """A report entry without what depends on the machine (times, speeds)."""
    timed = ("fps", "frame_ms", "stage_ms", "timings", "wall_s")
    return {k: v for k, v in d.items() if not k.startswith(timed) and "_ms" not in k}


@pytest.mark.gl
def test_process_video_is_what_the_cli_runs(tmp_path, gl_ctx):
    import arshadow
    from arshadow.camera.model import Intrinsics
    from arshadow.cli import main
    from arshadow.synth.markers import camera_path

    poses = camera_path(8, radius=0.5, height=(0.3, 0.42), sweep_deg=30.0, start_deg=-110.0)
    clip = make_clip(tmp_path / "clip.mp4", Intrinsics.from_file(CALIB), poses, blank={3}, noise=1.0)
    cli_out, api_out = tmp_path / "cli", tmp_path / "api"
    rc = main(
        [
            "video",
            str(clip),
            *BOX_SCENE,
            "-o",
            str(cli_out),
            "--format",
            "mkv",
            "--save-mask",
            "--report",
            str(cli_out / "r.json"),
            "-q",
        ]
    )
    assert rc == 0
    opts = arshadow.EngineOptions(fmt="mkv", codec="ffv1", mask="mkv", collect_items=True)
    run = arshadow.process_video(arshadow.scene_from_dict(SCENE), clip, api_out, options=opts)
    assert isinstance(run, arshadow.VideoRun) and run.failed == 0
    # the generator's truth: the marker is in every frame but the blank one, rendered with the held pose
    statuses = [it.status for it in run.items]
    assert statuses == ["ok"] * 3 + ["held"] + ["ok"] * 4, statuses
    # the CLI's files and report are the API's
    for name in ("clip.mkv", "clip.shadow.mkv"):
        a, b = read_frames(cli_out / name), read_frames(api_out / name)
        assert len(a) == len(b) == 8, name
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True)), name
    assert all(m.any() for m in read_frames(api_out / "clip.shadow.mkv"))  # a shadow in every frame
    # the report, its output paths relative to the output folder
    cli_rep = json.loads((cli_out / "r.json").read_text().replace(f"{cli_out}/", "OUT/"))
    api_rep = json.loads(json.dumps(run.report(), default=str).replace(f"{api_out}/", "OUT/"))
    assert [_comparable(i) for i in cli_rep["images"]] == [_comparable(i) for i in api_rep["images"]]
    ca, cb = [_comparable(v) for v in cli_rep["videos"]], [_comparable(v) for v in api_rep["videos"]]
    assert ca == cb, {k: (ca[0].get(k), cb[0].get(k)) for k in set(ca[0]) | set(cb[0]) if ca[0].get(k) != cb[0].get(k)}


def test_process_video_refuses_bad_arguments_before_any_work(tmp_path):
    import arshadow
    from arshadow.errors import UsageError

    (tmp_path / "file").write_text("x")
    with pytest.raises(UsageError, match="exists and is not a folder"):
        arshadow.process_video(SCENE, tmp_path / "none.mp4", tmp_path / "file")
    with pytest.raises(UsageError, match="jobs 0"):
        arshadow.process_video(SCENE, tmp_path / "none.mp4", tmp_path / "out", jobs=0)
