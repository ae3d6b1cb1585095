"""The paper-faithful reference detectors (arshadow.geometry.silhouette_reference) give the same edges as the fast
detectors on small closed meshes, and their operation counts follow from their loops."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_cases import SAMPLES, affine_icosphere, edge_multiset, random_lights

from arshadow.geometry.mesh import load_occluder
from arshadow.geometry.silhouette import silhouette
from arshadow.geometry.silhouette_reference import (
    delta_plus_reference,
    paper000_formulas,
    paper003_claim,
    ta_reference,
    vnv_reference,
)


def _small_meshes():
    return {
        "box": load_occluder("box:0.3,0.2,0.1", rotate=(10, 20, 30), place=(0, 0, 0.2)),
        "house": load_occluder(SAMPLES / "house.obj"),
        "affine0": affine_icosphere(0),
        "torus": load_occluder("torus:0.4,0.1", rotate=(30, 0, 0), place=(0, 0, 0.2)),
    }


@pytest.mark.parametrize("name", ["box", "house", "affine0", "torus"])
def test_reference_equals_fast(name, rng):
    c = _small_meshes()[name]
    n_lights = 2 if c.n_faces > 1000 else 8
    for L in random_lights(c, n_lights, rng):
        ta, cnt = ta_reference(c.vertices, c.faces, L, planes=c.face_planes)
        assert np.array_equal(edge_multiset(ta), edge_multiset(silhouette(c, L, "triangular").edges))
        assert cnt["writes"] == 3 * int(silhouette(c, L).facing.sum())  # one add or delete per visible side
        if c.n_faces <= 1000:
            vnv, vc = vnv_reference(c.vertices, c.faces, L, planes=c.face_planes)
            assert np.array_equal(edge_multiset(vnv), edge_multiset(silhouette(c, L, "vnv").edges))
            assert vc["pairs"] == len(c.edges) * c.n_faces
        dp, dc = delta_plus_reference(c.vertices, c.faces, L, planes=c.face_planes)
        assert np.array_equal(edge_multiset(dp), edge_multiset(silhouette(c, L, "delta_plus").edges))
        assert dc["ray_face_tests"] <= dc["ray_face_tests_no_early_exit"]


def test_paper_formulas_as_printed():
    # [Kolivand-DeltaPlus] Table II: 5 000 vertices -> 25 000 000 against 61 438
    p = paper003_claim(5000)
    assert p["quadratic"] == 25_000_000 and int(p["n_log2_n"]) == 61_438  # the paper truncates
    # [Kolivand-HSD] sec. VI: HSD is TA with m = 1 (its derivation), so TA(m=1) == HSD term by term
    f = paper000_formulas(100, 1)
    assert f["TA"]["C"] == f["HSD"]["C"] - 100 and f["TA"]["total"] < f["VnV"]["total"]
