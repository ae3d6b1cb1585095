"""Planar projection shadows: the matrix against first principles, the paper's version, the oracle."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_cases import closed_meshes, open_meshes, random_lights
from oracle import ground_shadow_triangles

from arshadow.errors import LightError, ShapeError
from arshadow.geometry.mesh import load_occluder
from arshadow.geometry.projection import GROUND_PLANE, paper_shadow_matrix, planar_shadow_matrix, project_to_ground


def test_matrix_projects_onto_plane_along_light_rays(rng):
    for _ in range(200):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        c = rng.normal(size=3)
        plane = np.r_[n, -n @ c]
        X = np.r_[rng.normal(size=3), 1.0]
        if rng.uniform() < 0.5:
            L = np.r_[rng.normal(size=3) * 5, 1.0]
        else:
            L = np.r_[rng.normal(size=3), 0.0]
        M = planar_shadow_matrix(plane, L)
        S = M @ X
        if abs(S[3]) < 1e-9:
            continue
        s = S[:3] / S[3]
        assert abs(plane[:3] @ s + plane[3]) < 1e-9 * (1 + np.abs(s).max())  # on the plane
        # on the line through X and the light
        d = L[:3] - L[3] * X[:3]
        assert np.linalg.norm(np.cross(s - X[:3], d)) < 1e-9 * (1 + np.linalg.norm(s - X[:3])) * np.linalg.norm(d)


def test_w_positive_between_light_and_plane(rng):
    for _ in range(100):
        L = np.r_[rng.uniform(-1, 1, 2), rng.uniform(0.5, 3), 1.0]
        X = np.r_[rng.uniform(-1, 1, 2), rng.uniform(0, 0.49), 1.0]
        for plane in (GROUND_PLANE, -GROUND_PLANE):  # either orientation of the same plane
            assert (planar_shadow_matrix(plane, L) @ X)[3] > 0


def test_paper_matrix_equals_ours_up_to_scale(rng):
    for _ in range(50):
        N = rng.normal(size=3)
        C = rng.normal(size=3)
        L = rng.normal(size=3) * 4
        A = paper_shadow_matrix(N, C, L)
        B = planar_shadow_matrix(np.r_[N, -N @ C], np.r_[L, 1.0])
        k = (A.ravel() @ B.ravel()) / (B.ravel() @ B.ravel())
        np.testing.assert_allclose(A, k * B, atol=1e-10 * np.abs(A).max())


@pytest.mark.parametrize("name", ["knot", "house", "icosphere", "umbrella", "sheet"])
def test_project_to_ground_matches_oracle(name, rng):
    c = {**closed_meshes(), **open_meshes()}[name]
    for L in random_lights(c, 20, rng, above_ground=True):
        got = project_to_ground(c, L)
        assert got.shape == (c.n_faces, 3, 3) and np.all(got[..., 2] == 0)
        ref = ground_shadow_triangles(c.vertices, c.faces, L)
        np.testing.assert_allclose(got[..., :2], ref, rtol=0, atol=1e-12 * (1 + np.abs(ref).max()))


def test_far_point_light_approaches_directional():
    c = closed_meshes()["knot"]
    d = np.array([0.3, -0.2, 0.9])
    far = project_to_ground(c, np.r_[c.bounds.mean(0) + 1e6 * d, 1.0])
    inf = project_to_ground(c, np.r_[d, 0.0])
    assert np.all(np.isfinite(far)) and np.abs(far - inf).max() < 1e-6


def test_projection_errors():
    box = load_occluder("box:1,1,1")
    with pytest.raises(LightError, match="not above"):
        project_to_ground(box, [0, 0, 1.0, 1])  # light at the top face's height
    with pytest.raises(LightError, match="not above"):
        project_to_ground(box, [0, 0, -2.0, 1])
    with pytest.raises(LightError, match="dz <= 0"):
        project_to_ground(box, [1, 0, 0, 0])
    with pytest.raises(LightError, match="lies in"):
        planar_shadow_matrix(GROUND_PLANE, [1, 2, 0, 1])
    with pytest.raises(LightError, match="parallel"):
        planar_shadow_matrix(GROUND_PLANE, [1, 2, 0, 0])
    with pytest.raises(ShapeError):
        planar_shadow_matrix([0, 0, 0, 1], [0, 0, 1, 1])
    with pytest.raises(LightError):
        planar_shadow_matrix(GROUND_PLANE, [0, 0, np.nan, 1])
