"""Synthetic photos lit by a known light: a reference object (the probe) casting its real shadow.

The truth of every photo is the light, reflectances and camera it is generated from, never an estimator's
output. Scene (world frame = marker frame, z up): the textured floor and the printed marker of
:func:`arshadow.synth.render_print_scene`, read as reflectance (8-bit sRGB codes decoded to linear), plus a
convex probe mesh standing on the ground (``box:WX,WY,HZ``, ``cylinder:R,H``, placed like ``--model``).

Light, in linear RGB irradiance on a horizontal surface: an ambient term ``A`` (uniform sky, every
point sees it; no ambient occlusion) plus one direct light ``E`` (directional, a sun, or a point light
without distance fall-off), blocked by the probe. Per pixel::

    ground:  rho_ground * (A + E * max(0, n.l) * visible)         n = +z
    probe:   rho_probe  * (A + E * max(0, n.l))                   n = the hit face's normal

The visibility is supersampled (``S x S`` samples per pixel) in the region of the probe and its shadow,
from the exact ground shadow (:func:`arshadow.geometry.exact.ground_shadow_triangles`) and exact ray /
triangle hits for the probe. The true shadow ratio (shadow / lit, per channel) of the ground next to the
probe is ``A / (A + E sin(elevation))``.

Camera: ``exposure * white_balance`` (per channel gains) on linear light, Gaussian optical blur in linear
light, the sRGB response curve, Gaussian noise in 8-bit units, rounding, JPEG.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from ..camera.model import Intrinsics
from ..compose.composite import SRGB_TO_LINEAR, linear_to_srgb
from ..errors import UsageError
from ..geometry.exact import ground_points, ground_shadow_triangles, points_in_triangles
from ..geometry.mesh import load_occluder
from ..lights.spec import parse_light
from ..transforms import transform_points
from .markers import SynthPhoto, camera_effects, look_at_pose, render_print_scene

__all__ = ["LitPhoto", "light_vector", "render_lit_photo"]


@dataclass
class LitPhoto(SynthPhoto):
    """A :class:`arshadow.synth.SynthPhoto` with its lighting truth.

    Attributes (besides the parent's)
    ---------------------------------
    light_kind : str
        ``"directional"`` or ``"point"``.
    light : (3,) float64
        Unit direction towards the light (directional) or its position (point), world frame.
    ambient, direct : (3,) float64
        Linear RGB irradiance of the ambient and the direct light on a horizontal surface facing it.
    shadow_ratio : (3,) float64
        Truth: ground in the probe's shadow / the same ground lit, linear RGB, at the probe's foot.
    paper_linear : (3,) float64
        Truth: the linear RGB (as the camera records it, before the response curve) of the lit paper.
    probe_mask : (H, W) bool
        Pixels whose centre sees the probe.
    """

    light_kind: str = "directional"
    light: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ambient: np.ndarray = field(default_factory=lambda: np.zeros(3))
    direct: np.ndarray = field(default_factory=lambda: np.zeros(3))
    shadow_ratio: np.ndarray = field(default_factory=lambda: np.ones(3))
    paper_linear: np.ndarray = field(default_factory=lambda: np.zeros(3))
    probe_mask: np.ndarray | None = None


def light_vector(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit direction towards a light at ``azimuth_deg`` (counter-clockwise from world +x, seen from
    above) and ``elevation_deg`` above the ground, world frame: (3,) float64.

    >>> light_vector(90.0, 30.0).round(6).tolist()
    [0.0, 0.866025, 0.5]
    """
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def _ray_hits(origin: np.ndarray, dirs: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit of rays ``origin + t dirs`` (n, 3) with triangles (m, 3, 3): (t (n,), face (n,) int, -1
    for a miss). Moller-Trumbore, vectorised over rays, looped over triangles."""
    n = len(dirs)
    best = np.full(n, np.inf)
    face = np.full(n, -1, np.intp)
    for k, (a, b, c) in enumerate(tris):
        e1, e2 = b - a, c - a
        p = np.cross(dirs, e2)
        det = p @ e1
        ok = np.abs(det) > 1e-15
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = origin - a
        u = (p @ s) * inv
        q = np.cross(s, e1)
        v = (dirs @ q) * inv
        t = (q @ e2) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9) & (t < best)
        best[hit] = t[hit]
        face[hit] = k
    return best, face


def _cone_directions(light: np.ndarray, radius_deg: float, seed: int | None) -> np.ndarray:
    """Unit directions uniform in solid angle within the cone of half-angle ``radius_deg`` around ``light``:
    (64, 3) float64, stratified (8 x 8 in cos(theta) and azimuth, jittered); ``light[None]`` for 0."""
    if radius_deg <= 0.0:
        return np.asarray(light, np.float64)[None]
    rng = np.random.default_rng(None if seed is None else int(seed) + 7919)
    k = 8
    u = (np.arange(k)[:, None] + rng.random((k, k))) / k
    v = (np.arange(k)[None, :] + rng.random((k, k))) / k
    cos_t = 1.0 - u.ravel() * (1.0 - math.cos(math.radians(radius_deg)))
    phi = 2.0 * math.pi * v.ravel()
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t**2))
    z = np.asarray(light, np.float64)
    a = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(z, a)
    dirs: np.ndarray = cos_t[:, None] * z + sin_t[:, None] * (np.cos(phi)[:, None] * a + np.sin(phi)[:, None] * b)
    return dirs


def _lighting_samples(
    intr: Intrinsics,
    pose: np.ndarray,
    verts: np.ndarray,
    faces: np.ndarray,
    normals: np.ndarray,
    kind: str,
    light: np.ndarray,
    roi: tuple[int, int, int, int],
    S: int,
    cone: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per pixel of ``roi = (x0, y0, w, h)``: (probe coverage, probe n.l (mean over covered samples),
    ground visibility (mean over ground samples and, for an extended directional light, over the ``cone``'s
    directions), ground n.l): four (h, w) float64 arrays."""
    x0, y0, w, h = roi
    off = (np.arange(S) + 0.5) / S - 0.5
    vv, uu = np.mgrid[y0 : y0 + h, x0 : x0 + w].astype(np.float64)
    su = np.broadcast_to(uu[:, :, None, None] + off[None, None, None, :], (h, w, S, S)).reshape(-1)
    sv = np.broadcast_to(vv[:, :, None, None] + off[None, None, :, None], (h, w, S, S)).reshape(-1)
    pin = np.stack([su, sv], 1)
    if intr.has_distortion:
        pin = intr.undistort_pixels(pin)
    R, t = pose[:3, :3], pose[:3, 3]
    C = -R.T @ t
    K = intr.K
    d_cam = np.stack([(pin[:, 0] - K[0, 2]) / K[0, 0], (pin[:, 1] - K[1, 2]) / K[1, 1], np.ones(len(pin))], 1)
    dirs = d_cam @ R
    tri = verts[faces]
    uvp = intr.project(verts, pose)  # only the samples in the probe's image box can hit it
    lo, hi = np.nanmin(uvp, axis=0) - 2.0, np.nanmax(uvp, axis=0) + 2.0
    near = np.flatnonzero((su >= lo[0]) & (su <= hi[0]) & (sv >= lo[1]) & (sv <= hi[1]))
    t_hit = np.full(len(su), np.inf)
    f_hit = np.full(len(su), -1, np.intp)
    t_hit[near], f_hit[near] = _ray_hits(C, dirs[near], tri)
    on_probe = f_hit >= 0
    g, hit = ground_points(pin[:, 0], pin[:, 1], K, pose)
    ground = hit & ~on_probe
    if kind == "directional":
        lh = np.append(light, 0.0)
        ndl_ground = np.full(len(g), max(0.0, light[2]))
    else:
        lh = np.append(light, 1.0)
        to_l = light[None, :] - np.column_stack([g, np.zeros(len(g))])
        ndl_ground = np.maximum(0.0, to_l[:, 2] / np.linalg.norm(to_l, axis=1))
    idx = np.flatnonzero(ground)
    dirs_l = [light] if cone is None or kind != "directional" else list(cone)
    shadow = np.zeros(len(g))
    for d in dirs_l:  # the exact hard shadow of each direction of the light's disc, averaged
        lk = np.append(d, lh[3])
        shadow[idx] += points_in_triangles(g[idx], ground_shadow_triangles(verts, faces, lk))
    shadow /= len(dirs_l)
    vis = np.where(ground, 1.0 - shadow, 0.0)
    ndl_probe = np.zeros(len(g))
    if on_probe.any():
        pts = C[None, :] + t_hit[on_probe, None] * dirs[on_probe]
        ldir = np.broadcast_to(light, pts.shape) if kind == "directional" else light[None, :] - pts
        ldir = ldir / np.linalg.norm(ldir, axis=1, keepdims=True)
        ndl_probe[on_probe] = np.maximum(0.0, np.sum(normals[f_hit[on_probe]] * ldir, axis=1))
    shp = (h, w, S * S)
    cov = on_probe.reshape(shp).mean(axis=2)
    probe_ndl = ndl_probe.reshape(shp).sum(axis=2) / np.maximum(on_probe.reshape(shp).sum(axis=2), 1)
    gcount = ground.reshape(shp).sum(axis=2)
    gvis = (vis * ndl_ground).reshape(shp).sum(axis=2) / np.maximum(gcount, 1)
    return cov, probe_ndl, gvis, gcount / (S * S)


def _outward_normals(verts: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit face normals pointing away from the (convex) mesh's centroid: (m, 3) float64."""
    tri = verts[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    flip = np.sum(n * (tri.mean(axis=1) - verts.mean(axis=0)), axis=1) < 0
    n[flip] *= -1.0
    return n


def render_lit_photo(
    intrinsics: Intrinsics,
    cam_from_world: npt.ArrayLike,
    *,
    marker_length: float = 0.05,
    dictionary: str = "DICT_6X6_250",
    marker_id: int = 0,
    probe: str = "box:0.05,0.05,0.1",
    probe_place: npt.ArrayLike = (0.1, 0.0, 0.0),
    probe_rotate: npt.ArrayLike = (0, 0, 0),
    probe_albedo: npt.ArrayLike = (0.55, 0.5, 0.45),
    light_kind: str = "directional",
    light: npt.ArrayLike = (0.5, 0.0, 0.866),
    ambient: npt.ArrayLike = (0.35, 0.38, 0.45),
    direct: npt.ArrayLike = (1.0, 0.95, 0.85),
    exposure: float = 0.8,
    white_balance: npt.ArrayLike = (1.0, 1.0, 1.0),
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    jpeg_quality: int | None = None,
    seed: int | None = None,
    supersample: int = 3,
    floor: str | Callable[[np.ndarray, np.ndarray], np.ndarray] = "texture",
    light_radius_deg: float = 0.0,
) -> LitPhoto:
    """Render a photo of the marker and a probe lit by ambient + one direct light, with its truth.

    Parameters
    ----------
    intrinsics : Intrinsics
    cam_from_world : (4, 4) float64
    marker_length : float
        The marker's side, metres (the print as :func:`arshadow.synth.render_marker_photo` makes it).
    probe : str
        A convex primitive (``box:...``, ``cylinder:...``), placed with ``probe_place`` / ``probe_rotate``.
    probe_albedo : (3,) float
        The probe's linear RGB reflectance.
    light_kind : {"directional", "point"}
    light : (3,) float
        Direction towards the light (directional; normalised here) or its position (point), world frame.
    ambient, direct : (3,) float
        Linear RGB irradiance: ambient, and the direct light on a surface facing it.
    exposure : float
        Camera gain on linear light; ``white_balance`` (3,) per channel gains (R, G, B).
    blur_sigma, noise_sigma, jpeg_quality, seed
        As :func:`arshadow.synth.render_marker_photo` (blur applied in linear light).
    supersample : int
        Samples per pixel side around the probe and its shadow.
    floor : str or callable
        As :func:`arshadow.synth.render_marker_photo`'s: ``"texture"``, ``"plain"`` or grey codes as a function
        of the ground point.
    light_radius_deg : float
        Directional light only: the angular radius of a uniformly bright disc (a lamp's or the sun's size):
        the ground's visibility is the mean over 64 directions uniform in solid angle within that cone
        (soft shadows, penumbra); the probe's own shading uses the centre direction.

    Returns
    -------
    LitPhoto
    """
    if light_kind not in ("directional", "point"):
        raise UsageError(f"light_kind must be 'directional' or 'point', got {light_kind!r}")
    light = np.asarray(light, np.float64).reshape(3)
    if light_kind == "directional":
        light = light / np.linalg.norm(light)
    ambient = np.asarray(ambient, np.float64).reshape(3)
    direct = np.asarray(direct, np.float64).reshape(3)
    gain = float(exposure) * np.asarray(white_balance, np.float64).reshape(3)
    scene = render_print_scene(
        intrinsics, cam_from_world, dictionary=dictionary, marker_id=marker_id, marker_length=marker_length, floor=floor
    )
    pose = scene["cam_from_world"]
    H, W = intrinsics.height, intrinsics.width
    rho = SRGB_TO_LINEAR[np.clip(np.rint(scene["image"]), 0, 255).astype(np.uint8)][:, :, ::-1].astype(np.float64)

    caster = load_occluder(probe, rotate=probe_rotate, place=probe_place)
    verts, faces = np.asarray(caster.vertices, np.float64), np.asarray(caster.faces)
    normals = _outward_normals(verts, faces)
    lh = np.append(light, 0.0 if light_kind == "directional" else 1.0)
    cone = _cone_directions(light, float(light_radius_deg), seed) if light_kind == "directional" else light[None]
    shadow2d = np.concatenate([ground_shadow_triangles(verts, faces, np.append(d, lh[3])).reshape(-1, 2) for d in cone])
    # the region of the probe and its shadow (+ margin), in the image
    pts = np.concatenate([verts, np.column_stack([shadow2d, np.zeros(len(shadow2d))])])
    cam_pts = transform_points(pose, pts)
    if np.any(cam_pts[:, 2] <= 1e-6):
        raise UsageError("render_lit_photo: the probe or its shadow is behind the camera")
    uv = intrinsics.project(pts, pose)
    x0, y0 = (np.floor(np.nanmin(uv, axis=0)) - 3).astype(int)
    x1, y1 = (np.ceil(np.nanmax(uv, axis=0)) + 4).astype(int)
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)

    # ground irradiance over the whole image (no shadow), then the region's exact visibility
    if light_kind == "directional":
        ndl = np.full((H, W), max(0.0, light[2]))
    else:
        vv, uu = np.mgrid[0:H, 0:W]
        pin = np.stack([uu.ravel(), vv.ravel()], 1).astype(np.float64)
        pin = intrinsics.undistort_pixels(pin) if intrinsics.has_distortion else pin
        g, _ = ground_points(pin[:, 0], pin[:, 1], intrinsics.K, pose)
        to_l = light[None, :] - np.column_stack([g, np.zeros(len(g))])
        ndl = np.maximum(0.0, to_l[:, 2] / np.linalg.norm(to_l, axis=1)).reshape(H, W)
    irr = ambient[None, None, :] + direct[None, None, :] * ndl[:, :, None]
    img = rho * irr
    probe_mask = np.zeros((H, W), bool)
    if x1 > x0 and y1 > y0:
        roi = (x0, y0, x1 - x0, y1 - y0)
        cov, pndl, gvis, gfrac = _lighting_samples(
            intrinsics, pose, verts, faces, normals, light_kind, light, roi, int(supersample), cone
        )
        sl = (slice(y0, y1), slice(x0, x1))
        ground_rad = rho[sl] * (ambient * gfrac[:, :, None] + direct * gvis[:, :, None])
        probe_rad = np.asarray(probe_albedo, np.float64) * (ambient + direct * pndl[:, :, None]) * cov[:, :, None]
        img[sl] = ground_rad + probe_rad
        probe_mask[sl] = cov >= 0.5
    lin = img * gain[None, None, :]
    if blur_sigma and blur_sigma > 0:
        lin = cv2.GaussianBlur(lin, (0, 0), float(blur_sigma))
    codes = (linear_to_srgb(lin) * 255.0)[:, :, ::-1].astype(np.float32)  # BGR, 8-bit units, unrounded
    out = camera_effects(codes, blur_sigma=0.0, noise_sigma=noise_sigma, seed=seed, jpeg_quality=jpeg_quality)

    foot = np.array([*caster.bounds.mean(axis=0)[:2], 0.0])
    sin_e = light[2] if light_kind == "directional" else (light - foot)[2] / np.linalg.norm(light - foot)
    ratio = ambient / (ambient + direct * max(sin_e, 0.0))
    sin_p = light[2] if light_kind == "directional" else light[2] / np.linalg.norm(light)  # at the marker
    paper_lin = gain * float(SRGB_TO_LINEAR[235]) * (ambient + direct * max(sin_p, 0.0))
    corners_px = {mid: intrinsics.project(c, pose) for mid, c in scene["corners_world"].items()}
    return LitPhoto(
        image=out,
        cam_from_world=pose,
        intrinsics=intrinsics,
        dictionary=scene["dictionary"],
        marker_id=int(marker_id),
        marker_length=float(marker_length),
        corners_px=corners_px,
        paper_world=scene["paper_world"],
        params={
            "probe": probe,
            "probe_place": list(map(float, np.ravel(probe_place))),
            "probe_rotate": list(map(float, np.ravel(probe_rotate))),
            "exposure": float(exposure),
            "white_balance": list(map(float, np.ravel(white_balance))),
            "blur_sigma": blur_sigma,
            "noise_sigma": noise_sigma,
            "jpeg_quality": jpeg_quality,
            "seed": seed,
        },
        light_kind=light_kind,
        light=light,
        ambient=ambient,
        direct=direct,
        shadow_ratio=ratio,
        paper_linear=paper_lin,
        probe_mask=probe_mask,
    )


#: (lat, lon, time) of the sun cases: elevations between 25 and 60 degrees
SUN_CASES = (
    ("48.85", "2.35", "2026-06-21T18:00+02:00"),
    ("52.2", "0.12", "2026-04-10T10:30+01:00"),
    ("40.4", "-3.7", "2026-09-22T16:00+02:00"),
    ("35.7", "139.7", "2026-03-20T09:30+09:00"),
)


def random_lit_case(
    rng: np.random.Generator,
    intrinsics: Intrinsics,
    kind: str = "directional",
    *,
    marker_length: float = 0.05,
    effects: bool = True,
    view: str = "shadow",
    point_distance: tuple[float, float] = (0.35, 0.8),
) -> dict[str, Any]:
    """A random case of the light estimate's test distribution (docs/light.md), with its truth.

    A 5 x 5 x (8..12) cm box probe beside the marker's paper (8..13 cm from its centre, turned at random), a light
    at elevation 25..60 degrees (directional, a sun at one of :data:`SUN_CASES` with the world turned by
    a random NORTH, or a point light 0.35..0.8 m from the probe), ambient 0.2..0.6 of the direct light with
    a random tint, exposure 0.45..0.9, white balance gains 0.85..1.15, blur 0..1.2 px, noise 0.5..3 codes,
    JPEG 75..95; the camera 0.4..0.6 m away, looking at the marker, the probe and the shadow.
    ``view="light"`` puts the camera on the light's side instead (the probe hides part of its shadow);
    ``point_distance`` (metres) is the range of a point light's distance from the probe's top.

    Returns ``{"photo": LitPhoto, "probe": spec, "probe_place": (3,), "probe_rotate": (3,), "kind": spec
    for estimate_light, "north_deg": float or None}``.
    """

    h = float(rng.uniform(0.08, 0.12))
    probe = f"box:0.05,0.05,{h:.4f}"
    ang = rng.uniform(0, 2 * np.pi)
    dist = rng.uniform(0.08, 0.13)  # beside the printed paper (half side 0.04), not on it
    place = (float(dist * np.cos(ang)), float(dist * np.sin(ang)), 0.0)
    rot = (0.0, 0.0, float(rng.uniform(0, 90)))
    north = None
    kind_spec = kind
    if kind == "sun":
        lat, lon, when = SUN_CASES[int(rng.integers(len(SUN_CASES)))]
        north = float(rng.uniform(0, 360))
        light = np.asarray(parse_light(f"sun:{lat},{lon},{when},{north}").vector, np.float64)
        light_kind, kind_spec = "directional", f"sun:{lat},{lon},{when}"
    else:
        light = light_vector(rng.uniform(0, 360), rng.uniform(25, 60))
        light_kind = "directional"
        if kind == "point":
            light = np.array([place[0], place[1], h]) + rng.uniform(*point_distance) * light
            light_kind = "point"
    amb = rng.uniform(0.2, 0.6) * rng.uniform(0.85, 1.15, 3)
    direct = rng.uniform(0.85, 1.15, 3)
    scale = 1.0 / (amb + direct * 0.7).max()
    # the camera on the shadow's side (the shadow in front of the probe), the marker, the probe and the
    # shadow in view, the probe not hiding the marker
    foot = np.array(place)
    tip = (
        foot[:2] - (h / light[2]) * light[:2]
        if light_kind == "directional"
        else light[:2] + light[2] / (light[2] - h) * (foot[:2] - light[:2])
    )
    pts = np.array([[-0.04, -0.04, 0], [0.04, 0.04, 0], [-0.04, 0.04, 0], [0.04, -0.04, 0], [*foot[:2], h], [*tip, 0]])
    target = np.r_[pts[:, :2].mean(axis=0), 0.0]
    away = math.atan2(tip[1] - foot[1], tip[0] - foot[0]) + (math.pi if view == "light" else 0.0)
    box = load_occluder(probe, rotate=rot, place=place).vertices
    for attempt in range(300):
        az = away + math.radians(rng.uniform(-1, 1) * min(180.0, 70.0 + attempt))
        tilt = math.radians(rng.uniform(20, 50))
        d = rng.uniform(0.4, 0.6) * (1.0 + attempt / 150.0)  # farther when it does not fit
        eye = target + d * np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az), math.cos(tilt)])
        pose = look_at_pose(eye, target)
        uv = intrinsics.project(pts, pose)
        if not (
            np.all(np.isfinite(uv))
            and np.all(uv >= 40)
            and np.all(uv[:, 0] <= intrinsics.width - 41)
            and np.all(uv[:, 1] <= intrinsics.height - 41)
        ):
            continue
        quad = intrinsics.project(0.8 * pts[[0, 3, 1, 2]], pose).astype(np.float32)  # the marker, 3 mm slack
        hull = cv2.convexHull(intrinsics.project(np.asarray(box), pose).astype(np.float32))
        if cv2.intersectConvexConvex(quad, hull)[0] <= 0.0:
            break
    else:
        raise UsageError("random_lit_case: no camera sees the marker, the probe and its shadow")
    kw: dict[str, Any] = {}
    if effects:
        kw = {
            "blur_sigma": float(rng.uniform(0, 1.2)),
            "noise_sigma": float(rng.uniform(0.5, 3.0)),
            "jpeg_quality": int(rng.integers(75, 96)),
            "exposure": float(rng.uniform(0.45, 0.9)),
            "white_balance": tuple(float(v) for v in rng.uniform(0.85, 1.15, 3)),
            "seed": int(rng.integers(1 << 30)),
        }
    photo = render_lit_photo(
        intrinsics,
        pose,
        marker_length=marker_length,
        probe=probe,
        probe_place=place,
        probe_rotate=rot,
        light_kind=light_kind,
        light=light,
        ambient=amb * scale,
        direct=direct * scale,
        supersample=2,
        **kw,
    )
    return {
        "photo": photo,
        "probe": probe,
        "probe_place": place,
        "probe_rotate": rot,
        "kind": kind_spec,
        "north_deg": north,
    }
