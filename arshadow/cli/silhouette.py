"""``arshadow silhouette MESH --light L [--method NAME] [--json]``: silhouette edges, loops and timings."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "silhouette",
        help="print a mesh's silhouette edges for one light",
        description=(
            "Detect the silhouette of MESH (a mesh file or a primitive spec box:WX,WY,HZ, cylinder:R,H, "
            "sphere:R, torus:R,r) for one light and print the number of edges, closed loops and the "
            'detection time. With --json print {"method", "edges", "loops", "time_ms"}, each edge as '
            "its two end points [[x1, y1, z1], [x2, y2, z2]] in the mesh's own (world) coordinates, oriented "
            "as the shadow volume uses them (as the light-facing face winds them)."
        ),
    )
    p.add_argument("mesh", metavar="MESH", help="mesh file (anything trimesh reads) or primitive spec")
    p.add_argument(
        "--light",
        required=True,
        metavar="L",
        help="point:X,Y,Z | directional:X,Y,Z | sun:LAT,LON,TIME[,NORTH] (world frame, metres)",
    )
    p.add_argument(
        "--method", default="adjacency", metavar="NAME", help="adjacency (default), triangular, vnv, hsd or delta_plus"
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    p.add_argument("--scale", type=float, default=1.0, metavar="S", help="uniform scale (applied first)")
    p.add_argument("--rotate", default="0,0,0", metavar="RX,RY,RZ", help="degrees about x, y, z (second)")
    p.add_argument("--place", default="0,0,0", metavar="X,Y,Z", help="translation in metres (last)")
    p.add_argument(
        "--repeat",
        type=int,
        default=5,
        metavar="N",
        help="time N runs after one warm-up and report the median (default 5)",
    )
    p.set_defaults(func=run)


def _light_h(spec: str) -> np.ndarray:
    from ..errors import LightError
    from ..lights.spec import parse_light

    light = parse_light(spec)
    if not light.above_horizon:
        raise LightError(f"light {spec!r} is below the horizon: it casts no shadow")
    return light.homogeneous


def run(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from ..errors import UsageError
    from ..geometry.mesh import load_occluder
    from ..geometry.silhouette import METHODS, silhouette, silhouette_loops
    from ..scene.spec import parse_triple

    if args.method not in METHODS:
        raise UsageError(f"unknown --method {args.method!r} (choose from {', '.join(METHODS)})")
    if args.repeat < 1:
        raise UsageError("--repeat must be at least 1")
    light_h = _light_h(args.light)
    t0 = time.perf_counter()
    caster = load_occluder(
        args.mesh,
        scale=args.scale,
        rotate=parse_triple(args.rotate, "--rotate"),
        place=parse_triple(args.place, "--place"),
    )
    t1 = time.perf_counter()
    sil = silhouette(caster, light_h, args.method)  # warm-up: builds the per-mesh caches
    t2 = time.perf_counter()
    times = []
    for _ in range(args.repeat):
        s0 = time.perf_counter()
        sil = silhouette(caster, light_h, args.method)
        times.append((time.perf_counter() - s0) * 1e3)
    time_ms = float(np.median(times))
    loops, n_open = silhouette_loops(sil.edges)
    if args.json:
        v = caster.vertices
        out = {
            "method": args.method,
            "edges": np.stack([v[sil.edges[:, 0]], v[sil.edges[:, 1]]], axis=1).tolist(),
            "loops": len(loops),
            "time_ms": round(time_ms, 4),
        }
        json.dump(out, sys.stdout)
        sys.stdout.write("\n")
        return 0
    kind = "closed" if caster.is_closed else "open/two-sided"
    print(
        f"{caster.name}: {len(caster.vertices)} vertices, {caster.n_faces} faces ({kind}"
        + (f", {caster.n_dropped_faces} degenerate dropped" if caster.n_dropped_faces else "")
        + ")"
    )
    print(f"light: {args.light} -> {np.round(light_h, 6).tolist()}")
    print(
        f"{args.method}: {sil.n_edges} silhouette edges, {len(loops)} loops"
        + (f", {n_open} edges not in closed loops" if n_open else "")
    )
    print(
        f"time: {time_ms:.3f} ms per light (median of {args.repeat}, min {min(times):.3f}, max {max(times):.3f}); "
        f"load {(t1 - t0) * 1e3:.1f} ms, first call incl. preparation {(t2 - t1) * 1e3:.1f} ms"
    )
    ops = {k: v for k, v in sil.stats.items() if k not in ("time_ms", "n_edges")}
    print("operations: " + ", ".join(f"{k} {v}" for k, v in ops.items()))
    return 0
