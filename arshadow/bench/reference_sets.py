"""The path-traced reference scenes: the project's own set and a held-out set (the realism work).

``OWN`` is for developing the rendering model (a box, a torus, a sphere, a cylinder under a sun, hard or
with a disc, plus a uniform sky, or a point light plus ambient); ``HELDOUT`` has other objects, lights,
floors and cameras and is kept for judging: tune nothing on it. ``PLAIN`` is four of them on a plain
neutral grey floor, for the light estimate (its shadow ratio with no floor pattern to confound it; a neutral
floor the marker's paper class must not swallow). Each entry is a function returning fresh
:class:`arshadow.bench.reference_scene.ReferenceScene` objects (render_scene sets their exposure).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from .reference_scene import ReferenceScene

__all__ = ["HELDOUT", "OWN", "PLAIN", "SETS"]

#: a point light and the ambient that goes with it (a dim uniform environment)
_POINT: dict[str, Any] = {
    "light": "point",
    "light_vec": (-0.22, -0.14, 0.34),
    "direct": (0.42, 0.4, 0.36),
    "sky": (0.45, 0.45, 0.5),
}


def own() -> list[ReferenceScene]:
    """The project's own six scenes."""
    return [
        ReferenceScene("box_sun"),
        ReferenceScene("torus_sun_disc", model="torus:0.035,0.013", sun_radius_deg=0.5, seed=3, seed2=4),
        ReferenceScene("sphere_sun", model="sphere:0.03", light_vec=(-0.45, -0.5, 0.75), seed=5, seed2=6),
        ReferenceScene("cylinder_sun_disc", model="cylinder:0.022,0.08", sun_radius_deg=0.5, seed=7, seed2=8),
        ReferenceScene("box_point", color=(0.5, 0.55, 0.6), seed=9, seed2=10, **_POINT),
        ReferenceScene("torus_point", model="torus:0.035,0.013", seed=11, seed2=12, **_POINT),
    ]


def heldout() -> list[ReferenceScene]:
    """Held-out scenes: other objects, lights, floors and cameras."""
    return [
        ReferenceScene(
            "ho_box_rotated_tiles",
            model="box:0.06,0.04,0.05",
            rotate=(0.0, 0.0, 30.0),
            floor="tiles",
            light_vec=(-0.45, -0.55, 0.55),
            eye=(0.05, -0.36, 0.3),
            fov_x_deg=50.0,
            principal_offset=(-4.0, 3.0),
            seed=21,
            seed2=22,
        ),
        ReferenceScene(
            "ho_tall_cylinder_disc",
            model="cylinder:0.018,0.11",
            sun_radius_deg=0.8,
            light_vec=(-0.7, -0.15, 0.8),
            floor_seed=11,
            floor_tint=(0.9, 1.0, 1.1),
            eye=(-0.05, -0.33, 0.3),
            seed=23,
            seed2=24,
        ),
        ReferenceScene(
            "ho_big_sphere_point",
            model="sphere:0.04",
            place=(0.08, 0.09, 0.0),
            floor="tiles",
            seed=25,
            seed2=26,
            **{**_POINT, "light_vec": (-0.26, -0.02, 0.32)},
        ),
        ReferenceScene(
            "ho_orange_torus_high_sun",
            model="torus:0.028,0.011",
            color=(0.7, 0.33, 0.08),
            light_vec=(-0.3, 0.5, 1.0),
            fov_x_deg=60.0,
            eye=(0.02, -0.3, 0.3),
            seed=27,
            seed2=28,
        ),
        ReferenceScene(
            "ho_orange_box_point",
            color=(0.7, 0.33, 0.08),
            floor_seed=3,
            principal_offset=(5.0, 4.0),
            seed=29,
            seed2=30,
            **{**_POINT, "light_vec": (-0.25, -0.05, 0.3)},
        ),
        ReferenceScene(
            "ho_cylinder_low_sun_blue_sky",
            model="cylinder:0.03,0.06",
            light_vec=(-0.85, -0.3, 0.5),
            sky=(1.0, 1.25, 1.9),
            floor="tiles",
            floor_tint=(1.05, 1.0, 0.9),
            seed=31,
            seed2=32,
        ),
    ]


def plain() -> list[ReferenceScene]:
    """Two own and two held-out scenes (a sun and a point light each) on the ``plain`` floor, untinted."""
    by_name = {sc.name: sc for sc in own() + heldout()}
    names = ("box_sun", "box_point", "ho_orange_torus_high_sun", "ho_orange_box_point")
    return [
        dataclasses.replace(by_name[n], name=f"plain_{n}", floor="plain", floor_tint=(1.0, 1.0, 1.0)) for n in names
    ]


OWN = own
HELDOUT = heldout
PLAIN = plain
#: the sets by name (their folder under tests/data/reference/)
SETS = {"own": own, "heldout": heldout, "plain": plain}
