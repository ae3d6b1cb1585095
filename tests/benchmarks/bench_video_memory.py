"""Resident memory over a long video: ``arshadow video`` on a 3 000-frame 1280x720 clip.

    python tests/benchmarks/bench_video_memory.py [--frames 3000]

The clip is the judged 300-frame clip of bench_video_engine.py looped (decoded and re-encoded, H.264) to
``--frames`` frames, cached in $ARSHADOW_BENCH_CACHE. The run goes through the CLI in this process
(default settings, with the mask video); the progress callback samples VmRSS from /proc/self/status.
Prints the RSS after frame 300 (everything warmed up and the look-ahead buffers full), the maximum and the
last sample, and growth = max - RSS(300).
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

    from arshadow.video.avio import AvReader, AvWriter

    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=3000)
    a = ap.parse_args()
    src, _ = b._clip("orbit", 300)
    long = b.CACHE / f"loop{a.frames}.mp4"
    if not long.exists():
        frames = [f.image for f in AvReader(src)]
        with AvWriter(long, 25, (1280, 720), crf=18, preset="veryfast") as w:
            for i in range(a.frames):
                w.write(frames[i % len(frames)])
        del frames
    import arshadow.video.engine as ve

    samples = []
    orig = ve.process_video

    def wrapped(*args, **kw):
        def progress(done, total):
            if done % 50 == 0 or done == total:
                samples.append((done, rss_mb()))
        kw["progress"] = progress
        return orig(*args, **kw)

    ve.process_video = wrapped
    from arshadow.cli import main as cli

    with tempfile.TemporaryDirectory() as d:
        rc = cli(["video", str(long), "--calib", str(b.CALIB_720), "--marker-length", "0.05", *b.KNOT_SCENE,
                  "-o", d, "-q", "--save-mask"])
    base = next(r for n, r in samples if n >= 300)
    peak = max(r for n, r in samples if n >= 300)
    out = {"rc": rc, "frames": a.frames, "rss_mb_at_300": round(base, 1), "rss_mb_max": round(peak, 1),
           "rss_mb_last": round(samples[-1][1], 1), "growth_mb": round(peak - base, 1),
           "samples": [(n, round(r, 1)) for n, r in samples[:: max(1, len(samples) // 20)]]}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
