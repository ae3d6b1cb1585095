"""The ground's light as the object's faces see it (arshadow.shading.objground) against a closed form: the
ground beyond a line a distance D in front of a vertical face of height h sends k times the ring's light.
A point of the face at height z sees that half-plane with the view factor z / (2 sqrt(z^2 + D^2)) (of the
open ground's 1/2), so the face's mean ground light over the ring's is

    1 + (k - 1) (sqrt(h^2 + D^2) - D) / h
"""

from __future__ import annotations

import math

import numpy as np
import pytest

BOX = "box:0.045,0.065,0.07"
H, FRONT = 0.07, -0.0325  # the box's height and its -y face


def _half_plane(d: float, k: float):
    def light(xy):
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        return np.where(xy[:, 1] < FRONT - d, k, 1.0)

    return light


def _closed(d: float, k: float) -> float:
    return 1.0 + (k - 1.0) * (math.hypot(H, d) - d) / H


@pytest.mark.parametrize("d", [0.005, 0.02, 0.06])
def test_face_ground_of_a_box_face_against_the_half_plane_view_factor(d):
    from arshadow.geometry.mesh import load_occluder
    from arshadow.shading.objground import face_ground

    box = load_occluder(BOX)
    front = np.flatnonzero(box.face_planes[:, 1] < -0.99)  # its two triangles, of equal area: the face's mean
    got = face_ground(box, _half_plane(d, 4.0), n_dirs=512)[front].mean()
    assert got == pytest.approx(_closed(d, 4.0), rel=0.01)
    # the renderer's default directions: a quadrature of the same integral
    got = face_ground(box, _half_plane(d, 4.0))[front].mean()
    assert got == pytest.approx(_closed(d, 4.0), rel=0.05)


@pytest.mark.gl
def test_rendered_face_takes_the_ground_it_sees(gl_ctx):
    # a white box's -y face lit by the ground's light alone (no sky, no lamp): bounce G times the face's
    # ground light, G = 1/2 for a vertical face; the paper-like ground beyond 2 cm in front is 4 x the ring's
    from test_gl_realism import _pixel, _render, _renderer

    from arshadow.geometry.mesh import load_occluder
    from arshadow.shading.sky import SkyShading
    from arshadow.synth.markers import look_at_pose

    box = load_occluder(BOX)
    pose = look_at_pose([0.0, -0.35, 0.25], [0.0, 0.0, 0.03])
    b, d = 0.3, 0.02
    kw = {"ambient": 0.0, "diffuse": 0.0, "specular": 0.0, "color": (1.0, 1.0, 1.0)}
    r = _renderer(gl_ctx)
    try:
        seen = _render(r, box, pose, sky=SkyShading(bounce=(b, b, b), object_ground=_half_plane(d, 4.0)), **kw)
        ring = _render(r, box, pose, sky=SkyShading(bounce=(b, b, b)), **kw)
    finally:
        r.release()
    x, y = _pixel(pose, [0.0, FRONT, 0.5 * H])
    assert ring.color[y, x, 1] == pytest.approx(0.5 * b, rel=1e-3)
    # a flat face takes its mean (the same at every height)
    assert seen.color[y, x, 1] == pytest.approx(0.5 * b * _closed(d, 4.0), rel=0.05)
