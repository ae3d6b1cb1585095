"""Benchmark: detection + pose run time against pose error, per corner refinement method and resolution.

Run (prints a JSON document and a markdown table; takes a few minutes):

    python tests/benchmarks/bench_tracking.py [--poses 60] [--repeat 5] [--json out.json]

or through pytest: ``pytest -m slow tests/benchmarks/bench_tracking.py -s``.

Photos come from :func:`arshadow.synth.render_marker_photo` with the acceptance conditions of the tracking acceptance tests
(marker 5-10 % of the image width, 0.3-0.8 m, tilt 0-70 deg, noise sigma 2, blur sigma 0.6, JPEG 90);
the same poses are used for every method at a resolution. The error is against the generating pose.
Per photo the time is the median of ``repeat`` runs after one warm-up, the configurations interleaved
round-robin; the table gives the median and IQR of those per-photo times. The machine is shared and
noisy: compare methods within one run only.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from arshadow import __version__
from arshadow.errors import MarkerNotFoundError
from arshadow.tracking.detect import REFINE_METHODS
from arshadow.tracking.tracker import MarkerTracker
from arshadow.transforms import rotation_error_deg

ROOT = Path(__file__).resolve().parents[2]
RESOLUTIONS = ((640, 480), (1280, 720), (1920, 1080))
from arshadow.bench.tracking import DIST, camera, make_photos  # noqa: E402,F401 (shared with `arshadow bench`)

CONFIGS = tuple((m, True) for m in REFINE_METHODS) + (("subpix", False),)  # (refinement, LM polish)


def run_configs(photos, cam, configs, repeat):
    """All configurations on the same photos; timings interleaved (photo by photo, round-robin over the
    configurations, ``repeat`` rounds) so that the shared machine's load changes hit every configuration
    alike. Returns one row per configuration."""
    acc = {c: dict(times=[], rot=[], trans=[], flagged=0, wrong_unflagged=0, found=0) for c in configs}
    for ph in photos:
        trackers, poses = {}, {}
        for c in configs:
            tr = MarkerTracker(
                cam, marker_length=ph.marker_length, marker_id=ph.marker_id, refine=c[0], pnp_refine=c[1]
            )
            try:
                poses[c] = tr.estimate(ph.image)  # warm-up, and the result
                trackers[c] = tr
            except MarkerNotFoundError:
                pass
        t = {c: [] for c in trackers}
        for _ in range(repeat):
            for c, tr in trackers.items():
                t0 = time.perf_counter()
                tr.estimate(ph.image)
                t[c].append(time.perf_counter() - t0)
        for c, pose in poses.items():
            a = acc[c]
            a["times"].append(np.median(t[c]))
            a["found"] += 1
            r = rotation_error_deg(pose.cam_from_world[:3, :3], ph.cam_from_world[:3, :3])
            a["rot"].append(r)
            a["trans"].append(np.linalg.norm(pose.tvec - ph.cam_from_world[:3, 3]) / ph.distance)
            a["flagged"] += pose.ambiguous
            a["wrong_unflagged"] += (r > 5.0) and not pose.ambiguous
    rows = []
    q = lambda a, p: float(np.percentile(a, p)) if a.size else None  # noqa: E731
    for (refine, lm), a in acc.items():
        times, rot, trans = np.array(a["times"]) * 1e3, np.array(a["rot"]), np.array(a["trans"]) * 100
        rows.append(
            dict(
                refine=refine,
                pnp_refine=lm,
                n=len(photos),
                detected=a["found"],
                time_ms_median=q(times, 50),
                time_ms_iqr=[q(times, 25), q(times, 75)],
                rot_deg_median=q(rot, 50),
                rot_deg_p95=q(rot, 95),
                rot_deg_max=float(rot.max()) if rot.size else None,
                trans_pct_median=q(trans, 50),
                trans_pct_p95=q(trans, 95),
                n_rot_over_5deg=int((rot > 5).sum()),
                n_flagged=int(a["flagged"]),
                n_wrong_unflagged=int(a["wrong_unflagged"]),
            )
        )
    return rows


def metadata():
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
    except OSError:  # pragma: no cover
        commit = None
    return dict(
        git_commit=commit,
        arshadow=__version__,
        opencv=cv2.__version__,
        numpy=np.__version__,
        python=platform.python_version(),
        machine=platform.machine(),
        cpus=cv2.getNumberOfCPUs(),
        threads=cv2.getNumThreads(),
    )


def run(poses=60, repeat=5, resolutions=RESOLUTIONS, configs=CONFIGS):
    rows = []
    for w, h in resolutions:
        cam = camera(w, h)
        photos = make_photos(cam, poses, seed=w)
        for r in run_configs(photos, cam, configs, repeat):
            rows.append(dict(resolution=f"{w}x{h}", **r))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    return dict(
        benchmark="tracking: detection + pose time vs pose error",
        metadata=metadata(),
        conditions=dict(
            poses_per_resolution=poses,
            repeat=repeat,
            marker_width_frac=[0.05, 0.10],
            distance_m=[0.3, 0.8],
            tilt_deg=[0, 70],
            noise_sigma=2,
            blur_sigma=0.6,
            jpeg_quality=90,
        ),
        rows=rows,
    )


def table(result) -> str:
    lines = [
        "| resolution | refinement | LM | detected | time ms median [IQR] | rot deg median / p95 / max "
        "| trans % median | >5 deg (unflagged) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['resolution']} | {r['refine']} | {'yes' if r['pnp_refine'] else 'no'} | {r['detected']}/{r['n']} "
            f"| {r['time_ms_median']:.1f} [{r['time_ms_iqr'][0]:.1f}, {r['time_ms_iqr'][1]:.1f}] "
            f"| {r['rot_deg_median']:.3f} / {r['rot_deg_p95']:.2f} / {r['rot_deg_max']:.2f} "
            f"| {r['trans_pct_median']:.3f} | {r['n_rot_over_5deg']} ({r['n_wrong_unflagged']}) |"
        )
    return "\n".join(lines)


@pytest.mark.slow
def test_bench_tracking():
    res = run(poses=30, repeat=3)
    print(table(res))
    assert all(r["detected"] > 0 for r in res["rows"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", type=Path, help="also write the JSON here")
    args = ap.parse_args(argv)
    res = run(args.poses, args.repeat)
    print(json.dumps(res, indent=1))
    print(table(res))
    if args.json:
        from arshadow.io import write_json

        write_json(args.json, res)


if __name__ == "__main__":
    main()
