"""Sky visibility (arshadow.shading.sky) against closed forms: Lambert's polygon form factor, the parallel
rectangle's view factor, a convex object's tilted-plane horizon."""

import math

import numpy as np
import pytest

from arshadow.geometry.caster import ShadowCaster
from arshadow.geometry.mesh import load_occluder, primitive
from arshadow.shading import sky
from arshadow.shading.decide import PAPER_ALBEDO, ground_light, ground_units
from arshadow.shading.sky import (
    GroundGrid,
    cosine_directions,
    ground_grid,
    ground_raster_cpu,
    ground_sky_visibility,
    lamp_incidence,
    object_sky_visibility,
)
from tests.conftest import TOL

UP = np.array([0.0, 0.0, 1.0])


def lambert_form_factor(p, n, poly):
    """Form factor from a differential area at ``p`` with normal ``n`` to the planar polygon ``poly (k, 3)``
    wholly in front of it (Lambert's contour formula: sum over edges of the subtended angle times the
    cosine of the edge plane's normal with n, over 2 pi)."""
    r = np.asarray(poly, float) - p
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    s = 0.0
    for i in range(len(r)):
        a, b = r[i], r[(i + 1) % len(r)]
        c = np.cross(a, b)
        s += math.acos(float(np.clip(a @ b, -1, 1))) * float(n @ c) / float(np.linalg.norm(c))
    return abs(s) / (2 * math.pi)


def box_faces(wx, wy, hz, z0=0.0):
    """Outward normal -> corner polygon of an axis-aligned box centred on the z axis, bottom at z0."""
    x, y, lo, hi = wx / 2, wy / 2, z0, z0 + hz
    return {
        (1, 0, 0): [[x, -y, lo], [x, y, lo], [x, y, hi], [x, -y, hi]],
        (-1, 0, 0): [[-x, -y, lo], [-x, y, lo], [-x, y, hi], [-x, -y, hi]],
        (0, 1, 0): [[-x, y, lo], [x, y, lo], [x, y, hi], [-x, y, hi]],
        (0, -1, 0): [[-x, -y, lo], [x, -y, lo], [x, -y, hi], [-x, -y, hi]],
        (0, 0, 1): [[-x, -y, hi], [x, -y, hi], [x, y, hi], [-x, y, hi]],
    }


def box_ground_visibility(p, wx, wy, hz):
    """1 - the form factor to a convex box's faces that face p (their projections tile its silhouette)."""
    f = 0.0
    for nf, poly in box_faces(wx, wy, hz).items():
        poly = np.array(poly, float)
        if np.dot(nf, p - poly.mean(0)) > 1e-12:
            f += lambert_form_factor(p, UP, poly)
    return 1.0 - f


def parallel_rectangle_ff(a, b, c):
    """View factor from a differential area to a parallel a x b rectangle at height c with one corner right
    above it (Howell's catalogue, C-11)."""
    x, y = a / c, b / c
    return (
        x / math.sqrt(1 + x * x) * math.atan(y / math.sqrt(1 + x * x))
        + y / math.sqrt(1 + y * y) * math.atan(x / math.sqrt(1 + y * y))
    ) / (2 * math.pi)


def test_cosine_directions_integrate_the_cosine_lobe():
    d = cosine_directions(4096, normal=(1.0, 2.0, 0.5))
    n = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    cos = d @ n
    assert cos.min() > 0
    # under the density cos/pi: E[cos] = 2/3, E[cos^2] = 1/2, mean direction = (2/3) n
    assert abs(cos.mean() - 2 / 3) < 1e-3 and abs((cos**2).mean() - 0.5) < 1e-3
    assert np.linalg.norm(d.mean(axis=0) - 2 / 3 * n) < 2e-3


BOX = (0.045, 0.065, 0.07)  # the box
BOX_SPEC = "box:0.045,0.065,0.07"
# ground points round it: 1 mm .. 10 cm from a face, off a corner, behind the other face
GROUND_POINTS = [(0.0225 + d, 0.0) for d in (0.001, 0.005, 0.015, 0.05, 0.1)] + [(0.03, 0.04), (0.0, -0.0345)]


def test_ground_visibility_beside_a_box_matches_lambert():
    g = ground_sky_visibility(load_occluder(BOX_SPEC))
    pts = np.array(GROUND_POINTS)
    expect = tapered(np.array([box_ground_visibility(np.r_[q, 0.0], *BOX) for q in pts]))
    got = g.sample(pts)
    assert np.abs(got - expect).max() <= TOL.sky_ground_abs, (got - expect).round(4).tolist()
    assert g.edge_occlusion < 0.02  # the grid reaches out to where the box hides ~1 % of the sky
    # open ground off the grid; nothing under the box is sky-lit (raw map before sampling)
    assert g.sample(np.array([[5.0, 5.0]]))[0] == 1.0


def tapered(v):
    """The map's documented taper of small occlusions (ACTIVE_OCCLUSION) applied to exact visibilities."""
    from arshadow.shading.sky import ACTIVE_OCCLUSION

    t0, t1 = ACTIVE_OCCLUSION
    occ = 1.0 - np.asarray(v)
    return 1.0 - occ * np.clip((occ - t0) / (t1 - t0), 0.0, 1.0)


def test_ground_visibility_converges_with_directions():
    c = load_occluder(BOX_SPEC)
    pts = np.array(GROUND_POINTS[1:])
    expect = tapered(np.array([box_ground_visibility(np.r_[q, 0.0], *BOX) for q in pts]))
    errs = [np.abs(ground_sky_visibility(c, n_dirs=n).sample(pts) - expect).mean() for n in (32, 1024)]
    assert errs[1] < 0.5 * errs[0], errs


def test_ground_under_a_raised_plate_matches_the_rectangle_view_factor():
    a, b, c = 0.2, 0.3, 0.05  # plate 20 x 30 cm, its underside 5 cm above the ground
    plate = load_occluder(f"box:{a},{b},0.002", place=(0, 0, c))
    g = ground_sky_visibility(plate)
    expect = 1.0 - 4 * parallel_rectangle_ff(a / 2, b / 2, c)  # four quadrants meeting above the point
    got = g.sample(np.array([[0.0, 0.0]]))[0]
    assert abs(got - expect) <= TOL.sky_ground_abs, (got, expect)


def test_ground_visibility_cie_sky_is_darker_near_a_wall():
    # the CIE overcast sky is brighter above: a box hides low sky, so it darkens the ground less than a
    # uniform sky at the same point (the hidden part weighs less); far away both tend to 1
    c = load_occluder(BOX_SPEC)
    pts = np.array([[0.03, 0.0], [0.05, 0.0]])
    u = ground_sky_visibility(c).sample(pts)
    cie = ground_sky_visibility(c, sky="cie").sample(pts)
    assert np.all(cie > u) and np.all(cie < 1)


def test_object_convex_box_against_the_horizon():
    c = load_occluder(BOX_SPEC)
    pts = np.array([[0.0225, 0.0, 0.02], [0.0, 0.0, 0.07], [0.0, -0.0325, 0.0]])
    nrm = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    sky, ground = object_sky_visibility(c, pts, nrm, n_dirs=4096)
    # a tilted plane alpha from horizontal sees (1 + cos alpha)/2 of the cosine lobe above the horizon
    assert np.abs(sky - [0.5, 1.0, 0.5]).max() <= TOL.sky_object_abs
    assert np.abs(ground - [0.5, 0.0, 0.5]).max() <= TOL.sky_object_abs
    # CIE overcast sky on a vertical face: (pi/6 + 4/9) / (7 pi / 9) (integral of (1 + 2 cos)/3 * cos)
    sky_cie, _ = object_sky_visibility(c, pts[:1], nrm[:1], n_dirs=4096, sky="cie")
    assert abs(sky_cie[0] - (math.pi / 6 + 4 / 9) / (7 * math.pi / 9)) <= TOL.sky_object_abs


def test_object_convexity_is_tested_on_every_face():
    # ShadowCaster.is_convex reads the face planes in blocks, stopping at the first with a vertex in front:
    # the sphere (1 280 faces) is convex and takes the closed form; with a tall box after its faces (the
    # last planes read) the mesh is not, and the box hides the sky of the side facing it
    vs, fs = primitive("sphere:0.04")
    vb, fb = primitive("box:0.02,0.1,0.3")
    p, n = np.array([[0.04, 0.0, 0.04]]), np.array([[1.0, 0.0, 0.0]])  # the sphere's side facing +x
    sky_alone, ground_alone = object_sky_visibility(ShadowCaster(vs, fs), p, n)
    assert (sky_alone[0], ground_alone[0]) == (0.5, 0.5)  # (1 + n_z) / 2: a vertical face of a convex object
    both = ShadowCaster(np.vstack([vs, vb + [0.07, 0.0, 0.0]]), np.vstack([fs, fb + len(vs)]))
    assert not both.is_convex
    sky_both, _ = object_sky_visibility(both, p, n)
    assert sky_both[0] < 0.1  # the box 3 cm away, 30 cm tall, fills most of that face's sky


def test_object_self_occlusion_beside_a_taller_box_matches_lambert():
    # one mesh of two boxes: a low one (5 cm) and, 2 cm beyond it, a tall one (20 cm); a point on the low
    # box's top sees the tall box's facing wall above its own horizon
    v1, f1 = primitive("box:0.06,0.06,0.05")
    v2, f2 = primitive("box:0.06,0.1,0.2")
    v2 = v2 + [0.08, 0.0, 0.0]  # its facing wall at x = 0.05, the low box's right face at x = 0.03
    caster = ShadowCaster(np.vstack([v1, v2]), np.vstack([f1, f2 + len(v1)]))
    pts = np.array([[0.02, 0.0, 0.05], [-0.02, 0.01, 0.05]])
    expect = []
    for q in pts:
        wall = np.array([[0.05, -0.05, 0.05], [0.05, 0.05, 0.05], [0.05, 0.05, 0.2], [0.05, -0.05, 0.2]])
        expect.append(1.0 - lambert_form_factor(q, UP, wall))
    sky, ground = object_sky_visibility(caster, pts, np.tile(UP, (2, 1)), n_dirs=1024)
    assert np.abs(sky - expect).max() <= TOL.sky_object_rays_abs, (sky, expect)
    assert np.all(ground == 0.0)


@pytest.mark.parametrize("spec", ["torus:0.05,0.015", "sphere:0.04"])
def test_torus_hole_and_sphere_base(spec):
    # qualitative, independent of the method: the torus's hole and the sphere's contact are darker than
    # open ground a torus-radius away; the ground map is symmetric under the primitive's symmetry
    c = load_occluder(spec)
    g = ground_sky_visibility(c, resolution=128)
    centre_or_contact = g.sample(np.array([[0.0, 0.0]]) if spec.startswith("torus") else np.array([[0.045, 0.0]]))[0]
    far = g.sample(np.array([[0.2, 0.0]]))[0]
    assert centre_or_contact < far - 0.2
    # symmetric under x -> -x and y -> -y (sampled at mirrored ground points)
    xs = np.linspace(-0.1, 0.1, 41)
    p = np.stack(np.meshgrid(xs, xs), -1).reshape(-1, 2)
    v = g.sample(p)
    # (the direction set is not symmetric: a point on a steep slope may differ by a few directions' share;
    # mean 0.0035 measured at 256 directions, 0.006 at 128, 0.0013 at 1024)
    assert np.abs(v - g.sample(p * [-1, 1])).mean() < 0.005 and np.abs(v - g.sample(p * [1, -1])).mean() < 0.005


def test_object_raster_matches_rays_on_a_torus():
    # the fast method (item buffers per direction, shared by every point) against the exact reference
    # (BVH rays, 256 cosine-weighted directions per point) on a torus: its hole's walls hide the sky
    from arshadow.geometry.normals import crease_normals

    c = load_occluder("torus:0.05,0.015")
    n = crease_normals(c.vertices, c.faces)
    rng = np.random.default_rng(0)
    fi, k = rng.integers(0, c.n_faces, 120), rng.integers(0, 3, 120)
    pts, nrm = c.vertices[c.faces[fi, k]], n[fi, k]
    s_ref, g_ref = object_sky_visibility(c, pts, nrm, n_dirs=256, method="rays")
    s, g = object_sky_visibility(c, pts, nrm, n_dirs=64, method="raster")
    assert (
        np.abs(s - s_ref).mean() <= TOL.sky_object_raster_mean
        and np.abs(g - g_ref).mean() <= TOL.sky_object_raster_mean
    )
    assert s_ref.min() < 0.3 and s_ref.max() > 0.9  # the test sees occluded and open points


def _reflected_light_rise(raster=None):
    """The box's map in front of its -x face with and without the ground's light, and the rise expected: the
    light from +x at 45 degrees (the face unlit, the box's shadow on the ground in front of it); every blocked
    sky direction there sees that face, so the map rises by ``albedo g S (1 - V) / r``, V the exact (Lambert)
    sky visibility and S the face's view of the ground counted at the ground's irradiance, ``(1 - r) lit(q) +
    r V(q)`` at each ground point q it sees (lit: outside the box's exact shadow; the ground beside a box is
    darker than the open ground the ring measures). S here: 2000 cosine-weighted rays from the face's centre
    (Malley's method), each ground point's V by Lambert's form factor. Returns ``(rise, expected rise, S)``."""
    c = load_occluder(BOX_SPEC)
    light, r, albedo, g = np.array([1.0, 0.0, 1.0]), 0.4, 0.5, 0.3
    wx, wy, hz = BOX
    rng = np.random.default_rng(3)
    rad, ang = np.sqrt(rng.uniform(0, 1, 2000)), rng.uniform(0, 2 * np.pi, 2000)
    local = np.c_[rad * np.cos(ang), rad * np.sin(ang), np.sqrt(1 - rad**2)]  # cosine lobe about +z
    d = np.c_[-local[:, 2], local[:, 0], local[:, 1]]  # about the face's normal -x
    centre = np.array([-wx / 2, 0.0, hz / 2])
    down = d[:, 2] < 0
    q = centre + (-centre[2] / d[down, 2])[:, None] * d[down]
    # the box's shadow under a light along (1, 0, 1): |y| <= wy / 2 and -wx / 2 - hz <= x <= wx / 2
    lit = ~((np.abs(q[:, 1]) <= wy / 2) & (q[:, 0] >= -wx / 2 - hz) & (q[:, 0] <= wx / 2))
    e_ground = np.array(
        [(1 - r) * lt + r * box_ground_visibility(np.r_[p[:2], 0.0], *BOX) for p, lt in zip(q, lit, strict=True)]
    )
    seen = down.mean() * e_ground.mean()
    pts = np.array([(-wx / 2 - dd, 0.0) for dd in (0.003, 0.01, 0.02)])
    v = np.array([box_ground_visibility(np.r_[p, 0.0], *BOX) for p in pts])
    without = ground_sky_visibility(c, bounce=(light, r, albedo), raster=raster).sample(pts)
    with_g = ground_sky_visibility(c, bounce=(light, r, albedo, g), raster=raster).sample(pts)
    return with_g - without, albedo * g * seen * (1.0 - v) / r, seen


def test_ground_light_reflected_by_the_object_back_onto_the_ground():
    # the ground lights the box's faces from below, and they reflect it back (_reflected_light_rise). Without
    # the ground's light (the old model) the path tracer's sphere and box halos came out too dark; with the
    # open ground's (S = 1/2 for a vertical face) the ground right beside round objects too bright
    # (docs/reference.md)
    rise, expect, seen = _reflected_light_rise()
    assert np.abs(rise - expect).max() <= TOL.sky_ground_abs, (rise, expect)
    assert np.all(expect > 0.03)  # a visible change
    assert 0.25 < seen < 0.45  # the ground it sees is darker than the open ground (1/2)


def test_the_map_reaches_as_far_as_the_light_the_object_reflects():
    # the taper keeps a texel where the object hides ACTIVE_OCCLUSION[1] of the sky *or* reflects that much of
    # the sky's light: in front of a brightly lit face under a dim sky the reflected light is 3 x the occlusion
    # and reaches further (the path tracer's glow in front of lit faces, docs/reference.md). Ground on the
    # -x face's axis sees that face only: its form factor is the occlusion (Lambert), and the face's
    # irradiance over the open ground's is (1 - r) n.L / L_z + r / 2 (no ground light given)
    c = load_occluder(BOX_SPEC)
    r, albedo = 0.15, 0.5
    pts = np.array([(-BOX[0] / 2 - d, 0.0) for d in (0.06, 0.08, 0.15)])
    occ = 1.0 - np.array([box_ground_visibility(np.r_[p, 0.0], *BOX) for p in pts])
    refl = albedo * ((1.0 - r) + r / 2.0) * occ / r  # over the sky's share
    t0, t1 = sky.ACTIVE_OCCLUSION
    assert occ[0] < t1 < refl[0] and occ[1] < t1 < refl[1]  # an occlusion-only taper cuts the first two short
    assert max(occ[2], refl[2]) < t0  # the third is beyond either
    got = ground_sky_visibility(c, bounce=(np.array([-1.0, 0.0, 1.0]), r, albedo)).sample(pts)
    expect = np.r_[1.0 - occ[:2] + refl[:2], 1.0]
    assert np.abs(got - expect).max() <= TOL.sky_ground_abs, (got - expect).round(4).tolist()


def test_faces_see_the_ground_light_beyond_a_line_as_the_strip_view_factor(monkeypatch):
    # the ground's reflected light read per ground point (arshadow.shading.decide.GroundLight: a white paper
    # beside the object) against the view factor from a point of a vertical face to the ground beyond a line
    # parallel to it, D in front: (sin phi2 - sin phi1) / 2 = h / (2 sqrt(h^2 + D^2)) (an infinite strip)
    monkeypatch.setattr(sky, "GROUND_SEEN_DIRS", 4096)
    caster = load_occluder("box:0.04,0.06,0.07")
    bounce = (np.array([-1.0, 0.0, 1.0]), 1e-9, 0.5, 0.2)  # lit from -x: the ground in front of -x is lit
    dirs = cosine_directions(64)
    x0, y0, t = ground_grid(caster, 128)
    grid = GroundGrid(x0, y0, t, 128)
    face_x, d, a = float(caster.bounds[0][0]), 0.015, 4.0  # the -x face; a paper 4 x the ring's light
    open_ = sky._ground_seen(caster, sky.Interreflection(*bounce), ground_raster_cpu, dirs, np.ones(64), grid)
    paper_light = sky.Interreflection(*bounce, ground_field=lambda q: np.where(q[:, 0] < face_x - d, a, 1.0))
    paper = sky._ground_seen(caster, paper_light, ground_raster_cpu, dirs, np.ones(64), grid)
    n = caster.face_planes[:, :3]
    west = np.flatnonzero(n[:, 0] < -0.99)
    h = caster.vertices[caster.faces[west]].mean(axis=1)[:, 2]
    expect = (a - 1.0) * h / (2.0 * np.sqrt(h * h + d * d))
    assert np.abs(paper[west] - open_[west] - expect).max() < 0.01, (paper[west] - open_[west], expect)
    assert np.abs(open_[west] - 0.5).max() < 0.01  # open, lit ground: (1 - n_z) / 2
    others = np.flatnonzero(n[:, 0] > -0.99)  # faces turned away from the line see none of it...
    far = others[n[others, 0] > 0.5]
    assert np.abs(paper[far] - open_[far]).max() < 1e-9


def test_point_lamp_lights_a_face_at_its_own_distance():
    # a face at the reference point itself is the open ground there (1); a vertical face nearer the lamp gets
    # the lamp's cos / d^2 there over its z / d^3 at the reference, not a far light's n.L / L_z
    flat = ShadowCaster(np.array([[-1e-3, -1e-3, 0.0], [1e-3, -1e-3, 0], [0, 1e-3, 0]]), np.array([[0, 1, 2]]))
    lamp, ref = np.array([-0.3, 0.0, 0.3]), np.zeros(3)
    assert abs(float(lamp_incidence(flat, lamp, ref)[0]) - 1.0) < 1e-4
    wall = ShadowCaster(np.array([[-0.1, -1e-3, 0.05], [-0.1, 1e-3, 0.05], [-0.1, 0.0, 0.052]]), np.array([[0, 2, 1]]))
    assert wall.face_planes[0, 0] < 0  # turned towards the lamp (-x)
    q = wall.vertices.mean(axis=0)
    dq = lamp - q
    exact = (-dq[0] / np.linalg.norm(dq) ** 3) / (lamp[2] / np.linalg.norm(lamp - ref) ** 3)
    got = float(lamp_incidence(wall, lamp, ref)[0])
    assert abs(got - exact) < 1e-4 * exact
    assert got > 1.5  # a far light from the same direction gives cos 45 / sin 45 = 1


def test_ground_light_field_and_ring_share_the_papers_units():
    # the field is used relative to the ring's value (SceneGeometry.set_ground_light): with --paper-albedo
    # both must read the same pixel alike (the field kept the default 0.8 while the ring took 0.9)
    from arshadow.shading.decide import ground_bounce

    img = np.full((100, 100, 3), 188, np.uint8)
    g = ground_light(img, lambda p: p[:, :2] * 1000.0, (1.0, 1.0, 1.0), (0.0, 0.0, 0.2), res=8, paper_albedo=0.9)
    ring = ground_bounce(img, np.array([[12.5, 12.5]]), (1.0, 1.0, 1.0), paper_albedo=0.9)
    assert ring is not None and abs(g(np.array([[0.0125, 0.0125]]))[0] - ring.mean()) < 1e-6


def test_ground_light_read_from_the_photo_and_its_units():
    # the paper (code 255) reads PAPER_ALBEDO with a unit gain, a mid grey half of it; off the photo NaN
    img = np.full((100, 100, 3), 255, np.uint8)
    img[:, 50:] = 188  # sRGB 188 ~ 0.503 linear
    g = ground_light(img, lambda p: p[:, :2] * 1000.0, (1.0, 1.0, 1.0), (0.0, 0.0, 0.2), res=8)
    v = g(np.array([[0.01, 0.01], [0.07, 0.01], [0.15, 0.01], [-0.5, 0.0]]))
    assert abs(v[0] - PAPER_ALBEDO) < 1e-6 and abs(v[1] - PAPER_ALBEDO * 0.5029) < 1e-3
    assert np.isnan(v[2]) and np.isnan(v[3])  # 150 px: off the photo; off the grid
    # a lamp nearer the paper (at the origin) than the object: the ring's light is in the paper's units
    lamp = np.array([-0.2, 0.0, 0.3, 1.0])
    ref, r = np.array([0.1, 0.0, 0.0]), 0.3
    k = (np.linalg.norm(lamp[:3] - ref) / np.linalg.norm(lamp[:3])) ** 3
    sin_e = 0.3 / np.linalg.norm(lamp[:3])
    assert abs(ground_units(lamp, r, ref, 0.25) - (r + (1 - r) * k) / (0.25 + sin_e)) < 1e-12


# -- the GPU rasteriser (arshadow.gl.sky.GLGroundRaster) against the same closed forms -------------------------


@pytest.fixture
def gl_raster(ctx):
    from arshadow.gl.sky import GLGroundRaster

    r = GLGroundRaster(ctx)
    yield r
    r.release()


def test_gl_ground_visibility_beside_a_box_matches_lambert(gl_raster):
    g = ground_sky_visibility(load_occluder(BOX_SPEC), raster=gl_raster)
    pts = np.array(GROUND_POINTS)
    expect = tapered(np.array([box_ground_visibility(np.r_[q, 0.0], *BOX) for q in pts]))
    got = g.sample(pts)
    assert np.abs(got - expect).max() <= TOL.sky_ground_abs, (got - expect).round(4).tolist()


def test_gl_ground_under_a_raised_plate_matches_the_rectangle_view_factor(gl_raster):
    a, b, c = 0.2, 0.3, 0.05
    plate = load_occluder(f"box:{a},{b},0.002", place=(0, 0, c))
    got = ground_sky_visibility(plate, raster=gl_raster).sample(np.array([[0.0, 0.0]]))[0]
    expect = 1.0 - 4 * parallel_rectangle_ff(a / 2, b / 2, c)
    assert abs(got - expect) <= TOL.sky_ground_abs, (got, expect)


def test_gl_ground_light_reflected_by_the_object_matches_lambert(gl_raster):
    # as test_ground_light_reflected_by_the_object_back_onto_the_ground: the depth test picks the face a
    # ground point sees first (the numpy path paints faces farthest first)
    rise, expect, _ = _reflected_light_rise(gl_raster)
    assert np.abs(rise - expect).max() <= TOL.sky_ground_abs, (rise, expect)


def test_gl_and_numpy_rasters_agree_on_a_mesh_through_the_ground(gl_raster):
    # a torus sunk 5 mm into the ground (the parts below z = 0 cast nothing: GL clips them, numpy splits the
    # triangles) and a knot-like non-convex shape: the two rasterisers differ only where the numpy one's
    # boundary sub-texels reach a third of a texel further out
    for spec, place in (("torus:0.05,0.015", (0.0, 0.0, -0.005)), ("torus:0.04,0.02", (0.01, -0.02, 0.0))):
        c = load_occluder(spec, place=place)
        a = ground_sky_visibility(c, taper=None)
        g = ground_sky_visibility(c, taper=None, raster=gl_raster)
        assert a.visibility.shape == g.visibility.shape
        d = np.abs(a.visibility - g.visibility)
        assert d.mean() <= TOL.sky_raster_mean and np.percentile(d, 99) <= TOL.sky_raster_p99, (d.mean(), d.max())
        assert a.visibility.min() < 0.5  # the maps hold real occlusion
