"""The shadow-map baseline (arshadow.gl.shadowmap) against the exact shadow (arshadow.geometry.exact): close at a
high map resolution, worse at a low one; and its light frustum encloses the caster."""

from __future__ import annotations

import numpy as np
import pytest
from image_oracle import ShadowOracle, iou

from arshadow.errors import UsageError
from arshadow.gl.shadowmap import light_view_projection
from arshadow.renderer.request import RenderRequest

W, H = 1280, 720


def _box_corners(b):
    return np.array([[x, y, z, 1.0] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])


@pytest.mark.parametrize(
    "light", [[-0.2, 0.1, 0.6, 1.0], [0.3, -0.2, 0.25, 1.0], [0.2, 0.5, 0.3, 0.0], [0.0, 0.0, 1.0, 0.0]]
)
def test_light_frustum_encloses_caster(light):
    b = np.array([[-0.05, -0.04, 0.0], [0.05, 0.04, 0.15]])
    clip = _box_corners(b) @ light_view_projection(np.array(light, float), b).T
    assert np.all(clip[:, 3] > 0)
    ndc = clip[:, :3] / clip[:, 3:]
    assert np.all(np.abs(ndc) <= 1.0 + 1e-9)


def test_light_inside_bounding_sphere_is_refused():
    b = np.array([[-0.05, -0.04, 0.0], [0.05, 0.04, 0.15]])
    with pytest.raises(UsageError, match="inside"):
        light_view_projection(np.array([0.0, 0.0, 0.1, 1.0]), b)


@pytest.mark.gl
@pytest.mark.parametrize("name", ["box_point", "wall_camera_in_shadow"])
def test_shadowmap_close_to_exact_at_high_resolution(ctx, tol, name):
    from render_scenes import ZNEAR, intrinsics, scenes

    from arshadow.gl.shadowmap import ShadowMapRenderer
    from arshadow.gl.stencil import LightPass
    from arshadow.transforms import CV_TO_GL

    sc = next(s for s in scenes() if s.name == name)
    K = intrinsics(sc.fx)
    orc = ShadowOracle(K.K, sc.cam_from_world, sc.caster.vertices, sc.caster.faces, sc.lights, sc.ground_size)
    exact = orc.image(W, H)[0] >= 0.5
    assert exact.sum() > 5000
    P, view = K.gl_projection(ZNEAR, None), CV_TO_GL @ sc.cam_from_world
    passes = [LightPass(h, w, None, "zpass") for h, w in sc.lights]
    masks = {}
    for size, pcf in ((512, 1), (4096, 3)):
        with ShadowMapRenderer(ctx, map_size=size, pcf=pcf, max_width=W, max_height=H) as r:
            res = r.render(
                RenderRequest(
                    projection=P,
                    view=view,
                    width=W,
                    height=H,
                    caster=sc.caster,
                    passes=passes,
                    ground_size=sc.ground_size,
                )
            )
        masks[size] = res.mask >= 0.5
        assert res.mask.shape == (H, W) and res.color.shape == (H, W, 3) and res.premultiplied
    assert iou(masks[4096], exact) >= tol.shadowmap_iou_4096
    # the baseline's error comes from its texels: a coarse map is measurably worse
    assert np.count_nonzero(masks[512] != exact) > np.count_nonzero(masks[4096] != exact)
