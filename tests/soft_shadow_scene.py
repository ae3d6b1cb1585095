"""The soft-shadow scene of tests/test_soft_shadows.py (a box edge seen from above at 0.5 mm per pixel) and its
measurements, shared with tests/benchmarks/bench_lights.py."""

from __future__ import annotations

import numpy as np
from oracle import profile_crossing

from arshadow.renderer.request import RenderRequest

F_PX, D = 2000.0, 1.0  # focal length (px) and camera height (m)
W, H_IMG = 640, 240  # ground x in [-0.16, 0.16] m at 0.5 mm per pixel
A, HB = 0.05, 0.1  # box half-width and height (m)


def render_masks(scene, renderer, lights, mode="zfail"):
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import LightPass

    total = sum(li.weight for li in lights)
    passes = []
    for li in lights:
        h = li.homogeneous
        sil = silhouette(scene["caster"], h)
        vol = shadow_volume(scene["caster"], h, sil, caps=(mode == "zfail"))
        passes.append(LightPass(light_h=h, weight=li.weight / total, volume=vol, mode=mode))
    res = renderer.render(
        RenderRequest(
            projection=scene["proj"],
            view=scene["view"],
            width=W,
            height=H_IMG,
            caster=scene["caster"],
            passes=passes,
            draw_occluder=False,
        )
    )
    return res.mask


def profile(scene, mask):
    """Mask along the row through the box centre, for x beyond the box edge (ground z = 0 at y = 0)."""
    row = int(round(scene["intr"].cy))
    x = scene["x"]
    keep = x > A
    return x[keep], mask[row, keep].astype(np.float64)


def widths(x, f, n):
    """Full penumbra width (first departure from 1 to last departure from 0) and the 10-90 % width."""
    eps = 0.5 / n
    part = np.nonzero((f > eps) & (f < 1 - eps))[0]
    lo, hi = np.nonzero(f < 1 - eps)[0][0], np.nonzero(f > eps)[0][-1]
    assert part.size > 3
    full = x[hi] - x[lo] + (x[1] - x[0])  # pixel extent: count the end pixels whole
    return full, profile_crossing(x, f, 0.1) - profile_crossing(x, f, 0.9)
