"""Soft shadows through the real renderer: the penumbra of a box edge under an area light (sphere light
and a sun-like cone) against the geometric prediction, and N = 1 reproducing the hard shadow exactly.

Set-up: a pinhole camera straight above the origin looking down, so ground pixels map linearly to world
(x, y) (u = cx + f x / D, v = cy - f y / D); the occluder is not drawn (``draw_occluder=False``) so the
whole ground is seen; the mask row through the box centre is read along +x, across the box's edge.
The prediction is pure geometry written out here (similar triangles, the circular-segment area of a disc):
nothing is taken from the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import TOL
from oracle import disc_segment_fraction, profile_crossing
from soft_shadow_scene import F_PX, H_IMG, HB, A, D, W, profile, render_masks, widths

from arshadow.lights.area import sample_area_light
from arshadow.lights.spec import Light, parse_light

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def scene():
    for mod in (
        "arshadow.gl.stencil",
        "arshadow.geometry.mesh",
        "arshadow.geometry.silhouette",
        "arshadow.geometry.volume",
    ):
        pytest.importorskip(mod)
    from arshadow.camera.model import Intrinsics
    from arshadow.geometry.mesh import load_occluder
    from arshadow.transforms import CV_TO_GL

    intr = Intrinsics(fx=F_PX, fy=F_PX, cx=(W - 1) / 2, cy=(H_IMG - 1) / 2, width=W, height=H_IMG, dist=np.zeros(0))
    cam_from_world = np.diag([1.0, -1.0, -1.0, 1.0])
    cam_from_world[2, 3] = D  # z_cam = D - z
    caster = load_occluder(f"box:{2 * A},{2 * A},{HB}")
    return {
        "intr": intr,
        "proj": intr.gl_projection(1e-3, None),
        "view": CV_TO_GL @ cam_from_world,
        "caster": caster,
        "x": (np.arange(W) - intr.cx) / F_PX * D,  # world x of each column on the ground
    }


@pytest.fixture(scope="module")
def renderer(gl_ctx):
    from arshadow.gl.stencil import ShadowRenderer

    r = ShadowRenderer(gl_ctx, max_width=W, max_height=H_IMG, samples=0)
    yield r
    r.release()


def test_point_light_penumbra_width(scene, renderer):
    r, Hl, n = 0.05, 0.5, 64
    li = parse_light(f"point:0,0,{Hl},radius={r}")
    mask = render_masks(scene, renderer, sample_area_light(li, n, seed=0))
    x, f = profile(scene, mask)
    # geometry: a disc sample at x-offset s is hidden from ground point x iff s < x - (x - A) Hl / HB
    full_pred = 2 * r * HB / (Hl - HB)
    c = x - (x - A) * Hl / HB
    exact = 1.0 - disc_segment_fraction(c / r)
    _, w1090_pred = widths(x, np.where(exact > 1 - 1e-12, 1.0, exact), 1e6)
    full, w1090 = widths(x, f, n)
    assert abs(full - full_pred) / full_pred <= TOL.penumbra_rel, (full, full_pred)
    assert abs(w1090 - w1090_pred) / w1090_pred <= TOL.penumbra_rel, (w1090, w1090_pred)
    # and the whole profile follows the disc's segment area (stratified: within a few samples)
    assert np.max(np.abs(f - exact)) < TOL.penumbra_profile_64
    # mask values are multiples of 1/n (each sample is a hard, equally weighted light)
    np.testing.assert_allclose(f * n, np.round(f * n), atol=2e-2)


def test_sun_cone_penumbra_width(scene, renderer):
    """Directional light at elevation e with angular radius alpha (a large 'sun' so the penumbra spans
    many pixels): penumbra from HB / tan(e + alpha) to HB / tan(e - alpha) beyond the edge."""
    e, alpha, n = math.radians(55.0), math.radians(3.0), 64
    li = Light("directional", [-math.cos(e), 0.0, math.sin(e)], radius=alpha, label="sun-like")
    mask = render_masks(scene, renderer, sample_area_light(li, n, seed=1))
    x, f = profile(scene, mask)
    full_pred = HB / math.tan(e - alpha) - HB / math.tan(e + alpha)
    full, _ = widths(x, f, n)
    assert abs(full - full_pred) / full_pred <= TOL.penumbra_rel, (full, full_pred)
    # 50 % where the centre direction puts the hard edge
    assert profile_crossing(x, f, 0.5) == pytest.approx(A + HB / math.tan(e), abs=2 * D / F_PX)


@pytest.mark.parametrize("spec", ["point:0.02,-0.01,0.5,radius=0.05@3", "directional:-1,0.2,1,radius=2"])
def test_one_sample_is_the_hard_shadow_exactly(scene, renderer, spec):
    li = parse_light(spec)
    hard = Light(li.kind, li.vector, weight=li.weight, radius=0.0, label=li.label)
    m1 = render_masks(scene, renderer, sample_area_light(li, 1))
    mh = render_masks(scene, renderer, [hard])
    np.testing.assert_array_equal(m1, mh)
    assert set(np.unique(m1)) <= {0.0, 1.0} and m1.sum() > 1000
    # and the soft shadow is not the hard one, yet has the same total darkness to within the penumbra
    ms = render_masks(scene, renderer, sample_area_light(li, 16))
    assert not np.array_equal(ms, mh)
