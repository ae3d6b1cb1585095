"""The ECC corner refinement against the edge refinement (docs/tracking.md, "The ECC refinement" and
"Edges in linear light").

    python tests/benchmarks/bench_ecc.py [--photos 200] [--sections synth,plates,cost] [--out result.json]

Methods: ``edge`` and ``ecc`` as shipped; ``edge_code`` / ``edge_linear``: the edge refinement with its
crossings in code values only (its behaviour before 2026-11-28) / in linear light only; ``ecc_code``: ECC
started from the ``edge_code`` corners (:func:`edge_space` swaps the tracker's edge refinement).

- ``synth``: synthetic photos (:func:`arshadow.synth.render_print_scene`) at 1280x720 with the benchmark's
  lens distortion, marker sides of 30-150 px, tilt 0-60 deg, any roll, a random marker id, blur 0 / 0.6 /
  1.2 px applied either in code values (as :func:`arshadow.synth.camera_effects`) or in linear light (as
  optics blur), noise 0 / 2 / 4, JPEG none / 90; each tracked by ``MarkerTracker(refine="edge")`` and
  ``refine="ecc"`` (and the methods above). Errors against the generating pose: corner error (px, mean of the four), rotation
  (deg) and translation (mm) of the pose; medians and 90th percentiles, overall and per condition.
- ``plates``: the committed path-traced plates (tests/data/reference/{own,heldout}), corners against the
  scene's true projected corners (``corner_*``) and against the corners of the camera the plates were
  rendered with (``rendered_*``: Mitsuba was given ``reference_scene.mitsuba_fov``; until 2026-11-28 a field
  of view over W - 1 pixels, which scaled the plates by W / (W - 1) about the principal point:
  docs/tracking.md, docs/reference.md; since, the scenes' own, and the two columns agree).
- ``cost``: ms per marker of the refinements alone on 1280x720 synthetic photos blurred by 0.6 px in code
  values (``<size>px``) or in linear light (``<size>px_linear_blur``): ``edge``, ``edge_code`` and what
  ECC adds (median over photos of the median of repeated runs, interleaved), with the load average.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import time
from collections.abc import Iterator

import _common
import numpy as np

import arshadow.tracking.tracker as tracker_module
from arshadow.bench.reference import load_cases
from arshadow.bench.reference_scene import intrinsics_of, mitsuba_fov, pose_of
from arshadow.bench.tracking import camera
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
#: method -> (the tracker's refinement, the edge refinement's space)
METHODS = {
    "edge": ("edge", "auto"),
    "edge_code": ("edge", "code"),
    "edge_linear": ("edge", "linear"),
    "ecc": ("ecc", "auto"),
    "ecc_code": ("ecc", "code"),
}


@contextlib.contextmanager
def edge_space(space: str) -> Iterator[None]:
    """The tracker's edge refinement with its crossings in ``space`` (``refine_edges``'s) meanwhile (the
    tracker passes its own ``space``: replaced)."""
    saved = tracker_module.refine_edges

    def in_space(*args: object, **kw: object) -> object:
        return saved(*args, **{**kw, "space": space})

    tracker_module.refine_edges = in_space
    try:
        yield
    finally:
        tracker_module.refine_edges = saved


def estimate(method: str, image: np.ndarray, cam, **kw):
    """The pose of ``image`` by ``method`` (:data:`METHODS`), or None when no marker is found."""
    refine, space = METHODS[method]
    with edge_space(space):
        try:
            return MarkerTracker(cam, refine=refine, **kw).estimate(image)
        except MarkerNotFoundError:
            return None


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
    photo = camera_effects(  # linear: optics, the blur acts on light before the tone curve
        img, blur_sigma=blur, blur_linear=space == "linear", noise_sigma=noise, seed=seed, jpeg_quality=jpeg
    )
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
        for method in METHODS:
            pose = estimate(method, ph["image"], cam, marker_length=MARKER_LENGTH, marker_id=ph["mid"])
            if pose is None:
                row[method] = None
                continue
            err = np.linalg.norm(pose.corners[:4] - ph["truth"], axis=1)
            row[method] = dict(
                corner_px=float(err.mean()),
                corner_max_px=float(err.max()),
                rot_deg=rotation_error_deg(pose.cam_from_world[:3, :3], ph["pose"][:3, :3]),
                trans_mm=1e3 * float(np.linalg.norm(pose.cam_from_world[:3, 3] - ph["pose"][:3, 3])),
                note=pose.refine_note,
            )
        rows.append(row)
    found = [r for r in rows if all(r[m] is not None for m in METHODS)]

    def stats(sel):
        return {
            m: {k: q([r[m][k] for r in sel]) for k in ("corner_px", "corner_max_px", "rot_deg", "trans_mm")}
            | {"n": len(sel)}
            for m in METHODS
        }

    out = {"photos": n, "found_both": len(found), "all": stats(found)}
    out["ecc_fallbacks"] = [r["ecc"]["note"] for r in found if r["ecc"]["note"]]
    for key in ("size", "noise"):
        out[f"by_{key}"] = {str(v): stats([r for r in found if r[key] == v]) for v in sorted({r[key] for r in found})}
    blurs = sorted({(r["space"], r["blur"]) for r in found})
    out["by_blur"] = {f"{s} {b}": stats([r for r in found if (r["space"], r["blur"]) == (s, b)]) for s, b in blurs}
    spaces = {"code_or_unblurred": ("code", "-"), "code": ("code",), "linear": ("linear",)}
    out["by_space"] = {k: stats([r for r in found if r["space"] in v]) for k, v in spaces.items()}
    return out


def plates():
    keys = (
        "corner_mean_px",
        "corner_max_px",
        "centroid_px",
        "rendered_mean_px",
        "rendered_max_px",
        "rendered_centroid_px",
    )
    out = {}
    for name in ("own", "heldout"):
        per = {}
        for c in load_cases(ROOT / "tests" / "data" / "reference" / name):
            K = intrinsics_of(c.scene)
            truth = K.project(marker_object_points(c.scene.marker_length), pose_of(c.scene))
            pp = np.array([K.cx, K.cy])
            f_rendered = c.scene.width / 2.0 / math.tan(math.radians(mitsuba_fov(c.scene)) / 2.0)
            rendered = pp + (truth - pp) * f_rendered / K.fx  # the plates' camera
            per[c.scene.name] = {}
            for method in METHODS:
                pose = estimate(method, c.plate8, K, marker_length=c.scene.marker_length)
                row = {}
                for label, t in (("corner", truth), ("rendered", rendered)):
                    e = np.linalg.norm(pose.corners[:4] - t, axis=1)
                    row[f"{label}_mean_px"] = round(float(e.mean()), 4)
                    row[f"{label}_max_px"] = round(float(e.max()), 4)
                    cen = round(float(np.linalg.norm((pose.corners[:4] - t).mean(axis=0))), 4)
                    row["centroid_px" if label == "corner" else "rendered_centroid_px"] = cen
                per[c.scene.name][method] = row | {"note": pose.refine_note}
        out[name] = {
            "cases": per,
            "median": {m: {k: q([v[m][k] for v in per.values()])[0] for k in keys} for m in METHODS},
            "max": {m: max(v[m]["corner_max_px"] for v in per.values()) for m in METHODS},
            "rendered_max": {m: max(v[m]["rendered_max_px"] for v in per.values()) for m in METHODS},
        }
    return out


def cost(repeat, seed):
    cam = camera(1280, 720)
    rng = np.random.default_rng(seed)
    out = {"loadavg_start": list(os.getloadavg())}
    for space, size in [(s, z) for s in ("code", "linear") for z in SIZES_PX]:
        te, to, tc = [], [], []
        for i in range(6):
            ph = make_photo(cam, rng, i, size=float(size), blur=0.6, space=space, noise=2.0, jpeg=90)
            gray = to_gray(ph["image"])
            try:
                start = MarkerTracker(cam, marker_length=MARKER_LENGTH, refine="none").estimate(ph["image"]).corners[:4]
            except MarkerNotFoundError:
                continue
            bits = marker_bits("DICT_6X6_250", ph["mid"])
            a, b, o = [], [], []
            for _ in range(repeat):  # interleaved: the machine's load hits all alike
                t0 = time.perf_counter()
                edge = refine_corners_edges(gray, start[None], cam)
                t1 = time.perf_counter()
                refine_corners_ecc(gray, edge, bits, cam)
                t2 = time.perf_counter()
                refine_corners_edges(gray, start[None], cam, space="code")
                t3 = time.perf_counter()
                a.append(t1 - t0)
                b.append(t2 - t1)
                o.append(t3 - t2)
            te.append(np.median(a))
            tc.append(np.median(b))
            to.append(np.median(o))
        out[f"{size}px" + ("" if space == "code" else "_linear_blur")] = {
            "edge_ms": round(1e3 * float(np.median(te)), 3),
            "edge_code_ms": round(1e3 * float(np.median(to)), 3),
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
