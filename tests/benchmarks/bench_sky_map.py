"""The ground occlusion map's cost against its error: numpy (OpenCV) and GL rasterisers, directions, texels.

    python tests/benchmarks/bench_sky_map.py [--repeat 5] [--out FILE.json]

Per mesh (the issue's 4.5 x 6.5 x 7 cm box, a torus, the 8 536-face knot of samples/meshes/knot.ply) and
configuration (rasteriser, sky directions, texels), :func:`arshadow.shading.sky.ground_sky_visibility` with
the object's reflected light on (the session's call), ``repeat`` times, the configurations interleaved
round-robin so that they see the same load: median and IQR of the times (ms). The error is the map's
visibility (``taper=None``) against a 2048-direction GL map, sampled on a 300 x 300 grid of ground points
over the map's square where that reference is under 0.98: mean and 99th percentile of the absolute
difference (visibility units: 1 = the whole sky; times the sky's share of the light, 0.35-0.45 outdoors, it
is the share of a pixel's light).
"""

from __future__ import annotations

import argparse
import time

import _common
import numpy as np

ROOT = _common.ROOT
MESHES = {"box": "box:0.045,0.065,0.07", "torus": "torus:0.05,0.015", "knot": str(ROOT / "samples/meshes/knot.ply")}
#: (rasteriser, sky directions, texels per side)
CONFIGS = [("numpy", 256, 256), ("gl", 256, 256), ("gl", 128, 256), ("gl", 64, 256)]
BOUNCE = (np.array([0.3, 0.2, 0.9]), 0.4, 0.5, 0.2)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out")
    args = ap.parse_args()
    from arshadow.geometry.mesh import load_occluder
    from arshadow.gl.context import create_context
    from arshadow.gl.sky import GLGroundRaster
    from arshadow.shading.sky import ground_sky_visibility

    ctx = create_context()
    gl = GLGroundRaster(ctx)
    rasters = {"numpy": None, "gl": gl}
    result: dict = {"meta": _common.metadata(), "rows": []}
    for name, spec in MESHES.items():
        c = load_occluder(spec)
        ref = ground_sky_visibility(c, n_dirs=2048, raster=gl, taper=None, max_triangle_draws=10**9)
        x0, y0, x1, y1 = ref.extent
        pts = np.stack(np.meshgrid(np.linspace(x0, x1, 300), np.linspace(y0, y1, 300)), -1).reshape(-1, 2)
        vr = ref.sample(pts)
        active = vr < 0.98
        times: dict = {cfg: [] for cfg in CONFIGS}
        for _ in range(args.repeat):
            for cfg in CONFIGS:
                kind, n, res = cfg
                t = time.perf_counter()
                ground_sky_visibility(c, n_dirs=n, resolution=res, bounce=BOUNCE, raster=rasters[kind])
                times[cfg].append((time.perf_counter() - t) * 1e3)
        for cfg in CONFIGS:
            kind, n, res = cfg
            m = ground_sky_visibility(c, n_dirs=n, resolution=res, raster=rasters[kind], taper=None)
            e = np.abs(m.sample(pts) - vr)[active]
            row = {
                "mesh": name,
                "faces": c.n_faces,
                "raster": kind,
                "directions": m.n_dirs,
                "texels": res,
                "ms": _common.summary(times[cfg]),
                "error_mean": round(float(e.mean()), 4),
                "error_p99": round(float(np.percentile(e, 99)), 4),
            }
            result["rows"].append(row)
            print(row, flush=True)
    gl.release()
    _common.emit(result, args.out)


if __name__ == "__main__":
    main()
