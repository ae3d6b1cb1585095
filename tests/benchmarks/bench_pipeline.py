"""Benchmark: one 1280x720 photo, detection -> composite, with the 8 536-face knot and one light.

    python tests/benchmarks/bench_pipeline.py [--runs 40] [--warmup 5] [--aa 4] [--photo P] [--variants]

Times :meth:`arshadow.frame.session.Session.process` (marker detection, pose, per-light mode decision,
silhouette + volume (cached after the first frame: the occluder and the light are fixed in the world
frame), ROI rendering, readback, lens warp, composite), excluding file decode/encode, process start and
context creation. Prints JSON: median, IQR and min/max of the total and of every stage over ``--runs``
runs after ``--warmup`` runs, plus metadata (git commit, versions, GL_RENDERER, load average).

``--variants`` adds rows for: MSAA 4, no ROI (full-frame render), a "cold" frame (silhouette and volume
rebuilt every frame, as for a moving light), OpenCV's default detector windows only (no fast pass),
volumes extruded to infinity, and the default again (the machine is shared: shows how the load moved).

``--detectors N`` compares ArUco detector settings on N random synthetic photos (1280x720, 5 cm marker at
0.3-0.8 m, tilt 0-70 deg, noise 2, blur 0.6, JPEG 90): detection time on the benchmark photo and the pose
error against the generating pose (median / 95th percentile rotation error, median translation error
relative to the distance, detection rate), so every speed-up comes with the error it costs.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _stats(values) -> dict:
    a = np.asarray(values, float)
    q25, q50, q75 = np.percentile(a, [25, 50, 75])
    return {
        "median": round(float(q50), 3),
        "iqr": round(float(q75 - q25), 3),
        "q25": round(float(q25), 3),
        "q75": round(float(q75), 3),
        "min": round(float(a.min()), 3),
        "max": round(float(a.max()), 3),
        "n": int(a.size),
    }


def _meta(ctx) -> dict:
    import cv2
    import moderngl

    from arshadow import __version__
    from arshadow.gl.context import gl_info

    try:
        commit = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
    except OSError:
        commit = None
    info = gl_info(ctx)
    return {
        "git_commit": commit,
        "arshadow": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "moderngl": moderngl.__version__,
        "GL_RENDERER": info.get("GL_RENDERER"),
        "GL_VERSION": info.get("GL_VERSION"),
        "cpus": os.cpu_count(),
        "loadavg_start": list(os.getloadavg()),
    }


def detector_settings() -> dict:
    """Named ArUco detector settings: keyword arguments of MarkerTracker."""
    import cv2

    def params(**kw):
        p = cv2.aruco.DetectorParameters()
        for k, v in kw.items():
            setattr(p, k, v)
        return p

    return {
        "default": {},
        "aruco3": {
            "detector_params": params(
                useAruco3Detection=True, minMarkerLengthRatioOriginalImg=0.02, minSideLengthCanonicalImg=16
            )
        },
        "one_threshold_window": {"detector_params": params(adaptiveThreshWinSizeMin=7, adaptiveThreshWinSizeMax=7)},
    }


def compare_detectors(image, intr, n, runs, seed=5) -> list:
    from arshadow.errors import MarkerNotFoundError
    from arshadow.synth.markers import random_pose, render_marker_photo
    from arshadow.tracking.tracker import MarkerTracker
    from arshadow.transforms import rotation_error_deg

    rng = np.random.default_rng(seed)
    photos = []
    h = 0.05 / 2 + 0.3 * 0.05
    paper = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], float)
    for i in range(n):
        pose = random_pose(rng, intr, distance=(0.3, 0.8), tilt_deg=(0.0, 70.0), keep_in_view=paper)
        ph = render_marker_photo(
            intr, pose, marker_length=0.05, noise_sigma=2.0, blur_sigma=0.6, jpeg_quality=90, seed=i
        )
        photos.append((ph.image, pose))
    from arshadow.tracking.tracker import make_fast_tracker

    rows = []
    settings = dict(detector_settings())
    settings["pipeline fast pass (half resolution + sub-pixel)"] = None
    for name, kw in settings.items():
        trk = (
            make_fast_tracker(intr, marker_length=0.05) if kw is None else MarkerTracker(intr, marker_length=0.05, **kw)
        )
        times = []
        for _ in range(runs):
            t = time.perf_counter()
            trk.estimate(image)
            times.append((time.perf_counter() - t) * 1e3)
        rot, trans, found = [], [], 0
        for img, pose in photos:
            try:
                est = trk.estimate(img)
            except MarkerNotFoundError:
                continue
            found += 1
            rot.append(rotation_error_deg(est.cam_from_world[:3, :3], pose[:3, :3]))
            trans.append(np.linalg.norm(est.cam_from_world[:3, 3] - pose[:3, 3]) / np.linalg.norm(pose[:3, 3]))
        rows.append(
            {
                "detector": name,
                "time_ms": _stats(times),
                "photos": n,
                "detected": found,
                "rot_err_deg_median": round(float(np.median(rot)), 4) if rot else None,
                "rot_err_deg_p95": round(float(np.percentile(rot, 95)), 4) if rot else None,
                "trans_err_rel_median": round(float(np.median(trans)), 5) if trans else None,
            }
        )
    return rows


def run_case(
    ctx,
    image,
    intr,
    caster,
    lights,
    *,
    runs,
    warmup,
    aa,
    roi=True,
    cold=False,
    label="",
    tracker_extra=None,
    fast_detect=True,
    truncate=True,
):
    from arshadow.frame.session import Session
    from arshadow.scene.spec import RenderOptions, Scene

    tracker = {"marker_length": 0.05, **(tracker_extra or {})}
    # cold: the planner's reuse switched off, so every frame rebuilds the silhouettes and volumes
    opts = RenderOptions(
        aa=aa, roi=roi, fast_detect=fast_detect, truncate=truncate, plan_off=("reuse",) if cold else ()
    )
    comp = Session(Scene(intr, caster, lights, opts, tracker), context=ctx)
    totals, stages = [], {}
    out_buf = np.empty_like(image)  # as `arshadow render` does: one output buffer reused per photo size
    with comp:
        for i in range(warmup + runs):
            t = time.perf_counter()
            item = comp.process(image, want_mask=False, out=out_buf).item
            dt = (time.perf_counter() - t) * 1e3
            if i >= warmup:
                totals.append(dt)
                for k, v in item.timings_ms.items():
                    stages.setdefault(k, []).append(v)
    row = {
        "case": label,
        "aa": aa,
        "roi": roi,
        "cold": cold,
        "fast_detect": fast_detect,
        "truncate": truncate,
        "loadavg_1min": os.getloadavg()[0],
        "roi_px": item.roi,
        "canvas": item.canvas,
        "mode": item.mode,
        "wall_ms": _stats(totals),
        "stages_ms": {k: _stats(v)["median"] for k, v in stages.items()},
    }
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--aa", type=int, default=None, help="MSAA samples (default: the render default)")
    ap.add_argument("--photo", default=str(ROOT / "samples" / "knot_point.jpg"))
    ap.add_argument("--calib", default=str(ROOT / "calib" / "synth_1280x720.yml"))
    ap.add_argument("--variants", action="store_true")
    ap.add_argument(
        "--detectors", type=int, default=0, metavar="N", help="compare detector settings on N synthetic photos"
    )
    ap.add_argument("--json", help="also write the result to this file")
    args = ap.parse_args(argv)
    if args.runs < 30:
        print("note: fewer than 30 runs", file=sys.stderr)

    sys.path.insert(0, str(ROOT))
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.gl.context import create_context
    from arshadow.io import read_image
    from arshadow.lights.spec import parse_light
    from arshadow.scene.spec import RenderOptions

    scenes = json.loads((ROOT / "samples" / "scenes.json").read_text())["scenes"]
    sc = next(s for s in scenes if Path(s["photo"]).name == Path(args.photo).name)
    image = read_image(args.photo)
    intr = Intrinsics.from_file(args.calib)
    caster = load_occluder(ROOT / sc["model"], rotate=sc.get("rotate", (0, 0, 0)), place=sc.get("place", (0, 0, 0)))
    lights = [parse_light(s) for s in sc["lights"][:1]]
    aa = RenderOptions().aa if args.aa is None else args.aa
    ctx = create_context()
    res = {
        "benchmark": "pipeline detection -> composite, 1280x720, one marker, one light",
        "photo": Path(args.photo).name,
        "faces": int(len(caster.faces)),
        "light": sc["lights"][0],
        "meta": _meta(ctx),
        "rows": [],
    }
    kw = dict(runs=args.runs, warmup=args.warmup)
    res["rows"].append(run_case(ctx, image, intr, caster, lights, aa=aa, label="default", **kw))
    if args.variants:
        res["rows"].append(run_case(ctx, image, intr, caster, lights, aa=4, label="MSAA 4", **kw))
        res["rows"].append(run_case(ctx, image, intr, caster, lights, aa=aa, roi=False, label="full frame", **kw))
        res["rows"].append(
            run_case(
                ctx, image, intr, caster, lights, aa=aa, cold=True, label="cold silhouette+volume every frame", **kw
            )
        )
        res["rows"].append(
            run_case(
                ctx,
                image,
                intr,
                caster,
                lights,
                aa=aa,
                fast_detect=False,
                label="OpenCV's default detector windows only",
                **kw,
            )
        )
        res["rows"].append(
            run_case(
                ctx,
                image,
                intr,
                caster,
                lights,
                aa=aa,
                truncate=False,
                label="volumes to infinity (not truncated)",
                **kw,
            )
        )
        # the machine is shared: the default again at the end shows how much the load moved
        res["rows"].append(run_case(ctx, image, intr, caster, lights, aa=aa, label="default (again)", **kw))
    if args.detectors:
        res["detectors"] = compare_detectors(image, intr, args.detectors, args.runs)
    res["meta"]["loadavg_end"] = list(os.getloadavg())
    ctx.release()
    text = json.dumps(res, indent=1)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
