"""Materials from mesh files (arshadow.geometry.material via load_occluder): textures, UVs, factors."""

from pathlib import Path

import numpy as np
import pytest
from conftest import TOL

from arshadow.geometry.mesh import load_occluder

pytest.importorskip("PIL", reason="trimesh decodes mesh textures with Pillow")

DATA = Path(__file__).parent / "data" / "textured"


def srgb_to_linear_ref(c):
    """IEC 61966-2-1, written out here (independent of arshadow.compose)."""
    c = np.asarray(c, np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def uv_at(caster, xy):
    """Texture coordinates at ground points xy (k, 2) by barycentric interpolation of the corner UVs of the
    caster's face containing each point (a flat quad in z = 0)."""
    out = []
    tri = caster.vertices[caster.faces][:, :, :2]
    for p in np.asarray(xy, float):
        for fi, t in enumerate(tri):
            m = np.c_[t[1] - t[0], t[2] - t[0]]
            b1, b2 = np.linalg.solve(m, p - t[0])
            if b1 >= -1e-9 and b2 >= -1e-9 and b1 + b2 <= 1 + 1e-9:
                uv = caster.material.uv[fi]
                out.append((1 - b1 - b2) * uv[0] + b1 * uv[1] + b2 * uv[2])
                break
        else:
            raise AssertionError(f"{p} is on no face")
    return np.array(out)


# world points on the square and the texture colour there (tests/data/make_textured_assets.py: the image
# lies on the square seen from above, top row at +y; quadrant colours; white disc in the top-left one)
POINTS = np.array([[-0.045, 0.045], [0.045, 0.045], [-0.045, -0.045], [0.045, -0.045], [-0.025, 0.025]])
COLOURS = srgb_to_linear_ref([(200, 30, 30), (30, 200, 30), (30, 30, 200), (220, 200, 40), (255, 255, 255)])


@pytest.mark.parametrize("name", ["quad.glb", "quad.obj"])
def test_texture_lands_where_the_file_puts_it(name):
    c = load_occluder(DATA / name)
    m = c.material
    assert m is not None and m.textured and m.source == ("gltf" if name.endswith("glb") else "obj")
    assert np.allclose(c.bounds[:, :2], [[-0.05, -0.05], [0.05, 0.05]]) and np.allclose(c.vertices[:, 2], 0)
    got = m.sample(uv_at(c, POINTS))
    assert np.abs(got - COLOURS).max() < 1e-6, got.round(4)
    assert np.allclose(m.base_color, 1.0)
    if name.endswith("glb"):
        assert (m.metallic, m.roughness) == (0.0, pytest.approx(0.8))


def test_uvs_follow_a_mirroring_scale_and_welding(tmp_path):
    # mirrored in x: the faces' winding is reversed; each corner must keep its own UV
    c = load_occluder(DATA / "quad.obj", scale=(-1, 1, 1))
    corner_xy = c.vertices[c.faces][:, :, :2]
    # file (x, y) -> (u, v) = ((x + 0.05) / 0.1, (y + 0.05) / 0.1); world x = -file x
    expect = np.stack([(-corner_xy[..., 0] + 0.05) / 0.1, (corner_xy[..., 1] + 0.05) / 0.1], axis=-1)
    assert np.allclose(c.material.uv, expect, atol=1e-6)
    # a cube-like UV seam: the quad written twice with different UVs (duplicate positions), plus a degenerate
    # face: the caster welds the positions and drops the face, the UVs stay per corner
    text = (DATA / "quad.obj").read_text().replace("mtllib quad.mtl", f"mtllib {DATA / 'quad.mtl'}")
    text += "vt 0.5 0.5\nv -0.05 -0.05 0\nv 0.05 -0.05 0\nf 1/5 2/5 2/5\nf 5/1 6/2 3/3\n"
    (tmp_path / "seam.obj").write_text(text)
    (tmp_path / "quad.png").write_bytes((DATA / "quad.png").read_bytes())
    c2 = load_occluder(tmp_path / "seam.obj")
    assert c2.n_dropped_faces == 1 and len(c2.vertices) == 4 and c2.n_faces == 3
    assert c2.material is not None and c2.material.uv.shape == (3, 3, 2)
    assert np.allclose(c2.material.uv[2], c2.material.uv[0])  # the duplicate face: same corners, same UVs


def test_colour_override_drops_the_material_and_plain_meshes_have_none():
    assert load_occluder(DATA / "quad.glb", color="#808080").material is None
    assert load_occluder("box:0.1,0.1,0.1").material is None


def test_measured_light_keeps_a_textured_mesh_textured():
    # --light-from without --color: the scene's occluder colour is the exposed grey default; a mesh with its
    # own texture / colours keeps them, times the exposure gain (it used to come out flat grey)
    from arshadow.frame.execute import frame_shading
    from arshadow.scene.options import RenderOptions
    from arshadow.shading.decide import PAPER_ALBEDO

    opts = RenderOptions(occluder_color=(0.6, 0.6, 0.6), material_gain=(1.2, 1.1, 0.9))
    sh = frame_shading(opts, load_occluder(DATA / "quad.glb"), None)
    # the texture is a reflectance; the gain makes a colour of 1 the paper's brightness, the paper's own
    # reflectance being PAPER_ALBEDO
    assert sh.color is None and sh.albedo_gain == pytest.approx(
        (1.2 / PAPER_ALBEDO, 1.1 / PAPER_ALBEDO, 0.9 / PAPER_ALBEDO)
    )
    plain = frame_shading(opts, load_occluder("box:0.1,0.1,0.1"), None)
    assert plain.color == (0.6, 0.6, 0.6) and plain.albedo_gain == (1.0, 1.0, 1.0)
    # an explicit colour (no material_gain) wins over the texture
    assert frame_shading(RenderOptions(occluder_color=(0.6, 0.6, 0.6)), load_occluder(DATA / "quad.glb"), None).color


@pytest.mark.parametrize("name", ["quad.glb", "quad.obj"])
def test_mean_albedo_of_a_textured_mesh_is_its_textures_mean(name):
    """The textured square covers its whole texture once: its area-weighted mean colour (what it reflects onto
    the ground: colour bleeding) is the decoded texture's plain mean (times the base colour), within the
    sampling's error (1024 points per face on two faces)."""
    c = load_occluder(DATA / name)
    m = c.material
    expect = np.asarray(m.base_color, np.float64)[:3] * np.asarray(m.texture, np.float64).reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(c.mean_albedo, expect, rtol=TOL.mean_albedo_rel)


def test_a_coloured_mesh_bleeds_its_own_colour_and_a_grey_one_none():
    """Colour bleeding takes the mesh's own colours when no colour is given: a red vertex-coloured mesh bleeds
    red (its linear colour over its mean, minus 1), the default grey box and a grey override none."""
    from arshadow.plan.scene_geometry import SceneGeometry
    from arshadow.scene.options import RenderOptions

    red = load_occluder("box:0.05,0.05,0.05")
    red = type(red)(red.vertices, red.faces, vertex_colors=np.tile([200, 40, 40], (len(red.vertices), 1)))
    lin = np.array([200, 40, 40]) / 255.0
    lin = np.where(lin <= 0.04045, lin / 12.92, ((lin + 0.055) / 1.055) ** 2.4)
    got = SceneGeometry(red, RenderOptions()).object_bleed
    assert got is not None
    np.testing.assert_allclose(got, lin / lin.mean() - 1.0, rtol=1e-6)  # colours stored as float32
    assert SceneGeometry(load_occluder("box:0.05,0.05,0.05"), RenderOptions()).object_bleed is None
    grey = RenderOptions(occluder_color=(0.5, 0.5, 0.5))
    assert SceneGeometry(red, grey).object_bleed is None


@pytest.mark.gl
@pytest.mark.parametrize("paper_albedo", [None, 0.9])
def test_a_material_as_reflective_as_the_paper_renders_as_bright_as_the_paper(gl_ctx, tmp_path, tol, paper_albedo):
    """A mesh's own colour is a reflectance (glTF's base colour, MTL's Kd): a box coloured the paper's
    reflectance (PAPER_ALBEDO, or the scene's ``paper_albedo``), lit by the light measured on the photo, shows
    its horizontal top face at the paper's colour as the light estimate measured it on the photo's marker (it
    came out 0.8 x as bright)."""
    import trimesh

    from arshadow.bench.common import ROOT
    from arshadow.camera.model import Intrinsics
    from arshadow.estimate import estimate_light
    from arshadow.frame.session import Session
    from arshadow.io import read_image
    from arshadow.scene.spec import scene_from_dict
    from arshadow.shading.decide import PAPER_ALBEDO

    photo = read_image(str(ROOT / "samples" / "probe_shadow.jpg"))
    calib = ROOT / "calib" / "synth_1280x720.yml"
    est = estimate_light(
        photo, calib=calib, marker_length=0.05, probe="box:0.05,0.05,0.1", probe_place=(0.1, 0.02, 0.0)
    )
    paper_r = PAPER_ALBEDO if paper_albedo is None else paper_albedo
    code = round(255 * (1.055 * paper_r ** (1 / 2.4) - 0.055))  # the paper's reflectance, sRGB
    box = trimesh.creation.box((0.03, 0.03, 0.03))
    box.apply_translation((0.0, 0.0, 0.015))
    box.visual.vertex_colors = np.tile([code, code, code, 255], (len(box.vertices), 1))
    ply = tmp_path / "paper_grey.ply"
    box.export(ply)
    place = (-0.06, -0.05, 0.0)
    spec = {"calib": str(calib), "marker_length": 0.05, "model": str(ply), "place": list(place), "light_from": est}
    if paper_albedo is not None:
        spec["paper_albedo"] = paper_albedo
    with Session(scene_from_dict({**spec, "ambient_occlusion": "off"})) as s:
        res = s.process(photo, want_mask=False)
    intr = Intrinsics.from_file(calib)
    top = [[place[0] + dx, place[1] + dy, 0.03] for dx in (-0.006, 0.0, 0.006) for dy in (-0.006, 0.0, 0.006)]
    uv = np.rint(intr.project(np.array(top), res.pose.cam_from_world)).astype(int)
    got = np.median(res.composite[uv[:, 1], uv[:, 0]].astype(float), axis=0)[::-1]  # RGB
    lin = np.asarray(est.exposure.paper_rgb, float)
    paper = 255 * np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    assert np.all(photo[uv[:, 1], uv[:, 0]] != res.composite[uv[:, 1], uv[:, 0]])  # the object is drawn there
    np.testing.assert_allclose(got, paper, atol=tol.paper_match_codes)


def test_paper_albedo_is_a_reflectance():
    """``paper_albedo`` (``--paper-albedo``) is a reflectance in (0, 1]: a percentage is refused, naming the
    probable mistake."""
    from arshadow.errors import UsageError
    from arshadow.scene.options import RenderOptions

    assert RenderOptions(paper_albedo=0.9).check().paper_albedo == 0.9
    with pytest.raises(UsageError, match=r"a percentage\? 0.85"):
        RenderOptions(paper_albedo=85).check()
    for bad in (0.0, -0.5, float("nan"), 1.5):
        with pytest.raises(UsageError, match="--paper-albedo"):
            RenderOptions(paper_albedo=bad).check()
    # a plausible mistake is warned of, naming it: the floor's or the ink's reflectance given for the paper's
    from arshadow.scene.sanity import paper_warnings

    assert paper_warnings(0.8) == [] and paper_warnings(0.9) == []
    assert "not of the floor or the ink" in paper_warnings(0.25)[0]
    assert "perfect white" in paper_warnings(0.99)[0]
