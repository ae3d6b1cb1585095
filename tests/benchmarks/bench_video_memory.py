"""Resident memory over a long video: ``arshadow video`` on a 3 000-frame clip (720p or 2160p).

    python tests/benchmarks/bench_video_memory.py [--frames 3000] [--height 720|1080|2160] [--warm 300]
                                                  [--limit-mb 100]

The clip is the judged 300-frame clip of bench_video_engine.py (upscaled to ``--height`` as in
bench_video_scale.py) looped (decoded and re-encoded, H.264) to ``--frames`` frames, cached in
$ARSHADOW_BENCH_CACHE. The run goes through the CLI in this process (default settings, with the mask
video); the progress callback samples VmRSS from /proc/self/status. Prints the RSS after frame ``--warm``
(everything warmed up and the look-ahead buffers full), the maximum and the last sample, and growth =
max - RSS(warm); exits 1 when growth exceeds ``--limit-mb`` (the long-video work: a 3 000-frame 2160p run grows
<= 100 MB). A short check: ``--height 2160 --frames 150 --warm 50 --source-frames 40``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "tests" / "benchmarks"))


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def main() -> int:
    import bench_video_engine as b
    import bench_video_scale as sc

    from arshadow.video.avio import AvReader, AvWriter

    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=3000)
    ap.add_argument("--height", type=int, default=720, choices=sorted(sc.SIZES))
    ap.add_argument("--warm", type=int, default=300, help="the frame whose RSS is the baseline")
    ap.add_argument("--limit-mb", type=float, default=100.0)
    ap.add_argument("--source-frames", type=int, default=300, help="frames of the clip that is looped")
    a = ap.parse_args()
    warm = min(a.warm, a.frames // 2)
    src = sc.clip(a.height, a.source_frames)
    size = sc.SIZES[a.height]
    long = b.CACHE / f"loop{a.height}_{a.source_frames}_{a.frames}.mp4"
    if not long.exists():
        frames = [f.image for f in AvReader(src)]
        with AvWriter(long, 25, size, crf=18, preset="veryfast") as w:
            for i in range(a.frames):
                w.write(frames[i % len(frames)])
        del frames
    import arshadow.video.runner as vr

    samples = []
    orig = vr.process_video

    def wrapped(*args, **kw):
        def progress(done, total):
            if done % 25 == 0 or done == total:
                samples.append((done, rss_mb()))

        kw["progress"] = progress
        return orig(*args, **kw)

    vr.process_video = wrapped
    from arshadow.cli import main as cli

    with tempfile.TemporaryDirectory() as d:
        rc = cli(
            [
                "video",
                str(long),
                "--calib",
                str(b.CALIB_720),
                "--marker-length",
                "0.05",
                *b.KNOT_SCENE,
                "-o",
                d,
                "-q",
                "--save-mask",
            ]
        )
    base = next(r for n, r in samples if n >= warm)
    peak = max(r for n, r in samples if n >= warm)
    out = {
        "rc": rc,
        "frames": a.frames,
        "height": a.height,
        "warm": warm,
        "rss_mb_at_warm": round(base, 1),
        "rss_mb_max": round(peak, 1),
        "rss_mb_last": round(samples[-1][1], 1),
        "growth_mb": round(peak - base, 1),
        "limit_mb": a.limit_mb,
        "samples": [(n, round(r, 1)) for n, r in samples[:: max(1, len(samples) // 20)]],
    }
    print(json.dumps(out, indent=1))
    return 0 if rc == 0 and peak - base <= a.limit_mb else 1


if __name__ == "__main__":
    sys.exit(main())
