"""Frame time against the number of lights and against soft-shadow samples ([Kolivand-Stencil], Figure 8 analogue).

A plain script: prints one JSON object (median and IQR / min-max of repeated frames after warm-up, plus
metadata: git commit, versions, GL_RENDERER). Not a test (timings on a shared 2-core machine are noisy).

Scene: a 640x480 photo (flat grey; the tracker is bypassed: ``Compositor.render_pose`` with a known
pose), the occluder ``torus:0.05,0.02`` (4096 faces) unless ``--mesh``, the default render options
(MSAA 4, region of interest on, stencil shadow volumes, mode chosen per light).

* ``lights``: k = 1, 2, 4, 8 hard point lights on a circle (radius 0.3 m, height 0.4 m), equal weights.
* ``soft``: one area light rendered with N = 1, 4, 16, 64 samples (a point light of radius 0.05 m at
  (0.2, -0.1, 0.4); and the sun's 0.266 deg disc, 50 deg high).

``warm`` = a video frame once silhouettes and volumes are cached (static lights; what a video pays per
frame); ``cold`` = the first frame of a run (silhouette + volume of every light/sample, then the frame).

``penumbra_quality``: the penumbra width error against N in tests/test_soft_shadows.py's scene (the
quality side of the trade-off; deterministic, not a timing).

Run::

    python tests/benchmarks/bench_lights.py [--repeats 15] [--mesh SPEC] [--out FILE]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import _common
import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _rendered(res):
    """A :class:`arshadow.frame.session.FrameResult` as ``(composite, mask, report item)``."""
    return res.composite, res.mask, res.item


def _stats(ms) -> dict:
    """Frame times (ms): median, IQR, min, max, n (:func:`_common.summary`) and the median's frame rate."""
    s = _common.summary(ms, 3)
    s["fps_median"] = round(1000.0 / s["median"], 2)
    return s


def penumbra_quality(ctx, ns) -> dict:
    """The other side of the trade-off: penumbra width error vs samples, in tests/soft_shadow_scene.py's
    scene (box edge, sphere light r = 0.05 m at 0.5 m; sun-like cone alpha = 3 deg at 55 deg)."""
    sys.path.insert(0, str(ROOT / "tests"))
    import soft_shadow_scene as T
    from oracle import disc_segment_fraction

    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.gl.stencil import ShadowRenderer
    from arshadow.lights.area import sample_area_light
    from arshadow.lights.spec import Light, parse_light
    from arshadow.transforms import CV_TO_GL

    intr = Intrinsics(
        fx=T.F_PX, fy=T.F_PX, cx=(T.W - 1) / 2, cy=(T.H_IMG - 1) / 2, width=T.W, height=T.H_IMG, dist=np.zeros(0)
    )
    cfw = np.diag([1.0, -1.0, -1.0, 1.0])
    cfw[2, 3] = T.D
    sc = {
        "intr": intr,
        "proj": intr.gl_projection(1e-3, None),
        "view": CV_TO_GL @ cfw,
        "caster": load_occluder(f"box:{2 * T.A},{2 * T.A},{T.HB}"),
        "x": (np.arange(T.W) - intr.cx) / T.F_PX * T.D,
    }
    out = {}
    with ShadowRenderer(ctx, max_width=T.W, max_height=T.H_IMG) as r:
        for n in ns:
            rr, hl = 0.05, 0.5
            x, f = T.profile(
                sc, T.render_masks(sc, r, sample_area_light(parse_light(f"point:0,0,{hl},radius={rr}"), n))
            )
            full_pred = 2 * rr * T.HB / (hl - T.HB)
            exact = 1 - disc_segment_fraction((x - (x - T.A) * hl / T.HB) / rr)
            _, w_pred = T.widths(x, np.where(exact > 1 - 1e-12, 1.0, exact), 1e6)
            full, w = T.widths(x, f, n)
            e, al = math.radians(55), math.radians(3)
            sun = Light("directional", [-math.cos(e), 0, math.sin(e)], radius=al)
            x2, f2 = T.profile(sc, T.render_masks(sc, r, sample_area_light(sun, n, seed=1)))
            full2, _ = T.widths(x2, f2, n)
            fp2 = T.HB / math.tan(e - al) - T.HB / math.tan(e + al)
            out[str(n)] = {
                "point_full_width_err": round(full / full_pred - 1, 4),
                "point_10_90_width_err": round(w / w_pred - 1, 4),
                "point_profile_max_dev": round(float(np.max(np.abs(f - exact))), 4),
                "sun_full_width_err": round(full2 / fp2 - 1, 4),
            }
            print(f"penumbra n={n}: {out[str(n)]}", file=sys.stderr)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--warmup", type=int, default=2)
    ap.add_argument("--mesh", default="torus:0.05,0.02")
    ap.add_argument("--lights", default="1,2,4,8")
    ap.add_argument("--samples", default="1,4,16,64")
    ap.add_argument("--out", default=None, help="also write the JSON here")
    args = ap.parse_args(argv)

    from arshadow.camera.model import Intrinsics
    from arshadow.frame.session import Session
    from arshadow.geometry.mesh import load_occluder
    from arshadow.gl.context import create_context
    from arshadow.gl.stencil import ShadowRenderer
    from arshadow.lights.spec import Light, parse_light
    from arshadow.scene.spec import RenderOptions, Scene
    from arshadow.synth.markers import look_at_pose

    ctx = create_context()
    W, H = 640, 480
    intr = Intrinsics(fx=600.0, fy=600.0, cx=319.5, cy=239.5, width=W, height=H, dist=np.zeros(0))
    cam_from_world = look_at_pose(np.array([0.35, -0.45, 0.4]), np.array([0.0, 0.0, 0.02]))
    image = np.full((H, W, 3), 128, np.uint8)
    caster = load_occluder(args.mesh)
    opts = RenderOptions()
    renderer = ShadowRenderer(ctx, max_width=W, max_height=H, samples=opts.aa)

    def run(lights, soft_samples):
        o = RenderOptions(soft_samples=soft_samples)
        cold = []
        for _ in range(max(3, args.repeats // 3)):
            t = time.perf_counter()
            scene = Scene(intr, caster, lights, o, {})
            with Session(scene, context=ctx, renderer=renderer) as comp:
                _rendered(comp.render(image, cam_from_world))
            cold.append((time.perf_counter() - t) * 1e3)
        scene = Scene(intr, caster, lights, o, {})
        with Session(scene, context=ctx, renderer=renderer) as comp:
            for _ in range(args.warmup):
                _, mask, info = _rendered(comp.render(image, cam_from_world))
            warm = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                _, mask, info = _rendered(comp.render(image, cam_from_world))
                warm.append((time.perf_counter() - t) * 1e3)
            n_passes = len(comp.geometry.lights)
        return {
            "warm": _stats(warm),
            "cold": _stats(cold),
            "passes": n_passes,
            "modes": sorted(set(info.modes)),
            "shadow_pixels": int(np.count_nonzero(mask)),
        }

    out = {
        "benchmark": "bench_lights",
        "scene": {
            "image": [W, H],
            "mesh": args.mesh,
            "faces": int(len(caster.faces)),
            "options": {"aa": opts.aa, "roi": opts.roi, "shadow_method": opts.shadow_method},
        },
        "meta": _common.metadata(ctx),
        "lights": {},
        "soft_point": {},
        "soft_sun": {},
    }
    for k in (int(x) for x in args.lights.split(",")):
        lights = [
            parse_light(
                f"point:{0.3 * math.cos(2 * math.pi * i / k + 0.3):.6f},"
                f"{0.3 * math.sin(2 * math.pi * i / k + 0.3):.6f},0.4"
            )
            for i in range(k)
        ]
        out["lights"][str(k)] = run(lights, 1)
        print(f"lights={k}: {out['lights'][str(k)]['warm']['median']} ms", file=sys.stderr)
    point = parse_light("point:0.2,-0.1,0.4,radius=0.05")
    e = math.radians(50.0)
    sun = Light(
        "directional",
        [math.cos(e) * math.sin(math.radians(200)), math.cos(e) * math.cos(math.radians(200)), math.sin(e)],
        radius=math.radians(0.266),
        label="sun",
    )
    for n in (int(x) for x in args.samples.split(",")):
        out["soft_point"][str(n)] = run([point], n)
        out["soft_sun"][str(n)] = run([sun], n)
        print(
            f"samples={n}: point {out['soft_point'][str(n)]['warm']['median']} ms, "
            f"sun {out['soft_sun'][str(n)]['warm']['median']} ms",
            file=sys.stderr,
        )
    renderer.release()
    # N = 1 is the hard shadow (no penumbra to measure; tested bit for bit against it)
    out["penumbra_quality"] = penumbra_quality(ctx, [n for n in map(int, args.samples.split(",")) if n > 1] + [256])
    _common.emit(out, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
