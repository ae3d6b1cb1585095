"""Where the ground residual of the path-traced reference comes from (the realism work; docs/reference.md).

    python tests/benchmarks/diagnose_realism.py [--set own|heldout|plain ...] [--png DIR] [--opt KEY=VALUE ...]

Per committed case, four pipelines (all with the scene's ``--ambient-occlusion on`` unless ``--opt`` says
otherwise):

- ``measured``: ``arshadow light`` + ``render --light-from``, the marker tracked (what a user gets);
- ``measured_pose``: the same estimate, the scene's true camera pose (no tracking error);
- ``true_dir``: the true light's direction/position with the estimate's shadow ratio and exposure, true pose;
- ``oracle``: the true direction and the true shadow ratio (the sky's share of the open ground's light at
  the object, from the scene's direct and sky irradiance), true pose: the rendering model alone.

Each pipeline's ground residual is split by where its error lies (shares of the same denominator, so the
four add up to the ground residual): ``contact`` (the contact band), ``edge`` (ground within
:data:`EDGE_PX` px of the true light's hard shadow outline: pose error and the penumbra a sun disc gives),
``umbra`` (inside the hard shadow beyond that: the shadow's darkness), ``outside`` (the rest: the ground's
glow / interreflection, the sky occlusion's halo), plus the signed sum per part (+: the composite too
bright). ``--png DIR`` writes the signed difference map S(composite - truth) (summed over channels; red:
composite too bright, blue: too dark; the hard shadow's outline in green, the contact band in grey) per
case and pipeline, scaled 3x.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import _common
import cv2
import numpy as np

ROOT = _common.ROOT
#: ground within this many pixels of the hard shadow's outline counts as its edge
EDGE_PX = 3
PARTS = ("contact", "edge", "umbra", "outside")


def true_ratio(sc) -> np.ndarray:
    """The sky's share of the open ground's light at the object's place, (3,) float64."""
    v = np.asarray(sc.light_vec, np.float64)
    sky = np.asarray(sc.sky, np.float64)
    if sc.light == "sun":
        e = np.asarray(sc.direct, np.float64) * max(v[2] / np.linalg.norm(v), 0.0)
    else:
        rel = v - np.array([sc.place[0], sc.place[1], 0.0])
        d = np.linalg.norm(rel)
        e = np.asarray(sc.direct, np.float64) * max(rel[2] / d, 0.0) / d**2
    return sky / (sky + e)


def composite(case, est, pipeline: str, opts: dict):
    """The composite (H, W, 3) uint8 of one pipeline."""
    from arshadow.bench.reference import run_arshadow
    from arshadow.bench.reference_scene import light_spec

    o = {"ambient_occlusion": "on", **opts}
    if pipeline == "measured":
        return run_arshadow(case.plate8, case.scene, "measured", o, "tracked", est)[0]
    if pipeline == "measured_pose":
        return run_arshadow(case.plate8, case.scene, "measured", o, "true", est)[0]
    if pipeline == "oracle":
        # the true ratio is the one at the object: read there (a lamp's ratio is rescaled from ratio_at)
        sc = case.scene
        est = dataclasses.replace(
            est,
            shadow_ratio=tuple(float(v) for v in true_ratio(sc)),
            ratio_at=(float(sc.place[0]), float(sc.place[1])),
        )
    o["lights"] = [light_spec(case.scene)]
    return run_arshadow(case.plate8, case.scene, "measured", o, "true", est)[0]


def hard_shadow(case) -> np.ndarray:
    """(h, w) bool in the crop: the true light's hard shadow on the ground at the true pose (arshadow's own
    shadow mask for the true light: exact geometry)."""
    from arshadow.bench.reference import intrinsics_of, object_color
    from arshadow.bench.reference_scene import light_spec, pose_of
    from arshadow.frame.session import Session
    from arshadow.scene.spec import scene_from_dict

    sc = case.scene
    d = {
        "calib": intrinsics_of(sc),
        "marker_length": sc.marker_length,
        "model": sc.model,
        "place": list(sc.place),
        "rotate": list(sc.rotate),
        "color": object_color(sc),
        "lights": [light_spec(sc)],
    }
    with Session(scene_from_dict(d)) as s:
        mask = s.render(case.plate8, pose_of(sc), want_mask=True).mask
    y0, y1, x0, x1 = case.crop
    return mask[y0:y1, x0:x1] >= 128


def split(case, comp8: np.ndarray, shadow: np.ndarray) -> tuple[dict, np.ndarray, np.ndarray]:
    """``(parts, signed, region)``: the ground residual's shares per part (``PARTS``, and their signed
    versions ``<part>_signed``), the signed smoothed difference summed over channels (h, w) and the scored
    ground region (h, w) bool."""
    from arshadow.bench.reference_score import change_map, decode8, smooth_regions

    y0, y1, x0, x1 = case.crop
    plate = decode8(case.plate8[y0:y1, x0:x1])
    sc = smooth_regions(decode8(comp8[y0:y1, x0:x1]) - plate, case.masks)
    st = case.smoothed_truth
    thr = change_map(case.threshold, plate)
    ref = np.abs(st).sum(axis=2)
    changed = (ref > thr) | (np.abs(sc).sum(axis=2) > thr)
    changed = cv2.dilate(changed.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    region = case.masks["ground"] & (changed | case.masks["contact"])
    diff = sc - st
    err = np.abs(diff).sum(axis=2)
    signed = diff.sum(axis=2)
    den = float(ref[region].sum())
    k = np.ones((2 * EDGE_PX + 1, 2 * EDGE_PX + 1), np.uint8)
    s8 = shadow.astype(np.uint8)
    edge = (cv2.dilate(s8, k) > 0) & ~(cv2.erode(s8, k) > 0)
    contact = case.masks["contact"]
    masks = {
        "contact": contact,
        "edge": edge & ~contact,
        "umbra": shadow & ~edge & ~contact,
        "outside": ~shadow & ~edge & ~contact,
    }
    out = {}
    for name, m in masks.items():
        r = region & m
        out[name] = round(float(err[r].sum()) / den, 3)
        out[f"{name}_signed"] = round(float(signed[r].sum()) / den, 3)
    out["ground"] = round(float(err[region].sum()) / den, 3)
    return out, signed, region


def write_png(path: Path, signed: np.ndarray, region: np.ndarray, shadow: np.ndarray, contact: np.ndarray, scale):
    """The signed map as a colour image: red = composite too bright, blue = too dark (full at +-scale)."""
    t = np.clip(signed / scale, -1.0, 1.0)
    img = np.full(signed.shape + (3,), 255.0)
    img[..., 0] -= 255.0 * np.clip(t, 0, 1)  # B reduced where too bright -> red
    img[..., 1] -= 255.0 * np.abs(t)
    img[..., 2] -= 255.0 * np.clip(-t, 0, 1)  # R reduced where too dark -> blue
    img[~region] = img[~region] * 0.85
    c8 = contact.astype(np.uint8)
    img[(cv2.dilate(c8, np.ones((3, 3), np.uint8)) > 0) & ~(c8 > 0)] = (128, 128, 128)
    s8 = shadow.astype(np.uint8)
    img[(cv2.dilate(s8, np.ones((3, 3), np.uint8)) > 0) & ~(s8 > 0)] = (0, 160, 0)
    img = cv2.resize(img.astype(np.uint8), None, fx=3, fy=3, interpolation=cv2.INTER_NEAREST)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", action="append", choices=("own", "heldout", "plain"), help="default: own and heldout")
    ap.add_argument("--pipeline", action="append", choices=("measured", "measured_pose", "true_dir", "oracle"))
    ap.add_argument("--only", action="append", help="case name(s)")
    ap.add_argument("--opt", action="append", default=[], help="scene key=value (JSON value)")
    ap.add_argument("--png", help="folder for the signed difference maps")
    ap.add_argument("--out")
    args = ap.parse_args()
    import json

    from arshadow.bench.reference import load_cases, measure_light
    from arshadow.errors import EstimateError

    opts = {}
    for kv in args.opt:
        k, v = kv.split("=", 1)
        try:
            opts[k] = json.loads(v)
        except json.JSONDecodeError:
            opts[k] = v
    pipelines = args.pipeline or ["measured", "measured_pose", "true_dir", "oracle"]
    result: dict = {"meta": _common.metadata(), "opts": opts, "cases": {}, "median": {}}
    for name in args.set or ["own", "heldout"]:
        rows: dict = {p: [] for p in pipelines}
        for case in load_cases(ROOT / "tests" / "data" / "reference" / name):
            if args.only and case.scene.name not in args.only:
                continue
            try:
                est = measure_light(case.plate8, case.scene)
            except EstimateError as e:  # the estimate refuses (the trust fixes): no measured pipeline for this case
                result["cases"][f"{name}/{case.scene.name}"] = {"refused": str(e)}
                print(case.scene.name, "refused:", e, file=sys.stderr, flush=True)
                continue
            shadow = hard_shadow(case)
            entry = {"ratio_est": [round(float(v), 3) for v in est.shadow_ratio]}
            entry["ratio_true"] = [round(float(v), 3) for v in true_ratio(case.scene)]
            scale = float(np.abs(case.smoothed_truth).sum(axis=2).max()) / 8.0
            for p in pipelines:
                parts, signed, region = split(case, composite(case, est, p, opts), shadow)
                entry[p] = parts
                rows[p].append(parts)
                if args.png:
                    write_png(
                        Path(args.png) / f"{case.scene.name}_{p}.png",
                        signed,
                        region,
                        shadow,
                        case.masks["contact"],
                        scale,
                    )
            result["cases"][f"{name}/{case.scene.name}"] = entry
            print(case.scene.name, json.dumps(entry), file=sys.stderr, flush=True)
        result["median"][name] = {
            p: {k: round(float(np.median([r[k] for r in rs])), 3) for k in rs[0]} for p, rs in rows.items() if rs
        }
    _common.emit(result, args.out)


if __name__ == "__main__":
    main()
