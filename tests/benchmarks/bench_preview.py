"""Benchmark: ``arshadow preview``'s server time per drag frame at 720p (the knot sample, one point light).

    python tests/benchmarks/bench_preview.py [--steps 40] [--model samples/meshes/knot.ply] [--json OUT]

Drives the preview's engine as the page does (no browser, no HTTP): a drag of ``--steps`` pointer moves
along a path on the ground (draft frames: :mod:`arshadow.preview.draft`), then the release (the exact
render ``arshadow render`` writes), repeated ``--drags`` times; also ``--steps`` turns of the object by
the slider (drafts too) and the same moves rendered exactly (``draft`` false: a new mesh each time).
Prints JSON: per kind, the median, IQR, min/max of the server's times for the request: ``wait`` (queue),
``prepare`` (scene check, pose lookup, drag ray cast), ``render`` (the session's render of the frame),
``encode`` (lossless BMP) and ``total``, with the machine's load at start and end.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _common  # noqa: E402

ROOT = _common.ROOT


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=40, help="pointer moves per drag (default 40)")
    ap.add_argument("--drags", type=int, default=3, help="drags (default 3)")
    ap.add_argument("--model", default=str(ROOT / "samples" / "meshes" / "knot.ply"))
    ap.add_argument("--json", metavar="OUT", help="also write the JSON here")
    args = ap.parse_args(argv)

    from arshadow.preview.engine import Media, PreviewEngine

    base = {
        "calib": str(ROOT / "calib" / "synth_1280x720.yml"),
        "marker_length": 0.05,
        "model": args.model,
        "place": [0.1, 0.05, 0.0],
        "rotate": [0.0, 0.0, 15.0],
        "lights": ["point:-0.12,0.2,0.42"],
    }
    controls = {"place": [0.1, 0.05, 0.0], "rotate": [0.0, 0.0, 15.0], "scale": 1.0}
    meta = _common.metadata()
    times: dict[str, dict[str, list]] = {
        k: {"wait": [], "prepare": [], "render": [], "encode": [], "total": []}
        for k in ("drag_draft", "release_exact", "turn_draft", "drag_exact")
    }
    with tempfile.TemporaryDirectory() as tmp:
        engine = PreviewEngine(Media(ROOT / "samples" / "knot_point.jpg"), base, Path(tmp) / "s.yml")
        try:

            def go(kind, **body):
                r = engine.render(engine.request({"controls": controls, **body}))
                if kind:
                    assert r["draft"] == kind.endswith("draft"), (kind, r["draft"])
                    for k in times[kind]:
                        times[kind][k].append(r["server_ms"][k])

            go(None)  # the session and its context
            go(None, drag_to=[700.0, 420.0], draft=True)  # the drafts' session (once per scale / options)
            for d in range(args.drags):
                for i in range(args.steps):
                    f = i / max(args.steps - 1, 1)
                    go("drag_draft", drag_to=[600.0 + 300.0 * f, 380.0 + 120.0 * f + 10.0 * d], draft=True)
                go("release_exact", drag_to=[900.0, 500.0 + 10.0 * d])
            for i in range(args.steps):
                go("turn_draft", draft=True, controls={**controls, "rotate": [0.0, 0.0, 15.0 + 4.0 * i]})
            for i in range(args.steps):
                f = i / max(args.steps - 1, 1)
                go("drag_exact", drag_to=[600.0 + 300.0 * f, 380.0 + 120.0 * f])
        finally:
            engine.close()
    result = {
        "benchmark": "preview drag, 1280x720, knot (8 536 faces), one point light",
        "server_ms": {k: {s: _common.summary(v) for s, v in d.items()} for k, d in times.items()},
        "meta": meta,
    }
    _common.emit(result, args.json)
    return result


if __name__ == "__main__":
    main()
