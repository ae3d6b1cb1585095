"""Per-frame cost of the render seam's values (microseconds): what the layout work adds to a frame, apart from the
GL work (a frame of ``ab_pipeline.py``'s case takes ~14 ms).

    python tests/benchmarks/seam_overhead.py      # from the repository root

Each figure is the best of 5 repeats of 20 000 calls (the machine's load inflates them; quote ``uptime``).
"""

from __future__ import annotations

import timeit

import numpy as np

import arshadow
from arshadow.compose.composite import Workspace
from arshadow.compose.look import Look
from arshadow.frame.execute import FrameContext, FrameOutputs, render_request
from arshadow.gl.context import create_context
from arshadow.gl.resources import set_uniforms
from arshadow.gl.stencil import ShadowRenderer
from arshadow.renderer.request import LightPass, Shading
from arshadow.synth.markers import look_at_pose

N = 20000


def best_us(fn) -> float:
    return min(timeit.repeat(fn, number=N, repeat=5)) / N * 1e6


def main() -> None:
    spec = {"calib": "calib/synth_1280x720.yml", "marker_length": 0.05, "model": "box:0.04,0.04,0.06"}
    s = arshadow.Session({**spec, "lights": ["point:0.1,0.1,0.4"]})
    plan = s.plan(look_at_pose([0.1, -0.3, 0.4], [0, 0, 0]), 1280, 720)
    cal = s.hooks.calibration(1280, 720)
    passes = [LightPass(np.array([0.1, 0.1, 0.4, 1.0]), 1.0, None, "planar")]
    r = ShadowRenderer(create_context())
    sh, work = Shading.from_options(s.options), Workspace()
    base, light = r.prog_occ_base, r.prog_occ_light

    def before_uniforms():  # what the renderer wrote per frame (one light) before the seam
        base["u_ambient"].value = 0.25
        light["u_kd"].value = 1.0
        light["u_ks"].value = 0.25
        light["u_shininess"].value = 32.0

    figures = {
        "render_request (incl. projection, view)": lambda: render_request(plan, cal.intrinsics, s.geometry, passes),
        "  of which the projection (before too)": lambda: cal.intrinsics.gl_projection(
            plan.znear, None, canvas=plan.canvas
        ),
        "Look.from_options": lambda: Look.from_options(s.options, (1.0, 0.9, 0.8)),
        "FrameContext": lambda: FrameContext(
            geometry=s.geometry,
            renderer=lambda: r,
            work=work,
            calibration=s.hooks.calibration,
            compose_key=s.hooks.compose_key,
            chooser=s.hooks.compose_chooser,
        ),
        "FrameOutputs": lambda: FrameOutputs(True, None, None),
        "set_uniforms (2 programs)": lambda: set_uniforms((base, light), sh.uniforms()),
        "4 uniform writes (before)": before_uniforms,
    }
    for name, fn in figures.items():
        print(f"{name:42s} {best_us(fn):7.2f} us")
    r.release()
    s.close()


if __name__ == "__main__":
    main()
