"""The object's light on itself (arshadow.shading.interreflect) against closed forms: two long parallel walls
standing on the ground, a gap W apart, H high. Far from their ends the geometry is two-dimensional, and a
point on a wall's inner face at height z sees, of its cosine-weighted hemisphere (the view factor of a
differential strip, Hottel's crossed strings: half the difference of the sines of the edges' angles),

    the other wall  O(z) = ((H - z) / sqrt((H - z)^2 + W^2) + z / sqrt(z^2 + W^2)) / 2
    the sky         V(z) = (1 - (H - z) / sqrt((H - z)^2 + W^2)) / 2
    the ground      G(z) = (1 - z / sqrt(z^2 + W^2)) / 2

Under a uniform sky alone (ambient A, no direct light, no ground light) each inner face gets A V(z), and by
reciprocity the light the walls send onto the parts that see them is, per unit of O, the O-weighted mean of
their radiosity: albedo A int O V dz / int O dz (every other face sees nothing of the object).
"""

from __future__ import annotations

import numpy as np
import pytest

H, W, L, T = 0.05, 0.05, 1.0, 0.01  # wall height, gap, length, thickness (metres)
STRIPS, SEGMENTS = 16, 8  # the inner face's grid (heights, lengths)


def _wall(y_in: float, y_out: float) -> tuple[np.ndarray, np.ndarray]:
    """One wall, x in [-L/2, L/2], y between y_in (the inner face) and y_out, z in [0, H]: the inner face a grid
    of STRIPS x SEGMENTS quads, the other faces one quad each; faces wound outwards."""
    x0, x1 = -L / 2, L / 2
    zs = np.linspace(0.0, H, STRIPS + 1)
    xs = np.linspace(x0, x1, SEGMENTS + 1)
    verts, faces = [], []

    def quad(a, b, c, d):  # counter-clockwise seen from outside
        k = len(verts)
        verts.extend([a, b, c, d])
        faces.extend([[k, k + 1, k + 2], [k, k + 2, k + 3]])

    s = 1.0 if y_out > y_in else -1.0  # the inner face looks towards -s y
    for z0, z1 in zip(zs[:-1], zs[1:], strict=True):
        for a0, a1 in zip(xs[:-1], xs[1:], strict=True):
            p = [[a0, y_in, z0], [a1, y_in, z0], [a1, y_in, z1], [a0, y_in, z1]]
            quad(*(p if s > 0 else p[::-1]))
    o = [[x0, y_out, 0.0], [x0, y_out, H], [x1, y_out, H], [x1, y_out, 0.0]]
    quad(*(o if s > 0 else o[::-1]))
    t = [[x0, y_in, H], [x1, y_in, H], [x1, y_out, H], [x0, y_out, H]]
    quad(*(t if s > 0 else t[::-1]))
    b = [[x0, y_in, 0.0], [x0, y_out, 0.0], [x1, y_out, 0.0], [x1, y_in, 0.0]]
    quad(*(b if s > 0 else b[::-1]))
    e0 = [[x0, y_in, 0.0], [x0, y_in, H], [x0, y_out, H], [x0, y_out, 0.0]]
    quad(*(e0 if s > 0 else e0[::-1]))
    e1 = [[x1, y_in, 0.0], [x1, y_out, 0.0], [x1, y_out, H], [x1, y_in, H]]
    quad(*(e1 if s > 0 else e1[::-1]))
    return np.array(verts, np.float64), np.array(faces)


def _walls():
    from arshadow.geometry.caster import ShadowCaster

    va, fa = _wall(-W / 2, -W / 2 - T)
    vb, fb = _wall(W / 2, W / 2 + T)
    return ShadowCaster(np.concatenate([va, vb]), np.concatenate([fa, fb + len(va)]))


def _closed(z):
    z = np.asarray(z, np.float64)
    up, down = (H - z) / np.hypot(H - z, W), z / np.hypot(z, W)
    return (1.0 - up) / 2.0, (1.0 - down) / 2.0, (up + down) / 2.0  # V, G, O


def _closed_mean_ov(n: int = 4000) -> float:
    z = (np.arange(n) + 0.5) / n * H
    v, _, o = _closed(z)
    return float((o * v).sum() / o.sum())


def test_walls_sky_ground_and_self_shares_against_the_strip_view_factors():
    from arshadow.shading.sky import object_sky_visibility

    caster = _walls()
    z = np.array([0.1, 0.3, 0.5, 0.7, 0.9]) * H
    pts = np.c_[np.zeros_like(z), np.full_like(z, W / 2), z]  # wall B's inner face, mid-length
    nrm = np.tile([0.0, -1.0, 0.0], (len(z), 1))
    cv, cg, co = _closed(z)
    # exact rays (the reference method; the renderer's item buffers: the rendered test below, whose 64
    # directions over the sphere are up to 0.07 off per point, their quadrature's error)
    v, g = object_sky_visibility(caster, pts, nrm, method="rays", n_dirs=2048)
    np.testing.assert_allclose(v, cv, atol=0.005)
    np.testing.assert_allclose(g, cg, atol=0.005)
    np.testing.assert_allclose(1.0 - v - g, co, atol=0.005)


def test_self_light_of_the_walls_is_the_reciprocity_mean_of_their_radiosity():
    from arshadow.renderer.request import Shading
    from arshadow.shading.interreflect import SelfView, face_irradiance, self_light
    from arshadow.shading.sky import SkyShading, object_sky_visibility

    caster = _walls()
    centres = caster.vertices[caster.faces].mean(axis=1)
    side = np.abs(caster.face_planes[:, 1]) > 0.5
    centres[side, 0] = 0.0  # the walls' long faces at mid-length (the two-dimensional part)
    s, g = object_sky_visibility(caster, centres, caster.face_planes[:, :3], method="rays", n_dirs=512)
    view = SelfView(caster, np.c_[s, g])
    A, albedo = 0.7, 0.6
    shading = Shading(ambient=A, sky=SkyShading(bounce=(0.0, 0.0, 0.0)))  # the sky alone, white
    got = self_light(view, face_irradiance(view, [], shading), (albedo,) * 3)
    want = albedo * A * _closed_mean_ov()
    np.testing.assert_allclose(got, want, rtol=0.03)


def test_a_convex_mesh_sees_none_of_itself():
    from arshadow.geometry.mesh import load_occluder
    from arshadow.shading.interreflect import self_view
    from arshadow.shading.sky import object_sky_visibility

    box = load_occluder("box:0.045,0.065,0.07")
    p = box.vertices[box.faces].reshape(-1, 3)
    n = np.repeat(box.face_planes[:, :3], 3, axis=0)
    s, g = object_sky_visibility(box, p, n)
    assert self_view(box, np.arange(3 * box.n_faces).reshape(-1, 3), np.c_[s, g]) is None


@pytest.mark.gl
def test_rendered_wall_gets_the_sky_and_the_other_walls_light(gl_ctx):
    # the renderer end to end: a white wall's inner face under a uniform sky (ambient A, no direct light)
    # records A V(z) + albedo A O(z) int O V / int O (the closed forms above); without the albedo, A V(z)
    from test_gl_realism import _pixel, _render, _renderer

    from arshadow.shading.sky import SkyShading
    from arshadow.synth.markers import look_at_pose

    caster = _walls()
    pose = look_at_pose([0.0, -0.1, 0.4], [0.0, 0.02, 0.02])
    A, albedo = 0.7, 0.6
    r = _renderer(gl_ctx)
    try:
        kw = {"ambient": A, "diffuse": 0.0, "specular": 0.0, "color": (1.0, 1.0, 1.0)}
        res = _render(r, caster, pose, sky=SkyShading(albedo=(albedo,) * 3), **kw)
        dark = _render(r, caster, pose, sky=SkyShading(), **kw)
    finally:
        r.release()
    for zf in (0.5, 0.7, 0.85):
        x, y = _pixel(pose, [0.0, W / 2, zf * H])
        v, _, o = _closed(zf * H)
        assert res.alpha[y, x] == 1.0
        # the item buffers' 64 directions: a few hundredths of the shares per vertex
        assert dark.color[y, x, 1] == pytest.approx(A * v, abs=0.05 * A)
        added = float(res.color[y, x, 1] - dark.color[y, x, 1])
        assert added == pytest.approx(albedo * A * o * _closed_mean_ov(), rel=0.12)
