"""``estimate_light``: photos (or video frames) of the marker and a probe -> a :class:`LightEstimate`.

(About 560 lines: the one public entry and its private steps -- evidence per photo, the fit, the trust
checks -- in the order they run; the shadow ratio lives in :mod:`.ratio`, the checks' own measurements in
:mod:`.outline`, :mod:`.shading` and :mod:`.shadow`.)
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import cast

import cv2
import numpy as np

from ..camera.model import Intrinsics
from ..errors import EstimateError, ImageError, MarkerNotFoundError, UsageError
from ..geometry.caster import ShadowCaster
from ..geometry.mesh import load_occluder
from ..io import read_image, to_bgr8
from ..lights.spec import parse_light
from ..shading.decide import PAPER_ALBEDO
from ..tracking.dictionary import DEFAULT_DICTIONARY, marker_object_points
from ..tracking.tracker import MarkerTracker
from .checks import check_outline, check_warnings, light_checks, point_warnings
from .exposure import Exposure, ExposureError, measure_exposure
from .light import FitResult, MakeFine, fit_directional, fit_point, fit_sun
from .optics import measure_blur
from .outline import outline_agreement
from .penumbra import fit_angular_radius
from .ratio import ProbeGround, floor_albedo, probe_ground, shadow_ratio
from .record import LightEstimate
from .shading import ProbeViews, probe_albedo
from .shadow import LUMA, Evidence, build_evidence, sample_blur_px, shadow_coverage

__all__ = ["MAX_FRAMES", "VIDEO_EXTENSIONS", "estimate_light"]

#: smallest fitted angular radius (degrees) written into the light spec (below: a hard light)
MIN_RADIUS_DEG = 0.25

VIDEO_EXTENSIONS = (".mp4", ".mov", ".avi", ".mkv", ".m4v", ".webm")
#: frames of a video used at most (evenly spaced)
MAX_FRAMES = 30
#: lowest light elevation searched, degrees (sets the ground grid's extent)
MIN_ELEVATION = 12.0
CONVEX_PRIMITIVES = ("box:", "cylinder:", "sphere:")
#: frames whose probe faces are compared with the fitted light's shading (convex probes)
SHADING_VIEWS = 3
#: the ``fit`` keys of the probe's and the floor's reflectances read from the photo (:func:`_albedos`)
ALBEDO_KEYS = ("probe_albedo", "floor_albedo")
#: sun: the shadow's own elevation (a free directional fit) this far from the sun's (degrees) is a refusal
#: (when also beyond 3 sigma of the free fit): the time, its zone or the place is wrong
SUN_REFUSE_DEG = 3.0
#: ... and this far, a warning (the sun's direction is then at least this far from the shadow's)
SUN_FLAG_DEG = 1.5
#: lights' homogeneous vectors -> one frame's fine evidence grid covering their shadows (:func:`_grids`)
FineGrid = Callable[[list], Evidence]


def _frames(item: str | os.PathLike[str] | np.ndarray, max_frames: int) -> Iterator[tuple[str, np.ndarray]]:
    """Yield (name, BGR uint8 image) for a photo path, an array or a video path."""
    if isinstance(item, np.ndarray):
        yield "array", to_bgr8(item)
        return
    p = Path(item)
    if p.suffix.lower() not in VIDEO_EXTENSIONS:
        yield str(p), read_image(p)
        return
    cap = cv2.VideoCapture(str(p))
    if not cap.isOpened():
        raise ImageError(f"{p}: cannot open the video")
    try:
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or max_frames
        want = set(np.unique(np.linspace(0, max(n - 1, 0), min(n, max_frames)).round().astype(int)).tolist())
        i = 0
        while want:
            ok, img = cap.read()
            if not ok:
                break
            if i in want:
                want.discard(i)
                yield f"{p}#{i}", img
            i += 1
    finally:
        cap.release()


def _probe_in_view(intr: Intrinsics, pose: np.ndarray, verts: np.ndarray, name: str) -> None:
    cam = verts @ pose[:3, :3].T + pose[:3, 3]
    uv = intr.project(verts, pose)
    inside = (
        (cam[:, 2] > 0)
        & np.all(np.isfinite(uv), axis=1)
        & (uv[:, 0] >= 0)
        & (uv[:, 0] <= intr.width - 1)
        & (uv[:, 1] >= 0)
        & (uv[:, 1] <= intr.height - 1)
    )
    if inside.mean() < 0.5:
        raise EstimateError(
            f"{name}: the probe is not in view ({100 * inside.mean():.0f} % of its corners in the "
            "image): check --probe-place, or frame the probe and its shadow"
        )


def _grids(
    img: np.ndarray,
    intr: Intrinsics,
    pose: np.ndarray,
    verts: np.ndarray,
    faces: np.ndarray,
    L: float,
    paper: Sequence[float],
    convex: bool,
    blur_px: float | None = None,
) -> tuple[Evidence, FineGrid, float]:
    """The coarse evidence (the whole reach of the shadow), a builder of fine evidence and the size of a
    pixel on the ground at the probe (metres). ``blur_px``: a sharp ground edge's blur as the grids'
    samples see it (:func:`.shadow.sample_blur_px`), the modelled shadow's edges."""
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    centre = 0.5 * (lo[:2] + hi[:2])
    radius = 0.5 * float(np.linalg.norm(hi[:2] - lo[:2]))
    reach = min(0.8, radius + hi[2] / math.tan(math.radians(MIN_ELEVATION)))
    depth = float((pose[:3, :3] @ np.r_[centre, 0.5 * hi[2]] + pose[:3, 3])[2])
    px = depth / float(intr.K[0, 0])  # metres per pixel at the probe
    coarse_step = float(np.clip(max(6 * px, reach / 60.0), 0.003, 0.02))
    sigma = 0.6 * float(min(hi[0] - lo[0], hi[1] - lo[1]))
    coarse = build_evidence(
        img,
        intr,
        pose,
        verts,
        faces,
        marker_length=L,
        paper_rgb=paper,
        center=centre,
        half=reach,
        step=coarse_step,
        convex=convex,
        sigma=sigma,
        supersample=2,
        blur_px=blur_px,
    )
    fine_step = float(np.clip(1.5 * px, 0.0006, 0.006))

    def fine(lights_h: list) -> Evidence:
        pts = [verts[:, :2]]
        for h in lights_h:
            S = shadow_coverage(coarse, h)
            if S is not None:
                rr, cc = np.nonzero(S > 0)
                pts.append(np.column_stack([coarse.x0 + cc * coarse.step, coarse.y0 + rr * coarse.step]))
        allp = np.concatenate(pts)
        c = 0.5 * (allp.min(axis=0) + allp.max(axis=0))
        half = 0.5 * float((allp.max(axis=0) - allp.min(axis=0)).max()) + 0.03 + 2 * sigma
        step = max(fine_step, half / 110.0)  # at most ~220 x 220 cells
        return build_evidence(
            img,
            intr,
            pose,
            verts,
            faces,
            marker_length=L,
            paper_rgb=paper,
            center=c,
            half=half,
            step=step,
            convex=convex,
            sigma=sigma,
            blur_px=blur_px,
        )

    return coarse, fine, px


def _edge_blur(img: np.ndarray, intr: Intrinsics, cam_from_world: np.ndarray, L: float, cells: int) -> float | None:
    """A sharp ground edge's blur as the evidence's samples see it (pixels): the photo's point spread
    measured on the marker's outer edges (:func:`.optics.measure_blur`) with the sampling's own; None when
    no edge gave a measurement."""
    corners = intr.project(marker_object_points(L), cam_from_world)
    try:
        return sample_blur_px(measure_blur(img, corners, cells=cells).sigma_px)
    except EstimateError:
        return None


def _sun_enu(spec: str) -> np.ndarray:
    light = parse_light(spec)  # NORTH 0: world = east-north-up
    if light.sun is None:
        raise UsageError(f"--kind {spec!r}: expected sun:LAT,LON,TIME")
    return np.asarray(light.vector, np.float64)


def estimate_light(
    inputs: str | os.PathLike[str] | np.ndarray | Sequence[str | os.PathLike[str] | np.ndarray],
    *,
    calib: str | os.PathLike[str] | Intrinsics,
    marker_length: float,
    probe: str,
    probe_place: Sequence[float] = (0.0, 0.0, 0.0),
    probe_rotate: Sequence[float] = (0.0, 0.0, 0.0),
    probe_scale: float = 1.0,
    dictionary: str | None = None,
    marker_id: int | None = None,
    kind: str = "directional",
    max_frames: int = MAX_FRAMES,
    sky_occlusion: bool = True,
) -> LightEstimate:
    """Measure the light from photos (or a video) of the marker and a probe's real shadow.

    Parameters
    ----------
    inputs : path, (H, W, 3) uint8 array, or a list of them
        Photos or videos (their frames evenly spaced, at most ``max_frames`` each). All frames see the
        same light fixed in the world (the marker's frame).
    calib : path or Intrinsics
        The camera's calibration.
    marker_length : float
        The marker's side, metres.
    probe : str
        The reference object: a mesh file or ``box:WX,WY,HZ`` / ``cylinder:R,H`` / ``sphere:R``, placed like
        ``--model`` with ``probe_place`` (metres), ``probe_rotate`` (degrees) and ``probe_scale``.
    dictionary, marker_id
        The marker (default dictionary; the lowest id found).
    kind : str
        ``"directional"`` (2 DOF), ``"point"`` (3 DOF) or ``"sun:LAT,LON,TIME"`` (the world's bearing,
        1 DOF).
    sky_occlusion : bool
        The shadow ratio allows for the sky the probe hides from the ground round it (true of every real
        photo: :func:`.ratio.shadow_ratio`); False for images rendered without it (``arshadow.synth.lit``).

    Returns
    -------
    LightEstimate

    Raises
    ------
    MarkerNotFoundError
        No marker in a photo (named).
    EstimateError
        The probe is not in view; no shadow found (flat light, hidden, off-image); an ambiguous fit.
    UsageError
        Bad options (kind, probe, calibration).
    """
    t0 = time.perf_counter()
    # a str is a Sequence too: the list / tuple test is what tells one input from several
    items = cast(
        Sequence[str | os.PathLike[str] | np.ndarray], inputs if isinstance(inputs, (list, tuple)) else [inputs]
    )
    if not items:
        raise UsageError("give at least one photo or video")
    kind_name = "sun" if str(kind).startswith("sun:") else str(kind)
    if kind_name not in ("directional", "point", "sun"):
        raise UsageError(f"--kind {kind!r}: choose directional, point or sun:LAT,LON,TIME")
    enu = _sun_enu(kind) if kind_name == "sun" else None
    base = calib if isinstance(calib, Intrinsics) else Intrinsics.from_file(os.fspath(calib))
    caster = load_occluder(probe, scale=probe_scale, rotate=probe_rotate, place=probe_place)
    verts, faces = np.asarray(caster.vertices, np.float64), np.asarray(caster.faces)
    if verts[:, 2].min() < -1e-6:
        raise UsageError(
            f"--probe {probe}: the probe must stand on the ground (z >= 0), it reaches z = {verts[:, 2].min():.3f}"
        )
    convex = str(probe).lower().startswith(CONVEX_PRIMITIVES)
    dictionary = dictionary or DEFAULT_DICTIONARY
    tracker = MarkerTracker(base, dictionary=dictionary, marker_length=marker_length, marker_id=marker_id)
    coarse, fines, pxs, exposures, notes, outline = [], [], [], [], [], []
    views: list[tuple[np.ndarray, Intrinsics, np.ndarray]] = []  # (image, camera, cam_from_world), shading
    for item in items:
        for name, img in _frames(item, max_frames):
            intr, _ = base.for_image(img.shape[1], img.shape[0])
            try:
                pose = tracker.estimate(img)
            except MarkerNotFoundError as exc:
                raise MarkerNotFoundError(f"{name}: {exc}") from None
            T = pose.cam_from_world
            _probe_in_view(intr, T, verts, name)
            outline.append(outline_agreement(img, intr, T, verts, faces))
            if convex and len(views) < SHADING_VIEWS:
                views.append((img, intr, T))
            try:
                exp = measure_exposure(img, intr, T, marker_length, dictionary, pose.marker_ids[0])
            except ExposureError as exc:  # a shadow over the marker: its brightest cell, flagged
                exp = measure_exposure(img, intr, T, marker_length, dictionary, pose.marker_ids[0], min_cells=1)
                notes.append(f"{name}: {exc}; the exposure is from its brightest white cell")
            blur = _edge_blur(img, intr, T, marker_length, tracker.dictionary.markerSize + 2)
            c, f, px = _grids(img, intr, T, verts, faces, marker_length, exp.paper_rgb, convex, blur)
            coarse.append(c)
            pxs.append(px)
            fines.append(f)
            exposures.append(exp)
    check_outline(outline)
    return _fit(
        kind_name,
        kind,
        enu,
        coarse,
        fines,
        pxs,
        exposures,
        ProbeViews(verts, faces, views, sky_occlusion),
        t0,
        notes,
        outline,
    )


def _sun_elevation_check(coarse: list[Evidence], make_fine: MakeFine, enu: np.ndarray, kind: str) -> tuple:
    """The shadow's own elevation (a directional light fitted with a free direction) against the sun's at the
    given time and place. Raises EstimateError when they clearly disagree (more than
    :data:`SUN_REFUSE_DEG` and 3 sigma of the free fit); returns ``(shadow elevation, sun elevation, warning
    or None)`` (a warning beyond :data:`SUN_FLAG_DEG`); ``(None, sun elevation, None)`` when the free fit
    fails (ambiguous)."""
    sun_el = math.degrees(math.asin(float(enu[2] / np.linalg.norm(enu))))
    try:
        free = fit_directional(coarse, make_fine)
    except EstimateError:
        return None, sun_el, None
    el = math.degrees(math.asin(float(np.clip(free.light_h[2], -1.0, 1.0))))
    diff = abs(el - sun_el)
    body = kind.split(":", 1)[1].split("@")[0]
    lat, lon, when = body.split(",")[:3]
    text = (
        f"the shadow says {el:.0f} deg elevation, the sun at {when} at {lat},{lon} is at {sun_el:.0f} deg: "
        "check the time and its time zone (or the probe's height)"
    )
    if diff > SUN_REFUSE_DEG and diff > 3.0 * free.uncertainty_deg:
        raise EstimateError(text)
    return el, sun_el, (f"low confidence: {text}" if diff > SUN_FLAG_DEG else None)


def _pooled_exposure(exposures: Sequence[Exposure]) -> Exposure:
    """The frames' exposures as one: the paper's and the ink's medians."""
    paper = np.median(np.array([e.paper_rgb for e in exposures]), axis=0)
    ink = np.median(np.array([e.ink_rgb for e in exposures]), axis=0)
    return Exposure(
        tuple(map(float, paper)),
        tuple(map(float, ink)),
        int(np.median([e.white_cells for e in exposures])),
        any(e.saturated for e in exposures),
    )


def _albedos(
    res: FitResult, r: float, probe: ProbeViews, ground: ProbeGround | None, exp: Exposure
) -> tuple[float, float]:
    """``(probe, floor)``: the probe's reflectance off its top face (:func:`.shading.probe_albedo`) and the
    floor's round it (:func:`.ratio.floor_albedo`), both against the paper, under the fitted light and the
    sky's share ``r`` (luminance); NaN where not measured (no view of the top face, a clipped paper, sky
    occlusion off: ``ground`` None)."""
    if ground is None or exp.saturated:
        return math.nan, math.nan
    paper = float(np.asarray(exp.paper_rgb) @ LUMA)
    r = float(np.clip(r, 0.0, 0.95))
    top = probe_albedo(probe, res.light_h, r, paper)
    return top, floor_albedo(res.fine, res.light_h, r, ground, paper)


def _read_ratio(
    res: FitResult, pxs: Sequence[float], probe: ProbeViews, exp: Exposure
) -> tuple[tuple[float, ...], tuple[float, float] | None, ProbeGround | None, tuple[float, float]]:
    """The shadow ratio of the fitted light (:func:`.ratio.shadow_ratio`), allowing for what the probe does to
    the ground beside its shadow: ``(ratio, where it was read, the probe's ProbeGround, (probe, floor)
    reflectances)``. Read first with the sky the probe hides, then, with both reflectances read and possible
    (0..1], again with the light it reflects (:func:`.ratio.probe_ground`); neither without
    ``probe.ground_effects`` (``arshadow.synth.lit``'s photos)."""
    caster = ShadowCaster(probe.verts, probe.faces) if probe.ground_effects else None
    ground = probe_ground(caster, res.light_h)
    ratio, ratio_at = shadow_ratio(res.fine, res.light_h, pxs, ground)
    albedos = _albedos(res, float(np.asarray(ratio) @ LUMA), probe, ground, exp)
    if caster is not None and all(math.isfinite(a) and 0.0 < a <= 1.0 for a in albedos):
        ground = probe_ground(caster, res.light_h, albedos, ratio_at, sky=ground.sky if ground else None)
        ratio, ratio_at = shadow_ratio(res.fine, res.light_h, pxs, ground)
    return ratio, ratio_at, ground, albedos


def _fit(
    kind_name: str,
    kind: str,
    enu: np.ndarray | None,
    coarse: list[Evidence],
    fines: list[FineGrid],
    pxs: list[float],
    exposures: list[Exposure],
    probe: ProbeViews,
    t0: float,
    notes: list[str],
    outline: list[tuple[float, int]],
) -> LightEstimate:
    def make_fine(lights_h: list) -> list[Evidence]:
        return [f(lights_h) for f in fines]

    sun_check = None

    anchor = np.r_[probe.foot[:2], probe.verts[:, 2].max()]  # the probe's top
    if kind_name == "directional":
        res = fit_directional(coarse, make_fine)
    elif kind_name == "sun":
        assert enu is not None  # kind_name 'sun': _sun_enu(kind)
        sun_check = _sun_elevation_check(coarse, make_fine, enu, kind)  # first: a wrong time named as such
        res = fit_sun(coarse, make_fine, enu)
    else:
        res = fit_point(coarse, make_fine, anchor)
    exp = _pooled_exposure(exposures)
    ratio, ratio_at, ground, albedos = _read_ratio(res, pxs, probe, exp)
    checks = light_checks(res, (ratio, ratio_at), pxs, outline, probe, ground)
    warnings = list(notes)
    if exp.saturated:
        warnings.append("the marker's paper is over-exposed (clipped): the exposure match is a lower bound")
    if sun_check is not None and sun_check[2] is not None:
        warnings.append(sun_check[2])
    warnings += check_warnings(checks)
    if math.isfinite(albedos[0]) and albedos[0] > 1.0:
        warnings.append(
            f"the probe's top face reads brighter than any matte surface (reflectance {albedos[0]:.2f}, the "
            f"paper's taken as {PAPER_ALBEDO:g}): it is glossy, or lit by something the paper is not; the light it "
            "reflects onto the floor is left out of the shadow ratio"
        )
    if res.uncertainty_deg > 3.0:
        warnings.append(f"low confidence: uncertainty {res.uncertainty_deg:.1f} degrees")
    if res.position_sigma is not None:
        warnings += point_warnings(res, float(np.linalg.norm(res.light_h[:3] - anchor)))
    if res.runner_up is not None and res.runner_up > 0.6:
        warnings.append(f"a second light explains {100 * res.runner_up:.0f} % as much: check the result")
    fit = {
        **{k: (None if not math.isfinite(v) else round(v, 3)) for k, v in checks.items()},
        **{k: (None if not math.isfinite(v) else round(v, 3)) for k, v in zip(ALBEDO_KEYS, albedos, strict=True)},
        "explained": round(res.explained, 4),
        **(
            {}
            if sun_check is None
            else {
                "shadow_elevation_deg": None if sun_check[0] is None else round(sun_check[0], 2),
                "sun_elevation_deg": round(sun_check[1], 2),
            }
        ),
        "visible": round(res.visible, 3),
        "runner_up": None if res.runner_up is None else round(res.runner_up, 3),
        "evaluations": int(res.evaluations),
        "darkening": round(1 - float(np.exp(np.median(res.deltas))), 4),
        "time_ms": round((time.perf_counter() - t0) * 1e3, 1),
    }
    h = res.light_h
    if kind_name == "directional":
        d = tuple(float(v) for v in h[:3])
        radius, _ = fit_angular_radius(res.fine, np.asarray(d))  # the penumbra: the light's angular size
        spec = "directional:{:.6f},{:.6f},{:.6f}".format(*d) + (
            f",radius={radius:.3f}" if radius >= MIN_RADIUS_DEG else ""
        )
        return LightEstimate(
            "directional",
            spec,
            direction=d,
            shadow_ratio=ratio,
            uncertainty_deg=res.uncertainty_deg,
            exposure=exp,
            frames=len(coarse),
            fit=fit,
            warnings=warnings,
            angular_diameter_deg=2.0 * radius,
        )
    if kind_name == "sun":
        north = float(res.params[0]) % 360.0
        body = kind.split(":", 1)[1].split("@")[0]
        lat, lon, when = body.split(",")[:3]
        return LightEstimate(
            "sun",
            f"sun:{lat},{lon},{when},{north:.4f}",
            direction=tuple(float(v) for v in h[:3]),
            north_deg=north,
            shadow_ratio=ratio,
            uncertainty_deg=res.uncertainty_deg,
            exposure=exp,
            frames=len(coarse),
            fit=fit,
            warnings=warnings,
        )
    p = tuple(float(v) for v in h[:3])
    return LightEstimate(
        "point",
        "point:{:.6f},{:.6f},{:.6f}".format(*p),
        position=p,
        shadow_ratio=ratio,
        ratio_at=ratio_at,
        uncertainty_deg=res.uncertainty_deg,
        position_uncertainty=res.position_sigma,
        distance_interval=None if res.distance_interval is None else tuple(float(v) for v in res.distance_interval),
        exposure=exp,
        frames=len(coarse),
        fit=fit,
        warnings=warnings,
    )
