"""Render the path-traced reference cases with Mitsuba 3 (the ``reference`` extra) and store them small.

    pip install -e '.[reference]'
    python tests/reference/make_reference.py                 # both sets -> tests/data/reference/{own,heldout}
    python tests/reference/make_reference.py --only box_sun  # one case
    python tests/reference/make_reference.py --score         # also run arshadow on them and print residuals

The scenes are :data:`arshadow.bench.reference_sets.OWN` (the project's own, for development) and
:data:`arshadow.bench.reference_sets.HELDOUT` (other objects, lights, floors and cameras: for judging).
docs/reference.md explains the residual, the noise floor and the baseline.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from arshadow import ArshadowError
from arshadow.bench.reference import make_case, run_case, save_case
from arshadow.bench.reference_sets import SETS

ROOT = Path(__file__).resolve().parents[2] / "tests" / "data" / "reference"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT, help="folder of the sets (default tests/data/reference)")
    ap.add_argument("--set", choices=sorted(SETS), action="append", help="only this set (repeatable)")
    ap.add_argument("--only", action="append", help="only the case of this name (repeatable)")
    ap.add_argument("--spp", type=int, help="samples per pixel (default: the scene's, 64)")
    ap.add_argument("--keep", type=Path, help="also write the full-frame float renders here (not committed)")
    ap.add_argument("--score", action="store_true", help="run arshadow on each case and print its residuals")
    args = ap.parse_args(argv)
    for set_name in args.set or sorted(SETS):
        for sc in SETS[set_name]():
            if args.only and sc.name not in args.only:
                continue
            if args.spp:
                sc.spp = args.spp
            t0 = time.perf_counter()
            case, full = make_case(sc)
            save_case(args.out / set_name, case)
            if args.keep:
                args.keep.mkdir(parents=True, exist_ok=True)
                arrays = {k: full[k].astype(np.float32) for k in ("plate", "truth", "truth2")}
                np.savez_compressed(args.keep / f"{sc.name}.npz", **arrays)
            line = {"set": set_name, "case": sc.name, "seconds": round(time.perf_counter() - t0, 1)}
            line["noise_floor"] = {k: round(v, 4) for k, v in case.info["noise_floor_crop"].items()}
            if args.score:
                for light, pose in (("measured", "tracked"), ("true", "tracked"), ("measured", "true")):
                    try:
                        r = run_case(case, light, pose=pose)
                    except ArshadowError as exc:  # e.g. the probe's shadow out of view: change the scene
                        line[f"{light}_light_{pose}_pose"] = f"error: {exc}"
                        continue
                    line[f"{light}_light_{pose}_pose"] = {k: round(v, 4) for k, v in r.items() if not k.endswith("_px")}
            print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
