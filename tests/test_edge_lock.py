"""A video's edge-fit space decided once per marker (arshadow.tracking.edgelock).

The ``edge`` refinement checks on every frame whether the blur acted in code values or in linear light; a
video's trackers share an :class:`EdgeSpaceLock` that skips the check for a marker after
:data:`LOCK_FRAMES` frames in a row found the code values right. The truth here is the refinement without
the lock (the same frames, a tracker of its own), and the blur's space the generating one.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from conftest import ROOT
from test_edge_refine import linear_light_photo

from arshadow.camera.model import Intrinsics
from arshadow.synth.markers import look_at_pose, render_marker_photo
from arshadow.tracking.edgelock import LOCK_FRAMES, EdgeSpaceLock
from arshadow.tracking.refine import refine_edges
from arshadow.tracking.tracker import MarkerTracker

CAM = Intrinsics.from_file(ROOT / "calib" / "synth_1280x720.yml").scaled(640, 360)
L = 0.05
N = LOCK_FRAMES + 3


def poses(n):
    """A short orbit: the camera ``n`` frames along an arc, looking at the marker."""
    return [look_at_pose([0.06 + 0.01 * k, -0.18, 0.3], [0.0, 0.0, 0.0]) for k in range(n)]


def code_frames(n):
    """Frames blurred in code values (arshadow.synth's blur), with noise."""
    return [render_marker_photo(CAM, p, marker_length=L, blur_sigma=0.9, noise_sigma=2.0, seed=k).image
            for k, p in enumerate(poses(n))]  # fmt: skip


def track(frames, lock):
    """The reference marker's corners per frame (n, 4, 2) and the lock's state after each frame."""
    tracker = MarkerTracker(CAM, marker_length=L, refine="edge", edge_lock=lock)
    out, states = [], []
    for f in frames:
        out.append(tracker.estimate(f).all_corners[0])
        states.append(tracker.state())
    return np.array(out), states


def test_a_code_blurred_video_locks_after_lock_frames_with_the_same_corners():
    frames = code_frames(N)
    for f in frames:  # the premise: each frame's own check finds the code values right (weight 0)
        gray = cv2.cvtColor(f, cv2.COLOR_BGR2GRAY)
        start = MarkerTracker(CAM, marker_length=L, refine="none").detect(f).corners
        assert refine_edges(gray, start, CAM).linear_weight[0] == 0.0
    plain, _ = track(frames, None)
    locked, states = track(frames, EdgeSpaceLock())
    assert np.array_equal(locked, plain)  # bit for bit: the same code-value fit
    assert [s["edge_code"] for s in states] == [[]] * (LOCK_FRAMES - 1) + [[0]] * (N - LOCK_FRAMES + 1)
    assert states[LOCK_FRAMES - 2]["edge_runs"] == {"0": LOCK_FRAMES - 1}


def test_a_linear_blurred_video_is_never_locked_and_keeps_its_corners():
    frames = [linear_light_photo(CAM, p, 0, 1.0, seed=k) for k, p in enumerate(poses(N))]
    plain, _ = track(frames, None)
    locked, states = track(frames, EdgeSpaceLock())
    assert np.array_equal(locked, plain)
    assert all(s["edge_code"] == [] for s in states)
    assert states[-1]["edge_runs"] == {}  # each frame's check found the bias: no run under way


def test_a_locked_marker_takes_the_code_fit_without_the_check():
    """The lock decides: a marker locked on code-blurred frames keeps the code-value fit on a frame blurred
    in linear light, where the check would interpolate towards the linear fit (why it is tracker state)."""
    lock = EdgeSpaceLock(frames=1)
    tracker = MarkerTracker(CAM, marker_length=L, refine="edge", edge_lock=lock)
    tracker.estimate(code_frames(1)[0])
    assert lock.spaces([0]) == ["code"]
    frame = linear_light_photo(CAM, poses(1)[0], 0, 1.2)
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    start = MarkerTracker(CAM, marker_length=L, refine="none").detect(frame).corners
    code, auto = refine_edges(gray, start, CAM, space="code"), refine_edges(gray, start, CAM)
    assert auto.linear_weight[0] > 0.5
    got = tracker.estimate(frame).all_corners[0]
    assert np.allclose(got, code.corners[0], atol=1e-9)
    assert np.abs(got - auto.corners[0]).max() > 0.1


def test_a_video_session_shares_one_lock_reset_per_video_and_a_photo_session_has_none():
    import arshadow

    scene = {"calib": str(ROOT / "calib" / "synth_640x360.yml"), "marker_length": L, "model": "box:0.02,0.02,0.03",
             "lights": ["point:0.1,0.1,0.4"]}  # fmt: skip
    with arshadow.Session(scene) as photo_session:
        fast, full = photo_session.hooks.calibration(640, 360).trackers()
        assert full.edge_lock is None and (fast is None or fast.edge_lock is None)
    with arshadow.Session({**scene, "track_roi": True}) as s:
        for f in code_frames(LOCK_FRAMES):
            s.track(f)
        fast, full = s.hooks.calibration(640, 360).trackers()
        assert full.edge_lock is not None and (fast is None or fast.edge_lock is full.edge_lock)
        assert s.hooks.tracker_state(640, 360)[-1]["edge_code"] == [0]
        s.hooks.reset_tracking()
        assert s.hooks.tracker_state(640, 360)[-1]["edge_code"] == []


def test_refine_edges_takes_one_space_per_marker_and_says_what_is_wrong():
    frame = code_frames(1)[0]
    gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    start = MarkerTracker(CAM, marker_length=L, refine="none").detect(frame).corners
    two = np.concatenate([start, start])
    res = refine_edges(gray, two, CAM, space=["code", "linear"])
    assert np.array_equal(res.corners[0], refine_edges(gray, start, CAM, space="code").corners[0])
    assert np.array_equal(res.corners[1], refine_edges(gray, start, CAM, space="linear").corners[0])
    for bad in (["code"], ["code", "cod"], "lin"):
        with pytest.raises(ValueError, match="space must be one of"):
            refine_edges(gray, two, CAM, space=bad)
