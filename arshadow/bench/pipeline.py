"""Section 4: the whole pipeline (detection -> composite) on synthetic photos with a known pose.

- per-stage times at 640x480, 1280x720 and 1920x1080 (the 8 536-face knot, one point light);
- frames per second against the number of lights (paper 002 Fig. 8 plots the same curve for its scene);
- paper 003's AR scene (8 536 faces, one light) against its reported 74.35 FPS, also with Delta+ run on
  every frame (as a moving light or object needs) - the paper's hardware was a 2.5 GHz Core i5-3210 with
  an ATI Radeon HD 7670M GPU; here it is the CPU and Mesa's software rasteriser (see the metadata).

The photos come from :func:`arshadow.synth.render_marker_photo` (5 cm marker, lens distortion, noise,
blur, JPEG), so the lens warp stage is exercised; their generation is not timed.
"""

from __future__ import annotations

import numpy as np

from . import driver
from .common import ROOT, summary, t_fields

RESOLUTIONS = ((640, 480), (1280, 720), (1920, 1080))
#: paper 003 sec. V: "The AR system including shadow volumes using Delta+ Algorithm is performed in 74.35 FPS.
#: The 3D objects include 8536 faces." Hardware: 2.5 GHz Intel Core i5-3210, ATI Radeon HD 7670M.
PAPER003_FPS = 74.35
PAPER003_HARDWARE = "2.5 GHz Intel Core i5-3210 CPU + ATI Radeon HD 7670M GPU (paper 003)"


def photo(width, height, seed=1):
    """A synthetic photo of a 5 cm marker seen from ~0.5 m, with its camera."""
    from ..synth import look_at_pose, render_marker_photo
    from .tracking import camera

    cam = camera(width, height)
    T = look_at_pose([0.3, -0.32, 0.3], [0.0, 0.02, 0.02])
    ph = render_marker_photo(cam, T, marker_length=0.05, noise_sigma=2.0, blur_sigma=0.6, jpeg_quality=90, seed=seed)
    return ph.image, cam


def _knot():
    from ..geometry.mesh import load_occluder

    return load_occluder(ROOT / "samples" / "meshes" / "knot.ply")


def _lights(n):
    from ..lights.spec import parse_light

    return [parse_light(f"point:{0.3 * np.cos(a):.4f},{0.3 * np.sin(a):.4f},0.5")
            for a in np.linspace(0, 2 * np.pi, n, endpoint=False) + 2.2]


def stages(cfg, ctx, log) -> list[dict]:
    rows = []
    caster = _knot()
    for w, h in cfg["resolutions"]:
        image, cam = photo(w, h)
        for method in ("volume", "shadowmap"):
            with driver.open_pipeline(ctx, cam, caster, _lights(1), shadow_method=method) as pipe:
                walls, st = driver.run_frames(pipe, image, cfg["frames"], cfg["warmup"])
            rows.append({"resolution": f"{w}x{h}", "pixels": w * h, "shadow_method": method, **t_fields("wall", walls),
                         "fps": 1000.0 / summary(walls)["median"],
                         **{f"{k}_ms": summary(v, 4)["median"] for k, v in st.items()}})
        log(f"  pipeline: {w}x{h} done")
    return rows


def lights_sweep(cfg, ctx, log) -> list[dict]:
    rows = []
    caster = _knot()
    image, cam = photo(1280, 720)
    for n in cfg["light_counts"]:
        for method in ("volume", "shadowmap"):
            with driver.open_pipeline(ctx, cam, caster, _lights(n), shadow_method=method) as pipe:
                walls, st = driver.run_frames(pipe, image, cfg["frames"], cfg["warmup"])
            rows.append({"lights": n, "shadow_method": method, **t_fields("wall", walls),
                         "fps": 1000.0 / summary(walls)["median"],
                         "render_ms": summary(st["render"], 4)["median"]})
    log("  pipeline: lights sweep done")
    return rows


def paper003_scene(cfg, ctx, log) -> list[dict]:
    rows = []
    caster = _knot()
    image, cam = photo(1280, 720)
    for label, kw, cold in (("default (adjacency, volumes cached: fixed light)", {}, False),
                            ("adjacency silhouette + volume every frame", {}, True),
                            ("Delta+ silhouette + volume every frame (the paper's detector)",
                             {"silhouette": "delta_plus"}, True)):
        with driver.open_pipeline(ctx, cam, caster, _lights(1), **kw) as pipe:
            walls, st = driver.run_frames(pipe, image, cfg["frames"] if not kw else max(cfg["frames"] // 3, 3),
                                          cfg["warmup"] if not kw else 1, cold=cold)
        rows.append({"case": label, "faces": caster.n_faces, **t_fields("wall", walls),
                     "fps": 1000.0 / summary(walls)["median"], "paper_fps": PAPER003_FPS,
                     "paper_hardware": PAPER003_HARDWARE,
                     "silhouette_ms": summary(st["silhouette"], 4)["median"], "render_ms": summary(st["render"], 4)["median"]})
    log("  pipeline: paper 003 scene done")
    return rows


def run(cfg, ctx, log) -> dict:
    return {"stages": stages(cfg, ctx, log), "lights": lights_sweep(cfg, ctx, log), "paper003": paper003_scene(cfg, ctx, log)}
