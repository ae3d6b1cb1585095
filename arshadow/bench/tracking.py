"""Section 3: tracking time against pose error (synthetic photos with a known generating pose).

Every configuration but one is a scene (:func:`arshadow.scene.scene_from_dict`) tracked by
:meth:`arshadow.Session.track`, as ``arshadow render`` / ``video`` and the Python API track: the fast
half-resolution pass first (:mod:`arshadow.tracking.fastdetect`), the full search if it finds nothing.

- corner refinement methods (``arshadow.tracking.detect.REFINE_METHODS``, scene key ``refine``);
- the fast pass against the full search only (``fast_detect`` off), and the full search without the LM
  pose polish (``MarkerTracker(pnp_refine=False)``: a tracker keyword, not a scene option);
- full frame against the video tracker's region of interest (``track_roi``: the marker is searched in a
  window around its last detection, :mod:`arshadow.tracking.roi_track`; here the warm-up call's detection
  on the same photo);
- single marker against a grid board (5 x 7 markers, calib/gridboard_5x7.yml);
- real footage (the real-footage work): the shared webcam clips of the ArUco library (``../shared/realvideo`` or
  ``$ARSHADOW_REALVIDEO``; skipped when absent), tracked as ``arshadow video`` tracks (the Y plane, the
  colour frame's grey on a miss, the window around the last marker): frames with the target marker
  ``detected`` against the frames where stock OpenCV detects it (their ``detections.csv``), time per frame;
  no true pose, so no pose error (the reprojection error instead).

Photos: :func:`arshadow.synth.render_marker_photo` with the acceptance conditions of the tracking acceptance tests (marker
5-10 % of the image width, 0.3-0.8 m, tilt 0-70 deg, noise sigma 2, blur sigma 0.6, JPEG 90).
Per photo the time is the median of ``repeat`` runs after a warm-up, configurations interleaved.
"""

from __future__ import annotations

import csv
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..camera.model import Intrinsics
from ..errors import MarkerNotFoundError
from ..frame.session import Session
from ..scene.spec import scene_from_dict
from ..synth.markers import random_pose, render_marker_photo
from ..tracking.board import load_board
from ..tracking.detect import REFINE_METHODS
from ..tracking.dictionary import marker_object_points
from ..tracking.tracker import MarkerTracker
from ..transforms import rotation_error_deg
from .common import ROOT

DIST = np.array([-0.045, 0.021, 0.0004, -0.0003, -0.006])


def camera(w: int, h: int) -> Intrinsics:
    """A camera with the horizontal field of view of calib/synth_1280x720.yml (f = 0.78 W)."""
    f = 1000.0 * w / 1280.0
    return Intrinsics(f, f, w / 2.0 + 1.3 * w / 1280, h / 2.0 - 1.8 * w / 1280, w, h, DIST)


def make_photos(cam: Intrinsics, n: int, seed: int) -> list:
    """``n`` single-marker photos under the issue-2 conditions."""
    rng = np.random.default_rng(seed)
    photos = []
    for i in range(n):
        d = rng.uniform(0.3, 0.8)
        frac = rng.uniform(0.05, 0.10)
        L = frac * cam.width * d / cam.fx
        pose = random_pose(rng, cam, distance=(d, d), tilt_deg=(0, 70), keep_in_view=marker_object_points(1.6 * L))
        photos.append(
            render_marker_photo(
                cam,
                pose,
                marker_length=L,
                marker_id=int(rng.integers(250)),
                noise_sigma=2.0,
                blur_sigma=0.6,
                jpeg_quality=90,
                seed=seed * 1000 + i,
            )
        )
    return photos


def _errors(pose: Any, truth: np.ndarray, distance: float) -> tuple[float, float]:
    return (
        rotation_error_deg(pose.cam_from_world[:3, :3], truth[:3, :3]),
        float(np.linalg.norm(pose.cam_from_world[:3, 3] - truth[:3, 3]) / distance),
    )


def session(
    cam: Intrinsics,
    *,
    marker_length: float | None = None,
    marker_id: int | None = None,
    board: Any = None,
    **options: Any,
) -> Session:
    """An :class:`arshadow.Session` that tracks ``cam``'s photos (scene keys ``options``: ``refine``,
    ``fast_detect``, ``track_roi``...; the model and light are placeholders: tracking draws nothing)."""
    d = {"calib": cam, "model": "box:0.02,0.02,0.02", "lights": ["point:0,0,1"], **options}
    d.update({"board": str(board)} if board is not None else {"marker_length": marker_length, "marker_id": marker_id})
    return Session(scene_from_dict(d))


def run_configs(photos: list, configs: dict, repeat: int) -> list[dict]:
    """Every configuration on the same photos, timings interleaved round-robin. ``configs``: label ->
    ``make(photo) -> (tracker, image)``, the tracker an :class:`arshadow.Session` (``track``) or a
    :class:`arshadow.tracking.tracker.MarkerTracker` (``estimate``). One row per configuration: time median /
    IQR over photos, rotation error (deg) median / p95, translation error (% of distance) median, detections."""
    acc: dict[str, dict[str, Any]] = {c: dict(times=[], rot=[], trans=[], found=0) for c in configs}
    for ph in photos:
        jobs, poses, opened = {}, {}, []
        for c, make in configs.items():
            tr, img = make(ph)
            opened.append(tr)
            est = getattr(tr, "track", None) or tr.estimate
            try:
                poses[c] = est(img)  # warm-up, and the result
                jobs[c] = (est, img)
            except MarkerNotFoundError:
                pass
        t: dict[str, list[float]] = {c: [] for c in jobs}
        for _ in range(repeat):
            for c, (est, img) in jobs.items():
                t0 = time.perf_counter()
                est(img)
                t[c].append((time.perf_counter() - t0) * 1e3)
        for tr in opened:
            if hasattr(tr, "close"):
                tr.close()
        dist = float(np.linalg.norm(ph.cam_from_world[:3, 3]))
        for c, pose in poses.items():
            a = acc[c]
            a["times"].append(np.median(t[c]))
            a["found"] += 1
            r, tr_ = _errors(pose, ph.cam_from_world, dist)
            a["rot"].append(r)
            a["trans"].append(100 * tr_)
    rows = []
    for c, a in acc.items():
        tm, rot, trn = (np.asarray(a[k], float) for k in ("times", "rot", "trans"))
        q = lambda x, p: float(np.percentile(x, p)) if x.size else None  # noqa: E731
        rows.append(
            {
                "config": c,
                "photos": len(photos),
                "detected": a["found"],
                "time_ms": q(tm, 50),
                "time_q25": q(tm, 25),
                "time_q75": q(tm, 75),
                "rot_deg_median": q(rot, 50),
                "rot_deg_p95": q(rot, 95),
                "trans_pct_median": q(trn, 50),
            }
        )
    return rows


def refinement_and_roi(cfg: dict, log: Callable[[str], None]) -> list[dict]:
    rows = []
    for w, h in cfg["track_resolutions"]:
        cam = camera(w, h)
        photos = make_photos(cam, cfg["poses"], seed=w)

        def mk(**kw: Any) -> Callable[[Any], tuple[Any, np.ndarray]]:
            return lambda ph: (
                session(ph.intrinsics, marker_length=ph.marker_length, marker_id=ph.marker_id, **kw),
                ph.image,
            )

        configs = {f"refine {m}, full frame": mk(refine=m) for m in REFINE_METHODS}
        configs["refine subpix, full search only (fast_detect off)"] = mk(refine="subpix", fast_detect=False)
        configs["refine subpix, full search only, no LM polish"] = lambda ph: (
            MarkerTracker(
                ph.intrinsics, marker_length=ph.marker_length, marker_id=ph.marker_id, refine="subpix", pnp_refine=False
            ),
            ph.image,
        )
        configs["refine subpix, ROI window (track_roi)"] = mk(refine="subpix", track_roi=True)
        for r in run_configs(photos, configs, cfg["repeat"]):
            rows.append({"resolution": f"{w}x{h}", **r})
        log(f"  tracking: {w}x{h} done")
    return rows


def marker_vs_board(cfg: dict, log: Callable[[str], None]) -> list[dict]:
    """A 5 cm single marker against the 5 x 7 grid board at the same camera poses (1280x720)."""
    board_file = ROOT / "calib" / "gridboard_5x7.yml"
    board = load_board(board_file)
    cam = camera(1280, 720)
    rng = np.random.default_rng(11)
    corners = np.concatenate(list(board.marker_corners_world.values()))
    centre = corners.mean(axis=0)
    single, boards = [], []
    for i in range(cfg["poses"]):
        pose = random_pose(rng, cam, distance=(0.6, 1.0), tilt_deg=(0, 60), keep_in_view=corners, target=centre)
        boards.append(
            render_marker_photo(cam, pose, board=board, noise_sigma=2.0, blur_sigma=0.6, jpeg_quality=90, seed=500 + i)
        )
        # the single marker at the board's centre, same camera position
        shift = np.eye(4)
        shift[:3, 3] = centre
        single.append(
            render_marker_photo(
                cam, pose @ shift, marker_length=0.05, noise_sigma=2.0, blur_sigma=0.6, jpeg_quality=90, seed=500 + i
            )
        )
    rows = run_configs(
        single,
        {"single 5 cm marker": lambda ph: (session(cam, marker_length=0.05, marker_id=ph.marker_id), ph.image)},
        cfg["repeat"],
    )
    rows += run_configs(
        boards, {"grid board 5x7 (35 markers)": lambda ph: (session(cam, board=board_file), ph.image)}, cfg["repeat"]
    )
    log("  tracking: marker vs board done")
    return [{"resolution": "1280x720", **r} for r in rows]


#: real clips (the real-footage work): folder, video, target id, marker side (m)
REAL_CLIPS = (("aruco_chessboard_paroj", "chessboard.avi", 32, 0.034), ("aruco_single_paroj", "video.avi", 101, 0.05))


def realvideo_dir() -> Path:
    """``$ARSHADOW_REALVIDEO`` or ``../shared/realvideo`` next to the checkout."""
    return Path(os.environ.get("ARSHADOW_REALVIDEO", ROOT.parent / "shared" / "realvideo"))


def track_clip(session: Any, path: Path | str, max_frames: int | None = None) -> list[tuple[Any, float]]:
    """Per frame of a video: ``(pose or None, ms)``, tracked as the video engine tracks (the Y plane; on a
    miss the colour frame's grey; the session's ``track_roi`` window)."""
    from ..errors import MarkerNotFoundError
    from ..video.avio import AvReader
    from ..video.framejob import gray_of

    out = []
    with AvReader(path, max_frames=max_frames, raw=True) as reader:
        for fr in reader:
            t0 = time.perf_counter()
            pose = None
            for colour in (False, True):
                if colour and getattr(fr, "format", "") != "yuv420p":
                    break
                try:
                    pose = session.track(gray_of(fr, reader.height, colour=colour))
                    break
                except MarkerNotFoundError:
                    pass
            out.append((pose, (time.perf_counter() - t0) * 1e3))
    return out


def real_footage(cfg: dict, log: Callable[[str], None]) -> list[dict]:
    """One row per shared real clip and refinement (the video default edge, apriltag): target marker found in the frames
    where stock OpenCV finds it; time per frame; reprojection error (no true pose)."""
    from ..camera.model import Intrinsics

    base = realvideo_dir()
    if not (base / REAL_CLIPS[0][0] / "detections.csv").is_file():
        log(f"  tracking: real footage skipped (no clips at {base}; set ARSHADOW_REALVIDEO)")
        return []
    rows = []
    for folder, video, mid, length in REAL_CLIPS:
        d = base / folder
        with open(d / "detections.csv") as fh:
            stock = {int(r["frame"]): mid in set(map(int, r["ids"].split())) for r in csv.DictReader(fh)}
        cam = Intrinsics.from_file(d / "intrinsics.yml")
        n = 30 if cfg.get("quick") else None
        for refine in ("edge", "apriltag"):  # the video command's default, and AprilTag
            s = session(
                cam,
                marker_length=length,
                marker_id=mid,
                dictionary="DICT_ARUCO_ORIGINAL",
                refine=refine,
                track_roi=True,
            )
            res = track_clip(s, d / video, n)
            s.close()
            seen = [k for k in range(len(res)) if stock.get(k)]
            ms = np.asarray([t for _, t in res])
            err = [p.reprojection_error_px for p, _ in res if p is not None]
            rows.append(
                {
                    "resolution": "real 640x480",
                    "config": f"real {folder} id {mid}, refine {refine}",
                    "photos": len(seen),
                    "detected": sum(res[k][0] is not None for k in seen),
                    "time_ms": float(np.median(ms)),
                    "time_q25": float(np.percentile(ms, 25)),
                    "time_q75": float(np.percentile(ms, 75)),
                    "rot_deg_median": None,
                    "rot_deg_p95": None,
                    "trans_pct_median": None,
                    "reprojection_px_median": float(np.median(err)) if err else None,
                }
            )
        log(f"  tracking: real footage {folder} done")
    return rows


def run(cfg: dict, log: Callable[[str], None]) -> list[dict]:
    return refinement_and_roi(cfg, log) + marker_vs_board(cfg, log) + real_footage(cfg, log)
