"""Does the probe's own shading agree with the fitted light?

A matte probe of one colour under ambient + one light has faces as bright as ``rho (A + E g max(0, n.l))``
(``n`` a face's normal, ``l`` the unit vector to the light; ``g = (d_foot / d)^2`` a point light's fall-off
from the probe's foot to the face's centre, 1 for a directional light). The ground's shadow ratio at the
probe's foot fixes ``A / E``: a horizontal ground lit at elevation ``e`` keeps ``r = A / (A + E sin e)`` in
the shadow, so ``A / E = r sin(e) / (1 - r)``. (A point light 30-40 cm from an 8 cm probe lights its top a
third more than its sides' centres, and its ratio changes by a fifth between the probe's shadow edge, where
it is read, and its foot: without the two, every point-light plate of the path-traced reference failed this
check with the right light, its faces 26-42 % off; with them 5-15 %, docs/light.md.) What is left unknown is one scale (``rho E`` and the exposure), so with two or
more faces in view, the ratios of their brightness test the light: a light fitted to the floor's pattern (a
hidden shadow, a probe not there) shades the faces in the wrong order or proportions.

:func:`face_shading_residual` measures every face group of a convex probe turned to the camera (coplanar
triangles together), the median linear luminance of its pixels (eroded by 3 px from its outline), and
returns the largest log residual of the model after fitting its scale.

:func:`probe_albedo` reads the probe's reflectance off its top face, against the marker's paper: both
horizontal and open to the whole sky, so under a far light both get the open ground's light, and the ratio
of their brightness is the ratio of their reflectances (a point light: each at its own distance and
incidence). The shadow ratio then allows for the light the probe reflects onto the ground beside it
(:mod:`arshadow.estimate.ratio`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..camera.model import Intrinsics
from ..compose.composite import SRGB_TO_LINEAR
from ..shading.decide import PAPER_ALBEDO
from ..transforms import transform_points
from .record import lamp_irradiance, moved_ratio
from .shadow import LUMA

__all__ = ["MIN_FACE_PX", "TOP_FACE_COS", "ProbeViews", "face_luminances", "face_shading_residual", "probe_albedo"]

#: a face is measured when at least this many of its pixels remain after eroding its outline by 3 px
MIN_FACE_PX = 40
#: a face group whose normal's z exceeds this is the probe's top (horizontal within 2.6 degrees)
TOP_FACE_COS = 0.999


@dataclass(frozen=True, eq=False)
class ProbeViews:
    """The probe as the light estimate sees it: its mesh and the photos that show it.

    Attributes
    ----------
    verts : (n, 3) float64, faces : (m, 3) int
        The probe, world frame (metres), standing on the ground.
    views : tuple of (image (H, W, 3) uint8, Intrinsics, cam_from_world (4, 4) float64)
        The frames its faces are read in (a convex probe's; empty otherwise).
    ground_effects : bool
        Whether its effect on the ground round it is allowed for (the sky it hides, the light it reflects):
        true of every real photo; False for ``arshadow.synth.lit``'s (``estimate_light(sky_occlusion=)``).
    foot : (3,) float64
        The centre of its footprint's bounding box on the ground (derived).
    """

    verts: np.ndarray
    faces: np.ndarray
    views: Sequence[tuple[np.ndarray, Intrinsics, np.ndarray]] = ()
    ground_effects: bool = True
    foot: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        v = np.asarray(self.verts, np.float64)
        object.__setattr__(self, "verts", v)
        object.__setattr__(self, "faces", np.asarray(self.faces))
        object.__setattr__(self, "views", tuple(self.views))
        object.__setattr__(self, "foot", np.r_[0.5 * (v[:, :2].min(axis=0) + v[:, :2].max(axis=0)), 0.0])


def _face_groups(verts: np.ndarray, faces: np.ndarray, eye: np.ndarray) -> list:
    """[(unit outward normal (3,), centroid (3,), triangle indices)] of the faces turned to ``eye``, coplanar
    triangles grouped (normals within ~0.5 degree)."""
    tri = verts[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    flip = np.sum(n * (tri.mean(axis=1) - verts.mean(axis=0)), axis=1) < 0
    n[flip] *= -1.0
    front = np.sum(n * (eye - tri.mean(axis=1)), axis=1) > 0
    groups: dict = {}
    for k in np.flatnonzero(front):
        key = tuple(np.round(n[k] * 100).astype(int))
        groups.setdefault(key, []).append(k)
    return [(n[ks[0]], tri[ks].reshape(-1, 3).mean(axis=0), ks) for ks in groups.values()]


def face_shading_residual(
    image_bgr: np.ndarray,
    intr: Intrinsics,
    cam_from_world: np.ndarray,
    verts: np.ndarray,
    faces: np.ndarray,
    light_h: np.ndarray,
    shadow_ratio: float,
    ratio_at: tuple[float, float] | None = None,
) -> tuple:
    """The largest disagreement between the probe's faces in the photo and their shading by a light.

    Parameters
    ----------
    image_bgr : (H, W, 3) uint8
    intr : Intrinsics
    cam_from_world : (4, 4) float64
    verts : (n, 3) float64, faces : (m, 3) int
        A convex probe, world frame.
    light_h : (4,) float
        ``(dx, dy, dz, 0)`` towards a directional light or ``(x, y, z, 1)`` a point light, world frame.
    shadow_ratio : float
        The ground's shadow / lit (luminance), that fixes ``A / E``.
    ratio_at : (2,) float, optional
        Where it was read (world, metres): a point light's is moved to the probe's foot, the centre of its
        footprint (:func:`arshadow.estimate.record.moved_ratio`); None: read at the foot.

    Returns
    -------
    (residual, faces) : (float, int)
        The largest ``|log(measured) - log(scale * model)|`` over the faces measured (the scale fitted in
        log), and how many faces were measured; ``(NaN, k)`` with fewer than two.
    """
    v = np.asarray(verts, np.float64)
    pose = np.asarray(cam_from_world, np.float64)
    h = np.asarray(light_h, np.float64)
    foot = np.r_[0.5 * (v[:, :2].min(axis=0) + v[:, :2].max(axis=0)), 0.0]

    def to_light(p: np.ndarray) -> np.ndarray:
        d = h[:3] if h[3] == 0.0 else h[:3] / h[3] - p
        return d / np.linalg.norm(d)

    def falloff(p: np.ndarray) -> float:  # a point light's irradiance at p over at the foot (normal incidence)
        return 1.0 if h[3] == 0.0 else float(np.sum((h[:3] / h[3] - foot) ** 2) / np.sum((h[:3] / h[3] - p) ** 2))

    if h[3] != 0.0 and ratio_at is not None:
        shadow_ratio = float(moved_ratio([shadow_ratio], h[:3] / h[3], ratio_at, foot[:2])[0])
    r = float(np.clip(shadow_ratio, 0.0, 0.95))
    amb = r * max(to_light(foot)[2], 0.0) / (1.0 - r)  # A / E
    measured, model = [], []
    for normal, centre, value in face_luminances(image_bgr, intr, pose, v, np.asarray(faces)):
        measured.append(value)
        model.append(amb + max(0.0, float(normal @ to_light(centre))) * falloff(centre))
    if len(measured) < 2 or min(measured) <= 0 or min(model) <= 0:
        return math.nan, len(measured)
    res = np.log(measured) - np.log(model)
    return float(np.abs(res - res.mean()).max()), len(measured)


def face_luminances(
    image_bgr: np.ndarray, intr: Intrinsics, cam_from_world: np.ndarray, verts: np.ndarray, faces: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Each face group of a convex probe turned to the camera with at least :data:`MIN_FACE_PX` pixels once
    its outline is eroded by 3 px: ``(unit outward normal (3,), centroid (3,), median linear luminance)``
    (world frame; luminance in the photo's linear light, 0..1).

    ``image_bgr (H, W, 3) uint8``; ``cam_from_world (4, 4) float64``; ``verts (n, 3) float64`` and ``faces
    (m, 3) int``: the probe in the world frame."""
    v = np.asarray(verts, np.float64)
    f = np.asarray(faces)
    pose = np.asarray(cam_from_world, np.float64)
    eye = transform_points(np.linalg.inv(pose), np.zeros((1, 3)))[0]
    H, W = image_bgr.shape[:2]
    lum = cv2.LUT(image_bgr, SRGB_TO_LINEAR).astype(np.float32) @ LUMA[::-1].astype(np.float32)
    uv = intr.project(v, pose)
    kernel = np.ones((7, 7), np.uint8)
    out = []
    for normal, centre, ks in _face_groups(v, f, eye):
        mask: np.ndarray = np.zeros((H, W), np.uint8)
        for k in ks:
            t = uv[f[k]]
            if np.all(np.isfinite(t)):
                cv2.fillConvexPoly(mask, np.round(t * 16).astype(np.int32), 1, cv2.LINE_8, shift=4)
        px = lum[cv2.erode(mask, kernel) > 0]
        if len(px) >= MIN_FACE_PX:
            out.append((normal, centre, float(np.median(px))))
    return out


def probe_albedo(
    probe: ProbeViews,
    light_h: np.ndarray,
    shadow_ratio: float,
    paper_luminance: float,
    paper_albedo: float = PAPER_ALBEDO,
) -> float:
    """The probe's reflectance (luminance), read off its top face against the marker's paper; NaN when no
    view shows the top face (:func:`face_luminances`) or the paper is unknown.

    Both are horizontal and see the whole sky, so under a far light both get the open ground's light and
    ``albedo = paper_albedo * top / paper``. A point light lights each by ``(1 - r) g + r`` (``g`` its
    ``cos / d^2`` at the top face's centre and at the marker's centre, over at the probe's foot, where
    ``shadow_ratio`` ``r`` is taken to hold). The median over the probe's views.

    Parameters
    ----------
    probe : ProbeViews
        A convex probe and the photos that show it.
    light_h : (4,) float
        ``(dx, dy, dz, 0)`` towards a directional light or ``(x, y, z, 1)`` a point light, world frame.
    shadow_ratio : float
        The sky's share of the open ground's light (luminance).
    paper_luminance : float
        The lit paper's linear luminance in the same photos (:class:`arshadow.estimate.exposure.Exposure`).
    paper_albedo : float
        The paper's reflectance (:data:`arshadow.shading.decide.PAPER_ALBEDO`).

    Examples
    --------
    >>> from arshadow.camera import Intrinsics
    >>> from arshadow.synth import look_at_pose
    >>> box = np.array([[x, y, z] for x in (-0.02, 0.02) for y in (-0.02, 0.02) for z in (0.0, 0.05)])
    >>> tri = np.array([[1, 3, 7], [1, 7, 5]])  # the top face (z = 0.05)
    >>> cam = Intrinsics(500.0, 500.0, 159.5, 119.5, 320, 240)
    >>> photo = np.full((240, 320, 3), 128, np.uint8)  # the top face 0.216 in linear light
    >>> probe = ProbeViews(box, tri, [(photo, cam, look_at_pose([0.0, -0.1, 0.3], [0.0, 0.0, 0.05]))])
    >>> round(probe_albedo(probe, np.array([0.0, 0.0, 1.0, 0.0]), 0.3, 0.432), 3)
    0.4
    """
    paper = float(paper_luminance)
    if not (math.isfinite(paper) and paper > 0.0):
        return math.nan
    h = np.asarray(light_h, np.float64)
    r = float(np.clip(shadow_ratio, 0.0, 0.95))
    found = [
        (c, paper_albedo * value / paper)
        for image, intr, pose in probe.views
        for normal, c, value in face_luminances(image, intr, pose, probe.verts, probe.faces)
        if normal[2] > TOP_FACE_COS
    ]
    if not found:
        return math.nan
    centres, albedos = np.array([c for c, _ in found]), np.array([a for _, a in found])
    if h[3] != 0.0:  # each surface's light over the open ground's at the foot: (1 - r) g + r
        g = lamp_irradiance(h[:3] / h[3], np.vstack([centres, np.zeros((1, 3)), probe.foot]))
        light = (1.0 - r) * g[:-1] / g[-1] + r
        albedos = albedos * light[-1] / light[:-1]  # light[-1]: the paper's, at the marker's centre
    return float(np.median(albedos))
