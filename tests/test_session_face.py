"""Session's public face is what a user calls (the layout work): the video engine's hooks are on
``session.hooks``; poses are typed (``MarkerPose`` in and out, ``cam_from_marker`` matrices)."""

from __future__ import annotations

import numpy as np
from video_clips import ROOT

SCENE = {
    "calib": str(ROOT / "calib" / "synth_640x360.yml"),
    "marker_length": 0.05,
    "model": "box:0.04,0.04,0.06",
    "lights": ["point:0.1,0.1,0.4"],
}
#: what a user calls (and the scene it holds); nothing of the video engine's
PUBLIC = {
    "spec", "scene", "options", "geometry", "ground", "hooks", "context", "renderer", "intrinsics", "notes",
    "close", "track", "plan", "render", "process", "ground_camera", "state", "restore",
    "set_lights", "set_time", "use_sun_tracks", "sun_tracks", "time_lapse", "set_model", "camera_effects",
}  # fmt: skip
HOOKS = (
    "calibration", "tracker_state", "reset_tracking", "compose_key", "compose_chooser", "exposure",
    "exposure_region", "observe_exposure", "exposure_gap", "render", "camera_effects", "measured_camera",
)  # fmt: skip


def test_the_engine_hooks_are_off_the_public_face():
    import arshadow
    from arshadow.frame.hooks import EngineHooks

    with arshadow.Session(SCENE) as s:
        assert {n for n in dir(s) if not n.startswith("_")} == PUBLIC
        assert isinstance(s.hooks, EngineHooks) and all(hasattr(s.hooks, n) for n in HOOKS)


def test_track_returns_a_marker_pose_that_plan_takes_as_its_matrix():
    """``track`` returns a MarkerPose; ``plan`` takes it or its ``cam_from_marker`` matrix alike, and the
    plan's ``cam_from_world`` (the ground frame: here the marker's) is the generating pose (the truth)."""
    import arshadow
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo
    from arshadow.tracking.pose import MarkerPose

    intr = Intrinsics.from_file(SCENE["calib"])
    truth = look_at_pose([0.1, -0.3, 0.35], [0.0, 0.0, 0.0])
    photo = render_marker_photo(intr, truth, marker_length=0.05, noise_sigma=0.0).image
    with arshadow.Session(SCENE) as s:
        pose = s.track(photo)
        assert isinstance(pose, MarkerPose)
        a = s.plan(pose, intr.width, intr.height)
        b = s.plan(pose.cam_from_world, intr.width, intr.height)
    assert np.array_equal(a.cam_from_world, b.cam_from_world)
    assert np.linalg.norm(a.cam_from_world[:3, 3] - truth[:3, 3]) < 0.01 * np.linalg.norm(truth[:3, 3])
