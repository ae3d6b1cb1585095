"""The ECC corner refinement against the edge refinement (docs/tracking.md, "The ECC refinement").

    python tests/benchmarks/bench_ecc.py [--photos 200] [--sections synth,plates,cost] [--out result.json]

- ``synth``: synthetic photos (:func:`arshadow.synth.render_print_scene`) at 1280x720 with the benchmark's
  lens distortion, marker sides of 30-150 px, tilt 0-60 deg, any roll, a random marker id, blur 0 / 0.6 /
  1.2 px applied either in code values (as :func:`arshadow.synth.camera_effects`) or in linear light (as
  optics blur), noise 0 / 2 / 4, JPEG none / 90; each tracked by ``MarkerTracker(refine="edge")`` and
  ``refine="ecc"``. Errors against the generating pose: corner error (px, mean of the four), rotation
  (deg) and translation (mm) of the pose; medians and 90th percentiles, overall and per condition.
- ``plates``: the committed path-traced plates (tests/data/reference/{own,heldout}), corners against the
  scene's true projected corners.
- ``cost``: ms per marker of the two refinements alone on 1280x720 synthetic photos (median over photos of
  the median of repeated runs), per marker size, with the load average.
"""

from __future__ import annotations

import argparse
import os
import time

import _common
import cv2
import numpy as np

from arshadow.bench.reference import load_cases
from arshadow.bench.reference_scene import intrinsics_of, pose_of
from arshadow.bench.tracking import camera
from arshadow.compose.composite import linear_to_srgb, srgb_to_linear
from arshadow.errors import MarkerNotFoundError
from arshadow.synth.markers import camera_effects, random_pose, render_print_scene
from arshadow.tracking.detect import to_gray
from arshadow.tracking.dictionary import marker_bits, marker_object_points
from arshadow.tracking.ecc import refine_corners_ecc
from arshadow.tracking.refine import refine_corners_edges
from arshadow.tracking.tracker import MarkerTracker
from arshadow.transforms import rotation_error_deg

ROOT = _common.ROOT
SIZES_PX = (30, 45, 65, 100, 150)
MARKER_LENGTH = 0.05


def make_photo(cam, rng, seed, size=None, blur=None, space=None, noise=None, jpeg="random"):
    """One synthetic photo and its truth (a dict); unset conditions drawn from ``rng``."""
    size = float(rng.choice(SIZES_PX)) if size is None else size
    tilt = rng.uniform(0, 60)
    d = cam.fx * MARKER_LENGTH / size * np.sqrt(max(np.cos(np.radians(tilt)), 0.5))
    pose = random_pose(
        rng, cam, distance=(d, d), tilt_deg=(tilt, tilt), keep_in_view=marker_object_points(1.6 * MARKER_LENGTH)
    )
    mid = int(rng.integers(250))
    blur = float(rng.choice([0.0, 0.6, 1.2])) if blur is None else blur
    space = str(rng.choice(["code", "linear"])) if space is None else space
    noise = float(rng.choice([0.0, 2.0, 4.0])) if noise is None else noise
    jpeg = [None, 90][int(rng.integers(2))] if jpeg == "random" else jpeg
    img = render_print_scene(cam, pose, marker_id=mid, marker_length=MARKER_LENGTH)["image"]
    if space == "linear" and blur > 0:  # optics: the blur acts on light, before the tone curve
        lin = cv2.GaussianBlur(srgb_to_linear(np.clip(img, 0, 255) / 255.0).astype(np.float32), (0, 0), blur)
        img, code_blur = (linear_to_srgb(lin) * 255.0).astype(np.float32), 0.0
    else:
        code_blur = blur
    photo = camera_effects(img, blur_sigma=code_blur, noise_sigma=noise, seed=seed, jpeg_quality=jpeg)
    truth = cam.project(marker_object_points(MARKER_LENGTH), pose)
    cond = dict(size=size, blur=blur, space=space if blur > 0 else "-", noise=noise, jpeg=jpeg, tilt=round(tilt, 1))
    return dict(image=photo, pose=pose, mid=mid, truth=truth, cond=cond)


def q(a):
    """Median and 90th percentile, rounded."""
    a = np.asarray(a, np.float64)
    return [round(float(np.median(a)), 4), round(float(np.percentile(a, 90)), 4)] if a.size else None


def synth(n, seed):
    cam = camera(1280, 720)
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(n):
        ph = make_photo(cam, rng, seed * 1000 + i)
        row = dict(ph["cond"])
        for refine in ("edge", "ecc"):
            tr = MarkerTracker(cam, marker_length=MARKER_LENGTH, marker_id=ph["mid"], refine=refine)
            try:
                pose = tr.estimate(ph["image"])
            except MarkerNotFoundError:
                row[refine] = None
                continue
            err = np.linalg.norm(pose.corners[:4] - ph["truth"], axis=1)
            row[refine] = dict(
                corner_px=float(err.mean()),
                corner_max_px=float(err.max()),
                rot_deg=rotation_error_deg(pose.cam_from_world[:3, :3], ph["pose"][:3, :3]),
                trans_mm=1e3 * float(np.linalg.norm(pose.cam_from_world[:3, 3] - ph["pose"][:3, 3])),
                note=pose.refine_note,
            )
        rows.append(row)
    found = [r for r in rows if r["edge"] is not None and r["ecc"] is not None]

    def stats(sel):
        return {
            m: {k: q([r[m][k] for r in sel]) for k in ("corner_px", "corner_max_px", "rot_deg", "trans_mm")}
            | {"n": len(sel)}
            for m in ("edge", "ecc")
        }

    out = {"photos": n, "found_both": len(found), "all": stats(found)}
    out["ecc_fallbacks"] = [r["ecc"]["note"] for r in found if r["ecc"]["note"]]
    for key in ("size", "noise"):
        out[f"by_{key}"] = {str(v): stats([r for r in found if r[key] == v]) for v in sorted({r[key] for r in found})}
    blurs = sorted({(r["space"], r["blur"]) for r in found})
    out["by_blur"] = {f"{s} {b}": stats([r for r in found if (r["space"], r["blur"]) == (s, b)]) for s, b in blurs}
    return out


def plates():
    out = {}
    for name in ("own", "heldout"):
        per = {}
        for c in load_cases(ROOT / "tests" / "data" / "reference" / name):
            K = intrinsics_of(c.scene)
            truth = K.project(marker_object_points(c.scene.marker_length), pose_of(c.scene))
            per[c.scene.name] = {}
            for refine in ("edge", "ecc"):
                pose = MarkerTracker(K, marker_length=c.scene.marker_length, refine=refine).estimate(c.plate8)
                e = np.linalg.norm(pose.corners[:4] - truth, axis=1)
                per[c.scene.name][refine] = dict(
                    corner_mean_px=round(float(e.mean()), 4),
                    corner_max_px=round(float(e.max()), 4),
                    centroid_px=round(float(np.linalg.norm((pose.corners[:4] - truth).mean(axis=0))), 4),
                    note=pose.refine_note,
                )
        out[name] = {
            "cases": per,
            "median": {
                m: {
                    k: q([v[m][k] for v in per.values()])[0] for k in ("corner_mean_px", "corner_max_px", "centroid_px")
                }
                for m in ("edge", "ecc")
            },
            "max": {m: max(v[m]["corner_max_px"] for v in per.values()) for m in ("edge", "ecc")},
        }
    return out


def cost(repeat, seed):
    cam = camera(1280, 720)
    rng = np.random.default_rng(seed)
    out = {"loadavg_start": list(os.getloadavg())}
    for size in SIZES_PX:
        te, tc = [], []
        for i in range(6):
            ph = make_photo(cam, rng, i, size=float(size), blur=0.6, space="code", noise=2.0, jpeg=90)
            gray = to_gray(ph["image"])
            try:
                start = MarkerTracker(cam, marker_length=MARKER_LENGTH, refine="none").estimate(ph["image"]).corners[:4]
            except MarkerNotFoundError:
                continue
            bits = marker_bits("DICT_6X6_250", ph["mid"])
            a, b = [], []
            for _ in range(repeat):  # interleaved: the machine's load hits both alike
                t0 = time.perf_counter()
                edge = refine_corners_edges(gray, start[None], cam)
                t1 = time.perf_counter()
                refine_corners_ecc(gray, edge, bits, cam)
                t2 = time.perf_counter()
                a.append(t1 - t0)
                b.append(t2 - t1)
            te.append(np.median(a))
            tc.append(np.median(b))
        out[f"{size}px"] = {
            "edge_ms": round(1e3 * float(np.median(te)), 3),
            "ecc_extra_ms": round(1e3 * float(np.median(tc)), 3),
            "ecc_extra_ms_max": round(1e3 * float(np.max(tc)), 3),
            "photos": len(te),
        }
    out["loadavg_end"] = list(os.getloadavg())
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--photos", type=int, default=200)
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--sections", default="synth,plates,cost")
    ap.add_argument("--out")
    args = ap.parse_args()
    result: dict = {"meta": _common.metadata()}
    for sec in args.sections.split(","):
        t0 = time.perf_counter()
        if sec == "synth":
            result["synth"] = synth(args.photos, args.seed)
        elif sec == "plates":
            result["plates"] = plates()
        elif sec == "cost":
            result["cost"] = cost(args.repeat, args.seed)
        else:
            raise SystemExit(f"unknown section {sec!r}")
        result.setdefault("seconds", {})[sec] = round(time.perf_counter() - t0, 1)
    _common.emit(result, args.out)


if __name__ == "__main__":
    main()
