"""The exposure / white-balance match on the default render path (the light estimate).

Truth: :func:`arshadow.synth.lit.render_lit_photo` records the lit paper as ``paper_linear`` = the camera's
gains x the paper's reflectance x (ambient + direct sin(elevation)), from its own parameters (never from
the measurement). A white (255) virtual box lit like the paper must come out with that linear RGB.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from arshadow.camera.model import Intrinsics
from arshadow.compose.composite import SRGB_TO_LINEAR
from arshadow.frame.session import Session
from arshadow.scene.spec import scene_from_dict
from arshadow.synth.lit import light_vector, render_lit_photo
from arshadow.synth.markers import look_at_pose

CALIB = "calib/synth_1280x720.yml"
pytestmark = pytest.mark.gl
LIGHT = light_vector(-60, 40)  # on the camera's side: no specular highlight on the top face
EYE, TARGET = [0.2, -0.3, 0.45], [0.0, 0.0, 0.0]
BOX, PLACE = (0.04, 0.04, 0.03), (-0.1, 0.0, 0.0)


@pytest.fixture(scope="module")
def cam():
    return Intrinsics.from_file(CALIB)


def _spec(**kw):
    d = {
        "calib": CALIB,
        "marker_length": 0.05,
        "model": "box:{:g},{:g},{:g}".format(*BOX),
        "place": ",".join(map(str, PLACE)),
        "color": "255,255,255",
        "lights": ["directional:{:.6f},{:.6f},{:.6f}".format(*LIGHT)],
    }
    d.update(kw)
    return scene_from_dict(d)


def _top_face_linear(image, cam, pose) -> np.ndarray:
    """Median linear RGB over the central half of the virtual box's top face (analytic projection)."""
    hx, hy = BOX[0] / 4, BOX[1] / 4
    quad = np.array(
        [[PLACE[0] + sx * hx, PLACE[1] + sy * hy, BOX[2]] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    )
    uv = cam.project(quad, pose)
    m = np.zeros(image.shape[:2], np.uint8)
    cv2.fillConvexPoly(m, np.rint(uv).astype(np.int32), 1)
    lin = SRGB_TO_LINEAR[image[m > 0]][:, ::-1]
    assert len(lin) > 50
    return np.median(lin, axis=0)


@pytest.mark.parametrize("compose", ["cpu", "gpu"])
def test_white_box_top_face_matches_the_paper(cam, compose):
    """Both compose paths (numpy, shader) apply the gain (the outline's anti-aliasing off: with it a frame
    takes the numpy path)."""
    pose = look_at_pose(EYE, TARGET)
    p = render_lit_photo(
        cam,
        pose,
        light=LIGHT,
        probe="box:0.05,0.05,0.1",
        probe_place=(0.1, 0.05, 0.0),
        exposure=0.55,
        white_balance=(1.15, 1.0, 0.8),
        noise_sigma=1.0,
        seed=5,
        supersample=1,
    )
    with Session(_spec(compose=compose, outline_aa="off")) as s:
        res = s.process(p.image, name="lit")
    assert res.item.compose == compose
    top = _top_face_linear(res.composite, cam, pose)
    assert np.all(np.abs(top / p.paper_linear - 1) <= 0.05), (top, p.paper_linear)
    rep = res.item.to_dict()["exposure"]
    assert np.allclose(rep["paper_rgb"], p.paper_linear, rtol=0.03)
    assert len(rep["gain"]) == 3 and rep["shading"] == pytest.approx(0.25 + LIGHT[2], rel=1e-6)
    # switched off: the renderer's own shading, far from the paper under this exposure / white balance
    with Session(_spec(no_exposure=True)) as s:
        off = s.process(p.image, name="lit")
    assert off.item.to_dict().get("exposure") is None
    assert np.max(np.abs(_top_face_linear(off.composite, cam, pose) / p.paper_linear - 1)) > 0.2


def test_video_follows_an_exposure_step(cam):
    """A video session (``track_roi``): the smoothed paper is steady, then follows a step in exposure."""
    pose = look_at_pose(EYE, TARGET)
    shots = [
        render_lit_photo(
            cam,
            pose,
            light=LIGHT,
            probe="box:0.05,0.05,0.1",
            probe_place=(0.1, 0.05, 0.0),
            exposure=e,
            noise_sigma=1.0,
            seed=i,
            supersample=1,
        )
        for i, e in enumerate((0.45, 0.8))
    ]
    frames = [shots[0]] * 4 + [shots[1]] * 5
    with Session(_spec(track_roi=True)) as s:
        reps = [s.process(f.image.copy(), name=str(i)).item.to_dict()["exposure"] for i, f in enumerate(frames)]
    smooth = np.array([r["smoothed_paper_rgb"] for r in reps])
    assert np.allclose(smooth[:4], shots[0].paper_linear, rtol=0.03)
    assert np.allclose(smooth[6:], shots[1].paper_linear, rtol=0.03)  # followed within 2 frames of the step
    gains = np.array([r["gain"] for r in reps])
    assert np.allclose(gains[-1] / gains[0], shots[1].paper_linear / shots[0].paper_linear, rtol=0.04)


def test_a_hidden_marker_is_not_measured(cam):
    """The paper is measured only where the marker's white cells outshine its black ones: on a frame where
    the marker is hidden (the floor where the pose says it is), a measurement would be the floor's."""
    from arshadow.estimate.exposure import MIN_PAPER_CONTRAST, ExposureError, measure_exposure

    pose = look_at_pose(EYE, TARGET)
    p = render_lit_photo(cam, pose, light=LIGHT, exposure=0.55, noise_sigma=1.0, seed=3, supersample=1)
    ok = measure_exposure(p.image, cam, pose, 0.05, "DICT_6X6_250", 0)
    assert ok.contrast > 10 * MIN_PAPER_CONTRAST
    floor = p.image.copy()
    floor[:] = np.median(p.image.reshape(-1, 3), axis=0).astype(np.uint8)  # the marker covered
    with pytest.raises(ExposureError, match="not brighter than its black ones"):
        measure_exposure(floor, cam, pose, 0.05, "DICT_6X6_250", 0)
