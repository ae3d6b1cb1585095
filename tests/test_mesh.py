"""ShadowCaster preparation and load_occluder: welding, validation, adjacency, primitives, files."""

from __future__ import annotations

import numpy as np
import pytest

from arshadow.errors import MeshError
from arshadow.geometry.mesh import ShadowCaster, connected_labels, load_occluder, primitive, rotation_xyz_deg


def test_box_adjacency_and_planes():
    c = load_occluder("box:0.2,0.4,0.6")
    assert c.is_closed and not c.two_sided
    assert len(c.vertices) == 8 and c.n_faces == 12 and len(c.edges) == 18
    assert c.boundary_edges.size == 0 and c.nonmanifold_edges.size == 0
    np.testing.assert_allclose(c.bounds, [[-0.1, -0.2, 0.0], [0.1, 0.2, 0.6]], atol=1e-15)
    # every plane contains its face's vertices and its normal points away from the box centre
    n, d = c.face_planes[:, :3], c.face_planes[:, 3]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=1e-15)
    dist = np.einsum("fkj,fj->fk", c.triangles, n) + d[:, None]
    assert np.abs(dist).max() < 1e-15
    centre = c.bounds.mean(axis=0)
    assert np.all(n @ centre + d < 0)
    # edge_faces[:, 0] traverses edges as stored, column 1 the other way round
    for i, (a, b) in enumerate(c.edges):
        f0, f1 = c.faces[c.edge_faces[i]]
        assert (a, b) in {(f0[k], f0[(k + 1) % 3]) for k in range(3)}
        assert (b, a) in {(f1[k], f1[(k + 1) % 3]) for k in range(3)}


def test_arrays_read_only_and_inputs_untouched():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], float)
    f = np.array([[0, 1, 2], [0, 3, 2]])
    v0, f0 = v.copy(), f.copy()
    c = ShadowCaster(v, f)
    np.testing.assert_array_equal(v, v0)
    np.testing.assert_array_equal(f, f0)
    for a in (c.vertices, c.faces, c.face_planes, c.edges, c.edge_faces, c.bounds):
        assert not a.flags.writeable
    assert c.faces.dtype == np.intp and c.edges.dtype == np.intp and c.edge_faces.dtype == np.intp


def test_weld_and_drop_degenerate():
    # two triangles of a quad with duplicated corner vertices, plus a zero-area face and a repeated index
    v = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [3, 0, 0]]
    f = [[0, 1, 2], [3, 4, 5], [1, 6, 7], [0, 0, 1]]
    c = ShadowCaster(v, f, name="quad")
    assert len(c.vertices) == 4  # duplicates welded, vertices of dropped faces removed
    assert c.n_faces == 2 and c.n_dropped_faces == 2
    assert len(c.edges) == 5 and len(c.boundary_edges) == 4
    assert not c.is_closed


@pytest.mark.parametrize(
    "verts,faces,match",
    [
        (np.zeros((0, 3)), np.zeros((0, 3), int), "empty"),
        ([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], "NaN"),
        ([[0, 0, np.inf], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], "NaN or inf"),
        ([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]], "degenerate"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], "out of range"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0.5, 1, 2]], "integer"),
        ([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]], "shape"),
        ([[0, 0, 0], [1, 0], [0, 1, 0]], [[0, 1, 2]], "numeric"),
        ([["a", "b", "c"], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], "not numbers"),
    ],
)
def test_bad_meshes_raise(verts, faces, match):
    with pytest.raises(MeshError, match=match):
        ShadowCaster(verts, faces, name="bad")


def test_nonmanifold_and_misoriented_edges_detected():
    # three triangles on one edge (a "book" with three pages)
    v = [[0, 0, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0], [-1, -1, 0]]
    f = [[0, 1, 2], [1, 0, 3], [0, 1, 4]]
    c = ShadowCaster(v, f)
    assert len(c.nonmanifold_edges) == 1 and not c.is_closed
    e = c.edges[c.nonmanifold_edges[0]]
    assert set(e.tolist()) == {0, 1}
    # two triangles wound inconsistently across their shared edge
    c2 = ShadowCaster([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 2, 3]])
    assert len(c2.misoriented_edges) == 1 and not c2.is_closed


def test_single_triangle_is_open():
    c = ShadowCaster([[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 1, 2]])
    assert c.two_sided and len(c.boundary_edges) == 3
    np.testing.assert_array_equal(c.edge_faces[:, 1], -1)


@pytest.mark.parametrize(
    "spec,closed,faces",
    [("box:1,2,3", True, 12), ("cylinder:0.5,1", True, 256), ("sphere:0.3", True, 1280), ("torus:1,0.25", True, 4096)],
)
def test_primitives_stand_on_ground(spec, closed, faces):
    c = load_occluder(spec)
    assert c.is_closed is closed and c.n_faces == faces
    assert c.bounds[0, 2] == 0.0
    np.testing.assert_allclose(c.bounds.mean(axis=0)[:2], 0.0, atol=1e-12)
    # outward: the enclosed volume is positive
    t = c.triangles
    vol = np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6
    assert vol > 0


@pytest.mark.parametrize("spec", ["box:1,2", "cube:1", "sphere:-1", "torus:1,2", "sphere:nan", "box:a,b,c"])
def test_bad_primitive_specs(spec):
    with pytest.raises(MeshError):
        load_occluder(spec)


def test_transform_order_scale_rotate_place():
    c = load_occluder("box:1,1,1", scale=(2, 1, 1), rotate=(0, 0, 90), place=(10, 0, 0))
    # scaled to 2 x 1 x 1, then turned 90 degrees about z: 1 x 2, then moved
    np.testing.assert_allclose(c.bounds, [[9.5, -1, 0], [10.5, 1, 1]], atol=1e-12)
    np.testing.assert_allclose(rotation_xyz_deg((90, 0, 0)) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    # a mirroring scale keeps the normals outward
    m = load_occluder("box:1,1,1", scale=(-1, 1, 1))
    t = m.triangles
    assert np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() > 0


def test_load_file_roundtrip_and_errors(tmp_path):
    import trimesh

    v, f = primitive("torus:0.1,0.03")
    mesh = trimesh.Trimesh(v, f, process=False)
    mesh.visual.vertex_colors = np.tile([255, 0, 0, 255], (len(v), 1))
    p = tmp_path / "t.ply"
    mesh.export(p)
    c = load_occluder(p, place=(0, 0, 1))
    assert c.n_faces == len(f) and c.is_closed
    np.testing.assert_allclose(c.bounds[0, 2], 1.0, atol=1e-12)
    assert c.colors is not None and np.allclose(c.colors[:, 0], 1.0) and c.colors.dtype == np.float32
    c2 = load_occluder(p, color="#00ff00")
    assert np.allclose(c2.colors[:, :3], [0, 1, 0])
    with pytest.raises(MeshError, match="no such mesh file"):
        load_occluder(tmp_path / "missing.obj")
    bad = tmp_path / "bad.stl"
    bad.write_bytes(b"solid x\nfacet normal nan\n")
    with pytest.raises(MeshError):
        load_occluder(bad)


def test_stl_style_triangle_soup_welds_closed():
    v, f = primitive("sphere:1")
    soup_v = v[f].reshape(-1, 3)  # every triangle with its own three vertices, as STL stores them
    soup_f = np.arange(len(soup_v)).reshape(-1, 3)
    c = ShadowCaster(soup_v, soup_f)
    assert c.is_closed and len(c.vertices) == len(v)


def test_polygons_merge_coplanar_faces():
    c = load_occluder("box:1,1,1")
    p = c.polygons
    assert len(p["planes"]) == 6 and len(p["edges"]) == 24
    # faces of one polygon share the plane bit for bit
    for k in range(6):
        planes = c.face_planes[p["face_polygon"] == k]
        assert np.all(planes == planes[0])
    t = load_occluder("sphere:1")
    assert len(t.polygons["planes"]) == t.n_faces  # no coplanar neighbours on an icosphere


def test_connected_labels():
    lab = connected_labels(6, np.array([0, 2, 4]), np.array([1, 3, 3]))
    assert lab[0] == lab[1] and lab[2] == lab[3] == lab[4] and len(set(lab.tolist())) == 3


def test_winding_number():
    c = load_occluder("torus:1,0.3")
    assert abs(c.winding_number([1.0, 0, 0.3]) - 1) < 1e-9
    assert abs(c.winding_number([0.0, 0, 0.3])) < 1e-9
