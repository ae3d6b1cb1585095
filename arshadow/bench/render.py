"""Section 2: render quality against time.

Every point is one renderer configuration on one scene: the render time (median and IQR of repeated
renders of the scene's region of interest, after warm-up) and the error of its shadow mask against the
exact shadow (:class:`arshadow.geometry.exact.ShadowOracle`: the mesh's triangles projected from the light onto
z = 0, pixel centres tested exactly, pixels covered by the object excluded; no GL):

- ``iou``: IoU of ``mask >= 0.5`` and the exact pixel-centre shadow; ``area_ratio``: pixels of ``mask >= 0.5``
  / pixels of the exact shadow (a vanishing shadow: near 0);
- ``xor_px``: pixels that differ; ``edge_offset_px`` = ``xor_px`` / length of the exact boundary (px): the
  mean displacement of the shadow's edge;
- ``boundary_p95_px``, ``boundary_max_px``: distances between the two boundaries (both directions);
- ``coverage_mae``: mean absolute error of the fractional mask against the exact area coverage (8 x 8
  sub-samples per pixel) on the pixels within 2 px of the exact boundary (what anti-aliasing buys).

Configurations: stencil volumes (z-pass / z-fail, truncated / to infinity, planar projection), MSAA and
supersampling, render resolution scale (render smaller, upscale bilinearly), and the shadow-map baseline
(:class:`arshadow.gl.shadowmap.ShadowMapRenderer`, map 512-8192, PCF 1 and 3).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np

from ..camera.model import Intrinsics
from ..geometry.caster import ShadowCaster
from ..geometry.exact import ShadowOracle, boundary_error_px, ground_shadow_triangles, iou
from ..geometry.mesh import load_occluder
from ..geometry.silhouette import silhouette
from ..geometry.volume import shadow_volume
from ..gl.shadowmap import MAP_SIZES, ShadowMapRenderer
from ..gl.stencil import LightPass, ShadowRenderer
from ..lights.area import sample_area_light
from ..lights.spec import parse_light
from ..renderer.request import RenderRequest
from ..synth.markers import look_at_pose
from ..transforms import CV_TO_GL
from .common import ROOT, summary

#: (name, caster, camera, cam_from_world (4, 4), light_h (4,), families measured or None = all)
Scene = tuple[str, ShadowCaster, Intrinsics, np.ndarray, np.ndarray, tuple[str, ...] | None]

W, H = 1280, 720
ZNEAR = 0.01


#: configuration family measured only in the scenes that name it (the thin cards)
NO_BIAS = "shadow map, bias off"

#: the thin card: 6 cm x 8 cm, 1 mm thick, standing on the ground (the benchmarks' brief quotes pyrender's shadow map
#: losing a thin card's shadow at 4096 texels and above)
THIN_CARD = "box:0.06,0.001,0.08"


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """``(4,) float64`` homogeneous direction towards a light at that elevation above the ground and azimuth
    (degrees from +x towards +y)."""
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el), 0.0])


def scenes(quick: bool) -> list[Scene]:
    """``[(name, caster, Intrinsics, cam_from_world, light_h, families)]`` (``families``: the configuration
    families measured, None = all).

    The 8 536-face knot at 1280x720 under a point light (bench_render's scene) and, in the full run, under a
    low sun (a long shadow: the case that stretches a shadow map's texels); a 1 mm thin card
    (:data:`THIN_CARD`) under a 20 deg sun in the card's plane (the card seen edge-on by the light: a 1 mm
    wide sliver in the shadow map, a ~2 px wide shadow in the photo) and, in the full run, facing the same
    sun (a long, wide shadow cast by a 1 mm slab). The thin cards are measured with the stencil and
    shadow-map configurations only, plus shadow maps with the bias off (:data:`NO_BIAS`).
    """
    caster = load_occluder(ROOT / "samples" / "meshes" / "knot.ply")
    K = Intrinsics(fx=1000.0, fy=1000.0, cx=641.3, cy=357.8, width=W, height=H, dist=np.zeros(0))
    T = look_at_pose([0.3, -0.32, 0.3], [0.0, 0.02, 0.02])
    out: list[Scene] = [("knot, point light", caster, K, T, np.array([-0.15, 0.2, 0.5, 1.0]), None)]
    if not quick:
        T2 = look_at_pose([0.25, -0.45, 0.35], [-0.05, 0.05, 0.0])
        out.append(("knot, low sun (25 deg)", caster, K, T2, sun_direction(25.0, 120.0), None))
    card = load_occluder(THIN_CARD)  # the card's plane is x-z; 1 mm along y
    thin = ("stencil", "planar", "shadow map", NO_BIAS)
    out.append(
        (
            "thin card (1 mm), sun 20 deg in the card's plane (edge-on)",
            card,
            K,
            look_at_pose([0.3, 0.35, 0.3], [0.08, 0.0, 0.02]),
            sun_direction(20.0, 180.0),
            thin,
        )
    )
    if not quick:
        out.append(
            (
                "thin card (1 mm), sun 20 deg facing the card",
                card,
                K,
                look_at_pose([0.3, 0.35, 0.3], [0.0, -0.08, 0.02]),
                sun_direction(20.0, -90.0),
                thin,
            )
        )
    return out


def map_texel_m(caster: ShadowCaster, light_h: np.ndarray, map_size: int) -> float:
    """Side (metres) of one shadow-map texel at the caster's centre: the map spans the caster's bounding
    sphere (:func:`arshadow.gl.shadowmap.light_view_projection`: 2 r for a directional light, the tangent cone's
    width at the centre for a point light)."""
    b = np.asarray(caster.bounds, np.float64)
    c, r = 0.5 * (b[0] + b[1]), 0.5 * float(np.linalg.norm(b[1] - b[0]))
    h = np.asarray(light_h, np.float64)
    if h[3] == 0:
        return 2.0 * r / map_size
    d = float(np.linalg.norm(c - h[:3] / h[3]))
    return 2.0 * d * float(np.tan(np.arcsin(min(r / d, 1.0)))) / map_size


def roi_of(
    caster: ShadowCaster, K: Intrinsics, T: np.ndarray, L: np.ndarray, margin: int = 2, width: int = W, height: int = H
) -> tuple[int, int, int, int]:
    """Pixel box ``(u0, v0, w, h)`` of the occluder and its exact ground shadow, clipped to the image."""
    V = np.asarray(caster.vertices)
    S = ground_shadow_triangles(V, caster.faces, L).reshape(-1, 2)
    P = np.concatenate([V, np.c_[S, np.zeros(len(S))]])
    u, v = K.project(P, T, distort=False).T
    u0 = max(int(np.floor(u.min())) - margin, 0)
    v0 = max(int(np.floor(v.min())) - margin, 0)
    u1 = min(int(np.ceil(u.max())) + margin + 1, width)
    v1 = min(int(np.ceil(v.max())) + margin + 1, height)
    return u0, v0, u1 - u0, v1 - v0


class Reference:
    """The exact shadow of one scene on its ROI: pixel-centre mask, boundary band and area coverage."""

    def __init__(self, caster: ShadowCaster, K: Intrinsics, T: np.ndarray, L: np.ndarray, roi: Any):

        self.roi = roi
        self.oracle = ShadowOracle(K.K, T, caster.vertices, caster.faces, [(L, 1.0)])
        m, _, _ = self.oracle.image(W, H, canvas=roi)
        self.mask = m >= 0.5
        k = np.ones((5, 5), np.uint8)
        m8 = self.mask.astype(np.uint8)
        self.band = np.argwhere(cv2.dilate(m8, k) != cv2.erode(m8, k))
        u0, v0 = roi[:2]
        # 8 x 8 sub-samples: a grid finer than any anti-aliasing pattern measured (4 x 4 supersampling
        # would otherwise sample exactly the reference's points)
        sub = (np.arange(8) + 0.5) / 8 - 0.5
        su, sv = np.meshgrid(sub, sub)
        uu = (self.band[:, 1][:, None] + u0 + su.ravel()[None, :]).ravel()
        vv = (self.band[:, 0][:, None] + v0 + sv.ravel()[None, :]).ravel()
        self.coverage = self.oracle.classify(uu, vv)[0].reshape(len(self.band), 64).mean(axis=1)
        er = cv2.erode(m8, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)
        self.perimeter = int(np.count_nonzero(m8 != er))

    def errors(self, mask: np.ndarray) -> dict:
        b = mask >= 0.5
        xor = int(np.count_nonzero(b != self.mask))
        be = boundary_error_px(b, self.mask)
        return {
            "iou": iou(b, self.mask),
            "xor_px": xor,
            "edge_offset_px": xor / max(self.perimeter, 1),
            "area_ratio": int(np.count_nonzero(b)) / max(int(np.count_nonzero(self.mask)), 1),
            "boundary_p95_px": be["p95"],
            "boundary_max_px": be["max"],
            "coverage_mae": float(np.abs(mask[self.band[:, 0], self.band[:, 1]] - self.coverage).mean()),
        }


def _configs(ctx: Any, quick: bool) -> list[tuple[str, str, Callable[[], Any], dict]]:
    """``[(family, label, factory, pass options)]``; factory() -> renderer; pass options: mode, truncate,
    scale (render resolution scale)."""
    st = lambda **kw: lambda: ShadowRenderer(ctx, max_width=W, max_height=H, **kw)  # noqa: E731
    out: list[tuple[str, str, Callable[[], Any], dict]] = [
        ("stencil", "z-pass, truncated (default)", st(), dict(mode="zpass", truncate=True)),
        ("stencil", "z-pass, to infinity", st(), dict(mode="zpass", truncate=False)),
        ("stencil", "z-fail (caps), truncated", st(), dict(mode="zfail", truncate=True)),
        ("stencil", "z-fail (caps), to infinity", st(), dict(mode="zfail", truncate=False)),
        ("planar", "planar projection ([Kolivand-Stencil])", st(), dict(mode="planar")),
    ]
    ms = [s for s in (2, 4, 8) if s <= ctx.max_samples]
    aa = [(f"MSAA {s}", dict(samples=s)) for s in (ms if not quick else ms[-1:])]
    aa += [("supersample 2x2", dict(supersample=2))]
    if not quick:
        aa += [("supersample 4x4", dict(supersample=4)), ("MSAA 4 + supersample 2x2", dict(samples=4, supersample=2))]
    out += [("stencil AA", lab, st(**kw), dict(mode="zpass", truncate=True)) for lab, kw in aa]
    for s in (0.5,) if quick else (0.25, 0.5, 0.75):
        out.append(
            (
                "stencil scaled",
                f"render at {s:g}x resolution, bilinear upscale",
                st(),
                dict(mode="zpass", truncate=True, scale=s),
            )
        )
    sizes = (512, 2048, 8192) if quick else MAP_SIZES
    for size in sizes:
        for pcf in (1, 3) if not quick or size == 2048 else (3,):
            out.append(
                (
                    "shadow map",
                    f"shadow map {size}, PCF {pcf}x{pcf}",
                    functools.partial(ShadowMapRenderer, ctx, map_size=size, pcf=pcf, max_width=W, max_height=H),
                    dict(mode="zpass", map_size=size),
                )
            )
    # the bias's share in the thin card's error: the same map with glPolygonOffset(0, 0) (scenes that ask for
    # the family only)
    for size in (2048,) if quick else (1024, 4096):
        out.append(
            (
                NO_BIAS,
                f"shadow map {size}, PCF 1x1, bias off",
                functools.partial(
                    ShadowMapRenderer,
                    ctx,
                    map_size=size,
                    pcf=1,
                    slope_bias=0.0,
                    constant_bias=0.0,
                    max_width=W,
                    max_height=H,
                ),
                dict(mode="zpass", map_size=size),
            )
        )
    return out


def run(cfg: dict, ctx: Any, log: Callable[[str], None]) -> list[dict]:

    rows = []
    for name, caster, K, T, L, families in scenes(cfg["quick"]):
        u0, v0, w, h = roi_of(caster, K, T, L)
        # aligned to 4 px, so that the 0.25 / 0.5 / 0.75 x canvases cover exactly the same region
        u1, v1 = min(-(-(u0 + w) // 4) * 4, W), min(-(-(v0 + h) // 4) * 4, H)
        u0, v0 = u0 // 4 * 4, v0 // 4 * 4
        roi = (u0, v0, u1 - u0, v1 - v0)
        t0 = time.perf_counter()
        ref = Reference(caster, K, T, L, roi)
        log(f"  render: exact reference of '{name}' ({roi[2]}x{roi[3]} px) in {time.perf_counter() - t0:.1f} s")
        view = CV_TO_GL @ T
        sil = silhouette(caster, L)
        tz = -1e-3 * caster.scale
        vols = {
            (caps, tr): shadow_volume(caster, L, sil, caps=caps, truncate_z=tz if tr else None)
            for caps in (False, True)
            for tr in (False, True)
        }
        for family, label, factory, opt in _configs(ctx, cfg["quick"]):
            if (families is None and family == NO_BIAS) or (families is not None and family not in families):
                continue
            mode = opt["mode"]
            vol = None if mode == "planar" else vols[(mode == "zfail", opt.get("truncate", True))]
            passes = (LightPass(L, 1.0, vol, mode),)
            s = opt.get("scale", 1.0)
            u0, v0, w, h = roi
            if s != 1.0:
                Ks = K.scaled(int(round(W * s)), int(round(H * s)))
                canvas = (int(round(u0 * s)), int(round(v0 * s)), max(int(round(w * s)), 1), max(int(round(h * s)), 1))
                P = Ks.gl_projection(ZNEAR, None, canvas=canvas)
            else:
                canvas, P = roi, K.gl_projection(ZNEAR, None, canvas=roi)
            with factory() as r:

                def once() -> np.ndarray:
                    res = r.render(
                        RenderRequest(
                            projection=P, view=view, width=canvas[2], height=canvas[3], caster=caster, passes=passes
                        )
                    )
                    m = res.mask
                    if s != 1.0:
                        # the scaled canvas covers [u0*s, (u0+w)*s) ~ the ROI: resample to the ROI's pixels
                        m = cv2.resize(m, (w, h), interpolation=cv2.INTER_LINEAR)
                    out: np.ndarray = m
                    return out

                for _ in range(cfg["warmup"]):
                    once()
                ts = []
                for _ in range(cfg["render_repeat"]):
                    t1 = time.perf_counter()
                    m = once()
                    ts.append((time.perf_counter() - t1) * 1e3)
            st = summary(ts, 4)
            rows.append(
                {
                    "scene": name,
                    "family": family,
                    "config": label,
                    "roi_w": w,
                    "roi_h": h,
                    "time_ms": st["median"],
                    "time_q25": st["iqr"][0],
                    "time_q75": st["iqr"][1],
                    "time_n": st["n"],
                    **ref.errors(m),
                    "map_texel_um": (map_texel_m(caster, L, opt["map_size"]) * 1e6 if "map_size" in opt else None),
                }
            )
        log(f"  render: '{name}' {len(rows)} points")
    return rows + soft(cfg, ctx, log)


def equal_time(rows: list[dict]) -> list[dict]:
    """Per scene: the default stencil configuration against the most accurate shadow map that is not
    slower than it, and against the shadow map closest to it in time."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        rs = [r for r in rows if r["scene"] == scene]
        st = next((r for r in rs if r["config"].endswith("(default)")), None)
        if st is None or not any(r["family"] == "shadow map" for r in rs):
            continue
        sm = [r for r in rs if r["family"] == "shadow map"]
        faster = [r for r in sm if r["time_ms"] <= st["time_ms"]]
        best_fast = max(faster, key=lambda r: r["iou"]) if faster else None
        nearest = min(sm, key=lambda r: abs(np.log(r["time_ms"] / st["time_ms"])))
        out.append(
            {
                "scene": scene,
                "stencil": st,
                "shadowmap_not_slower": best_fast,
                "shadowmap_nearest_time": nearest,
                "best_shadowmap": max(sm, key=lambda r: r["iou"]),
            }
        )
    return out


def pareto(rows: list[dict], key: str = "xor_px") -> list[dict]:
    """The points no other point beats in both time and ``key`` (lower is better for both)."""
    pts = sorted(rows, key=lambda r: (r["time_ms"], r[key]))
    out, best = [], float("inf")
    for r in pts:
        if r[key] < best:
            out.append(r)
            best = r[key]
    return out


def soft(cfg: dict, ctx: Any, log: Callable[[str], None]) -> list[dict]:
    """Soft shadows: a spherical light of radius 4 cm split into N hard samples (stencil volumes, one pass
    each) against a GL-independent reference: the exact hard shadows (:class:`arshadow.geometry.exact.ShadowOracle`)
    of 256 stratified samples of the same disc, averaged. ``coverage_mae`` here is the mean |mask -
    reference| over the pixels where either is non-zero (umbra + penumbra)."""
    caster = load_occluder("box:0.08,0.06,0.12")
    K = Intrinsics(fx=1000.0, fy=1000.0, cx=641.3, cy=357.8, width=W, height=H, dist=np.zeros(0))
    T = look_at_pose([0.35, -0.45, 0.4], [0.0, 0.03, 0.02])
    light = parse_light("point:-0.15,0.1,0.45,radius=0.04")
    ref_lights = sample_area_light(light, 256, seed=99)
    u0, v0, w, h = roi_of(caster, K, T, np.array([-0.15, 0.1, 0.45, 1.0]), margin=40)
    orc = ShadowOracle(K.K, T, caster.vertices, caster.faces, [(s.homogeneous, s.weight) for s in ref_lights])
    ref = orc.image(W, H, canvas=(u0, v0, w, h))[0]
    P, view = K.gl_projection(ZNEAR, None, canvas=(u0, v0, w, h)), CV_TO_GL @ T
    rows = []
    with ShadowRenderer(ctx, max_width=W, max_height=H) as r:
        for n in cfg.get("soft_samples", (1, 4, 16, 64)):
            samples = sample_area_light(light, n, seed=1)
            tot = sum(s.weight for s in samples)
            passes = []
            for s in samples:
                hh = np.asarray(s.homogeneous, np.float64)
                vol = shadow_volume(caster, hh, silhouette(caster, hh), caps=False, truncate_z=-1e-3 * caster.scale)
                passes.append(LightPass(hh, s.weight / tot, vol, "zpass"))
            req = RenderRequest(projection=P, view=view, width=w, height=h, caster=caster, passes=tuple(passes))
            once = lambda: r.render(req)  # noqa: E731
            for _ in range(cfg["warmup"]):
                once()
            ts = []
            for _ in range(cfg["render_repeat"]):
                t1 = time.perf_counter()
                m = once().mask
                ts.append((time.perf_counter() - t1) * 1e3)
            st = summary(ts, 4)
            region = (ref > 0) | (m > 0)
            b, rb = m >= 0.5, ref >= 0.5
            rows.append(
                {
                    "scene": "box, spherical light r = 4 cm (soft)",
                    "family": "soft shadow",
                    "config": f"{n} sample{'s' if n > 1 else ''} per light",
                    "roi_w": w,
                    "roi_h": h,
                    "time_ms": st["median"],
                    "time_q25": st["iqr"][0],
                    "time_q75": st["iqr"][1],
                    "time_n": st["n"],
                    "iou": iou(b, rb),
                    "xor_px": int(np.count_nonzero(b != rb)),
                    "area_ratio": int(np.count_nonzero(b)) / max(int(np.count_nonzero(rb)), 1),
                    "edge_offset_px": float("nan"),
                    "boundary_p95_px": boundary_error_px(b, rb)["p95"],
                    "boundary_max_px": boundary_error_px(b, rb)["max"],
                    "coverage_mae": float(np.abs(m - ref)[region].mean()),
                }
            )
    log(f"  render: soft shadows {len(rows)} points")
    return rows
