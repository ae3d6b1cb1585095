"""The realism options scored against the path-traced reference (docs/reference.md, docs/shading.md).

    python tests/benchmarks/score_realism.py [--set own|heldout|plain ...] [--pose tracked|true]

Per committed case (tests/data/reference/<set>): the light measured once (``arshadow light`` with the
case's probe), then ``render --light-from`` with ``ambient_occlusion off`` (the old model: also no object
sky shading), ``on``, and ``on`` + ``camera_effects on``; prints JSON: per case the measured light's error
(``light``: degrees for a sun, % of the distance for a lamp) and per configuration the residuals (ground,
contact band, object), and per set their medians.
"""

from __future__ import annotations

import argparse
import sys

import _common
import numpy as np

ROOT = _common.ROOT
CONFIGS = {
    "off": {"ambient_occlusion": "off"},
    "sky": {"ambient_occlusion": "on"},
    "sky+camera": {"ambient_occlusion": "on", "camera_effects": "on"},
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", action="append", choices=("own", "heldout", "plain"), help="default: own and heldout")
    ap.add_argument("--pose", default="tracked", choices=("tracked", "true"))
    ap.add_argument("--out")
    args = ap.parse_args()
    from arshadow.bench.reference import light_error, load_cases, measure_light, run_case
    from arshadow.errors import EstimateError

    result: dict = {"meta": _common.metadata(), "pose": args.pose, "cases": {}, "median": {}}
    for name in args.set or ["own", "heldout"]:
        rows = {k: [] for k in CONFIGS}
        for case in load_cases(ROOT / "tests" / "data" / "reference" / name):
            try:
                est = measure_light(case.plate8, case.scene)
            except EstimateError as e:  # the estimate refuses (the trust fixes): no composite to score
                result["cases"][f"{name}/{case.scene.name}"] = {"refused": str(e)}
                print(case.scene.name, "refused:", e, file=sys.stderr, flush=True)
                continue
            entry: dict = {"light": {k: round(v, 3) for k, v in light_error(case.scene, est).items()}}
            for cfg, opts in CONFIGS.items():
                r = run_case(case, "measured", dict(opts), args.pose, est)
                entry[cfg] = {k: round(float(r[k]), 3) for k in ("ground", "contact", "object") if k in r}
                rows[cfg].append(entry[cfg])
            result["cases"][f"{name}/{case.scene.name}"] = entry
            print(case.scene.name, entry, file=sys.stderr, flush=True)
        result["median"][name] = {
            cfg: {k: round(float(np.median([r[k] for r in rs])), 3) for k in ("ground", "contact", "object")}
            for cfg, rs in rows.items()
        }
    _common.emit(result, args.out)


if __name__ == "__main__":
    main()
