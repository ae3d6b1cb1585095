"""A ground that is not the marker plane (the sanity gates): ``--ground wall:H`` / ``plane:...``.

- the pure math (:mod:`arshadow.geometry.ground`): parsing, the frame's axes against a hand-built one,
  rigidity, the refusals (camera below the plane, plane seen edge-on);
- a synthetic photo of a marker hanging on a wall (known truth: the true pose is composed in the ground
  frame, the photo rendered at ``cam_from_marker``): the shadow on the floor against the independent
  per-pixel oracle (tests/image_oracle.py: analytic projection of the mesh triangles) at the TRUE
  ``cam_from_ground`` -- with the true pose handed in (IoU >= 0.99) and with the pose estimated from the
  photo; the same photo with the marker plane as ground gives another shadow (the ground matters);
- the planner in the ground frame: a camera that frames the wall marker but not the floor culls
  everything (nothing rendered), where the marker-plane ground puts the object in view;
- a real ChArUco photo treated as a board on a wall (its bottom edge on the floor).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from image_oracle import ShadowOracle, iou

from arshadow.errors import UsageError
from arshadow.geometry.ground import check_camera_above, ground_frame, parse_ground
from arshadow.transforms import invert_rigid

W, H = 960, 720
WALL_H = 0.25  # the marker's centre above the floor (m)
MARKER = 0.12


def _wall_frame(h):
    """marker_from_ground of ``wall:h`` built by hand from the module's definition: x along the marker's
    x, z = the marker's +y (up the wall), y = z x x = the marker's -z (into the wall), origin below the
    marker's centre."""
    m = np.eye(4)
    m[:3, 0] = [1, 0, 0]
    m[:3, 1] = [0, 0, -1]
    m[:3, 2] = [0, 1, 0]
    m[:3, 3] = [0, -h, 0]
    return m


# ------------------------------------------------------------------------------------------------ pure
def test_parse_and_frames():
    assert parse_ground(None).is_marker and parse_ground("marker").is_marker and parse_ground(" ").is_marker
    np.testing.assert_array_equal(parse_ground("marker").marker_from_ground, np.eye(4))
    g = parse_ground("wall:0.25")
    assert g.text == "wall:0.25" and not g.is_marker
    np.testing.assert_allclose(g.marker_from_ground, _wall_frame(0.25), atol=1e-15)
    assert parse_ground("wall:0.25") == parse_ground("WALL: 0.250")  # normalised text
    # a plane parallel to the marker keeps its axes (translated along the normal)
    m = parse_ground("plane:0,0,-0.02,0,0,3").marker_from_ground
    np.testing.assert_allclose(m[:3, :3], np.eye(3), atol=1e-15)
    np.testing.assert_allclose(m[:3, 3], [0, 0, -0.02])
    # any plane: rigid, z = the unit normal, origin on the plane, x along the marker's x where it can be
    rng = np.random.default_rng(5)
    for _ in range(200):
        p, n = rng.normal(size=3), rng.normal(size=3)
        m = ground_frame(p, n)
        r = m[:3, :3]
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert abs(np.linalg.det(r) - 1.0) < 1e-12
        np.testing.assert_allclose(r[:, 2], n / np.linalg.norm(n), atol=1e-12)
        np.testing.assert_allclose(m[:3, 3], p)
        xp = np.array([1.0, 0, 0]) - n[0] / (n @ n) * n  # the marker's x projected onto the plane
        if np.linalg.norm(xp) > 0.2:
            np.testing.assert_allclose(r[:, 0], xp / np.linalg.norm(xp), atol=1e-12)
    # marker's x along the normal: the marker's y gives the frame
    m = ground_frame((0, 0, 0), (1, 0, 0))
    np.testing.assert_allclose(m[:3, 1], [0, 1, 0], atol=1e-15)


@pytest.mark.parametrize(
    "bad, match",
    [
        ("floor", "choose marker, wall:H or plane"),
        ("wall:", "expected 1"),
        ("wall:0", "must be > 0"),
        ("wall:-0.3", "must be > 0"),
        ("wall:nan", "finite"),
        ("plane:0,0,0,0,0", "expected 6"),
        ("plane:0,0,0,0,0,0", "must not be zero"),
        ("plane:a,0,0,0,0,1", "numbers"),
    ],
)
def test_bad_specs_are_refused(bad, match):
    with pytest.raises(UsageError, match=match):
        parse_ground(bad)


def test_scene_spec_and_options_carry_the_ground():
    from arshadow.scene.spec import RenderOptions, scene_from_dict

    d = {"calib": "c.yml", "marker_length": 0.05, "model": "box:0.1,0.1,0.1", "lights": ["point:0,0,1"]}
    assert scene_from_dict(d).options.ground == "marker"
    assert scene_from_dict({**d, "ground": "WALL:0.50"}).options.ground == "wall:0.5"
    with pytest.raises(UsageError, match="--ground"):
        scene_from_dict({**d, "ground": "ceiling"})
    with pytest.raises(UsageError, match="--ground"):
        RenderOptions(ground="plane:1,2,3").check()


def test_a_ground_in_millimetres_warns():
    from arshadow.geometry.ground import ground_warnings

    assert ground_warnings("marker") == [] and ground_warnings("wall:1.2") == []
    assert ground_warnings("plane:0,0,-2,0,0,1") == []
    (msg,) = ground_warnings("wall:300")
    assert "300 m from the marker" in msg and "wall:0.3" in msg
    (msg,) = ground_warnings("plane:0,0,-45,0,0,1")
    assert "45 m from the marker; lengths are metres" in msg


def test_loading_a_scene_warns_once(caplog):
    from pathlib import Path

    from arshadow.scene.spec import scene_from_dict

    calib = Path(__file__).resolve().parents[1] / "calib" / "synth_1280x720.yml"
    d = {"calib": calib, "marker_length": 0.05, "model": "box:0.1,0.1,0.1", "lights": ["point:0,0,1"]}
    with caplog.at_level("WARNING"):
        scene_from_dict({**d, "ground": "wall:0.3"}).build()
    assert "--ground" not in caplog.text
    with caplog.at_level("WARNING"):
        scene_from_dict({**d, "ground": "wall:300"}).build()
    assert caplog.text.count("--ground wall:300: the ground is 300 m") == 1


def test_command_line_option():
    import argparse

    from arshadow.cli.render import add_scene_options
    from arshadow.scene.spec import scene_from_args

    p = argparse.ArgumentParser()
    add_scene_options(p)
    base = ["--calib", "c.yml", "--marker-length", "0.05", "--model", "box:0.1,0.1,0.1", "--light", "point:0,0,1"]
    assert scene_from_args(p.parse_args(base)).options.ground == "marker"
    assert scene_from_args(p.parse_args(base + ["--ground", "wall:0.4"])).options.ground == "wall:0.4"
    with pytest.raises(UsageError, match="--ground 'wall:x'"):
        scene_from_args(p.parse_args(base + ["--ground", "wall:x"]))


def test_camera_below_or_edge_on_is_refused():
    from arshadow.synth.markers import look_at_pose

    mfg = _wall_frame(WALL_H)
    gfm = invert_rigid(mfg)
    # a camera above the floor, looking at the wall: fine
    check_camera_above(look_at_pose([0.1, -0.6, 0.45], [0, 0, 0.2]), "wall:0.25")
    # the same photo with the floor 1 m below the marker: the camera (0.2 m above the marker's centre)
    # is above it too; with a "floor" 0.5 m ABOVE the marker (normal down: plane through y=+0.5,
    # normal -y), the camera is below it
    cam_from_marker = look_at_pose([0.1, -0.6, 0.45], [0, 0, 0.2]) @ gfm
    check_camera_above(cam_from_marker @ parse_ground("wall:1").marker_from_ground)
    with pytest.raises(UsageError, match="below that ground plane"):
        check_camera_above(cam_from_marker @ ground_frame((0, 0.5, 0), (0, 1, 0)), "plane:0,0.5,0,0,1,0")
    with pytest.raises(UsageError, match="below that ground plane"):  # normal pointing away from the camera
        check_camera_above(cam_from_marker @ ground_frame((0, -0.25, 0), (0, -1, 0)))
    # edge-on: the camera 5 mm above a floor 2 m away
    with pytest.raises(UsageError, match="edge-on"):
        check_camera_above(look_at_pose([0.0, -2.0, 0.005], [0, 0, 0.2]))


# ------------------------------------------------------------------------------------------------ GL
POSES = [
    ([0.1, -0.6, 0.45], [-0.05, -0.1, 0.15]),
    ([-0.15, -0.55, 0.5], [-0.05, -0.1, 0.15]),
    ([0.25, -0.55, 0.4], [-0.05, -0.1, 0.15]),
]


def _scene():
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.lights.spec import parse_light

    intr = Intrinsics(900.0, 900.0, 479.5, 359.5, W, H, np.zeros(0))
    # on the floor in front of the wall (y < 0), lit from the right: the shadow falls to the left
    caster = load_occluder("box:0.08,0.06,0.1", place=(0.0, -0.15, 0.0))
    lights = [parse_light("point:0.3,-0.3,0.35")]
    return intr, caster, lights


def _session(ctx, intr, caster, lights, ground, tracker=None, **opts):
    from arshadow.frame.session import Session
    from arshadow.scene.spec import RenderOptions, Scene

    scene = Scene(intr, caster, lights, RenderOptions(ground=ground, **opts), tracker or {"marker_length": MARKER})
    return Session(scene, context=ctx)


@pytest.mark.gl
def test_wall_marker_shadow_on_the_floor(ctx, tol):
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    intr, caster, lights = _scene()
    mfg = _wall_frame(WALL_H)  # the truth, built independently of arshadow.geometry.ground
    known, general, tracked, control = [], [], [], []
    with (
        _session(ctx, intr, caster, lights, f"wall:{WALL_H}") as comp,
        _session(ctx, intr, caster, lights, f"wall:{WALL_H}", plan="general") as ref_path,
        _session(ctx, intr, caster, lights, "marker") as plain,
    ):
        for i, (eye, target) in enumerate(POSES):
            cam_from_ground = look_at_pose(eye, target)  # the true camera, in the ground frame
            cam_from_marker = cam_from_ground @ invert_rigid(mfg)
            ph = render_marker_photo(
                intr, cam_from_marker, marker_length=MARKER, noise_sigma=2.0, blur_sigma=0.6, jpeg_quality=90, seed=i
            )
            oracle = ShadowOracle(
                intr.K, cam_from_ground, caster.vertices, caster.faces, [(lt.homogeneous, lt.weight) for lt in lights]
            )
            ref = oracle.image(W, H)[0] >= 0.5
            assert ref.sum() > 5000, ref.sum()
            res = comp.render(ph.image, cam_from_marker)
            assert res.item.ground == f"wall:{WALL_H:g}"
            # the report keeps the marker's pose, the result the ground frame's camera
            np.testing.assert_allclose(res.item.tvec, cam_from_marker[:3, 3], atol=1e-9)
            np.testing.assert_allclose(res.cam_from_world, cam_from_ground, atol=1e-9)
            known.append(iou(res.mask >= 128, ref))
            assert res.item.mode == "planar"  # the planar fast path (convex box, light above it), ground frame
            res = ref_path.render(ph.image, cam_from_marker)  # the reference: z-fail volumes, no shortcuts
            assert res.item.mode == "zfail"
            general.append(iou(res.mask >= 128, ref))
            res = comp.process(ph.image, f"wall{i}")
            mask, item = res.mask, res.item
            assert item.status == "ok" and item.marker_ids == [0]
            # the report keeps the MARKER's pose (rvec/tvec world=marker -> camera)
            t_marker = np.asarray(item.tvec)
            np.testing.assert_allclose(t_marker, cam_from_marker[:3, 3], atol=0.01)
            tracked.append(iou(mask >= 128, ref))
            control.append(iou(plain.process(ph.image, f"plain{i}").mask >= 128, ref))
    print(
        f"\nwall marker IoUs: known pose {np.round(known, 4).tolist()} (general plan "
        f"{np.round(general, 4).tolist()}), tracked {np.round(tracked, 4).tolist()}, "
        f"marker plane as ground {np.round(control, 4).tolist()}"
    )
    assert min(known) >= 0.99 and min(general) >= 0.99, (known, general)
    assert np.median(tracked) >= tol.end_to_end_iou_median, tracked
    assert max(control) < 0.2, control


@pytest.mark.gl
def test_planner_culls_in_the_ground_frame(ctx):
    """A camera level with the marker frames the wall; the floor and the shadow are below the view (the
    top of the box just enters it): the light is culled (its footprint is outside the canvas), and the
    oracle agrees that no shadow pixel is in view. With the marker plane as ground the object stands out
    of the wall in front of the marker and its shadow falls on the wall, in view: not culled. The
    decision follows the ground frame."""
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    intr, caster, lights = _scene()
    cam_from_ground = look_at_pose([0.0, -0.5, WALL_H], [0.0, 0.0, WALL_H])
    cam_from_marker = cam_from_ground @ invert_rigid(_wall_frame(WALL_H))
    ph = render_marker_photo(intr, cam_from_marker, marker_length=MARKER, seed=4)
    with (
        _session(ctx, intr, caster, lights, f"wall:{WALL_H}") as comp,
        _session(ctx, intr, caster, lights, "marker") as plain,
    ):
        res = comp.render(ph.image, cam_from_marker)
        mask, plan = res.mask, res.plan
        assert [lp.mode for lp in plan.lights] == ["none"], plan.decisions
        assert "footprint outside the canvas" in str(plan.decisions)
        oracle = ShadowOracle(
            intr.K, cam_from_ground, caster.vertices, caster.faces, [(lt.homogeneous, lt.weight) for lt in lights]
        )
        assert not (oracle.image(W, H)[0] > 0).any()
        assert not mask.any()
        res2 = plain.render(ph.image, cam_from_marker)
        mask2, plan2 = res2.mask, res2.plan
        assert [lp.mode for lp in plan2.lights] != ["none"] and (mask2 >= 128).sum() > 1000
        # the camera below the ground: refused, naming the option
        with (
            pytest.raises(UsageError, match="--ground plane"),
            _session(ctx, intr, caster, lights, "plane:0,0.5,0,0,1,0") as bad,
        ):
            bad.render(ph.image, cam_from_marker)


@pytest.mark.gl
def test_real_charuco_photo_as_a_wall_board(ctx, realdata):
    """The tutorial's ChArUco photo read as a board hanging on a wall turned 90 degrees, the floor along
    its left edge (board frame x = -0.02, normal +x; the camera is at board x = 0.13, above that floor):
    the composited shadow against the oracle at the tracked pose composed with a hand-built ground frame,
    seen through the real lens (cv2.undistortPoints)."""
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.io import read_image
    from arshadow.lights.spec import parse_light
    from arshadow.tracking.board import Board
    from arshadow.transforms import matrix_from_rvec_tvec

    folder = realdata / "aruco_tutorial"
    photo = read_image(folder / "choriginal.jpg")
    intr = Intrinsics.from_file(folder / "tutorial_camera_charuco.yml")
    board = Board(kind="charuco", size=(5, 7), square_length=0.04, marker_length=0.02, dictionary="DICT_6X6_250")
    # the board's x is along the normal: the frame's y is the board's y, x = y cross z = -board z
    mfg = np.eye(4)
    mfg[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]  # columns: x = -board z, y = board y, z = board x
    mfg[:3, 3] = [-0.02, 0.0, 0.0]
    # in front of the wall (x < 0 here: the floor's x is minus the board's z), lit from high on the right
    caster = load_occluder("box:0.04,0.04,0.05", place=(-0.07, -0.14, 0.0))
    lights = [parse_light("point:-0.12,-0.02,0.22")]
    with _session(ctx, intr, caster, lights, "plane:-0.02,0,0,1,0,0", tracker={"board": board}, aa=4) as comp:
        res = comp.process(photo, name="choriginal.jpg")
    mask, item = res.mask, res.item
    assert item.status == "ok"
    cam_from_ground = matrix_from_rvec_tvec(item.rvec, item.tvec) @ mfg
    oracle = ShadowOracle(
        intr.K, cam_from_ground, caster.vertices, caster.faces, [(lt.homogeneous, lt.weight) for lt in lights]
    )
    hh, ww = mask.shape
    vv, uu = np.mgrid[0:hh, 0:ww]
    pts = np.stack([uu.ravel(), vv.ravel()], 1).astype(np.float64).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    und = cv2.undistortPoints(pts, intr.K, intr.dist, None, intr.K, criteria=crit).reshape(-1, 2)
    ref = (oracle.classify(und[:, 0], und[:, 1])[0] >= 0.5).reshape(hh, ww)
    assert ref.sum() > 1000, ref.sum()
    score = iou(mask >= 128, ref)
    print(f"\nreal ChArUco photo as a wall board: IoU {score:.4f} ({int(ref.sum())} shadow px)")
    assert score >= 0.99
