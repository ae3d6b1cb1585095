"""Video engine benchmark: throughput, accuracy and stability on the judged synthetic 720p clip.

    python tests/benchmarks/bench_video_engine.py [--frames 300] [--runs 3] [--refine edge,apriltag,subpix]
                                                  [--pan 120] [--out results.json]

The clip: ``--frames`` frames at 1280x720, 25 fps, along :func:`arshadow.synth.camera_path`, rendered by
:func:`arshadow.synth.render_marker_photo` with the lens distortion of calib/synth_1280x720.yml, noise
sigma 2, blur 0.8 px, JPEG 85, then H.264 (CRF 18); frames 100-129 without the marker (marker loss).
Cached in $ARSHADOW_BENCH_CACHE (default /tmp/arshadow-bench). Scene: the 8 536-face knot of
samples/knot_point.jpg, one point light.

Prints JSON with:

- ``throughput``: ``arshadow video`` at default settings (decode -> track -> smooth -> render -> encode
  H.264), ``--runs`` runs: frames per second over the whole video (open to last frame written; no process
  start / GL context creation), median and min/max over the runs, the load average before each run, and
  the per-stage medians (ms per frame, from the JSON Lines report) of the median run.
- ``accuracy`` per ``--refine``: the run with ``--save-mask``: shadow IoU per frame of the lossless mask
  video against :class:`tests.video_clips.ExactShadow` at the true pose (polygon-filled analytic
  projection, independent of the renderer), frames where the pose is rendered (tracked or held); pose
  errors of the raw (unsmoothed) pose; flipped frames (rotation error > 5 degrees); centroid jitter of
  the exact shadow under the raw vs the smoothed poses (RMS frame-to-frame motion error) and their ratio.
- ``pan`` (``--pan`` frames of :func:`arshadow.synth.pan_path`): lag of the smoothed and raw shadow
  centroid, in frames, and the jitter ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

import _common  # noqa: E402
from video_clips import CALIB_720, KNOT_SCENE, ExactShadow, iou, jitter_and_lag, make_clip  # noqa: E402

CACHE = Path(os.environ.get("ARSHADOW_BENCH_CACHE", "/tmp/arshadow-bench"))
BLANK = range(100, 130)


def _clip(kind: str, n: int):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import camera_path, pan_path

    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"{kind}{n}.mp4"
    poses = camera_path(n) if kind == "orbit" else pan_path(n)
    if not path.exists():
        intr = Intrinsics.from_file(CALIB_720)
        make_clip(path, intr, poses, blank=set(BLANK) if kind == "orbit" and n > 130 else set(), seed=11)
    return path, poses


EXTRA: list = []


def _run(clip, out, *extra):
    from arshadow.cli import main

    extra = (*EXTRA, *extra)
    argv = [
        "video",
        str(clip),
        "--calib",
        str(CALIB_720),
        "--marker-length",
        "0.05",
        *KNOT_SCENE,
        "-o",
        str(out),
        "-q",
        "--report",
        str(Path(out) / "r.json"),
        *extra,
    ]
    rc = main(argv)
    rep = json.loads((Path(out) / "r.json").read_text())
    lines = [json.loads(s) for s in (Path(out) / f"{Path(clip).stem}.frames.jsonl").read_text().splitlines()]
    return rc, rep["videos"][0], lines


def _pose(rvec, tvec):
    from arshadow.transforms import matrix_from_rvec_tvec

    return matrix_from_rvec_tvec(np.asarray(rvec, float), np.asarray(tvec, float))


def _exact():
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.lights.spec import parse_light

    intr = Intrinsics.from_file(CALIB_720)
    args = dict(zip(KNOT_SCENE[::2], KNOT_SCENE[1::2], strict=True))
    caster = load_occluder(
        args["--model"],
        rotate=[float(x) for x in args["--rotate"].split(",")],
        place=[float(x) for x in args["--place"].split(",")],
    )
    return intr, ExactShadow(intr, caster.vertices, caster.faces, parse_light(args["--light"]).homogeneous)


def throughput(clip, runs):
    res = []
    for _ in range(runs):
        load = os.getloadavg()
        with tempfile.TemporaryDirectory() as d:
            rc, summ, lines = _run(clip, d)
        assert rc == 0, summ
        res.append((summ["fps_processed"], load, summ, lines))
    fps = [r[0] for r in res]
    k = int(np.argsort(fps)[len(fps) // 2])
    lines = res[k][3]
    stages = {
        key: round(float(np.median([ln["timings_ms"][key] for ln in lines])), 3) for key in lines[0]["timings_ms"]
    }
    return {
        "fps_runs": fps,
        "fps_median": float(np.median(fps)),
        "fps_min": min(fps),
        "fps_max": max(fps),
        "loadavg_before_runs": [[round(x, 2) for x in r[1]] for r in res],
        "stage_ms_median": stages,
        "frames": res[k][2]["frames"],
        "wall_s": res[k][2]["wall_s"],
    }


def accuracy(clip, poses, refine):
    from arshadow.transforms import rotation_error_deg
    from arshadow.video.avio import AvReader

    intr, ex = _exact()
    with tempfile.TemporaryDirectory() as d:
        rc, summ, lines = _run(clip, d, "--save-mask", "--corner-refine", refine, "--contact-sheet", "0")
        masks = [f.image[:, :, 0] >= 128 for f in AvReader(Path(d) / f"{Path(clip).stem}.shadow.mkv")]
    ious, rot_raw, dist_raw, flips, c_raw, c_sm, c_true = [], [], [], 0, [], [], []
    for ln, m, true in zip(lines, masks, poses, strict=True):
        if ln["status"] == "no_marker":
            c_raw.append([np.nan, np.nan]), c_sm.append([np.nan, np.nan]), c_true.append(ex.centroid(true))
            continue
        ref = ex.mask(true)
        ious.append(iou(m, ref))
        sm = _pose(ln["rvec"], ln["tvec"])
        c_true.append(ex.centroid(true))
        c_sm.append(ex.centroid(sm))
        if ln["raw"] is not None:
            raw = _pose(ln["raw"]["rvec"], ln["raw"]["tvec"])
            e = rotation_error_deg(raw[:3, :3], true[:3, :3])
            rot_raw.append(e)
            flips += int(rotation_error_deg(sm[:3, :3], true[:3, :3]) > 5.0)
            dist_raw.append(abs(np.linalg.norm(raw[:3, 3]) / np.linalg.norm(true[:3, 3]) - 1) * 100)
            c_raw.append(ex.centroid(raw))
        else:
            c_raw.append([np.nan, np.nan])
    # jitter over the frames tracked in both (held frames have no raw pose)
    both = np.all(np.isfinite(c_raw), axis=1)
    c_sm = np.where(both[:, None], c_sm, np.nan)
    j_raw, _ = jitter_and_lag(c_raw, c_true)
    j_sm, _ = jitter_and_lag(c_sm, c_true)
    return {
        "refine": refine,
        "frames": summ["frames"],
        "statuses": {s: sum(ln["status"] == s for ln in lines) for s in ("ok", "held", "no_marker")},
        "iou": _common.summary(ious),
        "rotation_error_deg_raw": _common.summary(rot_raw),
        "distance_error_pct_raw": _common.summary(dist_raw),
        "flipped_frames": flips,
        "jitter_px_raw": round(j_raw, 4),
        "jitter_px_smoothed": round(j_sm, 4),
        "jitter_ratio": round(j_raw / j_sm, 3) if j_sm > 0 else None,
        "detect_pose_ms_median": round(
            float(
                np.median(
                    [ln["timings_ms"]["detect"] + ln["timings_ms"]["pose"] for ln in lines if ln["raw"] is not None]
                )
            ),
            3,
        ),
    }


def pan(n):
    clip, poses = _clip("pan", n)
    intr, ex = _exact()
    with tempfile.TemporaryDirectory() as d:
        rc, summ, lines = _run(clip, d, "--contact-sheet", "0")
    assert rc == 0, summ
    c_true = [ex.centroid(p) for p in poses]
    c_sm = [ex.centroid(_pose(ln["rvec"], ln["tvec"])) for ln in lines]
    c_raw = [ex.centroid(_pose(ln["raw"]["rvec"], ln["raw"]["tvec"])) if ln["raw"] else [np.nan] * 2 for ln in lines]
    j_raw, lag_raw = jitter_and_lag(c_raw, c_true)
    j_sm, lag_sm = jitter_and_lag(c_sm, c_true)
    speed = float(np.median(np.linalg.norm(np.diff(np.asarray(c_true), axis=0), axis=1)))
    return {
        "frames": n,
        "shadow_speed_px_per_frame": round(speed, 3),
        "lag_frames_smoothed": round(lag_sm, 4),
        "lag_frames_raw": round(lag_raw, 4),
        "jitter_px_raw": round(j_raw, 4),
        "jitter_px_smoothed": round(j_sm, 4),
        "jitter_ratio": round(j_raw / j_sm, 3) if j_sm > 0 else None,
    }


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--refine", default="edge,apriltag,subpix")
    ap.add_argument("--pan", type=int, default=120)
    ap.add_argument("--skip", default="", help="comma list of throughput,accuracy,pan to skip")
    ap.add_argument("--out")
    ap.add_argument("--extra", default="", help="more arshadow video options, space-separated")
    a = ap.parse_args()
    EXTRA[:] = a.extra.split()
    skip = set(filter(None, a.skip.split(",")))
    clip, poses = _clip("orbit", a.frames)
    out = {
        "clip": str(clip),
        "frames": a.frames,
        "cpu_count": os.cpu_count(),
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }
    if "throughput" not in skip:
        out["throughput"] = throughput(clip, a.runs)
        print(json.dumps(out["throughput"]), file=sys.stderr)
    if "accuracy" not in skip:
        out["accuracy"] = [accuracy(clip, poses, r) for r in a.refine.split(",") if r]
    if "pan" not in skip and a.pan:
        out["pan"] = pan(a.pan)
    out["meta"] = _common.metadata()
    _common.emit(out, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
