"""Geometry benchmark: silhouette detectors, volume construction and one-time preparation, at 1k, 10k,
100k and 1M faces; plus the measured disagreement of Delta+ ([Kolivand-DeltaPlus]) with the exact silhouette and
with the outline seen from the light, and HSD's edge operations against TA.

    python tests/benchmarks/bench_geometry.py [--sizes 1000,10000,100000,1000000] [--lights 10]
        [--repeat 5] [--out FILE.json] [--skip-delta-measure]

Prints (and optionally writes) JSON: per size and detector the time per light in ms (median, IQR, min,
max over lights x repeats, each after a warm-up call), preparation and volume construction times, and
metadata (git commit, versions, CPU count, load average). Meshes are (2, 3) torus-knot tubes (closed,
non-convex) from samples/make_meshes.py. The machine is shared: read the min beside the median.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import _common  # noqa: E402

from arshadow.geometry.mesh import ShadowCaster, load_occluder  # noqa: E402
from arshadow.geometry.silhouette import METHODS, silhouette  # noqa: E402
from arshadow.geometry.volume import shadow_volume  # noqa: E402


def _make_meshes_module():
    spec = importlib.util.spec_from_file_location("make_meshes", ROOT / "samples" / "make_meshes.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


KNOT_RES = {1000: (25, 20), 10000: (125, 40), 100000: (500, 100), 1000000: (2500, 200)}


def _lights(caster, n, seed=7):
    from arshadow.bench.silhouettes import lights

    return lights(caster, n, seed)


def _timed(fn, repeat):
    return _common.timed(fn, repeat)


def bench_size(n_faces: int, n_lights: int, repeat: int, methods=METHODS, volumes: bool = True) -> dict:
    mm = _make_meshes_module()
    v, f, _ = mm.torus_knot(*KNOT_RES[n_faces])
    t0 = time.perf_counter()
    c = ShadowCaster(v, f)
    t1 = time.perf_counter()
    _ = c.face_planes, c.edges, c.closed_edge_faces, c._facing_prep  # adjacency detector's preparation
    t2 = time.perf_counter()
    _ = c.polygons  # HSD
    t3 = time.perf_counter()
    from arshadow.geometry._bvh import _tree

    _tree(c)  # Delta+
    t4 = time.perf_counter()
    out = {
        "faces": c.n_faces,
        "vertices": len(c.vertices),
        "edges": len(c.edges),
        "prepare_ms": {
            "weld_validate": round((t1 - t0) * 1e3, 2),
            "adjacency_planes": round((t2 - t1) * 1e3, 2),
            "hsd_polygons": round((t3 - t2) * 1e3, 2),
            "delta_plus_bvh": round((t4 - t3) * 1e3, 2),
        },
        "detectors_ms": {},
        "volume_ms": {},
        "silhouette_edges": {},
    }
    lights = _lights(c, n_lights)
    for m in methods:
        ts = []
        nl, rp = n_lights, repeat
        if m == "delta_plus" and n_faces >= 100000:
            nl, rp = min(n_lights, 4 if n_faces == 100000 else 2), 1
        for L in lights[:nl]:
            ts += _timed(lambda: silhouette(c, L, m), rp)
        out["detectors_ms"][m] = _common.summary(ts, 4)
    ne = [silhouette(c, L).n_edges for L in lights]
    out["silhouette_edges"] = {"median": float(np.median(ne)), "min": int(min(ne)), "max": int(max(ne))}
    tz = -1e-3 * c.scale
    for label, kw in (
        ()
        if not volumes
        else (
            ("zpass_sides", {"caps": False}),
            ("zfail_caps", {"caps": True}),
            ("truncated_caps", {"caps": True, "truncate_z": tz}),
            ("truncated_sides", {"caps": False, "truncate_z": tz}),
        )
    ):
        ts = []
        for L in lights:
            s = silhouette(c, L)
            ts += _timed(lambda: shadow_volume(c, L, s, **kw), repeat)
        out["volume_ms"][label] = _common.summary(ts, 4)
    return out


# ---------------------------------------------------------------------------- Delta+ disagreement
def _project_2d(points, L, centre):
    """Project points as seen from the light onto a plane perpendicular to the view direction."""
    if L[3] == 0:
        fwd = -L[:3] / np.linalg.norm(L[:3])
    else:
        fwd = centre - L[:3]
        fwd /= np.linalg.norm(fwd)
    a = np.array([1.0, 0, 0]) if abs(fwd[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(fwd, a)
    u /= np.linalg.norm(u)
    w = np.cross(fwd, u)
    if L[3] == 0:
        return np.stack([points @ u, points @ w], axis=-1)
    rel = points - L[:3]
    z = rel @ fwd
    return np.stack([(rel @ u) / z, (rel @ w) / z], axis=-1)


def _covered(pts2, tri2, chunk=400):
    """Is each 2-D point inside any 2-D triangle (either orientation, edges inclusive)?"""
    out = np.zeros(len(pts2), bool)
    a, b, c = tri2[:, 0], tri2[:, 1], tri2[:, 2]
    for s in range(0, len(pts2), chunk):
        p = pts2[s : s + chunk, None, :]

        def ef(x, y):
            return (y[None, :, 0] - x[None, :, 0]) * (p[..., 1] - x[None, :, 1]) - (y[None, :, 1] - x[None, :, 1]) * (
                p[..., 0] - x[None, :, 0]
            )

        e0, e1, e2 = ef(a, b), ef(b, c), ef(c, a)
        ins = ((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0))
        out[s : s + chunk] = ins.any(axis=1)
    return out


def outline_classes(c, L, edges, n_samples=5, rel_off=1e-5):
    """Classify edges as seen from the light: for ``n_samples`` points along each (projected) edge,
    offset a little to both sides, is either side outside the projection of the whole mesh? Returns
    (k,) int: 2 = every sample on the outline, 1 = some (partly hidden), 0 = none (hidden)."""
    centre = c.bounds.mean(axis=0)
    tri2 = _project_2d(c.triangles.reshape(-1, 3), L, centre).reshape(-1, 3, 2)
    p2 = _project_2d(c.vertices[edges[:, 0]], L, centre)
    q2 = _project_2d(c.vertices[edges[:, 1]], L, centre)
    d = q2 - p2
    ln = np.linalg.norm(d, axis=1)
    nrm = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.maximum(ln, 1e-300)[:, None]
    ts = (np.arange(n_samples) + 0.5) / n_samples
    samples = p2[:, None, :] + ts[None, :, None] * d[:, None, :]
    off = (rel_off * ln)[:, None, None] * nrm[:, None, :]
    left = _covered((samples + off).reshape(-1, 2), tri2).reshape(len(edges), n_samples)
    right = _covered((samples - off).reshape(-1, 2), tri2).reshape(len(edges), n_samples)
    on = ~(left & right)
    return np.where(on.all(axis=1), 2, np.where(on.any(axis=1), 1, 0))


def delta_plus_disagreement(c: ShadowCaster, n_lights: int, eps: float = 1e-6) -> dict:
    from arshadow.geometry.silhouette import silhouette_loops

    tot = {
        "transition_edges": 0,
        "delta_edges": 0,
        "delta_in_transition": 0,
        "missed_transitions": 0,
        "extra_edges": 0,
        "outline_full": 0,
        "outline_partial": 0,
        "delta_on_full_outline": 0,
        "delta_on_partial_outline": 0,
        "full_outline_missed": 0,
        "lights_with_open_loops": 0,
        "lights_exact": 0,
    }
    for L in _lights(c, n_lights, seed=11):
        A = silhouette(c, L)
        D = silhouette(c, L, "delta_plus", eps=eps)
        a = {tuple(e) for e in A.edges.tolist()}
        d = {tuple(e) for e in D.edges.tolist()}
        cls = outline_classes(c, L, A.edges)
        full = {tuple(e) for e, k in zip(A.edges.tolist(), cls, strict=True) if k == 2}
        part = {tuple(e) for e, k in zip(A.edges.tolist(), cls, strict=True) if k == 1}
        tot["transition_edges"] += len(a)
        tot["delta_edges"] += len(d)
        tot["delta_in_transition"] += len(d & a)
        tot["missed_transitions"] += len(a - d)
        tot["extra_edges"] += len(d - a)
        tot["outline_full"] += len(full)
        tot["outline_partial"] += len(part)
        tot["delta_on_full_outline"] += len(d & full)
        tot["delta_on_partial_outline"] += len(d & part)
        tot["full_outline_missed"] += len(full - d)
        _, n_open = silhouette_loops(D.edges)
        tot["lights_with_open_loops"] += n_open > 0
        tot["lights_exact"] += a == d
    tot["lights"] = n_lights
    tot["recall_vs_transitions"] = round(tot["delta_in_transition"] / max(tot["transition_edges"], 1), 4)
    tot["precision_vs_transitions"] = round(tot["delta_in_transition"] / max(tot["delta_edges"], 1), 4)
    tot["recall_vs_full_outline"] = round(tot["delta_on_full_outline"] / max(tot["outline_full"], 1), 4)
    tot["eps"] = eps
    return tot


def hsd_vs_ta_ops(c: ShadowCaster, n_lights: int = 50) -> dict:
    ta, hsd = [], []
    for L in _lights(c, n_lights, seed=3):
        ta.append(silhouette(c, L, "triangular").stats["edge_ops"])
        hsd.append(silhouette(c, L, "hsd").stats["edge_ops"])
    return {
        "faces": c.n_faces,
        "polygons": len(c.polygons["planes"]),
        "ta_edge_ops_mean": float(np.mean(ta)),
        "hsd_edge_ops_mean": float(np.mean(hsd)),
        "ratio": round(float(np.mean(hsd) / np.mean(ta)), 4),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000,10000,100000,1000000")
    ap.add_argument("--lights", type=int, default=10)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--delta-lights", type=int, default=20)
    ap.add_argument("--skip-delta-measure", action="store_true", help="skip the Delta+ and HSD/TA sections")
    ap.add_argument("--methods", default=",".join(METHODS), help="detectors to time (comma separated)")
    ap.add_argument("--no-volumes", action="store_true", help="skip volume construction timings")
    ap.add_argument("--out")
    a = ap.parse_args(argv)
    res = {"meta": _common.metadata(), "sizes": {}}
    for n in [int(x) for x in a.sizes.split(",")]:
        res["sizes"][str(n)] = bench_size(n, a.lights, a.repeat, a.methods.split(","), not a.no_volumes)
        print(f"# {n} faces done", file=sys.stderr)
    samples = ROOT / "samples" / "meshes"
    if a.skip_delta_measure:
        pass
    else:
        res["delta_plus"] = {
            "knot_8536": delta_plus_disagreement(load_occluder(samples / "knot.ply"), a.delta_lights),
            "torus_4096": delta_plus_disagreement(load_occluder("torus:0.04,0.012"), a.delta_lights),
            "icosphere_1280": delta_plus_disagreement(load_occluder("sphere:0.05"), a.delta_lights),
            "house_28": delta_plus_disagreement(load_occluder(samples / "house.obj"), a.delta_lights),
        }
    res["hsd_vs_ta"] = (
        {}
        if a.skip_delta_measure
        else {
            "box": hsd_vs_ta_ops(load_occluder("box:0.1,0.1,0.1")),
            "house": hsd_vs_ta_ops(load_occluder(samples / "house.obj")),
            "cylinder": hsd_vs_ta_ops(load_occluder("cylinder:0.05,0.1")),
            "knot": hsd_vs_ta_ops(load_occluder(samples / "knot.ply"), 10),
        }
    )
    _common.emit(res, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
