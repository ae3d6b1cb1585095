"""A/B benchmark: the 720p photo pipeline with the compositing layers off and on (the compositing-layers work: on <= 15 %).

    python tests/benchmarks/ab_layers.py [--frames 200] [--warmup 10] [--write png|exr] [--quick]

One process, one Session (samples/knot_point.jpg, 1280 x 720, the knot under its first light, as
bench_pipeline.py's default row); the photo is processed with ``layers=False`` and ``layers=True`` in
turn (the order alternating every pair), so both see the same machine load. Prints JSON: per variant the
median, IQR and min of the frame times, the median of the paired ratios on / off with its IQR, and (with
``--write``) the median time of writing one frame's three layer files (not part of the pipeline: an
encoder's cost, like writing the composite).

"Off costs nothing" is the A/B between trees: ``python tests/benchmarks/ab_pipeline.py --a MAIN --b THIS``.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # run from a checkout: this tree's arshadow

import _common  # noqa: E402 (after the sys.path line: this tree's arshadow)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=200, help="pairs of frames timed (default 200)")
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--write", choices=("png", "exr"), help="also time writing the layer files")
    ap.add_argument("--quick", action="store_true", help="10 pairs, 2 warm-up frames: only proves it runs")
    ap.add_argument("--json", metavar="OUT", help="also write the result here")
    args = ap.parse_args(argv)
    if args.quick:
        args.frames, args.warmup = 10, 2

    import arshadow
    from arshadow.export.layerfiles import layer_paths, write_layers
    from arshadow.io import read_image

    sc = next(
        s
        for s in json.loads((ROOT / "samples" / "scenes.json").read_text())["scenes"]
        if s["photo"] == "knot_point.jpg"
    )
    spec = arshadow.scene_from_dict(
        {
            "calib": str(ROOT / "calib" / "synth_1280x720.yml"),
            "marker_length": 0.05,
            "model": str(ROOT / sc["model"]),
            "rotate": sc.get("rotate", (0, 0, 0)),
            "place": sc.get("place", (0, 0, 0)),
            "lights": [sc["lights"][0]],
        }
    )
    image = read_image(ROOT / "samples" / "knot_point.jpg")
    buf = np.empty_like(image)
    times = {"off": [], "on": []}
    compose = {"off": set(), "on": set()}
    write_ms = []
    with arshadow.Session(spec) as s, tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.warmup):
            s.process(image, want_mask=False, out=buf)
            s.process(image, want_mask=False, out=buf, layers=True)
        for i in range(args.frames):
            for variant in ("off", "on") if i % 2 == 0 else ("on", "off"):
                t = time.perf_counter()
                res = s.process(image, want_mask=False, out=buf, layers=variant == "on")
                times[variant].append((time.perf_counter() - t) * 1e3)
                compose[variant].add(res.item.compose)
                if variant == "on" and args.write and i < 20:
                    t = time.perf_counter()
                    write_layers(layer_paths(tmp, "frame", args.write), res.layers, args.write)
                    write_ms.append((time.perf_counter() - t) * 1e3)
    off, on = np.asarray(times["off"]), np.asarray(times["on"])
    ratio = on / off
    result = {
        "benchmark": "ab_layers",
        "meta": _common.metadata(),
        "photo": "samples/knot_point.jpg 1280x720",
        "frames": args.frames,
        "off": _common.summary(off),
        "on": _common.summary(on),
        "compose_path": {k: sorted(str(v) for v in vs) for k, vs in compose.items()},
        "ratio_on_off": {
            "median": round(float(np.median(ratio)), 4),
            "iqr": [round(float(np.percentile(ratio, q)), 4) for q in (25, 75)],
        },
        "budget": "on <= 1.15 x off (the compositing-layers work)",
    }
    if write_ms:
        result["write_ms_median"] = round(float(np.median(write_ms)), 2)
    _common.emit(result, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
