"""Benchmark of the GL render stage (plain script; prints JSON).

    python tests/benchmarks/bench_render.py [--repeat 30] [--out FILE.json] [--no-accuracy]

Scene: 1280x720 pinhole camera ~0.45 m from the 8 536-face sample mesh (samples/meshes/knot.ply, or a
generated 8.6k-face non-convex blob when absent), one point light, z-pass. Measured after warm-up:

- ``geometry``: silhouette + shadow volume (CPU, arshadow.geometry.silhouette/volume) - for context only;
- ``render`` (volume to infinity, and truncated 1e-3 x mesh size below the ground) at the full 1280x720
  canvas and at the ROI the compositor renders (bounding box of the
  occluder and of its ground shadow, + 2 px), split into upload / draw / readback as the renderer
  reports them (``draw`` ends with ctx.finish(), so it includes the GL work);
- per-pass GL times with ``profile=True`` (ctx.finish() after each pass: slightly slower in total);
- anti-aliasing options (MSAA samples x supersampling) at the ROI: median time, and error against the
  independent oracle (tests/image_oracle.py): IoU of mask >= 0.5 vs the pixel-centre oracle, and the mean
  absolute error of the fractional mask against the true area coverage (8x8 oracle samples per pixel) on
  the boundary band (pixels within 2 px of an oracle boundary).

Every time is the median (and IQR ``[q25, q75]``, min, max) of ``--repeat`` runs, in ms
(``_common.summary``).
"""

from __future__ import annotations

import argparse
import sys
import time

import _common
import numpy as np

from arshadow.renderer.request import RenderRequest

ROOT = _common.ROOT
sys.path.insert(0, str(ROOT / "tests"))

W, H = 1280, 720
ZNEAR = 0.01
stats = _common.summary


def load_scene():
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.synth.markers import look_at_pose

    p = ROOT / "samples" / "meshes" / "knot.ply"
    if p.is_file():
        caster = load_occluder(str(p))
    else:  # same generator as tests/test_gl_renderer.py
        from render_scenes import nonconvex_blob

        caster = nonconvex_blob()
    K = Intrinsics(fx=1000.0, fy=1000.0, cx=641.3, cy=357.8, width=W, height=H, dist=np.zeros(0))
    T = look_at_pose([0.3, -0.32, 0.3], [0.0, 0.02, 0.02])
    L = np.array([-0.15, 0.2, 0.5, 1.0])
    return caster, K, T, L


def roi_of(caster, K, T, L, margin=2):
    """Pixel bbox (u0, v0, w, h) of the occluder and its ground shadow (clipped to the image)."""
    from arshadow.bench.render import roi_of as _roi

    return _roi(caster, K, T, L, margin, W, H)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--out", default=None)
    ap.add_argument("--no-accuracy", action="store_true")
    args = ap.parse_args(argv)

    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.context import create_context
    from arshadow.gl.stencil import LightPass, ShadowRenderer
    from arshadow.transforms import CV_TO_GL

    ctx = create_context()
    caster, K, T, L = load_scene()
    view = CV_TO_GL @ T
    out = {"meta": {**_common.metadata(ctx), "faces": int(caster.n_faces), "image": [W, H], "repeat": args.repeat}}
    # geometry (context)
    tg = []
    for _ in range(args.repeat + 3):
        t0 = time.perf_counter()
        sil = silhouette(caster, L)
        vol = shadow_volume(caster, L, sil, caps=False)
        tg.append((time.perf_counter() - t0) * 1e3)
    out["geometry_ms"] = stats(tg[3:])
    out["volume"] = {"side_triangles": int(vol.n_side), "silhouette_edges": int(len(sil.edges))}
    vol_trunc = shadow_volume(caster, L, sil, caps=False, truncate_z=-1e-3 * caster.scale)
    passes = [LightPass(L, 1.0, vol, "zpass")]
    passes_trunc = [LightPass(L, 1.0, vol_trunc, "zpass")]
    roi = roi_of(caster, K, T, L)
    out["roi"] = list(roi)

    def bench(r, canvas, n, ps=None):
        u0, v0, w, h = canvas
        P = K.gl_projection(ZNEAR, None, canvas=canvas)
        recs = []
        for _ in range(n + 3):
            res = r.render(
                RenderRequest(projection=P, view=view, width=w, height=h, caster=caster, passes=ps or passes)
            )
            recs.append(res.timings_ms)
        recs = recs[3:]
        return {k: stats([t[k] for t in recs]) for k in recs[0]}, res

    with ShadowRenderer(ctx, max_width=W, max_height=H) as r:
        out["render_full_ms"], _ = bench(r, (0, 0, W, H), args.repeat)
        out["render_roi_ms"], _ = bench(r, roi, args.repeat)
        out["render_full_truncated_ms"], _ = bench(r, (0, 0, W, H), args.repeat, passes_trunc)
        out["render_roi_truncated_ms"], _ = bench(r, roi, args.repeat, passes_trunc)
        r.profile = True
        out["passes_full_ms"], _ = bench(r, (0, 0, W, H), max(args.repeat // 3, 5))
        out["passes_roi_ms"], _ = bench(r, roi, max(args.repeat // 3, 5))
        out["passes_roi_truncated_ms"], _ = bench(r, roi, max(args.repeat // 3, 5), passes_trunc)

    # anti-aliasing options at the ROI
    orc = cov = band = None
    if not args.no_accuracy:
        from image_oracle import ShadowOracle, iou

        orc = ShadowOracle(K.K, T, caster.vertices, caster.faces, [(L, 1.0)])
        u0, v0, w, h = roi
        om, og, oo = orc.image(W, H, canvas=roi)
        ob = om >= 0.5
        # boundary band: within 2 px of a change of the pixel-centre oracle
        import cv2 as _cv

        edge = _cv.dilate(ob.astype(np.uint8), np.ones((5, 5), np.uint8)) != _cv.erode(
            ob.astype(np.uint8), np.ones((5, 5), np.uint8)
        )
        band = np.argwhere(edge)
        sub = (np.arange(8) + 0.5) / 8 - 0.5
        su, sv = np.meshgrid(sub, sub)
        uu = (band[:, 1][:, None] + u0 + su.ravel()[None, :]).ravel()
        vv = (band[:, 0][:, None] + v0 + sv.ravel()[None, :]).ravel()
        cov = orc.classify(uu, vv)[0].reshape(len(band), 64).mean(axis=1)
    aa = []
    for samples, ss in ((0, 1), (2, 1), (4, 1), (0, 2), (4, 2), (0, 4)):
        if samples > ctx.max_samples:
            continue
        with ShadowRenderer(ctx, max_width=W, max_height=H, samples=samples, supersample=ss) as r:
            tm, res = bench(r, roi, args.repeat)
            tf, _ = bench(r, (0, 0, W, H), max(args.repeat // 3, 5))
        rec = {"samples": samples, "supersample": ss, "roi_total_ms": tm["total"], "full_total_ms": tf["total"]}
        if orc is not None:
            rec["iou_at_0.5"] = round(iou(res.mask >= 0.5, ob), 5)
            m = res.mask[band[:, 0], band[:, 1]]
            rec["band_mae_vs_area_coverage"] = round(float(np.abs(m - cov).mean()), 4)
            rec["band_pixels"] = int(len(band))
            rec["distinct_mask_levels"] = int(len(np.unique(res.mask)))
        aa.append(rec)
    out["anti_aliasing"] = aa
    _common.emit(out, args.out)
    ctx.release()


if __name__ == "__main__":
    main()
