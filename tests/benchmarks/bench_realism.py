"""Cost of the issue-28 realism options on one 720p photo (plain script; prints JSON).

    python tests/benchmarks/bench_realism.py [--repeat 15] [--compose auto|cpu|gpu] [--model SPEC] [--out FILE.json]

The light sample (samples/probe_shadow.jpg, 1280 x 720): the light measured by ``arshadow light`` with the
sample's probe, then a 4.5 x 6.5 x 7 cm box rendered with ``light_from`` (a session per configuration,
frames after the first): everything off (``ambient_occlusion off``, ``camera_effects off``), sky occlusion on,
and everything on (plus camera effects), and ``plain``: off with the outline's anti-aliasing off too (the
default before the realism work; ``ratio_to_plain``). The configurations are interleaved frame by frame so that they see
the same machine load; per configuration the median, IQR and min of the frame times (ms), and the paired
ratio to "off" (median and IQR). The first frame of each (the ground occlusion map, the buffers) is
reported apart (``first_ms``); ``compose`` gives each configuration's compose path and its reason.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _common
import numpy as np

ROOT = _common.ROOT
CONFIGS = {
    # the default before the realism work: no sky occlusion, no camera effects, pixel-centre outline
    "plain": {"ambient_occlusion": "off", "camera_effects": "off", "outline_aa": "off"},
    "off": {"ambient_occlusion": "off", "camera_effects": "off"},
    "sky": {"ambient_occlusion": "on", "camera_effects": "off"},
    "all": {"ambient_occlusion": "on", "camera_effects": "on"},
}


def _ratios(times: dict, base: str) -> dict:
    """Per configuration but ``base``: the median and IQR of its frame times over ``base``'s, paired."""
    b = np.array(times[base])
    out = {}
    for k, v in times.items():
        if k != base:
            r = np.array(v) / b
            out[k] = {
                "median": round(float(np.median(r)), 3),
                "iqr": [round(float(q), 3) for q in np.percentile(r, [25, 75])],
            }
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--out")
    ap.add_argument("--compose", choices=("auto", "cpu", "gpu"), default="auto", help="the sessions' compose path")
    ap.add_argument("--model", default="box:0.045,0.065,0.07", help="the object (a torus: its light on itself)")
    args = ap.parse_args()
    from arshadow.frame.session import Session
    from arshadow.io import read_image
    from arshadow.scene.spec import scene_from_dict

    photo = ROOT / "samples" / "probe_shadow.jpg"
    base = {
        "calib": str(ROOT / "calib" / "synth_1280x720.yml"),
        "marker_length": 0.05,
        "dictionary": "DICT_6X6_250",
        "model": args.model,
        "place": (-0.02, 0.1, 0.0),
        "compose": args.compose,
    }
    with tempfile.TemporaryDirectory() as tmp:
        light = Path(tmp) / "light.json"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "arshadow",
                "light",
                str(photo),
                "--calib",
                base["calib"],
                "--marker-length",
                "0.05",
                "--dictionary",
                "DICT_6X6_250",
                "--probe",
                "box:0.05,0.05,0.1",
                "--probe-place",
                "0.1,0.02,0",
                "-o",
                str(light),
            ],
            check=True,
            capture_output=True,
        )
        image = read_image(photo)
        sessions, first, roi, compose = {}, {}, {}, {}
        for name, opts in CONFIGS.items():
            s = Session(scene_from_dict({**base, **opts, "light_from": str(light)}))
            t = time.perf_counter()
            s.process(image, want_mask=False)
            first[name] = (time.perf_counter() - t) * 1e3
            sessions[name] = s
        times = {k: [] for k in CONFIGS}
        stages = {k: [] for k in CONFIGS}
        for i in range(args.repeat):
            order = list(CONFIGS) if i % 2 == 0 else list(CONFIGS)[::-1]
            for name in order:
                t = time.perf_counter()
                res = sessions[name].process(image, want_mask=False)
                times[name].append((time.perf_counter() - t) * 1e3)
                stages[name].append(dict(res.item.timings_ms))
                roi[name] = res.item.roi
                compose[name] = [res.item.compose, (res.item.plan or {}).get("compose")]
        for s in sessions.values():
            s.close()
    result = {
        "meta": _common.metadata(),
        "first_ms": {k: round(v, 1) for k, v in first.items()},
        "frame_ms": {k: _common.summary(v) for k, v in times.items()},
        "stage_median_ms": {
            k: {st: round(float(np.median([d.get(st, 0.0) for d in v])), 2) for st in v[0]} for k, v in stages.items()
        },
        "roi": roi,
        "compose": compose,
        "ratio_to_off": _ratios(times, "off"),
        "ratio_to_plain": _ratios(times, "plain"),
    }
    _common.emit(result, args.out)


if __name__ == "__main__":
    main()
