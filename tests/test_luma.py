"""The video frame's luma converted where the tracker reads it (:class:`arshadow.tracking.luma.LumaFrame`).

The shared real clips show several markers spread over the frame, so their tracking window is the whole
frame (they check the bit-identical poses); the synthetic single-marker clip checks the windowed case.

Truth: :func:`arshadow.tracking.luma.luma_to_gray` of the whole plane (the conversion the engine made before)
and the tracker's output on that whole converted plane; the lazy frame must give the same pixels where it
is read and the same poses, bit for bit, on real footage.
"""

from __future__ import annotations

import numpy as np
import pytest
from video_clips import CALIB_720, make_clip

from arshadow.bench.tracking import REAL_CLIPS, realvideo_dir, session
from arshadow.camera.model import Intrinsics
from arshadow.errors import MarkerNotFoundError
from arshadow.synth.markers import camera_path
from arshadow.tracking.detect import to_gray
from arshadow.tracking.luma import LumaFrame, luma_to_gray
from arshadow.video.avio import AvReader


def test_regions_are_the_whole_conversion():
    rng = np.random.default_rng(3)
    y = rng.integers(0, 256, (90, 130), dtype=np.uint8)
    want = luma_to_gray(y)
    f = LumaFrame(y)
    for _ in range(20):
        x0, y0 = int(rng.integers(-10, 120)), int(rng.integers(-10, 80))
        w, h = int(rng.integers(1, 60)), int(rng.integers(1, 60))
        got = f.region(max(0, x0), max(0, y0), w, h)
        assert np.array_equal(got, want[max(0, y0) : max(0, y0) + h, max(0, x0) : max(0, x0) + w])
    pts = np.array([[20.3, 30.1], [50.0, 31.0], [49.2, 60.7], [21.0, 58.0]])
    g = f.near(pts, margin=4, grow=0.0)
    assert np.array_equal(g[26:66, 16:55], want[26:66, 16:55])
    assert np.array_equal(to_gray(f), want)  # every other reader gets the whole frame
    assert not np.shares_memory(f.full(), y)  # the decoder's plane is never written


def test_only_read_regions_are_converted():
    f = LumaFrame(np.full((720, 1280), 120, np.uint8))
    f.region(100, 200, 50, 40)
    f.region(110, 210, 10, 10)  # inside: nothing more to convert
    assert f.converted == [(100, 200, 150, 240)]


def test_rejects_what_is_not_a_luma_plane():
    with pytest.raises(ValueError, match="luma plane"):
        LumaFrame(np.zeros((4, 4, 3), np.uint8))


def _poses(s, path, lazy: bool, n: int, shares: list):
    out = []
    with AvReader(path, max_frames=n, raw=True) as reader:
        for fr in reader:
            y = fr.image[: reader.height]
            f = LumaFrame(y)
            try:
                p = s.track(f if lazy else luma_to_gray(y))
                q = (p.corner_instability, p.border_occlusion, p.reprojection_error_px)  # read from the grey too
                out.append((p.cam_from_world.copy(), tuple(p.marker_ids), q))
            except MarkerNotFoundError as exc:
                out.append(str(exc))
            area = sum((x1 - x0) * (y1 - y0) for x0, y0, x1, y1 in f.converted)
            shares.append(area / y.size)
    return out


@pytest.mark.parametrize("refine", ["edge", "apriltag"])
def test_real_footage_poses_identical(refine):
    base = realvideo_dir()
    if not (base / REAL_CLIPS[0][0] / "detections.csv").is_file():
        pytest.skip(f"real video clips not found at {base} (set ARSHADOW_REALVIDEO)")
    for folder, video, mid, length in REAL_CLIPS:
        d = base / folder
        cam = Intrinsics.from_file(d / "intrinsics.yml")
        runs, shares = [], []
        for lazy in (False, True):
            s = session(
                cam,
                marker_length=length,
                marker_id=mid,
                dictionary="DICT_ARUCO_ORIGINAL",
                refine=refine,
                track_roi=True,
            )
            runs.append(_poses(s, d / video, lazy, 60, shares))
            s.close()
        full, lazy = runs
        assert len(full) == len(lazy) == 60
        assert sum(not isinstance(r, str) for r in full) >= 40  # the test sees tracked frames
        for a, b in zip(full, lazy, strict=True):
            if isinstance(a, str):
                assert a == b
            else:
                assert np.array_equal(a[0], b[0]) and a[1:] == b[1:]


def test_synthetic_clip_poses_identical_and_windowed(tmp_path):
    """A single marker: the tracking window is a small part of the frame; blank frames force full searches."""
    cam = Intrinsics.from_file(CALIB_720)
    clip = make_clip(tmp_path / "c.mp4", cam, camera_path(40), blank={15, 16, 17}, noise=1.0, seed=5)
    runs, shares = [], []
    for lazy in (False, True):
        s = session(cam, marker_length=0.05, marker_id=0, track_roi=True)
        runs.append(_poses(s, clip, lazy, 40, shares))
        s.close()
    full, lazy = runs
    assert sum(isinstance(r, str) for r in full) == 3  # the blank frames
    for a, b in zip(full, lazy, strict=True):
        if isinstance(a, str):
            assert a == b
        else:
            assert np.array_equal(a[0], b[0]) and a[1:] == b[1:]
    assert np.median(shares[40:]) < 0.2  # tracked frames convert the window only
    assert max(shares[40:]) == 1.0  # a search of the whole frame converts it all


def test_full_range_yuv420p_is_not_read_as_limited_luma(tmp_path):
    """A yuv420p stream flagged full range (FFV1 here; HEVC from some phones) must not take the planar
    path, whose luma expansion and I420 conversions assume 16..235: it is read as BGR, range honoured."""
    import av

    path = tmp_path / "full.mkv"
    y = np.full((48, 64), 250, np.uint8)
    y[10:20, 10:30] = 5
    planes = np.concatenate([y, np.full((24, 64), 128, np.uint8)])
    with av.open(str(path), "w") as c:
        s = c.add_stream("ffv1", rate=25)
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        s.codec_context.color_range = 2
        for _ in range(2):
            f = av.VideoFrame.from_ndarray(planes, format="yuv420p")
            f.color_range = 2
            for p in s.encode(f):
                c.mux(p)
        for p in s.encode():
            c.mux(p)
    with AvReader(path, raw=True) as reader:
        fr = next(iter(reader))
    assert fr.format == "bgr24"
    assert fr.image[0, 0].tolist() == [250, 250, 250] and fr.image[15, 15].tolist() == [5, 5, 5]
