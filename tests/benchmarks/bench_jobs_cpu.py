"""CPU overhead of ``arshadow video --jobs 2`` against the sequential run (the long-video work, judged: at most +10 %).

    python tests/benchmarks/bench_jobs_cpu.py [--size 720|2160] [--frames 300] [--runs 3] [--out r.json]

Clips: ``--size 720``: the judged 720p orbit clip of bench_video_engine.py (keyframes at 0 and 130 only:
the chunk boundary's primer is decoded from frame 0); ``--size 2160``: bench_video_scale.py's 3840x2160
upscale of it (a keyframe every 50 frames). Cached in $ARSHADOW_BENCH_CACHE (default /tmp/arshadow-bench).

Each run is one ``arshadow video`` process (knot, one point light, default settings), ``--jobs 1`` and
``--jobs 2`` interleaved (a slow moment of a shared machine hits both alike). CPU: user + system time of
the process and all its children (``os.wait4``: the chunk workers are reaped by it before it exits). The
``--jobs 2`` figure is split into the chunks' own CPU (``chunk_cpu_s``: the workers' ``process_time``
inside :func:`arshadow.video.chunks.run_chunk`) and the rest (interpreter start-ups, imports, GL
contexts, the keyframe scan, the join). Prints JSON: per run both CPU figures, the ratio, the load
average before it; the median ratio and its min/max; the frames each chunk decoded and tracked.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import _common  # noqa: E402
import bench_video_scale as scale  # noqa: E402


def clip(size: int, frames: int) -> Path:
    """The judged orbit clip at 720p, or its upscale (``bench_video_scale.clip``)."""
    if size == 720:
        import bench_video_engine as b

        return b._clip("orbit", frames)[0]
    return scale.clip(size, frames)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=720, choices=(720, 1080, 2160))
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out")
    a = ap.parse_args()
    scale.CACHE.mkdir(parents=True, exist_ok=True)
    path = clip(a.size, a.frames)
    runs = []
    for _ in range(a.runs):
        load = os.getloadavg()[0]
        one = scale.run(path)
        two = scale.run(path, "--jobs", "2")
        runs.append(
            {
                "load_before": round(load, 2),
                "cpu_s_jobs1": round(one["cpu_s"], 3),
                "cpu_s_jobs2": round(two["cpu_s"], 3),
                "ratio": round(two["cpu_s"] / one["cpu_s"], 4),
                "chunk_cpu_s": two.get("chunk_cpu_s"),
                "other_cpu_s_jobs2": round(two["cpu_s"] - (two.get("chunk_cpu_s") or 0.0), 3),
                "wall_s": {"1": one["process_wall_s"], "2": two["process_wall_s"]},
                "chunks": [
                    {
                        k: c.get(k)
                        for k in (
                            "k",
                            "frames",
                            "decoded_from",
                            "primed_from",
                            "cpu_s",
                            "process_cpu_s",
                            "setup_s",
                            "frames_decoded",
                        )
                    }
                    for c in two.get("chunks") or []
                ],
            }
        )
        print(
            f"run {len(runs)}: load {load:.2f}  jobs1 {one['cpu_s']:.2f} s  jobs2 {two['cpu_s']:.2f} s  "
            f"ratio {runs[-1]['ratio']:.3f}",
            file=sys.stderr,
            flush=True,
        )
    ratios = [r["ratio"] for r in runs]
    result = {
        "bench": "jobs_cpu",
        "meta": _common.metadata(),
        "clip": str(path),
        "size": a.size,
        "frames": a.frames,
        "runs": runs,
        "ratio_median": float(np.median(ratios)),
        "ratio_min": min(ratios),
        "ratio_max": max(ratios),
        "bound": 1.10,
    }
    _common.emit(result, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
