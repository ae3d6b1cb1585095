"""Marker maps (the marker-map work): what learning a map and tracking against it cost, and how accurate each mode is.

    python tests/benchmarks/bench_map.py [--repeat 3] [--frames 80] [--json out.json]

Figures (each the median of ``--repeat`` runs, with the load average in ``meta``):

* ``learn_ms_per_100``: ``arshadow map``'s work (decode, detect every frame, pose graph, bundle adjustment)
  per 100 frames at 640 x 480, on the synthetic clip of tests/map_scene.py and, when ``../shared/realvideo``
  is present, on its six-marker clip (145 frames); split into ``observe`` (decode + detect) and ``learn``.
* ``track_ms``: the video engine's tracking per frame (:func:`arshadow.frame.hooks.estimate_pose`: fast pass,
  tracking window for one marker, full search fallback) for one marker (the reference, ``--marker-id``), the
  learned map (a generic board), and their ratio.
* ``rot_err_deg``: median camera rotation error against the generating poses, one marker vs the map.

Pin it to two cores for the issue's figures: ``taskset -c 0,1 python tests/benchmarks/bench_map.py``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import _common  # noqa: E402
from map_scene import LENGTH, make_scene, write_frames  # noqa: E402

from arshadow.camera.model import Intrinsics  # noqa: E402
from arshadow.errors import MarkerNotFoundError  # noqa: E402
from arshadow.frame.hooks import CalibrationState, estimate_pose  # noqa: E402
from arshadow.frame.report import StageTimings  # noqa: E402
from arshadow.tracking.mapio import observe_inputs  # noqa: E402
from arshadow.tracking.mapping import learn_map  # noqa: E402
from arshadow.transforms import rotation_error_deg  # noqa: E402

REAL = Path(os.environ.get("ARSHADOW_REALVIDEO", _common.ROOT.parent / "shared" / "realvideo")) / "aruco_single_paroj"


def learn_cost(inputs, intr, length, dictionary, repeat):
    """(observe ms, learn ms, CPU ms of both (all threads), frames, map): medians of ``repeat`` runs."""
    obs_t, learn_t, cpu = [], [], []
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        obs = observe_inputs(inputs, intr, dictionary=dictionary)
        t1 = time.perf_counter()
        mmap = learn_map(obs, intr, length, dictionary=dictionary)
        t2 = time.perf_counter()
        obs_t.append(1e3 * (t1 - t0))
        learn_t.append(1e3 * (t2 - t1))
        cpu.append(1e3 * (time.process_time() - c0))
    return float(np.median(obs_t)), float(np.median(learn_t)), float(np.median(cpu)), obs.n_frames, mmap


def track_cost(frames, intr, kwargs, roi, repeat):
    """Median ms per frame of the engine's tracking, and the poses (None where nothing was found)."""
    per = []
    for _ in range(repeat):
        cal = CalibrationState(intr, False, None, dict(kwargs), roi, True)
        poses = []
        t0 = time.perf_counter()
        for g in frames:
            try:
                poses.append(estimate_pose(cal, g, StageTimings())[0])
            except MarkerNotFoundError:
                poses.append(None)
        per.append(1e3 * (time.perf_counter() - t0) / len(frames))
    return float(np.median(per)), poses


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--frames", type=int, default=80)
    ap.add_argument("--json", help="also write the result here")
    a = ap.parse_args()
    res = {"meta": _common.metadata()}
    sc = make_scene(a.frames)
    intr = sc["intrinsics"]
    with tempfile.TemporaryDirectory() as tmp:
        paths = write_frames(sc["frames"], tmp)
        o, m_ms, cpu, n, mmap = learn_cost(paths, intr, LENGTH, "DICT_6X6_250", a.repeat)
    res["synthetic_learn"] = {
        "frames": n,
        "observe_ms": o,
        "learn_ms": m_ms,
        "learn_ms_per_100": 100.0 * (o + m_ms) / n,
        "cpu_ms_per_100": 100.0 * cpu / n,
        "map_rms_px": mmap.rms_total_px,
    }
    grey = [cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) for f in sc["frames"]]
    single_kw = {"marker_length": LENGTH, "marker_id": 3, "refine": "edge"}
    t_single, p_single = track_cost(grey, intr, single_kw, True, a.repeat)
    t_map, p_map = track_cost(grey, intr, {"board": mmap.board(), "refine": "edge"}, False, a.repeat)
    truth = [c @ sc["world_from_marker"][3] for c in sc["cam_from_world"]]
    both = [k for k in range(len(grey)) if p_single[k] is not None and p_map[k] is not None]

    def err(p):
        return float(np.median([rotation_error_deg(p[k].cam_from_world[:3, :3], truth[k][:3, :3]) for k in both]))

    res["synthetic_track"] = {
        "single_ms": t_single,
        "map_ms": t_map,
        "ratio": t_map / t_single,
        "frames_tracked_single": sum(p is not None for p in p_single),
        "frames_tracked_map": sum(p is not None for p in p_map),
        "rot_err_deg_single": err(p_single),
        "rot_err_deg_map": err(p_map),
    }
    if (REAL / "video.avi").is_file():
        ri = Intrinsics.from_file(REAL / "intrinsics.yml")
        o, m_ms, cpu, n, rmap = learn_cost([REAL / "video.avi"], ri, 0.05, "DICT_ARUCO_ORIGINAL", a.repeat)
        res["real_learn"] = {
            "frames": n,
            "observe_ms": o,
            "learn_ms": m_ms,
            "learn_ms_per_100": 100.0 * (o + m_ms) / n,
            "cpu_ms_per_100": 100.0 * cpu / n,
            "map_rms_px": rmap.rms_total_px,
        }
        cap, frames = cv2.VideoCapture(str(REAL / "video.avi")), []
        while True:
            ok, f = cap.read()
            if not ok:
                break
            frames.append(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY))
        kw = {"marker_length": 0.05, "marker_id": 101, "refine": "edge", "dictionary": "DICT_ARUCO_ORIGINAL"}
        t_single, p_single = track_cost(frames, ri, kw, True, a.repeat)
        t_map, p_map = track_cost(frames, ri, {"board": rmap.board(), "refine": "edge"}, False, a.repeat)
        res["real_track"] = {
            "single_ms": t_single,
            "map_ms": t_map,
            "ratio": t_map / t_single,
            "frames_tracked_single": sum(p is not None for p in p_single),
            "frames_tracked_map": sum(p is not None for p in p_map),
        }
    _common.emit(res, a.json)


if __name__ == "__main__":
    main()
