"""Synthetic AR clips with known camera paths (shared by tests/test_video_engine.py and the benchmarks).

Frames come from :func:`arshadow.synth.render_marker_photo` (exact per-pixel rendering of the printed
marker on a textured floor, lens distortion, blur, noise, JPEG) and are encoded with PyAV; the true
``cam_from_world`` per frame is the generating pose, never a detector's output.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CALIB_720 = ROOT / "calib" / "synth_1280x720.yml"
CALIB_360 = ROOT / "calib" / "synth_640x360.yml"
#: the video tests' scene: a 4 x 3 x 6 cm box beside the marker under one point light (CLI arguments, and the
#: same as job keys: :data:`BOX_JOB`)
BOX_SCENE = [
    "--calib",
    str(CALIB_360),
    "--marker-length",
    "0.05",
    "--model",
    "box:0.04,0.03,0.06",
    "--place",
    "0.05,0,0",
    "--light",
    "point:-0.1,0.15,0.4",
]
BOX_JOB = {
    "calib": str(CALIB_360),
    "marker_length": 0.05,
    "model": "box:0.04,0.03,0.06",
    "place": [0.05, 0, 0],
    "lights": ["point:-0.1,0.15,0.4"],
}
#: the scene of samples/knot_point.jpg: the 8 536-face knot under one point light
KNOT_SCENE = [
    "--model",
    str(ROOT / "samples" / "meshes" / "knot.ply"),
    "--place",
    "0.1,0.05,0",
    "--rotate",
    "0,0,15",
    "--light",
    "point:-0.12,0.2,0.42",
]


def make_clip(
    path,
    intr,
    poses,
    *,
    marker_length=0.05,
    noise=2.0,
    blur=0.8,
    jpeg=85,
    blank=(),
    seed=0,
    crf=18,
    fps=25,
    codec="h264",
    audio=False,
    gop=None,
    rotation=0,
):
    """Encode one synthetic frame per pose (frames in ``blank``: the floor only, no marker); returns path."""
    from arshadow.synth.markers import render_marker_photo
    from arshadow.video.avio import AvWriter

    path = Path(path)
    with AvWriter(
        path, fps, (intr.width, intr.height), codec=codec, crf=crf, preset="medium", gop=gop, rotation=rotation
    ) as w:
        for i, pose in enumerate(poses):
            ph = render_marker_photo(
                intr,
                pose,
                marker_length=marker_length,
                noise_sigma=noise,
                blur_sigma=blur,
                jpeg_quality=jpeg,
                seed=seed + i,
            )
            img = ph.image
            if i in blank:
                img = np.full_like(img, 128)
            w.write(img)
    if audio:
        _add_tone(path, len(poses) / fps)
    return path


def _add_tone(path, seconds):
    """Rewrite ``path`` with a 440 Hz AAC tone as its audio track (video packets copied)."""
    import av

    tmp = path.with_name(path.stem + ".a" + path.suffix)
    with av.open(str(path)) as src, av.open(str(tmp), "w") as dst:
        vin = src.streams.video[0]
        vout = dst.add_stream_from_template(vin)
        aout = dst.add_stream("aac", rate=44100)
        aout.layout = "mono"
        for pkt in src.demux(vin):
            if pkt.dts is None:
                continue
            pkt.stream = vout
            dst.mux(pkt)
        n = int(seconds * 44100)
        t = np.arange(n) / 44100.0
        pcm = (0.2 * np.sin(2 * np.pi * 440 * t)).astype(np.float32)[None, :]
        for k in range(0, n, 1024):
            fr = av.AudioFrame.from_ndarray(pcm[:, k : k + 1024], format="fltp", layout="mono")
            fr.sample_rate = 44100
            fr.pts = k
            for p in aout.encode(fr):
                dst.mux(p)
        for p in aout.encode(None):
            dst.mux(p)
    tmp.replace(path)


class ExactShadow:
    """The exact shadow mask of a mesh at a known pose, independent of the renderer.

    The mesh's shadow on z = 0 is the union of its triangles projected from the light
    (:func:`tests.oracle.ground_shadow_triangles`); those ground triangles and the mesh's own triangles are
    projected through the (distorted) camera (:meth:`Intrinsics.project`) and polygon-filled by OpenCV at
    1/16-pixel precision (pixel centres at integer coordinates, CONVENTIONS.md). Mask = shadow and not
    covered by the object. The triangles are millimetres wide, so a straight edge between two distorted
    vertices is exact to far below a pixel.
    """

    SHIFT = 4
    #: supersampling: OpenCV's polygon fill puts an edge within half a (fine) pixel; 8x makes that 1/16 px
    SS = 8

    def __init__(self, intr, vertices, faces, light_h):
        import sys

        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from oracle import ground_shadow_triangles

        self.intr = intr
        self.V = np.asarray(vertices, np.float64)
        self.F = np.asarray(faces)
        tris = ground_shadow_triangles(self.V, self.F, np.asarray(light_h, np.float64))
        self.shadow = np.concatenate([tris, np.zeros(tris.shape[:2] + (1,))], axis=2)  # (m, 3, 3) on z = 0

    def mask(self, pose) -> np.ndarray:
        """``(H, W) bool`` shadow mask for ``cam_from_world`` ``pose`` (pixel-centre samples)."""
        return self._raster(pose)[0]

    def centroid(self, pose) -> np.ndarray:
        """``(2,)`` centroid (u, v) of the shadow at 1/8-pixel resolution (no pixel-sampling noise)."""
        return self._raster(pose)[1]

    def _raster(self, pose):
        import cv2

        H, W = self.intr.height, self.intr.width
        uv_s = self.intr.project(self.shadow.reshape(-1, 3), pose).reshape(-1, 3, 2)
        uv_o = self.intr.project(self.V[self.F].reshape(-1, 3), pose).reshape(-1, 3, 2)
        uv_s = uv_s[np.all(np.isfinite(uv_s), axis=(1, 2))]
        uv_o = uv_o[np.all(np.isfinite(uv_o), axis=(1, 2))]
        out = np.zeros((H, W), bool)
        nan = np.array([np.nan, np.nan])
        if not len(uv_s):
            return out, nan
        lo = np.floor(uv_s.reshape(-1, 2).min(axis=0)) - 2
        hi = np.ceil(uv_s.reshape(-1, 2).max(axis=0)) + 2
        x0, y0 = int(max(lo[0], 0)), int(max(lo[1], 0))
        x1, y1 = int(min(hi[0], W - 1)), int(min(hi[1], H - 1))
        if x1 < x0 or y1 < y0:
            return out, nan
        S = self.SS
        fh, fw = (y1 - y0) * S + 1, (x1 - x0) * S + 1

        def fill(uv):
            img = np.zeros((fh, fw), np.uint8)
            # fine pixel F <-> image coordinate x0 + F / S: pixel centre u is the fine pixel S (u - x0)
            pts = np.round((uv - [x0, y0]) * S * (1 << self.SHIFT)).astype(np.int32)
            for tri in pts:  # one by one: fillPoly on a list fills by parity (overlaps would cancel)
                cv2.fillConvexPoly(img, tri, 1, lineType=cv2.LINE_8, shift=self.SHIFT)
            return img > 0

        fine = fill(uv_s) & ~fill(uv_o)
        out[y0 : y1 + 1, x0 : x1 + 1] = fine[::S, ::S]
        fv, fu = np.nonzero(fine)
        c = np.array([x0 + fu.mean() / S, y0 + fv.mean() / S]) if fu.size else nan
        return out, c


def iou(a, b) -> float:
    u = np.logical_or(a, b).sum()
    return 1.0 if u == 0 else float(np.logical_and(a, b).sum() / u)


def centroid(mask):
    v, u = np.nonzero(mask)
    return np.array([u.mean(), v.mean()]) if u.size else np.array([np.nan, np.nan])


def jitter_and_lag(c_est, c_true):
    """Frame-to-frame jitter (RMS of the motion error, px) and lag (frames, + = behind) of centroids.

    ``jitter = sqrt(mean |(c_est[t] - c_est[t-1]) - (c_true[t] - c_true[t-1])|^2)``;
    ``lag = median over t of -((c_est[t] - c_true[t]) . v[t]) / |v[t]|^2`` with the true velocity
    ``v[t] = (c_true[t+1] - c_true[t-1]) / 2`` (frames where it is at least 0.5 px/frame).
    """
    c_est, c_true = np.asarray(c_est, float), np.asarray(c_true, float)
    ok = np.all(np.isfinite(c_est), axis=1) & np.all(np.isfinite(c_true), axis=1)
    d = np.diff(c_est, axis=0) - np.diff(c_true, axis=0)
    dk = ok[1:] & ok[:-1]
    jitter = float(np.sqrt(np.mean(np.sum(d[dk] ** 2, axis=1))))
    v = (c_true[2:] - c_true[:-2]) / 2.0
    e = (c_est - c_true)[1:-1]
    sp = np.sum(v * v, axis=1)
    k = ok[1:-1] & ok[2:] & ok[:-2] & (sp >= 0.25)
    lag = float(np.median(-np.sum(e[k] * v[k], axis=1) / sp[k])) if k.any() else float("nan")
    return jitter, lag


class CvClipWriter:
    """A plain OpenCV ``cv2.VideoWriter`` (MPEG-4 part 2 for .mp4/.mov/.m4v, MJPG for .avi, FFV1 for .mkv):
    the clips tests/test_video.py was written with (arshadow itself encodes with PyAV)."""

    FOURCC = {".mp4": "mp4v", ".m4v": "mp4v", ".mov": "mp4v", ".avi": "MJPG", ".mkv": "FFV1"}

    def __init__(self, path, fps, size, color=True):
        import cv2

        fourcc = cv2.VideoWriter_fourcc(*self.FOURCC[Path(path).suffix.lower()])
        self.w = cv2.VideoWriter(str(path), cv2.CAP_FFMPEG, fourcc, float(fps), tuple(size), bool(color))
        assert self.w.isOpened(), path

    def write(self, frame):
        self.w.write(np.ascontiguousarray(frame))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.w.release()


def read_frames(path) -> list:
    """Every frame of a video file decoded by OpenCV (independent of arshadow's PyAV reader), BGR uint8."""
    import cv2

    cap = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        out.append(f)
    cap.release()
    return out
