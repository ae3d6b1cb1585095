"""Motion blur of the inserted layers in a video (camera effects; arshadow/frame/motion.py, docs/shading.md).

Ground truth is computed here, independently of the code under test: the image motion by projecting the
object's box corners by hand (pinhole) or with ``cv2.projectPoints`` (the calibration's lens), the kernel's
shape from a segment's moments and an edge's linear rise, the blurred layers from the static ones blurred by
a kernel built here (a box convolved with the bilinear tent, applied as a weighted sum of shifted copies).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from video_clips import BOX_JOB, BOX_SCENE, make_clip

av = pytest.importorskip("av")

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_640x360.yml"
#: the object: box:0.04,0.03,0.06 placed at (0.05, 0, 0), standing on the ground (world = marker frame)
BOX = np.array([[x, y, z] for x in (0.03, 0.07) for y in (-0.015, 0.015) for z in (0.0, 0.06)])
SCENE = BOX_SCENE
JOB = dict(BOX_JOB)


def _cli(*argv):
    from arshadow.cli import main

    return main([str(a) for a in argv])


def _lines(path):
    return [json.loads(s) for s in Path(path).read_text().splitlines()]


def _pinhole(points, cam_from_world, f=500.0, cx=319.5, cy=179.5):
    """Hand projection (no lens): ``u = f x / z + cx``, ``v = f y / z + cy`` in the OpenCV camera frame."""
    p = points @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
    return np.c_[f * p[:, 0] / p[:, 2] + cx, f * p[:, 1] / p[:, 2] + cy]


def _poses(n, sweep=40.0):
    from arshadow.synth.poses import camera_path

    return camera_path(n, radius=0.5, height=(0.3, 0.42), sweep_deg=sweep, start_deg=-110.0)


# --------------------------------------------------------------------------------------------------
def test_frame_motion_is_the_box_corners_projected_motion_times_the_shutter(tol):
    from arshadow.camera.model import Intrinsics
    from arshadow.frame.motion import MIN_SHIFT_PX, frame_motion, image_motion

    intr = Intrinsics(500.0, 500.0, 319.5, 179.5, 640, 360)
    a, b, c = _poses(3, sweep=8.0)
    truth_ac = (_pinhole(BOX, c) - _pinhole(BOX, a)).mean(axis=0)
    assert np.abs(image_motion(intr, BOX, a, c) - truth_ac).max() <= tol.motion_project_px
    # central: the previous and the next frame, two frames apart; times the shutter
    m = frame_motion(intr, BOX, b, (a, 1), (c, 1), 0.5)
    assert np.abs(np.array(m.frame_px) - truth_ac / 2).max() <= tol.motion_project_px
    assert np.abs(np.array(m.shift_px) - truth_ac / 4).max() <= tol.motion_project_px
    assert m.active and m.length_px > 2 and m.report()["from"].startswith("central")
    # one-sided at a gap: this frame and the one neighbour with a pose
    back = frame_motion(intr, BOX, b, (a, 1), None, 1.0)
    truth_ab = (_pinhole(BOX, b) - _pinhole(BOX, a)).mean(axis=0)
    assert np.abs(np.array(back.shift_px) - truth_ab).max() <= tol.motion_project_px
    fwd = frame_motion(intr, BOX, b, None, (c, 1), 1.0)
    truth_bc = (_pinhole(BOX, c) - _pinhole(BOX, b)).mean(axis=0)
    assert np.abs(np.array(fwd.shift_px) - truth_bc).max() <= tol.motion_project_px
    # no neighbour, or a displacement under the threshold: recorded, not applied
    none = frame_motion(intr, BOX, b, None, None, 0.5)
    assert not none.active and none.reach == 0 and none.kernel is None and none.report()["applied"] is False
    tiny = frame_motion(intr, BOX, b, (a, 1), (c, 1), 0.9 * MIN_SHIFT_PX / float(np.hypot(*truth_ac / 2)))
    assert not tiny.active and "skipped" in tiny.report()["why"]


@pytest.mark.parametrize("shift", [(5.0, 3.0), (0.0, 7.3), (-2.2, 0.9)])
def test_kernel_moments_are_a_segments(tol, shift):
    """A box of length L along the shift: mean 0, variance L^2 / 12 along it, ~0 across (the splat's)."""
    from arshadow.frame.motion import motion_kernel

    k = motion_kernel(shift).astype(np.float64)
    r = k.shape[0] // 2
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    assert abs(k.sum() - 1) < 1e-6
    assert abs((k * xx).sum()) < 1e-6 and abs((k * yy).sum()) < 1e-6
    length = float(np.hypot(*shift))
    d = np.array(shift) / length
    along, across = xx * d[0] + yy * d[1], -xx * d[1] + yy * d[0]
    assert abs((k * along**2).sum() - length**2 / 12) <= tol.motion_moment_px2
    assert (k * across**2).sum() <= tol.motion_moment_px2


def test_an_edge_spreads_along_the_motion_only(tol):
    """A vertical step edge blurred along x rises linearly over L (10-90 %: 0.8 L); blurred along y (the
    edge's own direction) it is unchanged (to float32 rounding) away from the array's border."""
    from arshadow.frame.motion import motion_blur_layers, motion_kernel

    step = np.zeros((60, 80), np.float32)
    step[:, 40:] = 1.0
    # lengths of several pixels: read on the pixel grid, an unblurred step already rises over 0.8 px (the
    # linear interpolation between two pixels), which adds visibly below ~4 px
    for length in (6.0, 11.5, 20.3):
        (b,) = motion_blur_layers(motion_kernel((length, 0.0)), step)
        row = b[30, 10:70].astype(np.float64)  # rising (the zero border pulls the array's ends down)
        x = np.arange(10, 70, dtype=np.float64)
        x10, x90 = np.interp(0.1, row, x), np.interp(0.9, row, x)
        assert abs((x90 - x10) - 0.8 * length) <= tol.motion_ramp_px, (length, x90 - x10)
        assert abs(np.interp(0.5, row, x) - 39.5) <= tol.motion_ramp_px  # centred on the edge
        (c,) = motion_blur_layers(motion_kernel((0.0, length)), step)
        m = int(np.ceil(length / 2)) + 2
        assert np.abs(c[m:-m] - step[m:-m]).max() <= tol.motion_layer_abs  # float32 sums


@pytest.mark.parametrize("shift", [(4.0, 0.0), (12.0, 0.0), (12.0, 7.0), (20.0, -13.0), (-30.0, 30.0), (3.0, 25.0)])
def test_a_long_kernel_in_pieces_is_the_direct_convolution(tol, shift):
    """Kernels past OpenCV's DFT threshold are applied in pieces (arshadow.frame.motion.kernel_pieces): the
    result equals the convolution written out here as a sum of shifted copies of the zero-padded layer."""
    from arshadow.frame.motion import DFT_AREA, kernel_pieces, motion_blur_layers, motion_kernel

    rng = np.random.default_rng(7)
    a = rng.random((70, 90, 3)).astype(np.float32)
    k = motion_kernel(shift)
    r = k.shape[0] // 2
    p = np.pad(a.astype(np.float64), ((r, r), (r, r), (0, 0)))
    want = np.zeros(a.shape, np.float64)
    for i, j in zip(*np.nonzero(k), strict=True):  # out[y, x] += k[i, j] a[y + i - r, x + j - r]
        want += float(k[i, j]) * p[i : i + a.shape[0], j : j + a.shape[1]]
    (got,) = motion_blur_layers(k, a)
    assert np.abs(got - want).max() <= tol.motion_layer_abs
    pieces = kernel_pieces(k)
    assert all(pc.size < DFT_AREA for pc, _, _ in pieces)
    total = np.zeros_like(k)
    for pc, y0, x0 in pieces:
        total[y0 : y0 + pc.shape[0], x0 : x0 + pc.shape[1]] += pc
    assert np.array_equal(total, k)


def _trapezoid(length):
    """A box of integer ``length`` convolved with the bilinear tent, at integer offsets -L/2..L/2 (the ends
    half weight): what a box of that length sampled by linear interpolation is."""
    w = np.ones(int(length) + 1)
    w[[0, -1]] = 0.5
    return w / length


def _shift_sum(a, weights, axis):
    """``a`` convolved along ``axis`` with ``weights`` centred (zeros beyond the array): shifted copies."""
    r = len(weights) // 2
    out = np.zeros(a.shape, np.float64)
    pad = [(0, 0)] * a.ndim
    pad[axis] = (r, r)
    p = np.pad(a.astype(np.float64), pad)
    n = a.shape[axis]
    for i, w in enumerate(weights):
        out += w * np.take(p, np.arange(2 * r - i, 2 * r - i + n), axis=axis)
    return out


@pytest.mark.gl
def test_rendered_layers_are_the_static_ones_blurred_along_the_motion(ctx, tol):
    """The frame rendered with a motion blur of 8 px along x: its object layer (premultiplied RGBA) equals
    the static frame's blurred by the trapezoid built here, and its shadow mask the static one's within a
    level; the frame is composited by the numpy path, and the report carries the values."""
    from arshadow.frame.execute import MOTION_WHY, FrameOutputs
    from arshadow.frame.hooks import EngineFrame
    from arshadow.frame.motion import MotionBlur
    from arshadow.frame.session import Session
    from arshadow.synth.poses import look_at_pose

    photo = np.full((360, 640, 3), 140, np.uint8)
    pose = look_at_pose([0.25, -0.35, 0.35], [0.03, 0.0, 0.02])
    motion = MotionBlur(shift_px=(8.0, 0.0), frame_px=(16.0, 0.0), shutter=0.5, source="given")
    with Session(JOB, context=ctx) as s:
        still = s.hooks.render(photo, pose, outputs=FrameOutputs(), layers=True)
        moved = s.hooks.render(photo, pose, outputs=FrameOutputs(), layers=True, frame=EngineFrame(motion=motion))
        # without layers asked for, a frame the shader path would composite (forced) takes the numpy path
        forced = Session({**JOB, "compose": "gpu"}, context=ctx)
        with forced:
            plain = forced.hooks.render(photo, pose, outputs=FrameOutputs(), frame=EngineFrame(motion=motion))
    assert plain.item.compose == "cpu" and plain.item.plan["compose"] == MOTION_WHY
    assert np.array_equal(plain.composite, moved.composite)
    rep = moved.item.plan["motion_blur"]
    assert rep["shift_px"] == [8.0, 0.0] and rep["shutter"] == 0.5 and rep["applied"] is True
    assert "motion_blur" not in still.item.plan
    obj_s, _ = still.layers.full()
    obj_m, _ = moved.layers.full()
    assert obj_s[..., 3].sum() > 500  # the object is in view
    truth = _shift_sum(obj_s, _trapezoid(8), axis=1)
    assert np.abs(obj_m - truth).max() <= tol.motion_layer_abs
    # the mask (8-bit, blocked light): the static one's blurred, within one level of rounding
    mask_truth = _shift_sum(still.mask.astype(np.float64), _trapezoid(8), axis=1)
    assert np.abs(moved.mask - mask_truth).max() <= 1.0
    assert not np.array_equal(moved.composite, still.composite)


def _video(tmp_path, clip, tag, *extra):
    out = tmp_path / tag
    assert _cli("video", clip, *SCENE, "-o", out, "--format", "mkv", "-q", "--camera-effects", "on", *extra) == 0
    from arshadow.video.avio import AvReader

    return [f.image for f in AvReader(out / "c.mkv", raw=True)], _lines(out / "c.frames.jsonl")


@pytest.mark.gl
def test_video_motion_from_the_rendered_poses_and_off_unchanged(tmp_path, gl_ctx, tol):
    """In a video each frame's motion is the box corners' projected motion between the previous and the
    next frame's rendered poses (their records, projected with cv2.projectPoints and the calibration's lens),
    over the frames between them, times the shutter; one-sided beside a frame without the marker (held:
    none); --motion-blur off, and a blur skipped as negligible, leave the frames as they are without it,
    bit for bit."""
    from arshadow.camera.model import Intrinsics

    intr = Intrinsics.from_file(CALIB)
    n, gap = 9, 5
    clip = make_clip(tmp_path / "c.mkv", intr, _poses(n, sweep=60.0), codec="ffv1", noise=1.0, blank={gap})
    on, rec = _video(tmp_path, clip, "on", "--shutter", "0.75")
    off, rec_off = _video(tmp_path, clip, "off", "--motion-blur", "off")
    tiny, rec_tiny = _video(tmp_path, clip, "tiny", "--shutter", "0.001")
    assert [r["status"] for r in rec] == ["ok"] * gap + ["held"] + ["ok"] * (n - gap - 1)
    assert all("motion_blur" not in r for r in rec_off)
    K = np.array([[intr.fx, 0, intr.cx], [0, intr.fy, intr.cy], [0, 0, 1]])

    def project(r):
        return cv2.projectPoints(BOX, np.array(r["rvec"]), np.array(r["tvec"]), K, np.asarray(intr.dist))[0][:, 0]

    def tracked(i):
        return 0 <= i < n and rec[i]["status"] == "ok"

    applied = 0
    for i in range(n):
        mb = rec[i]["motion_blur"]
        assert rec_tiny[i]["motion_blur"]["applied"] is False
        assert np.array_equal(tiny[i], off[i])
        if i == gap:
            assert mb["from"].startswith("none") and mb["shift_px"] == [0.0, 0.0] and not mb["applied"]
            continue
        lo, hi = (i - 1 if tracked(i - 1) else i), (i + 1 if tracked(i + 1) else i)
        truth = (project(rec[hi]) - project(rec[lo])).mean(axis=0) / (hi - lo)
        kind = "central" if hi - lo == 2 else "forward" if lo == i else "backward"
        assert mb["from"].split(":")[0] == kind, (i, mb["from"])
        assert np.abs(np.array(mb["frame_motion_px"]) - truth).max() <= tol.motion_record_px, (i, mb, truth)
        assert np.abs(np.array(mb["shift_px"]) - 0.75 * truth).max() <= tol.motion_record_px
        applied += mb["applied"]
    assert applied >= n - 3
    changed = [not np.array_equal(x, y) for x, y in zip(on, off, strict=True)]
    assert sum(changed) >= applied


@pytest.mark.gl
def test_a_photo_is_never_motion_blurred(ctx):
    """A photo has no neighbouring frames: with camera effects and motion blur on, nothing of it is in the
    report and the composite equals the one with motion blur off."""
    from arshadow.camera.model import Intrinsics
    from arshadow.frame.session import Session
    from arshadow.synth.markers import render_marker_photo
    from arshadow.synth.poses import look_at_pose

    photo = render_marker_photo(
        Intrinsics.from_file(CALIB), look_at_pose([0.2, -0.3, 0.35], [0.02, 0.0, 0.0]), marker_length=0.05, seed=4
    ).image
    out = {}
    for flag in ("on", "off"):
        job = {**JOB, "camera_effects": "on", "motion_blur": flag, "shutter": 1.0}
        with Session(job, context=ctx) as s:
            res = s.process(photo)
        assert "camera_effects" in res.item.plan and "motion_blur" not in res.item.plan
        out[flag] = res.composite
    assert np.array_equal(out["on"], out["off"])
