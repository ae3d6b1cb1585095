"""Section 4: the whole pipeline (detection -> composite) on synthetic photos with a known pose.

- per-stage times at 640x480, 1280x720 and 1920x1080 (the 8 536-face knot, one point light);
- frames per second against the number of lights ([Kolivand-Stencil] Fig. 8 plots the same curve for its scene);
- [Kolivand-DeltaPlus]'s AR scene (8 536 faces, one light) against its reported 74.35 FPS, also with Delta+ run on
  every frame (as a moving light or object needs) - the paper's hardware was a 2.5 GHz Core i5-3210 with
  an ATI Radeon HD 7670M GPU; here it is the CPU and Mesa's software rasteriser (see the metadata).

The photos come from :func:`arshadow.synth.render_marker_photo` (5 cm marker, lens distortion, noise,
blur, JPEG), so the lens warp stage is exercised; their generation is not timed. Every configuration is a
scene (:func:`arshadow.scene.scene_from_dict`) run by :class:`arshadow.Session` (``process``: detection ->
composite, as ``arshadow render`` and the Python API run it) on the benchmark's GL context.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..camera.model import Intrinsics
from ..frame.session import Session
from ..geometry.mesh import load_occluder
from ..scene.spec import SceneSpec, scene_from_dict
from ..synth.markers import look_at_pose, render_marker_photo
from .common import ROOT, summary, t_fields
from .tracking import camera

RESOLUTIONS = ((640, 480), (1280, 720), (1920, 1080))
#: [Kolivand-DeltaPlus] sec. V: "The AR system including shadow volumes using Delta+ Algorithm is performed in 74.35 FPS.
#: The 3D objects include 8536 faces." Hardware: 2.5 GHz Intel Core i5-3210, ATI Radeon HD 7670M.
PAPER003_FPS = 74.35
PAPER003_HARDWARE = "2.5 GHz Intel Core i5-3210 CPU + ATI Radeon HD 7670M GPU ([Kolivand-DeltaPlus])"


def photo(width: int, height: int, seed: int = 1) -> tuple[np.ndarray, Intrinsics]:
    """A synthetic photo of a 5 cm marker seen from ~0.5 m, with its camera."""
    cam = camera(width, height)
    T = look_at_pose([0.3, -0.32, 0.3], [0.0, 0.02, 0.02])
    ph = render_marker_photo(cam, T, marker_length=0.05, noise_sigma=2.0, blur_sigma=0.6, jpeg_quality=90, seed=seed)
    return ph.image, cam


def _lights(n: int) -> list[str]:
    """``n`` point lights 0.5 m up on a 0.3 m circle (spec strings)."""
    return [
        f"point:{0.3 * np.cos(a):.4f},{0.3 * np.sin(a):.4f},0.5"
        for a in np.linspace(0, 2 * np.pi, n, endpoint=False) + 2.2
    ]


def scene(cam: Intrinsics, n_lights: int, cold: bool = False, **options: Any) -> SceneSpec:
    """The :class:`arshadow.scene.SceneSpec` of the section: the 8 536-face knot on a 5 cm marker, ``n_lights``
    point lights, ``options`` (scene keys: ``shadow_method``, ``silhouette``...). ``cold``: rebuild every
    light's silhouette and volume every frame (``RenderOptions.plan_off = ("reuse",)``: a moving light or
    object)."""
    spec = scene_from_dict(
        {
            "calib": cam,
            "marker_length": 0.05,
            "model": str(ROOT / "samples" / "meshes" / "knot.ply"),
            "lights": _lights(n_lights),
            **options,
        }
    )
    if cold:
        spec = spec.replace(options=dataclasses.replace(spec.options, plan_off=("reuse",)))
    return spec


def run_frames(spec: Any, ctx: Any, image: np.ndarray, runs: int, warmup: int) -> tuple[list[float], dict]:
    """``runs`` timed :meth:`arshadow.Session.process` calls after ``warmup``, on a session of ``spec``
    sharing ``ctx``: wall times (ms) and ``{stage: [ms, ...]}`` (``FrameResult.timings_ms``)."""
    out = np.empty_like(image)
    walls: list[float] = []
    stages: dict[str, list[float]] = {}
    with Session(spec, context=ctx) as s:
        for i in range(warmup + runs):
            t = time.perf_counter()
            res = s.process(image, want_mask=False, out=out)
            w = (time.perf_counter() - t) * 1e3
            if i >= warmup:
                walls.append(w)
                for k, v in res.timings_ms.items():
                    stages.setdefault(k, []).append(v)
    return walls, stages


def stages(cfg: dict, ctx: Any, log: Callable[[str], None]) -> list[dict]:
    rows = []
    for w, h in cfg["resolutions"]:
        image, cam = photo(w, h)
        for method in ("volume", "shadowmap"):
            walls, st = run_frames(scene(cam, 1, shadow_method=method), ctx, image, cfg["frames"], cfg["warmup"])
            rows.append(
                {
                    "resolution": f"{w}x{h}",
                    "pixels": w * h,
                    "shadow_method": method,
                    **t_fields("wall", walls),
                    "fps": 1000.0 / summary(walls)["median"],
                    **{f"{k}_ms": summary(v, 4)["median"] for k, v in st.items()},
                }
            )
        log(f"  pipeline: {w}x{h} done")
    return rows


def lights_sweep(cfg: dict, ctx: Any, log: Callable[[str], None]) -> list[dict]:
    rows = []
    image, cam = photo(1280, 720)
    for n in cfg["light_counts"]:
        for method in ("volume", "shadowmap"):
            walls, st = run_frames(scene(cam, n, shadow_method=method), ctx, image, cfg["frames"], cfg["warmup"])
            rows.append(
                {
                    "lights": n,
                    "shadow_method": method,
                    **t_fields("wall", walls),
                    "fps": 1000.0 / summary(walls)["median"],
                    "render_ms": summary(st["render"], 4)["median"],
                }
            )
    log("  pipeline: lights sweep done")
    return rows


def paper003_scene(cfg: dict, ctx: Any, log: Callable[[str], None]) -> list[dict]:
    rows = []
    faces = load_occluder(ROOT / "samples" / "meshes" / "knot.ply").n_faces
    image, cam = photo(1280, 720)
    for label, kw, cold in (
        ("default (adjacency, volumes cached: fixed light)", {}, False),
        ("adjacency silhouette + volume every frame", {}, True),
        ("Delta+ silhouette + volume every frame (the paper's detector)", {"silhouette": "delta_plus"}, True),
    ):
        walls, st = run_frames(
            scene(cam, 1, cold=cold, **kw),
            ctx,
            image,
            cfg["frames"] if not kw else max(cfg["frames"] // 3, 3),
            cfg["warmup"] if not kw else 1,
        )
        rows.append(
            {
                "case": label,
                "faces": faces,
                **t_fields("wall", walls),
                "fps": 1000.0 / summary(walls)["median"],
                "paper_fps": PAPER003_FPS,
                "paper_hardware": PAPER003_HARDWARE,
                "silhouette_ms": summary(st["silhouette"], 4)["median"],
                "render_ms": summary(st["render"], 4)["median"],
            }
        )
    log("  pipeline: [Kolivand-DeltaPlus] scene done")
    return rows


def run(cfg: dict, ctx: Any, log: Callable[[str], None]) -> dict:
    return {
        "stages": stages(cfg, ctx, log),
        "lights": lights_sweep(cfg, ctx, log),
        "paper003": paper003_scene(cfg, ctx, log),
    }
