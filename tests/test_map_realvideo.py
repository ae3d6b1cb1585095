"""Marker maps on real footage (the marker-map work): the six-marker sheet of the ArUco library's webcam clip.

Truth here is the sheet's rigidity and stock OpenCV (its detections in ``detections.csv`` and its own
per-marker IPPE poses), never arshadow's output. Skipped, saying why, when ``../shared/realvideo`` (or
``$ARSHADOW_REALVIDEO``) is absent.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import TOL
from realvideo_clips import CLIPS, angle, jumps, literal_jumps, rot, stock_detections, stock_rotations

from arshadow.camera.model import Intrinsics
from arshadow.cli import main
from arshadow.tracking.mapio import observe_inputs
from arshadow.tracking.mapping import Observations, learn_map

SHEET = (101, 601, 701, 801, 901, 1001)
DICT = "DICT_ARUCO_ORIGINAL"


@pytest.fixture(scope="module")
def clip(realvideo_dir):
    folder = realvideo_dir / CLIPS["single"][0]
    intr = Intrinsics.from_file(folder / "intrinsics.yml")
    return folder, intr, observe_inputs([folder / "video.avi"], intr, dictionary=DICT)


@pytest.fixture(scope="module")
def realvideo_dir():
    import os
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    p = Path(os.environ.get("ARSHADOW_REALVIDEO", root.parent / "shared" / "realvideo"))
    if not (p / CLIPS["single"][0] / "detections.csv").is_file():
        pytest.skip(f"real video clips not found at {p} (set ARSHADOW_REALVIDEO)")
    return p


def centre_distances(mmap) -> dict:
    c = {i: mmap.corners[i].mean(axis=0) for i in mmap.corners}
    return {(a, b): float(np.linalg.norm(c[a] - c[b])) for a in c for b in c if a < b}


def part(obs: Observations, lo: int, hi: int) -> Observations:
    k = (obs.frame >= lo) & (obs.frame < hi)
    return Observations(obs.frame[k] - lo, obs.ids[k], obs.corners[k], hi - lo, obs.image_size)


@pytest.mark.realvideo
def test_sheet_map_is_rigid(clip):
    """All six markers mapped. The maps learned from the clip's two halves (disjoint frames) agree within
    1 mm on every distance between the four markers of the sheet's flat part; the whole clip's 701-901
    distance lies where stock OpenCV's per-frame distances do (0.0759 m +- 1.6 mm).

    The sheet is not rigid everywhere: the paper lies loose on the clipboard, and in the second half the
    hand holds and lifts its edge under markers 101 and 601 (frame 110 shows the lifted edge). The pairs
    with 101 or 601 differ between the halves by up to 2.5 mm (601-1001; measured: 0.1-2.5 mm), the six
    pairs of the flat part by at most 0.75 mm. Those pairs are printed, not judged: a rigid map cannot
    follow paper that bends.
    """
    _, intr, obs = clip
    full = learn_map(obs, intr, 0.05, dictionary=DICT)
    assert sorted(full.corners) == list(SHEET) and full.reference_id == 101
    print(full.summary(), {i: round(v, 2) for i, v in full.rms_px.items()})
    half = obs.n_frames // 2
    a = centre_distances(learn_map(part(obs, 0, half), intr, 0.05, dictionary=DICT))
    b = centre_distances(learn_map(part(obs, half, obs.n_frames), intr, 0.05, dictionary=DICT))
    diff = {k: abs(a[k] - b[k]) for k in a}
    print("halves, distance differences (mm):", {k: round(1e3 * v, 2) for k, v in diff.items()})
    flat = {k: v for k, v in diff.items() if not set(k) & {101, 601}}
    assert len(flat) == 6 and max(flat.values()) <= TOL.map_real_rigid_mm * 1e-3
    d = centre_distances(full)[(701, 901)]
    assert abs(d - 0.0759) < 0.0016, d
    assert full.rms_total_px < 1.5


@pytest.mark.gl
@pytest.mark.realvideo
def test_video_with_map_tracks_every_frame_with_a_sheet_marker(realvideo_dir, tmp_path):
    """``video --map auto``: every frame where stock OpenCV detects any marker of the sheet is tracked, at
    least 10 of them without the reference marker; no spike; where the pose turns more than 5 deg from
    both neighbours, the sheet's markers seen in both frames (posed alone by stock OpenCV) turn as much
    (measured: frames 90, 94, 140-141, the sheet turning 4.5-19 deg, the pose within 1 deg of it)."""
    name, video, _, length = CLIPS["single"]
    folder = realvideo_dir / name
    out = tmp_path / "out"
    argv = ["video", str(folder / video), "--calib", str(folder / "intrinsics.yml"), "--dictionary", DICT]
    argv += ["--marker-length", str(length), "--map", "auto", "--model", "box:0.01,0.01,0.01"]
    argv += ["--light", "point:0.1,0.1,0.5", "--contact-sheet", "0", "--quiet", "-o", str(out)]
    assert main(argv) == 0
    with open(next(out.glob("*.frames.jsonl"))) as fh:
        recs = [json.loads(line) for line in fh]
    stock = stock_detections(folder)
    seen = [r for r in recs if stock[r["frame"]] & set(SHEET)]
    missed = [(r["frame"], r["status"]) for r in seen if r["status"] != "ok"]
    assert not missed, missed
    assert sum(1 for r in seen if 101 not in r["marker_ids"]) >= 10  # tracked without the reference
    smooth = [None if r["rvec"] is None or r["status"] != "ok" else rot(r["rvec"]) for r in recs]
    assert jumps(smooth) == []
    rots = stock_rotations(folder, video, length)
    for i in literal_jumps(smooth):
        for j in (i - 1, i + 1):
            others = [angle(rots[i][k], rots[j][k]) for k in rots[i].keys() & rots[j].keys()]
            if others:  # (motion-blurred frames: stock OpenCV may see no marker in both; jumps() judged them)
                assert angle(smooth[i], smooth[j]) < float(np.median(others)) + 1.5, (i, j, others)


@pytest.mark.realvideo
def test_chessboard_clip_map_matches_the_printed_layout(realvideo_dir):
    """The 18 markers of the chessboard clip, learned from the footage alone, against the ArUco library's
    layout file of the printed board (independent truth): every centre-to-centre distance within 1.5 mm,
    their median within 0.5 mm (measured: 0.23 mm median, 0.81 mm worst)."""
    from arshadow.tracking.board import load_board

    name, video, _, length = CLIPS["chessboard"]
    folder = realvideo_dir / name
    intr = Intrinsics.from_file(folder / "intrinsics.yml")
    mmap = learn_map(observe_inputs([folder / video], intr, dictionary=DICT), intr, length, dictionary=DICT)
    layout = load_board(folder / "chessboardinfo_meters.yml").markers
    assert sorted(mmap.corners) == sorted(layout)
    ours, truth = centre_distances(mmap), {}
    c = {i: layout[i].mean(axis=0) for i in layout}
    truth = {(a, b): float(np.linalg.norm(c[a] - c[b])) for a in c for b in c if a < b}
    err = np.array([abs(ours[k] - truth[k]) for k in truth]) * 1e3
    print(f"{mmap.summary()}; centre distances vs layout: median {np.median(err):.2f} mm, max {err.max():.2f} mm")
    assert np.median(err) <= TOL.map_layout_median_mm and err.max() <= TOL.map_layout_max_mm
