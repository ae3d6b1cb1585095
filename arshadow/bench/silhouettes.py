"""Section 1: silhouette detectors - time per light against mesh size, error against the exact silhouette,
and the paper-faithful reference versions' operation counts against the papers' formulas.

The exact silhouette of a closed mesh for a light is the set of edges between a light-facing and a
light-averted face (one exact float64 sign test per face); the ``adjacency`` detector computes exactly
that, and :mod:`arshadow.geometry.silhouette_reference` (independent loops) checks it on the small meshes.
"""

from __future__ import annotations

import importlib.util
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..geometry.mesh import ShadowCaster, load_occluder
from ..geometry.silhouette import METHODS, as_light_h, silhouette
from ..geometry.silhouette_reference import (
    delta_plus_reference,
    paper000_formulas,
    paper003_claim,
    ta_reference,
    vnv_reference,
)
from .common import ROOT, summary, t_fields, timed

#: (n_seg, n_side) of the torus-knot tube for ~n faces (2 n_seg n_side triangles)
KNOT_RES = {200: (10, 10), 1470: (49, 15), 10000: (100, 50), 100000: (500, 100), 1000000: (2500, 200)}


def torus_knot(n_faces: int) -> ShadowCaster:
    """A closed, non-convex (2, 3) torus-knot tube with ``n_faces`` triangles (samples/make_meshes.py)."""
    spec = importlib.util.spec_from_file_location("make_meshes", ROOT / "samples" / "make_meshes.py")
    assert spec is not None and spec.loader is not None  # a .py file path: always a spec with a loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    v, f, _ = mod.torus_knot(*KNOT_RES[n_faces])
    return ShadowCaster(v, f, name=f"knot{n_faces}")


def meshes(sizes: Sequence[int]) -> list[tuple[str, ShadowCaster]]:
    """``[(label, caster)]``: the cube (12 triangles, 18 edges) and torus knots of the given sizes."""
    out = [("cube", load_occluder("box:0.1,0.1,0.1"))]
    return out + [(f"knot {n}", torus_knot(n)) for n in sizes]


def lights(caster: ShadowCaster, n: int, seed: int = 7) -> list[np.ndarray]:
    """``n`` lights around the caster: alternately point lights at 2-8 x its half-size and directions."""
    rng = np.random.default_rng(seed)
    c = caster.bounds.mean(axis=0)
    r = 0.5 * caster.scale
    out = []
    for i in range(n):
        d = rng.normal(size=3)
        d[2] = abs(d[2]) + 0.3
        d /= np.linalg.norm(d)
        out.append(as_light_h(np.r_[c + d * r * rng.uniform(2.0, 8.0), 1.0] if i % 2 == 0 else np.r_[d, 0.0]))
    return out


def _edge_set(e: np.ndarray) -> set[tuple]:
    return {tuple(x) for x in np.asarray(e).tolist()}


def detectors(cfg: dict, log: Callable[[str], None]) -> list[dict]:
    """Time per light and error of every detector at every mesh size."""
    rows = []
    for label, c in meshes(cfg["sizes"]):
        t0 = time.perf_counter()
        _ = c.face_planes, c.edges, c.closed_edge_faces, c.polygons  # one-time preparation (cached)
        prep = (time.perf_counter() - t0) * 1e3
        Ls = lights(c, cfg["lights"])
        exact = [_edge_set(silhouette(c, L).edges) for L in Ls]
        for m in METHODS:
            nl, rep = len(Ls), cfg["repeat"]
            if m == "delta_plus" and c.n_faces >= 100000:
                nl, rep = min(nl, 2), 1
            ts, missed, extra, total = [], 0, 0, 0
            for L, ex in zip(Ls[:nl], exact, strict=True):
                ts += timed(lambda: silhouette(c, L, m), rep)
                got = _edge_set(silhouette(c, L, m).edges)
                missed += len(ex - got)
                extra += len(got - ex)
                total += len(ex)
            rows.append(
                {
                    "mesh": label,
                    "faces": c.n_faces,
                    "edges": len(c.edges),
                    "method": m,
                    "lights": nl,
                    **t_fields("time", ts),
                    "prepare_ms": round(prep, 3),
                    "missed_edges_frac": missed / max(total, 1),
                    "extra_edges_frac": extra / max(total, 1),
                    "exact_lights": None,
                }
            )
        log(f"  silhouettes: {label} ({c.n_faces} faces) done")
    return rows


def reference_ops(cfg: dict, log: Callable[[str], None]) -> list[dict]:
    """Reference versions on small meshes: counted operations, time, same edges as the fast detectors,
    next to the paper's formula at the same n (faces) and m (3 sides, triangles)."""
    rows = []
    for label, c in meshes(cfg["ref_sizes"]):
        L = lights(c, 1, seed=3)[0]
        n = c.n_faces
        formula = paper000_formulas(n, 3)
        for name, fn, fast, key in (
            ("TA", ta_reference, "triangular", "compares"),
            ("VnV", vnv_reference, "vnv", "pairs"),
            ("Delta+", delta_plus_reference, "delta_plus", "ray_face_tests"),
        ):
            if name == "VnV" and n > cfg["vnv_max_faces"]:
                continue
            t0 = time.perf_counter()
            e, cnt = fn(c.vertices, c.faces, L, planes=c.face_planes)
            t_ref = (time.perf_counter() - t0) * 1e3
            s = silhouette(c, L, fast)
            t_fast = summary(timed(lambda: silhouette(c, L, fast), cfg["repeat"]))["median"]
            row = {
                "mesh": label,
                "faces": n,
                "vertices": len(c.vertices),
                "edges": len(c.edges),
                "algorithm": name,
                "counted_ops": cnt[key],
                "counted_what": key,
                "reference_ms": round(t_ref, 3),
                "fast_detector": fast,
                "fast_ms": t_fast,
                "same_edges": _edge_set(e) == _edge_set(s.edges),
                "formula_total": formula.get(name, {}).get("total") if name != "Delta+" else None,
                "formula_main_term": (formula[name]["C"] if name == "TA" else formula[name]["M"])
                if name != "Delta+"
                else None,
            }
            if name == "Delta+":
                V = len(c.vertices)
                row.update(
                    paper_n_log2_n=V * math.log2(V),
                    paper_n2=float(V) ** 2,
                    no_early_exit_tests=cnt["ray_face_tests_no_early_exit"],
                    fast_bvh_tests=int(
                        s.stats.get("node_tests", 0) + s.stats.get("triangle_tests", 0) + s.stats.get("local_tests", 0)
                    ),
                )
            rows.append(row)
        log(f"  reference detectors: {label} done")
    return rows


def paper_tables() -> list[dict]:
    """[Kolivand-HSD] Figs. 5-6 (formulas of sec. VI at n = 10, m = 5 and n = 100, m = 10), the 2 M-face ratio
    claim, and [Kolivand-DeltaPlus] Table II - all computed from the papers' own formulas (labelled as such)."""
    rows = []
    for n, m in ((10, 5), (100, 10), (2_000_000, 3)):
        f = paper000_formulas(n, m)
        for name in ("TA", "VnV", "HSD"):
            rows.append(
                {
                    "source": "[Kolivand-HSD] sec. VI formula",
                    "n": n,
                    "m": m,
                    "algorithm": name,
                    **{k: f[name][k] for k in ("C", "R", "M", "A", "W", "total")},
                    "ratio_to_HSD": f[name]["total"] / f["HSD"]["total"],
                }
            )
    p = paper003_claim(5000)
    rows.append(
        {"source": "[Kolivand-DeltaPlus] Table II", "n": 5000, "algorithm": "BSB/HFC O(n^2)", "total": p["quadratic"]}
    )
    rows.append(
        {
            "source": "[Kolivand-DeltaPlus] Table II",
            "n": 5000,
            "algorithm": "Delta+ O(n log2 n)",
            "total": p["n_log2_n"],
        }
    )
    return rows


def hsd_vs_ta(cfg: dict) -> list[dict]:
    """HSD's edge operations and time against TA on flat-faced and curved meshes ([Kolivand-HSD]'s claim that
    HSD does fewer operations and is faster)."""
    rows = []
    for label, c in (
        ("box", load_occluder("box:0.1,0.1,0.1")),
        ("house", load_occluder(ROOT / "samples" / "meshes" / "house.obj")),
        ("cylinder", load_occluder("cylinder:0.05,0.1")),
        ("knot 8536", load_occluder(ROOT / "samples" / "meshes" / "knot.ply")),
    ):
        Ls = lights(c, 6, seed=5)
        ta = [silhouette(c, L, "triangular").stats["edge_ops"] for L in Ls]
        hs = [silhouette(c, L, "hsd").stats["edge_ops"] for L in Ls]
        tt, th = [], []
        for L in Ls:  # interleaved
            tt += timed(lambda: silhouette(c, L, "triangular"), cfg["repeat"])
            th += timed(lambda: silhouette(c, L, "hsd"), cfg["repeat"])
        rows.append(
            {
                "mesh": label,
                "faces": c.n_faces,
                "polygons": len(c.polygons["planes"]),
                "ta_edge_ops": float(np.mean(ta)),
                "hsd_edge_ops": float(np.mean(hs)),
                "ops_ratio_hsd_ta": float(np.mean(hs) / np.mean(ta)),
                **t_fields("ta", tt),
                **t_fields("hsd", th),
            }
        )
    return rows


def run(cfg: dict, log: Callable[[str], None]) -> dict:
    return {
        "detectors": detectors(cfg, log),
        "reference": reference_ops(cfg, log),
        "paper": paper_tables(),
        "hsd_vs_ta": hsd_vs_ta(cfg),
    }
