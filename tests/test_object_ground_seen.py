"""The object's light from the ground weighted by the ground each point of it sees (``GroundOcclusion.irradiance``,
``occluder_rich_base.frag``'s ``ground_seen``): per fragment, so a face's foot, which sees the dark ground at
its base, is darker than its top, which sees farther. Against an independent Monte Carlo of the face point's
cosine-weighted view of an exact, analytic ground (not the renderer's spiral nor its texture)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import TOL

pytestmark = pytest.mark.gl

W, H = 640, 480
STRIP = (-0.05, -0.02, 0.3)  # the ground with y0 < y < y1 (in front of the box's -y face) receives 0.3


def _irradiance_exact(q: np.ndarray) -> np.ndarray:
    y0, y1, e = STRIP
    inside = (q[..., 1] > y0) & (q[..., 1] < y1) & (np.abs(q[..., 0]) < 0.1)
    return np.where(inside, e, 1.0)


def _mean_ground_seen(p: np.ndarray, n: np.ndarray, rng: np.random.Generator, k: int = 200_000) -> float:
    """The mean irradiance of the ground ``p`` sees along cosine-weighted random directions round ``n``."""
    u1, u2 = rng.random(k), rng.random(k)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    t1 = np.cross(n, [0.0, 0.0, 1.0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    d = np.outer(r * np.cos(phi), t1) + np.outer(r * np.sin(phi), t2) + np.outer(np.sqrt(1 - u1), n)
    down = d[:, 2] < 0
    q = p + (-p[2] / d[down, 2])[:, None] * d[down]
    return float(_irradiance_exact(q).mean())


def test_a_faces_ground_light_follows_the_ground_each_point_sees(ctx):
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.geometry.silhouette import silhouette
    from arshadow.geometry.volume import shadow_volume
    from arshadow.gl.stencil import ShadowRenderer
    from arshadow.renderer.request import LightPass, RenderRequest, Shading
    from arshadow.shading.sky import GroundOcclusion, SkyShading
    from arshadow.synth.markers import look_at_pose
    from arshadow.transforms import CV_TO_GL

    box = load_occluder("box:0.04,0.04,0.08")
    texel = 0.0005
    xs = -0.2 + (np.arange(800) + 0.5) * texel
    gx, gy = np.meshgrid(xs, xs)
    irr = GroundOcclusion(
        -0.2, -0.2, texel, _irradiance_exact(np.dstack([gx, gy])).astype(np.float32), 0, "uniform", 0.0
    )
    ground = GroundOcclusion(-0.1, -0.1, 0.01, np.ones((20, 20), np.float32), 0, "uniform", 0.0, None, irr)
    bounce = 0.5
    lh = np.array([0.0, 1.0, 1.0, 0.0])  # from behind: the -y face gets no direct light
    K = Intrinsics(fx=700.0, fy=700.0, cx=(W - 1) / 2, cy=(H - 1) / 2, width=W, height=H, dist=np.zeros(0))
    pose = look_at_pose([0.0, -0.3, 0.1], [0.0, 0.0, 0.04])
    r = ShadowRenderer(ctx, max_width=W, max_height=H)
    try:
        out = r.render(
            RenderRequest(
                projection=K.gl_projection(0.01, None), view=CV_TO_GL @ pose, width=W, height=H, caster=box,
                passes=[LightPass(lh, 1.0, shadow_volume(box, lh, silhouette(box, lh), caps=True), "zfail")],
                shading=Shading(ambient=0.0, specular=0.0, sky=SkyShading(ground=ground, bounce=(bounce,) * 3)),
            )
        )  # fmt: skip
    finally:
        r.release()
    albedo = ((0.8 + 0.055) / 1.055) ** 2.4  # the default grey, linear
    rng = np.random.default_rng(3)
    got, want = [], []
    for h in (0.004, 0.02, 0.07):
        p = np.array([0.0, -0.02, h])
        cam = pose[:3, :3] @ p + pose[:3, 3]
        x, y = (int(round(K.fx * cam[0] / cam[2] + K.cx)), int(round(K.fy * cam[1] / cam[2] + K.cy)))
        assert out.alpha[y, x] == 1.0
        got.append(float(out.color[y, x, 1]))
        # a vertical face of a convex box sees the ground with half its cosine lobe: albedo x bounce x 1/2 x seen
        want.append(albedo * bounce * 0.5 * _mean_ground_seen(p, np.array([0.0, -1.0, 0.0]), rng))
    np.testing.assert_allclose(got, want, rtol=TOL.ground_seen_rel)
    assert got[0] < 0.6 * got[2]  # the foot sees the dark strip, the top mostly beyond it
