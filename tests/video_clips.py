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
#: the scene of samples/knot_point.jpg: the 8 536-face knot under one point light
KNOT_SCENE = ["--model", str(ROOT / "samples" / "meshes" / "knot.ply"), "--place", "0.1,0.05,0", "--rotate", "0,0,15",
              "--light", "point:-0.12,0.2,0.42"]


def make_clip(path, intr, poses, *, marker_length=0.05, noise=2.0, blur=0.8, jpeg=85, blank=(), seed=0,
              crf=18, fps=25, codec="h264", audio=False):
    """Encode one synthetic frame per pose (frames in ``blank``: the floor only, no marker); returns path."""
    from arshadow.avio import AvWriter
    from arshadow.synth import render_marker_photo

    path = Path(path)
    with AvWriter(path, fps, (intr.width, intr.height), codec=codec, crf=crf, preset="medium") as w:
        for i, pose in enumerate(poses):
            ph = render_marker_photo(intr, pose, marker_length=marker_length, noise_sigma=noise, blur_sigma=blur,
                                     jpeg_quality=jpeg, seed=seed + i)
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
