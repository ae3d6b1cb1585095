"""What the ground's "outside" error is made of (the realism work; docs/reference.md, 2026-11-29). Needs Mitsuba.

    python tests/benchmarks/decompose_outside.py [--set own] [--only NAME ...] [--spp 256] [--no-taper]
                                                 [--cache DIR] [--out F.json]

Per case, the ``oracle`` pipeline of ``diagnose_realism.py`` (true light, true ratio, true pose) against the
path tracer split in two: Mitsuba renders the plate, the truth and the truth with the object's albedo 0 at
``--spp`` (seed 11; cached in ``--cache``): over the ground, ``truth - black`` is the light the object sends
there (and its own colour in ground pixels it partly covers), ``black - plate`` what it hides. arshadow's
composite is split the same way (the object's colour ``0,0,0`` against its own) and read in linear light
before the 8-bit encode (``compose cpu``; the 8-bit composite drops changes under half a code step). Over
the diagnosis's ``outside`` pixels, as shares of the case's ground denominator (composite - truth, signed):
``silhouette`` (within :data:`SILHOUETTE_PX` of the object's outline: the truth's mixed pixels),
``beyond`` (where the composite is the plate: past the map's outline) and ``rest``, each as hidden /
reflected, and ``noise`` (the committed 64-spp truth against this one). ``--no-taper``: the map without
its taper (the whole square).
"""

from __future__ import annotations

import argparse
import dataclasses
import pickle
import sys
from pathlib import Path

import _common
import cv2
import diagnose_realism as dr
import numpy as np

ROOT = _common.ROOT
#: ground pixels this close to the object's outline (px) count as its silhouette
SILHOUETTE_PX = 4
#: the high-spp renders' seed (the committed plates use the scene's seed and seed2)
SEED = 11


def renders(sc, spp: int, cache: Path) -> dict:
    """``{"plate", "truth", "black"}`` (H, W, 3) camera-linear float64 at ``spp``, cached per case."""
    from arshadow.bench import reference_scene as rs

    f = cache / f"{sc.name}_{spp}.pkl"
    if f.exists():
        with f.open("rb") as fh:
            out: dict = pickle.load(fh)
        return out
    rs.set_exposure(sc)
    black = dataclasses.replace(sc, color=(0.0, 0.0, 0.0))
    out = {}
    for key, s, obj in (("plate", sc, False), ("truth", sc, True), ("black", black, True)):
        img = rs._render(rs.build_scene(s, with_object=obj), spp, SEED) * sc.exposure
        out[key] = np.clip(img, 0.0, 1.0)
    cache.mkdir(parents=True, exist_ok=True)
    with f.open("wb") as fh:
        pickle.dump(out, fh)
    return out


def composite_linear(case, est, opts: dict) -> tuple[np.ndarray, np.ndarray]:
    """``(change (h, w, 3) linear in the crop, composite8)``: the oracle composite's change of the plate,
    captured before its 8-bit encode."""
    import arshadow.compose.composite as cc
    from arshadow.bench.reference_score import decode8

    encode = cc._encode
    full = decode8(case.plate8)[:, :, ::-1].astype(np.float32).copy()  # BGR, as the compositor's buffer

    def capture(lin, region, ws):
        base = region
        while isinstance(base.base, np.ndarray):
            base = base.base
        off = region.ctypes.data - base.ctypes.data
        y0, x0 = off // base.strides[0], (off % base.strides[0]) // base.strides[1]
        full[y0 : y0 + lin.shape[0], x0 : x0 + lin.shape[1]] = lin
        encode(lin, region, ws)

    cc._encode = capture
    try:
        comp = dr.composite(case, est, "oracle", {**opts, "compose": "cpu"})
    finally:
        cc._encode = encode
    y0, y1, x0, x1 = case.crop
    change = full[:, :, ::-1].astype(np.float64) - decode8(case.plate8)
    return change[y0:y1, x0:x1], comp


def decompose(case, est, opts: dict, spp: int, cache: Path) -> dict:
    """The case's outside shares (module docstring)."""
    from arshadow.bench.reference_score import smooth_regions

    y0, y1, x0, x1 = case.crop
    m = {k: v[y0:y1, x0:x1] for k, v in renders(case.scene, spp, cache).items()}
    hidden_t = smooth_regions(m["black"] - m["plate"], case.masks)
    sent_t = smooth_regions(m["truth"] - m["black"], case.masks)
    change, comp8 = composite_linear(case, est, opts)
    black, _ = composite_linear(case, est, {**opts, "color": "0,0,0"})
    comp, hidden_c = smooth_regions(change, case.masks), smooth_regions(black, case.masks)
    hard = dr.hard_shadow(case)
    parts, _, region = dr.split(case, comp8, hard)
    st = case.smoothed_truth
    den = float(np.abs(st).sum(axis=2)[region].sum())
    shadow = hard.astype(np.uint8)
    k = np.ones((2 * dr.EDGE_PX + 1,) * 2, np.uint8)
    edge = (cv2.dilate(shadow, k) > 0) & ~(cv2.erode(shadow, k) > 0)
    out = region & ~(shadow > 0) & ~edge & ~case.masks["contact"]
    dist = cv2.distanceTransform((~case.masks["object"]).astype(np.uint8), cv2.DIST_L2, 5)
    sil = out & (dist < SILHOUETTE_PX)
    beyond = out & (np.abs(comp).sum(axis=2) < 1e-4) & ~sil
    rest = out & ~sil & ~beyond

    def share(a: np.ndarray, where: np.ndarray) -> float:
        return round(float(a.sum(axis=2)[where].sum()) / den, 4)

    row: dict = {"ground": parts["ground"], "outside": share(comp - hidden_t - sent_t, out)}
    for name, where in (("silhouette", sil), ("beyond", beyond), ("rest", rest)):
        row[name] = (share(hidden_c - hidden_t, where), share(comp - hidden_c - sent_t, where))
    row["noise"] = share(st - hidden_t - sent_t, out)
    return row


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", default="own", choices=("own", "heldout"))
    ap.add_argument("--only", action="append", help="case name(s)")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--no-taper", action="store_true")
    ap.add_argument("--cache", default=str(Path.home() / ".cache" / "arshadow-decompose"))
    ap.add_argument("--out")
    args = ap.parse_args()
    import arshadow.shading.sky as sky
    from arshadow.bench.reference import load_cases, measure_light

    if args.no_taper:
        sky.ground_sky_visibility.__kwdefaults__["taper"] = None
    result: dict = {"meta": _common.metadata(), "spp": args.spp, "no_taper": args.no_taper, "cases": {}}
    for case in load_cases(ROOT / "tests" / "data" / "reference" / args.set):
        if args.only and case.scene.name not in args.only:
            continue
        est = measure_light(case.plate8, case.scene)
        row = decompose(case, est, {}, args.spp, Path(args.cache))
        result["cases"][f"{args.set}/{case.scene.name}"] = row
        print(case.scene.name, row, file=sys.stderr, flush=True)
    _common.emit(result, args.out)


if __name__ == "__main__":
    main()
