"""A/B benchmark of the video engine: the judged 720p clip through two source trees, runs interleaved.

    python tests/benchmarks/ab_video.py --a /path/to/old/tree --b /path/to/new/tree [--rounds 5] [--frames 300]
                                        [--extra "--ambient-occlusion on --camera-effects on"] [--b-extra ...]

The clip is ``bench_video_engine.py``'s (300 frames at 1280x720, the knot, one point light; cached in
$ARSHADOW_BENCH_CACHE). Each round runs ``arshadow video`` once per tree, each in a fresh process with
``PYTHONPATH`` = the tree (order alternating every round, so both see the same machine load at nearly the
same time), and reads the engine's own ``fps_processed`` (open to last frame written; no process start or
GL context creation). Prints JSON: per tree the median and [min, max] fps, and the median and [min, max]
of the paired ratios fps_A / fps_B (a time ratio B / A: above 1 means B is slower), with the load average
before each round.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parents[1]))

from video_clips import CALIB_720, KNOT_SCENE, make_clip  # noqa: E402  (tests/, put on the path above)

from arshadow.camera.model import Intrinsics  # noqa: E402
from arshadow.synth.markers import camera_path  # noqa: E402

CACHE = Path(os.environ.get("ARSHADOW_BENCH_CACHE", "/tmp/arshadow-bench"))

RUN = r"""
import json, sys
from pathlib import Path
from arshadow.cli import main
clip, out, calib = sys.argv[1], sys.argv[2], sys.argv[3]
scene = json.loads(sys.argv[4])
argv = ["video", clip, "--calib", calib, "--marker-length", "0.05", *scene, "-o", out, "-q",
        "--report", str(Path(out) / "r.json")]
rc = main(argv)
rep = json.loads((Path(out) / "r.json").read_text())
print(json.dumps({"rc": rc, "fps": rep["videos"][0]["fps_processed"]}))
"""


def judged_clip(n: int) -> Path:
    """``bench_video_engine.py``'s orbit clip of ``n`` frames (made once, cached in $ARSHADOW_BENCH_CACHE)."""
    path = CACHE / f"orbit{n}.mp4"
    if not path.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        blank = set(range(100, 130)) if n > 130 else set()
        make_clip(path, Intrinsics.from_file(CALIB_720), camera_path(n), blank=blank, seed=11)
    return path


def run_tree(tree: Path, clip: Path, calib: Path, scene: list[str]) -> float:
    """One ``arshadow video`` run of ``clip`` with the code of ``tree``; its processed fps."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    with tempfile.TemporaryDirectory() as out:
        res = subprocess.run(
            [sys.executable, "-c", RUN, str(clip), out, str(calib), json.dumps(scene)],
            env=env,
            cwd=str(tree),
            capture_output=True,
            text=True,
            check=True,
        )
    got = json.loads(res.stdout.strip().splitlines()[-1])
    if got["rc"] != 0:
        raise RuntimeError(f"{tree}: arshadow video exited {got['rc']}: {res.stderr[-400:]}")
    return float(got["fps"])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--a", type=Path, required=True, help="the old tree (A)")
    ap.add_argument("--b", type=Path, required=True, help="the new tree (B)")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--extra", default="", help="more arshadow video options for both trees, space-separated")
    ap.add_argument("--b-extra", default="", help="more arshadow video options for B only, space-separated")
    args = ap.parse_args()
    clip = judged_clip(args.frames)
    fps: dict[str, list[float]] = {"a": [], "b": []}
    loads = []
    for r in range(args.rounds):
        loads.append([round(x, 2) for x in os.getloadavg()])
        order = ("a", "b") if r % 2 == 0 else ("b", "a")
        for k in order:
            scene = list(KNOT_SCENE) + args.extra.split() + (args.b_extra.split() if k == "b" else [])
            fps[k].append(run_tree(getattr(args, k).resolve(), clip, Path(CALIB_720).resolve(), scene))
    ratio = np.asarray(fps["a"]) / np.asarray(fps["b"])

    def stats(x):
        return {
            "median": round(float(np.median(x)), 3),
            "min": round(float(np.min(x)), 3),
            "max": round(float(np.max(x)), 3),
            "runs": [round(float(v), 3) for v in x],
        }

    print(
        json.dumps(
            {
                "a": str(args.a),
                "b": str(args.b),
                "frames": args.frames,
                "extra": args.extra,
                "fps_a": stats(fps["a"]),
                "fps_b": stats(fps["b"]),
                "time_ratio_b_over_a": stats(ratio),
                "loadavg_before_rounds": loads,
            },
            indent=1,
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
