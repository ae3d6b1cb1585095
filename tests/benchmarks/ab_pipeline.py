"""A/B benchmark: bench_pipeline.py's default case in two source trees, frame by frame, interleaved.

    python tests/benchmarks/ab_pipeline.py --a /path/to/old/tree --b /path/to/new/tree [--frames 200]

Each tree runs in its own worker process (``PYTHONPATH`` = the tree), set up once like
``bench_pipeline.py``'s default row (samples/knot_point.jpg, 1280 x 720, the knot, its first light,
``Session.process(image, want_mask=False, out=buf)``, or
``Compositor.process`` in a tree from before the façade work); then the driver asks A and B for one frame each
in turn (order alternating every pair), so both see the same machine load at nearly the same time. Prints
JSON: per tree the median, IQR ``[q25, q75]`` and min of the frame times and the median of each stage the report times,
and the median and IQR of the paired ratios
B / A. On a shared machine the paired ratio is the figure to quote; absolute times move with the load.
``AB_NEW_OPTIONS='{"exposure": false}'`` sets RenderOptions fields in a tree whose engine is Session (the façade work
on), e.g. to time the façade without the exposure match that the light estimate turned on by default.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import _common
import numpy as np

WORKER = r"""
import sys, time, json
from pathlib import Path
import numpy as np
root = Path(sys.argv[1])
from arshadow.camera import Intrinsics
from arshadow.gl.context import create_context
from arshadow.io import read_image
try:
    from arshadow.geometry.mesh import load_occluder
    from arshadow.lights.spec import parse_light
except ImportError:  # a tree from before the move into subpackages
    from arshadow.lights import parse_light
    from arshadow.mesh import load_occluder
sc = next(s for s in json.loads((root / "samples" / "scenes.json").read_text())["scenes"]
          if s["photo"] == "knot_point.jpg")
image = read_image(root / "samples" / "knot_point.jpg")
intr = Intrinsics.from_file(root / "calib" / "synth_1280x720.yml")
caster = load_occluder(root / sc["model"], rotate=sc.get("rotate", (0, 0, 0)), place=sc.get("place", (0, 0, 0)))
ctx = create_context()
lights = [parse_light(sc["lights"][0])]
buf = np.empty_like(image)
try:  # a tree from before Session became the engine (the façade work): the Compositor
    from arshadow.pipeline import Compositor, RenderOptions
except ImportError:
    from arshadow.scene import RenderOptions, Scene
    from arshadow import Session  # the façade, in every tree since it became the engine
    import os  # AB_NEW_OPTIONS: RenderOptions fields for a tree with Session (e.g. '{"exposure": false}')
    opts = RenderOptions(**json.loads(os.environ.get("AB_NEW_OPTIONS", "{}")))
    comp = Session(Scene(intr, caster, lights, opts, {"marker_length": 0.05}), context=ctx)
    frame = lambda: comp.process(image, want_mask=False, out=buf).item
else:
    comp = Compositor(ctx, intr, caster, lights, RenderOptions(), tracker={"marker_length": 0.05})
    frame = lambda: comp.process(image, want_mask=False, out=buf)[2]
for _ in range(int(sys.argv[2])):
    frame()
print("ready", flush=True)
for line in sys.stdin:
    if line.strip() != "go":
        break
    t = time.perf_counter()
    item = frame()
    print(f"{(time.perf_counter() - t) * 1e3:.4f} " + json.dumps(item.timings_ms), flush=True)
comp.close()
ctx.release()
"""


def _commit(tree: Path):
    r = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(
        ["git", "-C", str(tree), "status", "--porcelain", "arshadow"], capture_output=True, text=True
    ).stdout.strip()
    return r.stdout.strip() + ("+dirty" if dirty else "")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--a", required=True, help="source tree A (the baseline)")
    ap.add_argument("--b", required=True, help="source tree B")
    ap.add_argument("--frames", type=int, default=200, help="frames per tree (default 200)")
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--json", help="also write the result here")
    args = ap.parse_args(argv)
    trees = [Path(args.a).resolve(), Path(args.b).resolve()]
    procs = []
    for t in trees:
        env = dict(os.environ, PYTHONPATH=str(t))
        p = subprocess.Popen(
            [sys.executable, "-c", WORKER, str(t), str(args.warmup)],
            cwd=t,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        procs.append(p)
    for p in procs:
        if p.stdout.readline().strip() != "ready":
            raise SystemExit("a worker failed to start")
    times, stages = [[], []], [{}, {}]
    for i in range(args.frames):
        order = (0, 1) if i % 2 == 0 else (1, 0)
        for k in order:
            procs[k].stdin.write("go\n")
            procs[k].stdin.flush()
            total, _, st = procs[k].stdout.readline().partition(" ")
            times[k].append(float(total))
            for name, ms in json.loads(st).items():
                stages[k].setdefault(name, []).append(ms)
    for p in procs:
        p.stdin.write("stop\n")
        p.stdin.close()
        p.wait(timeout=60)
    ratios = np.asarray(times[1]) / np.asarray(times[0])
    res = {
        "benchmark": "ab_pipeline: bench_pipeline default case, interleaved frame by frame",
        **{
            ab: {
                "tree": str(trees[k]),
                "commit": _commit(trees[k]),
                "frame_ms": _common.summary(times[k]),
                "stage_ms_median": {n: round(float(np.median(v)), 3) for n, v in stages[k].items()},
            }
            for k, ab in enumerate("ab")
        },
        "ratio_b_over_a": _common.summary(ratios),
        "meta": _common.metadata(),
    }
    _common.emit(res, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
