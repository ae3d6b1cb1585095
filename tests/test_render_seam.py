"""The render seam (the layout work): one frozen RenderRequest per frame, the object's Shading in it, the
renderers' capabilities as typed attributes, execute's four values."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from arshadow.compose.composite import srgb_to_linear
from arshadow.errors import UsageError
from arshadow.renderer.request import LightPass, Renderer, RendererBase, RenderRequest, RenderResult, Shading
from arshadow.scene.options import RenderOptions


def test_shading_and_request_are_frozen_values():
    req = RenderRequest(projection=np.eye(4), view=np.eye(4), width=8, height=6, caster=None, passes=[])
    assert req.passes == () and req.shading == Shading()
    with pytest.raises(dataclasses.FrozenInstanceError):
        req.width = 9
    with pytest.raises(dataclasses.FrozenInstanceError):
        req.shading.ambient = 0.5
    with pytest.raises(UsageError, match="ambient"):
        Shading(ambient=float("nan"))


def test_shading_comes_from_the_options():
    """The options' ambient, specular and occluder colour reach the renderer through Shading (diffuse and
    shininess at the renderers' former defaults: K_d 1, n 32)."""
    sh = Shading.from_options(RenderOptions(ambient=0.4, specular=0.1, occluder_color=(0.2, 0.5, 0.7)))
    assert (sh.ambient, sh.specular, sh.color) == (0.4, 0.1, (0.2, 0.5, 0.7))
    assert sh.uniforms() == {
        "u_ambient": 0.4,
        "u_kd": 1.0,
        "u_ks": 0.1,
        "u_shininess": 32.0,
        "u_albedo_gain": (1.0, 1.0, 1.0),
        "u_point_falloff": 0.0,
        "u_ambient_tint": (1.0, 1.0, 1.0),
        "u_direct_tint": (1.0, 1.0, 1.0),
    }
    assert Shading.from_options(RenderOptions()).uniforms() == Shading().uniforms()
    # a measured sky's and light's colours (light_from) tint the ambient and the direct terms
    tinted = Shading.from_options(RenderOptions(ambient_tint=(0.8, 1.0, 1.2), direct_tint=(1.1, 1.0, 0.9))).uniforms()
    assert (tinted["u_ambient_tint"], tinted["u_direct_tint"]) == ((0.8, 1.0, 1.2), (1.1, 1.0, 0.9))
    # a measured light's point lamp falls off with distance (the exposure is matched at the paper)
    assert Shading.from_options(RenderOptions(ambient_measured=True)).uniforms()["u_point_falloff"] == 1.0


def test_a_renderer_declares_its_capabilities():
    """The protocol's capabilities are attributes (no getattr probing): a renderer from RendererBase has the
    defaults, and one without them is not a Renderer."""

    class Blank(RendererBase):
        def render(self, request):
            z = np.zeros((request.height, request.width), np.float32)
            return RenderResult(z, np.zeros(z.shape + (3,), np.float32), z, z > 0, z)

        def release(self):
            pass

    class Bare:
        def render(self, request):
            raise AssertionError

        def release(self):
            pass

    b = Blank()
    assert isinstance(b, Renderer) and not isinstance(Bare(), Renderer)
    assert (b.gpu_layers, b.software, b.backend, b.ctx) == (False, False, "?", None)
    with pytest.raises(UsageError, match="gpu_layers"):
        b.render_gpu(None)


@pytest.mark.gl
@pytest.mark.parametrize("method", ["volume", "shadowmap"])
def test_shading_reaches_the_shader(ctx, tol, method):
    """Shading's ambient and colour are what the occluder's base pass writes: with a light of weight 0 (no
    diffuse or specular added) every covered pixel of the box is ``ambient * linear(colour)``, computed here
    from the sRGB curve, in both renderers (the uniform goes by name into each program that declares it)."""
    from arshadow.camera.model import Intrinsics
    from arshadow.frame.hooks import default_renderer
    from arshadow.geometry.mesh import load_occluder
    from arshadow.synth.markers import look_at_pose
    from arshadow.transforms import CV_TO_GL

    W, H = 160, 120
    K = Intrinsics(fx=150.0, fy=150.0, cx=(W - 1) / 2, cy=(H - 1) / 2, width=W, height=H, dist=np.zeros(0))
    box = load_occluder("box:0.1,0.1,0.1")
    color = (0.8, 0.4, 0.2)
    r = default_renderer(ctx, RenderOptions(shadow_method=method))
    try:
        assert isinstance(r, Renderer)
        for ambient in (0.25, 0.6):
            res = r.render(
                RenderRequest(
                    projection=K.gl_projection(0.01, None),
                    view=CV_TO_GL @ look_at_pose([0.3, -0.3, 0.3], [0.0, 0.0, 0.05]),
                    width=W,
                    height=H,
                    caster=box,
                    passes=[LightPass(np.array([0.0, 0.0, 1.0, 0.0]), 0.0, None, "planar")],
                    shading=Shading(ambient=ambient, color=color),
                )
            )
            inside = res.alpha == 1.0
            assert np.count_nonzero(inside) > 1000
            want = ambient * srgb_to_linear(np.array(color))
            got = res.color[inside]
            assert np.allclose(got, want, rtol=tol.half_float_rel, atol=0), (ambient, got.min(0), got.max(0), want)
    finally:
        r.release()


def test_a_bad_tint_is_a_usage_error_naming_it():
    """A tint that is not three finite gains >= 0 is refused by the options' check, naming the option."""
    from arshadow.errors import UsageError

    for bad in ((1.0, float("nan"), 1.0), (1.0, 1.0), (1.0, -0.5, 1.0)):
        with pytest.raises(UsageError, match="ambient_tint"):
            RenderOptions(ambient_tint=bad).check()
    with pytest.raises(UsageError, match="direct_tint"):
        RenderOptions(direct_tint=(float("inf"), 1.0, 1.0)).check()
