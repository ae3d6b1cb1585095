"""The render accuracy scenes (a box, a non-convex blob, a torus, a camera inside a wall's shadow volume, two
lights) at 1280x720: shared by tests/test_gl_renderer.py, tests/test_plan.py, tests/test_shadowmap.py and
tests/benchmarks/bench_render.py."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

W, H = 1280, 720
ZNEAR = 0.01


@dataclass
class Scene:
    name: str
    caster: object
    cam_from_world: np.ndarray
    lights: list  # [(light_h, weight)]
    fx: float = 1000.0
    ground_size: float | None = None


def intrinsics(fx):
    from arshadow.camera.model import Intrinsics

    return Intrinsics(fx=fx, fy=fx, cx=(W - 1) / 2 + 3.3, cy=(H - 1) / 2 - 2.7, width=W, height=H, dist=np.zeros(0))


def nonconvex_blob():
    """A star-shaped bumpy sphere, ~8.6k faces, standing on the ground (deep concavities self-shadow)."""
    import trimesh

    from arshadow.geometry.mesh import ShadowCaster

    m = trimesh.creation.uv_sphere(radius=1.0, count=[48, 92])
    v = np.asarray(m.vertices, np.float64)
    r = np.linalg.norm(v, axis=1)
    th = np.arctan2(v[:, 1], v[:, 0])
    ph = np.arccos(np.clip(v[:, 2] / r, -1, 1))
    rad = 0.06 * (1.0 + 0.35 * np.sin(5 * th) * np.sin(4 * ph) ** 2)
    v = v / r[:, None] * rad[:, None]
    v[:, 2] -= v[:, 2].min()
    return ShadowCaster(v, np.asarray(m.faces), name="blob")


def scenes():
    from arshadow.geometry.mesh import ShadowCaster, load_occluder
    from arshadow.synth.markers import look_at_pose

    box = load_occluder("box:0.1,0.08,0.15")
    t = load_occluder("torus:0.08,0.03", rotate=(60, 0, 0))
    tv = np.array(t.vertices)
    tv[:, 2] -= tv[:, 2].min()  # stand the tilted torus on the ground
    torus = ShadowCaster(tv, t.faces, name="torus")
    wall = load_occluder("box:1.0,0.05,0.6")
    blob = nonconvex_blob()
    return [
        Scene(
            "box_point",
            box,
            look_at_pose([0.45, -0.55, 0.45], [0.05, 0.08, 0.02]),
            [(np.array([-0.2, 0.1, 0.6, 1.0]), 1.0)],
        ),
        Scene(
            "nonconvex_point",
            blob,
            look_at_pose([0.35, -0.4, 0.35], [0.02, 0.05, 0.03]),
            [(np.array([-0.15, 0.2, 0.5, 1.0]), 1.0)],
        ),
        Scene(
            "torus_directional",
            torus,
            look_at_pose([0.3, -0.45, 0.4], [0.03, 0.06, 0.0]),
            [(np.array([0.45, 0.3, 1.0, 0.0]) / np.linalg.norm([0.45, 0.3, 1.0]), 1.0)],
        ),
        Scene(
            "wall_camera_in_shadow",
            wall,
            look_at_pose([0.1, -0.6, 0.15], [0.6, -1.5, 0.0]),
            [(np.array([0.0, 1.0, 0.25, 0.0]) / np.linalg.norm([0.0, 1.0, 0.25]), 1.0)],
            fx=800.0,
        ),
        Scene(
            "box_two_lights",
            box,
            look_at_pose([0.5, -0.45, 0.5], [0.03, 0.03, 0.02]),
            [(np.array([-0.25, 0.05, 0.55, 1.0]), 0.5), (np.array([0.2, 0.25, 0.7, 1.0]), 0.5)],
        ),
    ]
