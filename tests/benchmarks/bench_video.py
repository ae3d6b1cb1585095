"""Video benchmark: per-frame time of ``arshadow video`` and IPPE flips with / without the temporal choice.

    python tests/benchmarks/bench_video.py [--quick]

Prints JSON:

- ``frame_ms``: the sample clip samples/video/orbit.mp4 (640x360, 60 frames) through the whole video path
  (decode -> detect + pose -> temporal choice -> render -> lens warp -> composite -> encode), the house
  mesh under one sun light; per frame ``total`` = detection -> composite (no decode / encode, no process
  start or context creation), and ``wall`` including decode and encode; median, IQR, min/max over the
  frames of the 2nd of two runs (the first warms up); per corner-refinement method, with the median
  distance error of the estimated pose against the clip's true poses (orbit.json) that the method costs.
- ``flips``: ambiguous synthetic sequences (small marker seen nearly face-on, noise sigma 2, blur 0.6,
  640x360): frames on the wrong IPPE branch and branch changes between consecutive frames, for the
  choice by reprojection error, the tracker's own previous-frame hook (ratio >= 0.6), and
  :class:`arshadow.video.chooser.TemporalPoseChooser` with lag 0 and 16.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from itertools import pairwise
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def _meta():
    import cv2

    from arshadow import __version__

    try:
        commit = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
    except OSError:
        commit = None
    info = {}
    try:
        from arshadow.gl.context import create_context, gl_info

        ctx = create_context()
        info = gl_info(ctx)
        ctx.release()
    except Exception as exc:  # noqa: BLE001
        info = {"error": str(exc)}
    return {
        "commit": commit,
        "arshadow": __version__,
        "opencv": cv2.__version__,
        "numpy": np.__version__,
        "GL_RENDERER": info.get("GL_RENDERER"),
        "date": time.strftime("%Y-%m-%dT%H:%M:%S"),
    }


def _stats(a):
    a = np.asarray(a, float)
    return {
        "median": round(float(np.median(a)), 2),
        "iqr": [round(float(np.percentile(a, 25)), 2), round(float(np.percentile(a, 75)), 2)],
        "min": round(float(a.min()), 2),
        "max": round(float(a.max()), 2),
        "n": int(a.size),
    }


def frame_times(refine: str):
    from arshadow.cli import main

    truth = json.loads((ROOT / "samples/video/orbit.json").read_text())["cam_from_world"]
    with tempfile.TemporaryDirectory() as d:
        argv = [
            "video",
            str(ROOT / "samples/video/orbit.mp4"),
            "--calib",
            str(ROOT / "calib/synth_640x360.yml"),
            "--marker-length",
            "0.05",
            "--model",
            str(ROOT / "samples/meshes/house.obj"),
            "--place",
            "0.07,0.03,0",
            "--rotate",
            "0,0,20",
            "--light",
            "sun:48.8566,2.3522,2024-06-21T10:00+02:00",
            "--corner-refine",
            refine,
            "-o",
            d,
            "--report",
            f"{d}/r.json",
            "-q",
        ]
        for _ in range(2):
            assert main(argv) == 0
        rep = json.loads(Path(f"{d}/r.json").read_text())
    items = [it for it in rep["images"] if it["status"] == "ok"]
    tot = [it["timings_ms"]["total"] for it in items]
    wall = [it["timings_ms"]["total"] + it["timings_ms"].get("decode", 0) + it["encode_ms"] for it in items]
    derr = [
        abs(np.linalg.norm(it["tvec"]) / np.linalg.norm(np.asarray(truth[it["frame"]])[:3, 3]) - 1) * 100
        for it in items
    ]
    stages = {k: _stats([it["timings_ms"][k] for it in items])["median"] for k in items[0]["timings_ms"]}
    return {
        "refine": refine,
        "total": _stats(tot),
        "wall": _stats(wall),
        "stage_medians": stages,
        "distance_error_pct_median": round(float(np.median(derr)), 3),
    }


def flips(n_frames=40, seeds=(0, 1, 2), marker_length=0.04):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import camera_path, render_marker_photo
    from arshadow.tracking.tracker import MarkerTracker
    from arshadow.transforms import rotation_error_deg as rotation_angle_deg
    from arshadow.video.chooser import TemporalPoseChooser

    intr = Intrinsics.from_file(ROOT / "calib/synth_640x360.yml")

    def branch_stats(chosen, truth):
        br = []
        for c, t in zip(chosen, truth, strict=True):
            a = rotation_angle_deg(c.cam_from_world, t)
            b = rotation_angle_deg(c.alternative.cam_from_world, t)
            br.append(0 if abs(a - b) < 5.0 else int(a > b))
        err = [rotation_angle_deg(c.cam_from_world, t) for c, t in zip(chosen, truth, strict=True)]
        return sum(br), sum(1 for x, y in pairwise(br) if x != y), err

    res = {k: [0, 0, []] for k in ("error", "tracker_hook", "chooser_lag0", "chooser_lag16")}
    for seed in seeds:
        truth = camera_path(n_frames, radius=0.15, height=(0.5, 0.6), sweep_deg=90, phase=0.3 * seed)
        tr = MarkerTracker(intr, marker_length=marker_length)
        est = [
            tr.estimate(
                render_marker_photo(
                    intr, p, marker_length=marker_length, noise_sigma=2.0, blur_sigma=0.6, seed=1000 * seed + i
                ).image
            )
            for i, p in enumerate(truth)
        ]
        hook, prev = [], None
        for p in est:  # the tracker's own hook: swap when ambiguous (ratio >= 0.6) and closer to previous
            if (
                prev is not None
                and p.ambiguous
                and rotation_angle_deg(p.alternative.cam_from_world, prev.cam_from_world)
                < rotation_angle_deg(p.cam_from_world, prev.cam_from_world)
            ):
                p = p.swapped()
            hook.append(p)
            prev = p
        runs = {"error": est, "tracker_hook": hook}
        for lag in (0, 16):
            ch = TemporalPoseChooser(lag=lag, fps=25.0)
            out = []
            for i, p in enumerate(est):
                out += ch.push(i, p, i / 25.0)
            out += ch.flush()
            runs[f"chooser_lag{lag}"] = [o.pose for o in out]
        for k, chosen in runs.items():
            w, f, e = branch_stats(chosen, truth)
            res[k][0] += w
            res[k][1] += f
            res[k][2] += e
    return {
        "frames": n_frames * len(seeds),
        "marker_length": marker_length,
        **{
            k: {
                "wrong_branch_frames": v[0],
                "branch_flips": v[1],
                "rotation_error_deg_median": round(float(np.median(v[2])), 2),
                "rotation_error_deg_p95": round(float(np.percentile(v[2], 95)), 2),
            }
            for k, v in res.items()
        },
    }


def main() -> int:
    quick = "--quick" in sys.argv
    out = {
        "meta": _meta(),
        "frame_ms": [frame_times("apriltag")] + ([] if quick else [frame_times("subpix")]),
        "flips": [flips(seeds=(0,) if quick else (0, 1, 2))],
    }
    if not quick:
        out["flips"].append(flips(seeds=(0, 1, 2), marker_length=0.05))
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
