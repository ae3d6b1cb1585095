"""Benchmark: precision and recall of each pose flag against the truth (the cluster and flags work).

Run (a few minutes; prints the table docs/tracking.md keeps, and writes every measurement as JSON Lines):

    python tests/benchmarks/bench_flags.py [--photos 600] [--seed 31] [--jsonl flags.jsonl] [--json out.json]

Photos come from :func:`arshadow.synth.render_marker_photo` (the generating pose is the truth) over a sweep
of: marker side 15-150 px (log-uniform, through the distance), tilt 0-75 deg, blur sigma 0-3 px, noise
sigma 0-4, JPEG quality 50-95 or none (half the photos), a grey patch over 15-40 % of the marker in one
photo of eight, at 1280x720 with mild barrel distortion. The bundled sample video
(``samples/video/orbit.mp4``, its truth in ``orbit.json``) is measured the same way, frame by frame.

A pose is **bad** when its rotation is more than 1 deg or its position more than 2 % of the distance from
the truth. For each flag (its measurement against a threshold) the table gives, over the photos with a
pose: precision (the share of flagged poses that are bad) and recall (the share of bad poses flagged), at
several thresholds; the shipped thresholds are those of :mod:`arshadow.tracking.quality`.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _common  # noqa: E402

from arshadow.camera.model import Intrinsics  # noqa: E402
from arshadow.errors import MarkerNotFoundError  # noqa: E402
from arshadow.synth.markers import look_at_pose, render_marker_photo  # noqa: E402
from arshadow.tracking import quality  # noqa: E402
from arshadow.tracking.tracker import MarkerTracker  # noqa: E402
from arshadow.transforms import rotation_error_deg  # noqa: E402

L = 0.05  # marker side, metres
BAD_ROT_DEG = 1.0
BAD_TRANS_SHARE = 0.02

#: candidate thresholds per flag: (measurement key, flagged when measurement >= / > threshold)
CANDIDATES = {
    "ambiguous": ("ratio", [0.3, 0.5, 0.7, 0.85, 0.95]),
    "blurred corners": ("instability", [0.008, 0.015, 0.03, 0.05, 0.08]),
    "marker partly covered": ("occlusion", [0.3, 0.4, 0.5, 0.6]),
    "small marker": ("neg_side", [-32.0, -25.0, -20.0, -16.0]),
    "reprojection": ("reproj_share", [1.0, 2.0, 4.0]),
}


def intrinsics() -> Intrinsics:
    """The sweep's camera: 1280x720, fx = fy = 1000, mild barrel distortion."""
    return Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720, np.array([-0.05, 0.02, 0.0, 0.0, 0.0]))


def sweep_case(r: np.random.Generator, intr: Intrinsics) -> tuple[np.ndarray, np.ndarray, dict]:
    """One random photo: ``(image (720, 1280, 3) uint8, true cam_from_world (4, 4), conditions)``."""
    side = float(np.exp(r.uniform(np.log(15.0), np.log(150.0))))
    d = intr.fx * L / side
    tilt = np.radians(r.uniform(0.0, 75.0))
    az = r.uniform(0, 2 * np.pi)
    target = np.r_[r.uniform(-0.3, 0.3, 2) * L, 0.0]
    eye = target + d * np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
    up = (np.cos(az + 1.0), np.sin(az + 1.0), 0.0) if tilt < np.radians(2.0) else (0, 0, 1)
    pose = look_at_pose(eye, target, up=up)
    blur = float(r.choice([0.0, r.uniform(0.3, 3.0)], p=[0.25, 0.75]))
    noise = float(r.uniform(0.0, 4.0))
    jpeg = int(r.integers(50, 96)) if r.random() < 0.5 else None
    img = render_marker_photo(
        intr,
        pose,
        marker_length=L,
        blur_sigma=blur,
        noise_sigma=noise,
        jpeg_quality=jpeg,
        seed=int(r.integers(1 << 30)),
    ).image
    covered = r.random() < 0.125
    if covered:
        h = L / 2
        q = intr.project(np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]]), pose)
        k = int(r.integers(4))
        f = float(np.sqrt(r.uniform(0.15, 0.4)))
        c0, c1, c3 = q[k], q[(k + 1) % 4], q[(k + 3) % 4]
        poly = np.array([c0, c0 + f * (c1 - c0), c0 + f * (c1 - c0) + f * (c3 - c0), c0 + f * (c3 - c0)])
        img = img.copy()
        cv2.fillConvexPoly(img, np.round(poly * 16).astype(np.int32), (110, 120, 115), cv2.LINE_AA, 4)
    cond = {"side_px": side, "tilt_deg": float(np.degrees(tilt)), "blur": blur, "noise": noise, "jpeg": jpeg}
    cond["covered"] = bool(covered)
    return img, pose, cond


def measure(pose, truth: np.ndarray) -> dict:
    """The flag measurements of a tracked pose and its error against ``truth`` (4, 4) cam_from_world."""
    q = np.asarray(pose.corners, np.float64)[:4]
    side = float(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).min())
    lim = quality.reprojection_limit_px(pose.corners)
    t_true = truth[:3, 3]
    c_true = -truth[:3, :3].T @ t_true
    c_est = -pose.cam_from_world[:3, :3].T @ pose.cam_from_world[:3, 3]
    rot = float(rotation_error_deg(pose.cam_from_world, truth))
    trans = float(np.linalg.norm(c_est - c_true) / np.linalg.norm(c_true))
    return {
        "ratio": None if pose.pose_ambiguity is None else float(pose.pose_ambiguity),
        "instability": pose.corner_instability,
        "occlusion": pose.border_occlusion,
        "side": side,
        "neg_side": -side,
        "reproj_px": float(pose.reprojection_error_px),
        "reproj_share": float(pose.reprojection_error_px) / lim,
        "rot_deg": rot,
        "trans_share": trans,
        "bad": bool(rot > BAD_ROT_DEG or trans > BAD_TRANS_SHARE),
        "flag_reasons": [r.split(":", 1)[0] for r in quality.all_reasons(pose)],  # flags and report fields
        "flagged": bool(pose.flagged),
    }


def orbit_rows() -> list[dict]:
    """Every frame of the bundled sample video, measured against ``orbit.json``'s truth."""
    from arshadow.video.avio import AvReader

    meta = json.loads((ROOT / "samples/video/orbit.json").read_text())
    intr = Intrinsics.from_file(ROOT / meta["calib"])
    # the refinement arshadow video uses by default
    tracker = MarkerTracker(intr, dictionary=meta["dictionary"], marker_length=meta["marker_length"], refine="edge")
    truths = np.asarray(meta["cam_from_world"], np.float64)
    rows = []
    reader = AvReader(str(ROOT / "samples/video" / meta["video"]))
    try:
        for k, fr in enumerate(reader):
            try:
                pose = tracker.estimate(fr.image)
            except MarkerNotFoundError:
                continue
            rows.append({"source": "orbit", "frame": k, **measure(pose, truths[k])})
    finally:
        reader.close()
    return rows


def _chordal_mean(rots) -> np.ndarray:
    u, _, vt = np.linalg.svd(np.sum(rots, axis=0))
    r = u @ vt
    return r if np.linalg.det(r) > 0 else u @ np.diag([1, 1, -1]) @ vt


def sheet_rows(folder: Path, refine: str, ref: int = 101) -> list[dict]:
    """The shared six-marker clip (``aruco_single_paroj``): marker ``ref``'s pose in every frame against the
    consensus of the other markers of the rigid sheet (truth without a generating pose).

    The sheet's layout (each marker's pose in ``ref``'s frame) is the chordal mean / median over the
    frames where both are found; a frame's consensus for ``ref`` is the medoid of the other markers'
    predictions (at least 3 of them, so one flipped marker cannot carry it). The consensus is itself
    noisy: its spread (median rotation distance of the predictions from the medoid) is reported per row.
    """
    from arshadow.video.avio import AvReader

    intr = Intrinsics.from_file(folder / "intrinsics.yml")
    ids = (101, 601, 701, 801, 901, 1001)
    trackers = {
        i: MarkerTracker(intr, dictionary="DICT_ARUCO_ORIGINAL", marker_length=0.05, marker_id=i, refine=refine)
        for i in ids
    }
    frames = []
    for fr in AvReader(str(folder / "video.avi")):
        poses = {}
        for i, t in trackers.items():
            try:
                poses[i] = t.estimate(fr.image)
            except MarkerNotFoundError:
                pass
        frames.append(poses)
    layout = {}
    for k in ids:
        if k == ref:
            continue
        rel = [np.linalg.inv(f[ref].cam_from_world) @ f[k].cam_from_world for f in frames if ref in f and k in f]
        if len(rel) < 10:
            continue
        m = np.eye(4)
        m[:3, :3] = _chordal_mean(np.array([r[:3, :3] for r in rel]))
        m[:3, 3] = np.median([r[:3, 3] for r in rel], axis=0)
        layout[k] = m
    rows = []
    for n, f in enumerate(frames):
        if ref not in f:
            continue
        preds = [f[k].cam_from_world @ np.linalg.inv(layout[k]) for k in layout if k in f]
        if len(preds) < 3:
            continue
        d = np.array([[rotation_error_deg(a, b) for b in preds] for a in preds])
        med = int(np.argmin(d.sum(axis=1)))
        row = {"source": "sheet", "refine": refine, "frame": n, **measure(f[ref], preds[med])}
        row["consensus_spread_deg"] = float(np.median(np.delete(d[med], med)))
        rows.append(row)
    return rows


def table(rows: list[dict]) -> list[dict]:
    """Precision and recall per flag and candidate threshold over ``rows`` (those with a pose)."""
    out = []
    bad = np.array([r["bad"] for r in rows])
    for name, (key, thresholds) in CANDIDATES.items():
        vals = np.array([np.nan if r[key] is None else r[key] for r in rows], np.float64)
        for t in thresholds:
            flagged = (
                np.nan_to_num(vals, nan=-np.inf) >= t if name == "ambiguous" else np.nan_to_num(vals, nan=-np.inf) > t
            )
            n_f = int(flagged.sum())
            out.append(
                {
                    "flag": name,
                    "threshold": abs(t),
                    "flagged": n_f,
                    "precision": round(float((flagged & bad).sum() / n_f), 3) if n_f else None,
                    "recall": round(float((flagged & bad).sum() / bad.sum()), 3) if bad.any() else None,
                }
            )
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--photos", type=int, default=600)
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--jsonl", help="write every photo's measurements here")
    ap.add_argument("--json", help="write the result JSON here")
    ap.add_argument("--refine", default="subpix,edge", help="corner refinements (render's default, video's)")
    ap.add_argument("--realvideo", help="the shared real clips' folder: also measure the six-marker sheet")
    ap.add_argument("--no-orbit", action="store_true", help="skip the sample video")
    a = ap.parse_args(argv)
    intr = intrinsics()
    trackers = {m: MarkerTracker(intr, marker_length=L, refine=m) for m in a.refine.split(",")}
    r = np.random.default_rng(a.seed)
    rows, missed = [], dict.fromkeys(trackers, 0)
    for i in range(a.photos):
        img, truth, cond = sweep_case(r, intr)
        for m, tracker in trackers.items():
            try:
                pose = tracker.estimate(img)
            except MarkerNotFoundError:
                missed[m] += 1
                continue
            rows.append({"source": "sweep", "refine": m, "photo": i, **cond, **measure(pose, truth)})
    orbit = [] if a.no_orbit else orbit_rows()
    sheet = []
    if a.realvideo:
        for m in trackers:
            sheet += sheet_rows(Path(a.realvideo) / "aruco_single_paroj", m)
    if a.jsonl:
        Path(a.jsonl).write_text("".join(json.dumps(x) + "\n" for x in rows + orbit + sheet))
    res = {
        "meta": _common.metadata(),
        "photos": a.photos,
        "not_detected": missed,
        "with_pose": {m: sum(x["refine"] == m for x in rows) for m in trackers},
        "bad": {m: int(sum(x["bad"] for x in rows if x["refine"] == m)) for m in trackers},
        "sweep": {m: table([x for x in rows if x["refine"] == m]) for m in trackers},
        "sheet": {
            m: {
                "frames": sum(x["refine"] == m for x in sheet),
                "bad": int(sum(x["bad"] for x in sheet if x["refine"] == m)),
                "consensus_spread_deg_median": float(np.median([x["consensus_spread_deg"] for x in sheet]))
                if sheet
                else None,
                "table": table([x for x in sheet if x["refine"] == m]),
            }
            for m in (trackers if sheet else ())
        },
        "orbit": {
            "frames": len(orbit),
            "bad": int(sum(x["bad"] for x in orbit)),
            "flagged_now": int(sum(x["flagged"] for x in orbit)),
            "table": table(orbit) if orbit else [],
        },
    }
    print("| refine | flag | threshold | flagged | precision | recall |\n|---|---|---|---|---|---|", file=sys.stderr)
    for m, tab in res["sweep"].items():
        for t in tab:
            print(
                f"| {m} | {t['flag']} | {t['threshold']:g} | {t['flagged']} | {t['precision']} | {t['recall']} |",
                file=sys.stderr,
            )
    _common.emit(res, a.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
