"""Corner normals with a per-face crease angle (arshadow.geometry.normals) and their use in the GL buffers."""

import numpy as np
import pytest

from arshadow.geometry.mesh import load_occluder, primitive
from arshadow.geometry.normals import crease_normals, face_normals
from tests.conftest import TOL


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(np.einsum("...j,...j->...", a, b), -1.0, 1.0)))


@pytest.mark.parametrize("spec", ["box:0.045,0.065,0.07", "box:0.01,0.3,0.02", "box:1,1,1"])
def test_box_faces_keep_their_face_normal(spec):
    # the issue's box: the old area-weighted vertex normal put its big faces' corners 25-37 deg off
    v, f = primitive(spec)
    n = crease_normals(v, f, 40.0)
    # independent: a box's outward normals are the six axis directions; each triangle's is the axis
    # along which its three vertices share a coordinate at the box's min or max
    centre = v.mean(axis=0)
    tri = v[f]
    axis = np.argmin(np.ptp(tri, axis=1), axis=1)
    expect = np.zeros((len(f), 3))
    expect[np.arange(len(f)), axis] = np.sign(tri[np.arange(len(f)), 0, axis] - centre[axis])
    assert _angle_deg(n, expect[:, None, :]).max() <= TOL.normal_flat_deg


def test_sphere_stays_smooth():
    v, f = primitive("sphere:0.05")
    n = crease_normals(v, f, 40.0)
    c = v - [0.0, 0.0, 0.05]  # the primitive stands on the ground: centre at z = R
    radial = c[f] / np.linalg.norm(c[f], axis=2, keepdims=True)
    assert _angle_deg(n, radial).max() <= TOL.normal_sphere_deg
    # one normal per vertex: every corner at a vertex carries the same one (no faceting)
    per_vertex = np.zeros((len(v), 3))
    per_vertex[f.ravel()] = n.reshape(-1, 3)
    assert np.abs(per_vertex[f] - n).max() < 1e-12


def test_cylinder_rim_splits_side_from_cap():
    v, f = primitive("cylinder:0.03,0.1")
    n = crease_normals(v, f, 40.0)
    fn = face_normals(v, f)
    cap = np.abs(fn[:, 2]) > 0.99
    assert _angle_deg(n[cap], fn[cap][:, None]).max() <= TOL.normal_flat_deg  # caps flat
    assert np.abs(n[~cap][..., 2]).max() < 1e-12  # side normals horizontal (smooth round, not tilted to the caps)
    # and smooth round the side: a side vertex's corners all share one normal
    side = f[~cap].ravel()
    per_vertex = np.zeros((len(v), 3))
    per_vertex[side] = n[~cap].reshape(-1, 3)
    assert np.abs(per_vertex[f[~cap]] - n[~cap]).max() < 1e-12


def test_gl_buffers_carry_flat_box_normals(ctx):
    # the lighting pass's vertex buffer (pos4, normal3, albedo3) of the box: every normal an axis
    from arshadow.gl.resources import CasterBuffers, program

    caster = load_occluder("box:0.045,0.065,0.07")
    prog = program(ctx, "occluder.vert", "occluder_light.frag")
    base = program(ctx, "occluder.vert", "occluder_base.frag")
    pos = program(ctx, "common.vert", "mask.frag")
    bufs = CasterBuffers(ctx, base, prog, pos, caster, None, 40.0)
    try:
        data = np.frombuffer(bufs.vbo.read(), np.float32).reshape(-1, 10)
        nrm = data[:, 4:7].astype(np.float64)
        assert np.abs(np.abs(nrm).max(axis=1) - 1.0).max() < 1e-6
        assert bufs.n_light_vertices == 24  # 8 corners x 3 faces
    finally:
        bufs.release()
