"""Where the object residual of the path-traced reference comes from (docs/reference.md, "the object's residual").

    python tests/benchmarks/diagnose_object.py [--set own|heldout ...] [--only NAME ...] [--png DIR]
        [--pipeline oracle|measured ...]

Per committed case, the composite of ``diagnose_realism.py``'s ``oracle`` (the true light, the true shadow
ratio at the object, the true pose: the rendering model alone) and ``measured`` (``arshadow light`` +
``render --light-from``, tracked: what a user gets) pipelines, and the object residual split

- by face (:func:`by_face`: pixels grouped by their shading normal): each face's mean error (``level``, the
  channels' mean, and ``colour``, per channel less the level) and the rest (``within``: gradients, noise);
- by part of the object: ``top`` (a face whose normal is within 45 degrees of +z), ``side``, ``under``
  (normal z < -0.3), and per part ``lit`` (the light reaches the point: n.L > 0 and no part of the object in
  the way, a ray cast) against ``dark`` (facing away or shadowed by the object itself); ``contour`` (object
  pixels within :data:`CONTOUR_PX` px of the object's outline in the image) against the interior;
- by shading term (oracle only): the renderer is run again with each term of the object's shading off (the
  direct light, the sky, the ground's bounce) through a patched ``frame_shading``; each term's image ``T_k``
  is the full composite minus that one (smoothed within the object like the residual), and the signed error
  ``e = S(composite - truth)`` of the interior is fitted as ``sum_k a_k T_k`` (least squares over pixels and
  channels): ``a_k`` is the term's relative error (+0.05: 5 % too strong), ``share_k`` = ``sum a_k T_k / den``
  its signed share of the residual, ``fit_left`` what the fit leaves (``|e - sum a_k T_k|``).

Shares are of the residual's denominator (``sum |S(truth - plate)|`` over the object), so per case the
parts' ``abs`` add up to the object residual; ``signed`` is the sum of the error over channels (+: the
composite too bright). ``--png DIR``: the signed error summed over channels per case and pipeline (red: too
bright, blue: too dark, full at 10 % of the truth's mean change), 4x.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import sys
from pathlib import Path

import _common
import cv2
import numpy as np
import trimesh
from diagnose_realism import composite

ROOT = _common.ROOT
#: object pixels within this many pixels of the object's outline count as its contour
CONTOUR_PX = 2.5
TERMS = ("direct", "sky", "bounce")


@contextlib.contextmanager
def shading_off(term: str | None):
    """Patch :func:`arshadow.frame.execute.frame_shading` so that the object's shading lacks ``term``
    (``direct``: the lights' diffuse weight 0; ``sky``: the ambient 0; ``bounce``: the ground's bounce 0)."""
    from arshadow.frame import execute

    orig = execute.frame_shading

    def patched(opts, caster, sky):
        sh = orig(opts, caster, sky)
        if term == "direct":
            sh = dataclasses.replace(sh, diffuse=0.0)
        elif term == "sky":
            sh = dataclasses.replace(sh, ambient=0.0)
        elif term == "bounce" and sh.sky is not None:
            sh = dataclasses.replace(sh, sky=dataclasses.replace(sh.sky, bounce=(0.0, 0.0, 0.0)))
        return sh

    execute.frame_shading = patched if term else orig
    try:
        yield
    finally:
        execute.frame_shading = orig


def first_hit(tri: np.ndarray, orig: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moller-Trumbore against every triangle ``tri (m, 3, 3)`` for rays ``orig, dirs (k, 3)``: ``(t (k,),
    index (k,))`` of the nearest hit (t = inf, index -1 where none)."""
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    best_t, best_i = np.full(len(dirs), np.inf), np.full(len(dirs), -1)
    for s in range(0, len(dirs), 256):
        d, o = dirs[s : s + 256, None], orig[s : s + 256, None]
        p = np.cross(d, e2[None])
        det = (e1[None] * p).sum(-1)
        inv = 1.0 / np.where(np.abs(det) < 1e-15, np.nan, det)
        tv = o - a[None]
        u = (tv * p).sum(-1) * inv
        q = np.cross(tv, e1[None])
        v = (d * q).sum(-1) * inv
        t = (e2[None] * q).sum(-1) * inv
        ok = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-7)
        t = np.where(ok, t, np.inf)
        best_i[s : s + 256] = np.where(np.isfinite(t.min(1)), t.argmin(1), -1)
        best_t[s : s + 256] = t.min(1)
    return best_t, best_i


def object_geometry(case) -> dict:
    """Per object pixel of the crop (at its centre, the true pose): ``normal`` (h, w, 3) world (the shading
    normal: interpolated for the round primitives), ``lit`` (h, w) bool (n.L > 0 and the ray to the light
    misses the object), ``hit`` (h, w) bool, ``z`` (h, w) the point's height (metres)."""
    from arshadow.bench.reference_scene import _object_mesh, intrinsics_of, pose_of

    sc = case.scene
    y0, y1, x0, x1 = case.crop
    verts, faces, vn = _object_mesh(sc.model, sc.place, sc.rotate)
    tm = trimesh.Trimesh(verts, faces, process=False)
    K, pose = intrinsics_of(sc), pose_of(sc)
    R, t = pose[:3, :3], pose[:3, 3]
    eye = -R.T @ t
    ys, xs = np.nonzero(case.masks["object"])
    pix = np.stack([xs + x0, ys + y0, np.ones(len(xs))]).astype(np.float64)
    dirs = (R.T @ (np.linalg.inv(K.K) @ pix)).T
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    tris = verts[faces]
    tt, tri = first_hit(tris, np.repeat(eye[None], len(dirs), 0), dirs)
    ray_i = np.flatnonzero(tri >= 0)
    tri = tri[ray_i]
    loc = eye[None] + tt[ray_i, None] * dirs[ray_i]
    h, w = case.masks["object"].shape
    normal = np.zeros((h, w, 3))
    lit = np.zeros((h, w), bool)
    hit = np.zeros((h, w), bool)
    height = np.zeros((h, w))
    if vn is not None:
        bary = trimesh.triangles.points_to_barycentric(tm.triangles[tri], loc)
        n = (vn[faces[tri]] * bary[:, :, None]).sum(axis=1)
    else:
        n = tm.face_normals[tri]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    lv = np.asarray(sc.light_vec, np.float64)
    to_l = (lv - loc) if sc.light == "point" else np.repeat((lv / np.linalg.norm(lv))[None], len(loc), 0)
    to_l /= np.linalg.norm(to_l, axis=1, keepdims=True)
    fn = tm.face_normals[tri]
    facing = ((n * to_l).sum(axis=1) > 0) & ((fn * to_l).sum(axis=1) > 0)
    blocked = np.zeros(len(loc), bool)
    if facing.any():
        o = loc[facing] + 1e-5 * fn[facing]
        blocked[facing] = first_hit(tris, o, to_l[facing])[1] >= 0
    yy, xx = ys[ray_i], xs[ray_i]
    normal[yy, xx], lit[yy, xx], hit[yy, xx], height[yy, xx] = n, facing & ~blocked, True, loc[:, 2]
    return {"normal": normal, "lit": lit, "hit": hit, "z": height}


def parts_of(case, geo: dict) -> dict:
    """The object's parts (h, w) bool each (see the module's docstring)."""
    obj = case.masks["object"]
    dist = cv2.distanceTransform(obj.astype(np.uint8), cv2.DIST_L2, 5)
    contour = obj & (dist <= CONTOUR_PX)
    inner = obj & ~contour & geo["hit"]
    nz = geo["normal"][..., 2]
    out = {"contour": contour, "interior": obj & ~contour}
    for name, m in (("top", nz > 0.7071), ("side", (nz <= 0.7071) & (nz >= -0.3)), ("under", nz < -0.3)):
        out[f"{name}_lit"] = inner & m & geo["lit"]
        out[f"{name}_dark"] = inner & m & ~geo["lit"]
    return out


def signed_error(case, comp8: np.ndarray) -> np.ndarray:
    """S(composite - plate) - S(truth - plate) within the object, (h, w, 3) float64 (0 elsewhere)."""
    from arshadow.bench.reference_score import decode8, smooth_within

    y0, y1, x0, x1 = case.crop
    d = decode8(comp8[y0:y1, x0:x1]) - decode8(case.plate8[y0:y1, x0:x1])
    return smooth_within(d, case.masks["object"]) - case.smoothed_truth * case.masks["object"][:, :, None]


def term_images(case, est, full8: np.ndarray) -> dict:
    """Each shading term's image on the object (oracle), S(full - without it), (h, w, 3) float64."""
    from arshadow.bench.reference_score import decode8, smooth_within

    y0, y1, x0, x1 = case.crop
    full = decode8(full8[y0:y1, x0:x1])
    out = {}
    for t in TERMS:
        with shading_off(t):
            c8 = composite(case, est, "oracle", {})
        out[t] = smooth_within(full - decode8(c8[y0:y1, x0:x1]), case.masks["object"])
    return out


def split(case, e: np.ndarray, parts: dict) -> dict:
    """Each part's ``[abs share, signed share, pixels]`` of the object residual."""
    obj = case.masks["object"]
    den = float(np.abs(case.smoothed_truth).sum(axis=2)[obj].sum())
    err, sig = np.abs(e).sum(axis=2), e.sum(axis=2)
    out = {"object": [round(float(err[obj].sum()) / den, 4), round(float(sig[obj].sum()) / den, 4), int(obj.sum())]}
    for name, m in parts.items():
        out[name] = [round(float(err[m].sum()) / den, 4), round(float(sig[m].sum()) / den, 4), int(m.sum())]
    return out


def fit_terms(case, e: np.ndarray, terms: dict, region: np.ndarray) -> dict:
    """Least squares ``e ~ sum_k a_k T_k`` over ``region`` (h, w) bool and the channels: ``a_k``, the signed
    share ``sum a_k T_k / den`` (region only), what is left, and each term's size (``sum |T_k| / den``)."""
    obj = case.masks["object"]
    den = float(np.abs(case.smoothed_truth).sum(axis=2)[obj].sum())
    names = [k for k in TERMS if float(np.abs(terms[k][region]).sum()) > 1e-3 * den]
    A = np.column_stack([terms[k][region].ravel() for k in names])
    b = e[region].ravel()
    a = np.linalg.lstsq(A, b, rcond=None)[0]
    left = b - A @ a
    out: dict = {
        "fit_left": round(float(np.abs(left).sum()) / den, 4),
        "region_abs": round(float(np.abs(b).sum()) / den, 4),
    }
    for k, ak in zip(names, a, strict=True):
        out[k] = {
            "a": round(float(ak), 4),
            "share": round(float(ak * terms[k][region].sum()) / den, 4),
            "size": round(float(np.abs(terms[k][region]).sum()) / den, 4),
        }
    return out


def by_face(case, e: np.ndarray, geo: dict, parts: dict) -> dict:
    """The interior's error split by face (pixels grouped by their normal rounded to 0.25): ``level`` (each
    face's mean error, the channels' mean), ``colour`` (each face's mean per channel less its level),
    ``within`` (the error less its face's mean: gradients across a face, noise), shares ``[abs, signed]``."""
    obj = case.masks["object"]
    den = float(np.abs(case.smoothed_truth).sum(axis=2)[obj].sum())
    m = parts["interior"] & geo["hit"]
    key = np.round(geo["normal"][m] * 4.0)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    ev = e[m]
    mu = np.zeros_like(ev)
    for k in range(int(inv.max()) + 1):
        mu[inv == k] = ev[inv == k].mean(axis=0)
    level = np.repeat(mu.mean(axis=1, keepdims=True), 3, axis=1)
    out = {}
    for name, x in (("level", level), ("colour", mu - level), ("within", ev - mu)):
        out[name] = [round(float(np.abs(x).sum()) / den, 4), round(float(x.sum()) / den, 4)]
    return out


def write_png(path: Path, e: np.ndarray, case, parts: dict) -> None:
    """The signed error as colour (red: composite too bright), the contour's inner edge grey."""
    scale = 0.1 * float(np.abs(case.smoothed_truth).sum(axis=2)[case.masks["object"]].mean())
    t = np.clip(e.sum(axis=2) / scale, -1.0, 1.0)
    img = np.full(t.shape + (3,), 255.0)
    img[..., 0] -= 255.0 * np.clip(t, 0, 1)
    img[..., 1] -= 255.0 * np.abs(t)
    img[..., 2] -= 255.0 * np.clip(-t, 0, 1)
    img[~case.masks["object"]] = 200.0
    ys, xs = np.nonzero(case.masks["object"])
    img = img[max(ys.min() - 4, 0) : ys.max() + 5, max(xs.min() - 4, 0) : xs.max() + 5]
    img = cv2.resize(img.astype(np.uint8), None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--set", action="append", choices=("own", "heldout"))
    ap.add_argument("--pipeline", action="append", choices=("oracle", "measured"))
    ap.add_argument("--only", action="append")
    ap.add_argument("--png")
    ap.add_argument("--no-terms", action="store_true", help="skip the per-term fit (3 renders less per case)")
    ap.add_argument("--out")
    args = ap.parse_args()
    from arshadow.bench.reference import load_cases, measure_light
    from arshadow.errors import EstimateError

    result: dict = {"meta": _common.metadata(), "cases": {}, "median": {}}
    for name in args.set or ["own"]:
        rows: dict = {}
        for case in load_cases(ROOT / "tests" / "data" / "reference" / name):
            if args.only and case.scene.name not in args.only:
                continue
            try:
                est = measure_light(case.plate8, case.scene)
            except EstimateError as exc:
                print(case.scene.name, "refused:", exc, file=sys.stderr, flush=True)
                continue
            geo = object_geometry(case)
            parts = parts_of(case, geo)
            entry: dict = {}
            for p in args.pipeline or ["oracle", "measured"]:
                c8 = composite(case, est, p, {})
                e = signed_error(case, c8)
                entry[p] = split(case, e, parts)
                entry[p]["by_face"] = by_face(case, e, geo, parts)
                rows.setdefault(p, []).append(entry[p]["object"])
                if p == "oracle" and not args.no_terms:
                    interior = parts["interior"]
                    entry["terms"] = fit_terms(case, e, term_images(case, est, c8), interior)
                if args.png:
                    write_png(Path(args.png) / f"{case.scene.name}_{p}.png", e, case, parts)
            result["cases"][f"{name}/{case.scene.name}"] = entry
            print(case.scene.name, json.dumps(entry), file=sys.stderr, flush=True)
        result["median"][name] = {
            p: [round(float(np.median([r[i] for r in rs])), 4) for i in (0, 1)] for p, rs in rows.items()
        }
    _common.emit(result, args.out)


if __name__ == "__main__":
    main()
