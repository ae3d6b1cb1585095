"""Real footage (the real-footage work): video tracking against stock OpenCV on the shared clips of the ArUco library.

The clips, their intrinsics and stock OpenCV's per-frame detections (``detections.csv``: OpenCV 5's
``ArucoDetector`` with default parameters on the decoded colour frames) live in ``../shared/realvideo``
(or ``$ARSHADOW_REALVIDEO``); the tests skip, saying why, when the folder is absent. Ground truth is
OpenCV's detection list and the geometry of the rigid printed sheets, never arshadow's own output.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
from realvideo_clips import CLIPS, angle, jumps, literal_jumps, rot, stock_detections, stock_rotations

from arshadow.cli import main
from arshadow.tracking.board import load_board

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def realvideo() -> Path:
    """``../shared/realvideo`` (or ``$ARSHADOW_REALVIDEO``); skips, saying why, when it is absent."""
    p = Path(os.environ.get("ARSHADOW_REALVIDEO", ROOT.parent / "shared" / "realvideo"))
    if not (p / CLIPS["single"][0] / "detections.csv").is_file():
        pytest.skip(f"real video clips not found at {p} (set ARSHADOW_REALVIDEO)")
    return p


def run_video(tmp_path, folder: Path, video: str, *tracker_args) -> tuple[list, str]:
    """``arshadow video`` on a clip (a small box, one light): (frames report records, stderr)."""
    out = tmp_path / "out"
    argv = [
        "video",
        str(folder / video),
        "--calib",
        str(folder / "intrinsics.yml"),
        *tracker_args,
        "--model",
        "box:0.01,0.01,0.01",
        "--light",
        "point:0.1,0.1,0.5",
        "--contact-sheet",
        "0",
        "--quiet",
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    with open(next(out.glob("*.frames.jsonl"))) as fh:
        return [json.loads(line) for line in fh], ""


def jitter(rots) -> float:
    """Median distance (deg) of each rotation from the geodesic midpoint of its two neighbours."""
    d = []
    for i in range(1, len(rots) - 1):
        p, c, n = rots[i - 1], rots[i], rots[i + 1]
        if p is None or c is None or n is None:
            continue
        half = cv2.Rodrigues(0.5 * cv2.Rodrigues(np.ascontiguousarray(p.T @ n))[0])[0]
        d.append(angle(c, p @ half))
    return float(np.median(d))


@pytest.mark.gl
@pytest.mark.realvideo
@pytest.mark.parametrize("refine", ["default", "apriltag"])
@pytest.mark.parametrize("clip", sorted(CLIPS))
def test_target_marker_tracked_where_opencv_sees_it(realvideo, tmp_path, clip, refine):
    """The target marker is ``ok`` in >= 95 % of the frames where stock OpenCV detects it; reprojection
    stays sub-pixel-ish; no smoothed pose spikes; smoothing lowers the frame-to-frame jitter."""
    name, video, mid, length = CLIPS[clip]
    folder = realvideo / name
    args = ["--marker-length", str(length), "--dictionary", "DICT_ARUCO_ORIGINAL", "--marker-id", str(mid)]
    if refine != "default":
        args += ["--corner-refine", refine]
    recs, _ = run_video(tmp_path, folder, video, *args)
    stock = stock_detections(folder)
    seen = [r for r in recs if mid in stock[r["frame"]]]
    ok = [r for r in seen if r["status"] == "ok"]
    assert len(ok) >= 0.95 * len(seen), (
        f"{len(ok)} of {len(seen)} frames; missed "
        f"{[(r['frame'], r.get('not_tracked')) for r in seen if r['status'] != 'ok']}"
    )
    errs = [r["reprojection_error_px"] for r in recs if r["status"] == "ok"]
    assert np.median(errs) < 1.0
    smooth = [None if r["rvec"] is None or r["status"] != "ok" else rot(r["rvec"]) for r in recs]
    raw = [None if r["raw"] is None else rot(r["raw"]["rvec"]) for r in recs]
    assert jumps(smooth) == []
    assert jitter(smooth) < jitter(raw)
    # every frame not tracked says why (the tracker's reason)
    assert all(r.get("not_tracked") for r in recs if r["status"] != "ok" and r["frame"] > 1)


@pytest.mark.gl
@pytest.mark.realvideo
def test_fast_turns_of_the_5fps_clip_are_the_sheets_motion(realvideo, tmp_path):
    """Where the smoothed pose of the 5-fps clip's marker turns more than 5 deg from both neighbours (the
    issue's literal jump test), the printed sheet really turns that fast: its other markers, posed
    independently by stock OpenCV, turn by more than 5 deg too (their median) from the previous and to the
    next frame, and the tracked pose turns no more than they do (+ 1.5 deg). A spike (a wrong pose) would
    be alone in it. Measured: the smoothed pose turns 6.0 deg where the sheet turns ~8 (smoothing lags)."""
    name, video, mid, length = CLIPS["single"]
    folder = realvideo / name
    args = ["--marker-length", str(length), "--dictionary", "DICT_ARUCO_ORIGINAL", "--marker-id", str(mid)]
    recs, _ = run_video(tmp_path, folder, video, *args)
    smooth = [None if r["rvec"] is None or r["status"] != "ok" else rot(r["rvec"]) for r in recs]
    stock = stock_rotations(folder, video, length)
    fast = literal_jumps(smooth)
    print("frames turning > 5 deg from both neighbours:", fast)
    for i in fast:
        for j in (i - 1, i + 1):
            ours = angle(smooth[i], smooth[j])
            others = [angle(stock[i][k], stock[j][k]) for k in stock[i].keys() & stock[j].keys() if k != mid]
            assert len(others) >= 3, f"frame {i}: too few other markers to compare"
            sheet = float(np.median(others))
            assert sheet > 5.0, (i, j, ours, others)  # the sheet itself turned more than 5 deg
            assert ours < sheet + 1.5, (i, j, ours, others)  # and the pose no more (no overshoot, no spike)


@pytest.mark.gl
@pytest.mark.realvideo
def test_chessboard_clip_as_generic_board(realvideo, tmp_path):
    """The ArUco library's own layout file as a generic board: a pose in >= 95 % of the frames where stock
    OpenCV finds >= 4 markers, whole-board reprojection median <= 2 px (stock OpenCV: 1.71 px)."""
    name, video, _, _ = CLIPS["chessboard"]
    folder = realvideo / name
    board = load_board(folder / "chessboardinfo_meters.yml")
    assert board.kind == "markers" and board.n_markers == 18 and board.dictionary == "DICT_ARUCO_ORIGINAL"
    recs, _ = run_video(tmp_path, folder, video, "--board", str(folder / "chessboardinfo_meters.yml"))
    stock = stock_detections(folder)
    seen = [r for r in recs if len(stock[r["frame"]]) >= 4]
    ok = [r for r in seen if r["status"] == "ok"]
    assert len(ok) >= 0.95 * len(seen)
    assert np.median([r["reprojection_error_px"] for r in ok]) <= 2.0


@pytest.mark.gl
@pytest.mark.realvideo
def test_stderr_summary_and_reasons(realvideo, tmp_path, capsys):
    """Per video on stderr: tracked / held / lost and the longest gap (checked against the frames report)."""
    name, video, mid, length = CLIPS["single"]
    folder = realvideo / name
    out = tmp_path / "o"
    assert (
        main(
            [
                "video",
                str(folder / video),
                "--calib",
                str(folder / "intrinsics.yml"),
                "--marker-length",
                str(length),
                "--dictionary",
                "DICT_ARUCO_ORIGINAL",
                "--marker-id",
                str(mid),
                "--max-frames",
                "40",
                "--model",
                "box:0.01,0.01,0.01",
                "--light",
                "point:0.1,0.1,0.5",
                "--contact-sheet",
                "0",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    with open(next(out.glob("*.frames.jsonl"))) as fh:
        recs = [json.loads(line) for line in fh]
    st = [r["status"] for r in recs]
    longest, run = 0, 0
    for s in st:
        run = 0 if s == "ok" else run + 1
        longest = max(longest, run)
    assert (
        f"tracked {st.count('ok')}, held {st.count('held')}, lost {st.count('no_marker')} of {len(st)} frames; "
        f"longest gap {longest} frames"
    ) in err
