"""The CPU geometry of a scene that does not depend on the camera, and the region of interest's geometry.

Part of the planner (:mod:`arshadow.plan`, which re-exports these names): :class:`SceneGeometry` holds the
lights split into hard samples with their silhouettes and shadow volumes (built on first use, then reused:
the history a video depends on, :meth:`SceneGeometry.state`), and the world points that bound the region
of interest (:func:`scene_hull_points`: the object and its shadow footprints on the ground).

(About 625 lines, just over the project's ~600: :class:`SceneGeometry` is one cache whose parts (the lights'
silhouettes and volumes, the sky-visibility map and the ground light it is made with) are invalidated
together when the lights change; split, each part would read the others' private keys.)
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import cv2
import numpy as np
import numpy.typing as npt
from scipy.spatial import ConvexHull, QhullError

from ..errors import LightError
from ..lights.area import sample_area_light
from ..shading.decide import GroundLight, ground_units
from ..shading.sky import Interreflection
from ..transforms import invert_rigid, transform_points

if TYPE_CHECKING:
    from ..camera.model import Intrinsics
    from ..frame.report import StageTimings
    from ..geometry.caster import ShadowCaster
    from ..geometry.silhouette import Silhouette
    from ..geometry.volume import ShadowVolume
    from ..lights.spec import Light
    from ..scene.options import RenderOptions
    from ..shading.sky import GroundOcclusion, GroundRaster

__all__ = [
    "SceneGeometry",
    "LightState",
    "shadow_footprint",
    "scene_hull_points",
    "pinhole_rect_for_scene",
    "pinhole_rect",
    "int_rect",
    "ROI_MAX_POINTS",
]

#: meshes with at most this many vertices bound the ROI by their vertices (~0.2 ms per light at 20k)
ROI_MAX_POINTS = 20000


# --------------------------------------------------------------------------------------------------
# region of interest: pure geometry
# --------------------------------------------------------------------------------------------------
def _box_corners(bounds: npt.ArrayLike) -> np.ndarray:
    lo, hi = np.asarray(bounds, dtype=np.float64)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def shadow_footprint(
    bounds: npt.ArrayLike, light_h: npt.ArrayLike, *, points: np.ndarray | None = None, eps: float = 1e-9
) -> np.ndarray | None:
    """Ground points (z = 0) whose convex hull contains the shadow of anything inside ``bounds``.

    Parameters
    ----------
    bounds : (2, 3) float64
        Axis-aligned box (min, max) of the occluder, world frame.
    light_h : (4,) float64
        Homogeneous light (w = 1 point, w = 0 directional towards the light).
    points : (n, 3) float64, optional
        Use these points (e.g. the mesh's vertices: their convex hull contains the mesh) instead of the
        box's corners: a tighter footprint.

    Returns
    -------
    (n, 3) float64 or None
        The corners (or points) projected from the light onto z = 0 (points below the ground are clamped
        to it), or None when the footprint is unbounded (a point light not above all of them, a
        directional light at or below the horizon).

    Examples
    --------
    >>> float(shadow_footprint([[-1, -1, 0], [1, 1, 2]], [0, 0, 4, 1])[:, :2].max())
    2.0
    """
    corners = _box_corners(bounds) if points is None else np.array(points, dtype=np.float64)
    corners[:, 2] = np.maximum(corners[:, 2], 0.0)
    lh = np.asarray(light_h, dtype=np.float64)
    if lh[3] != 0.0:
        L = lh[:3] / lh[3]
        if not np.all(corners[:, 2] < L[2] * (1.0 - 1e-6)) or L[2] <= 0.0:
            return None
        t = L[2] / (L[2] - corners[:, 2])  # parameter along L -> corner where z reaches 0
        return _ground_hull(L + (corners - L) * t[:, None])
    d = lh[:3]
    n = np.linalg.norm(d)
    if not (n > 0.0) or d[2] / n <= eps:
        return None
    return _ground_hull(corners - d * (corners[:, 2] / d[2])[:, None])


def _ground_hull(fp: np.ndarray) -> np.ndarray:
    """The vertices of the 2D convex hull of ground points ``fp (n, 3)`` (z = 0): the same convex hull, so
    the same screen bounds (a central projection's extremes over a convex set lie at its vertices), with
    a few dozen points instead of one per mesh vertex (projected every frame by the planner)."""
    if len(fp) <= 8 or not np.all(np.isfinite(fp)):
        return fp
    idx = cv2.convexHull(np.ascontiguousarray(fp[:, :2], dtype=np.float32), returnPoints=False)
    return fp[np.sort(idx.ravel())]


def scene_hull_points(
    bounds: npt.ArrayLike,
    lights_h: Iterable[npt.ArrayLike],
    ground_size: float | None = None,
    points: np.ndarray | None = None,
) -> np.ndarray | None:
    """World points ``(n, 3) float64`` whose convex hull holds the occluder and its ground shadows, or None.

    They depend on the mesh and the lights only (not on the camera), so the :class:`Compositor` computes
    them once per set of lights. None means unbounded: a footprint is unbounded and no ``ground_size``
    limits it. ``points`` (the mesh's vertices) replaces the box corners when given.
    """
    pts = [_box_corners(bounds) if points is None else np.asarray(points, dtype=np.float64)]
    half = None if ground_size is None else 0.5 * float(ground_size)
    for lh in lights_h:
        fp = shadow_footprint(bounds, lh, points=points)
        if fp is None:
            if half is None:
                return None
            fp = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], float)
        elif half is not None:
            # shadow on the plane only inside the square: clip the footprint's box to it
            lo = np.maximum(fp[:, :2].min(axis=0), -half)
            hi = np.minimum(fp[:, :2].max(axis=0), half)
            if np.any(hi < lo):
                continue  # the shadow falls entirely off the plane
            fp = np.array([[lo[0], lo[1], 0], [hi[0], lo[1], 0], [hi[0], hi[1], 0], [lo[0], hi[1], 0]], float)
        pts.append(fp)
    return np.concatenate(pts)


def pinhole_rect_for_scene(
    intrinsics: Intrinsics,
    cam_from_world: npt.ArrayLike,
    bounds: npt.ArrayLike,
    lights_h: Iterable[npt.ArrayLike],
    ground_size: float | None = None,
    znear: float = 1e-3,
    points: np.ndarray | None = None,
) -> tuple[float, float, float, float] | None:
    """Pinhole pixel rectangle ``(u0, v0, u1, v1)`` covering the occluder and its shadows, or None (all).

    None means "the whole image": a footprint is unbounded and no ``ground_size`` limits it, or a point
    of the hull is behind the camera. ``points`` (the mesh's vertices) replaces the box corners when given.
    """
    hull = scene_hull_points(bounds, lights_h, ground_size, points)
    return None if hull is None else pinhole_rect(intrinsics, cam_from_world, hull, znear)


def extreme_points(points: npt.ArrayLike) -> np.ndarray:
    """The vertices of the convex hull of ``points (n, 3) float64`` (all of them when the hull is flat or
    cannot be built). The frame's ROI is the bounding box of the projected points, and a pinhole projection
    of points in front of the camera takes its extremes at hull vertices (``u`` is a ratio of affine
    functions, positive below: quasi-linear), as does their depth: the same box from fewer points (the
    knot: 667 of 4268, 0.6 ms less per 1080p frame).

    >>> cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    >>> len(extreme_points(np.vstack([cube, [[0.5, 0.5, 0.5]]])))
    8
    """
    p = np.asarray(points, np.float64)
    if len(p) < 5:
        return p
    try:
        hull: np.ndarray = p[np.sort(ConvexHull(p).vertices)]
        return hull
    except (QhullError, ValueError):  # flat (a plane, a line) or degenerate: every point
        return p


def pinhole_rect(
    intrinsics: Intrinsics, cam_from_world: npt.ArrayLike, hull: np.ndarray, znear: float
) -> tuple[float, float, float, float] | None:
    """Pinhole bounding rectangle of world points ``hull (n, 3)``; None if one is not beyond ``znear``."""
    pc = transform_points(cam_from_world, hull)
    if not np.all(pc[:, 2] > znear):
        return None
    u = intrinsics.fx * pc[:, 0] / pc[:, 2] + intrinsics.cx
    v = intrinsics.fy * pc[:, 1] / pc[:, 2] + intrinsics.cy
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(v))):
        return None
    return (float(u.min()), float(v.min()), float(u.max()), float(v.max()))


def int_rect(rect: Sequence[float], margin: int) -> tuple[int, int, int, int]:
    """Float pinhole rect (u0, v0, u1, v1) -> integer (x0, y0, w, h) with ``margin`` pixels around it."""
    u0, v0, u1, v1 = rect
    x0, y0 = math.floor(u0) - margin, math.floor(v0) - margin
    x1, y1 = math.ceil(u1) + margin, math.ceil(v1) + margin
    return (x0, y0, x1 - x0 + 1, y1 - y0 + 1)


# --------------------------------------------------------------------------------------------------
# the per-run geometry cache (history: which silhouettes and volumes exist)
# --------------------------------------------------------------------------------------------------
@dataclass
class LightState:
    """One (sample) light of the scene and its cached CPU geometry.

    Attributes
    ----------
    light : arshadow.lights.spec.Light
        The (hard) light.
    weight : float
        Its share of the total weight.
    light_h : (4,) float64
    sil : Silhouette or None
        Built on first use.
    volumes : dict
        ``(caps, truncated) (bool, bool) -> ShadowVolume``, built on first use.
    footprint : (n, 3) float64, None or False
        Ground footprint points (clipped to ``ground_size``; empty: the shadow misses the ground square),
        None when unbounded; False until computed.
    reuse : str or None
        How the geometry was carried over from a moved light (:func:`arshadow.plan.rules.reuse_light_geometry`).
    """

    light: Light
    weight: float
    light_h: np.ndarray
    sil: Silhouette | None = None
    volumes: dict[tuple[bool, bool], ShadowVolume] = field(default_factory=dict)
    footprint: np.ndarray | None | Literal[False] = False
    reuse: str | None = None


#: colour bleeding is drawn when a channel of the object's colour differs from its mean by this share or more
BLEED_MIN = 0.05


class SceneGeometry:
    """The CPU geometry of a scene that does not depend on the camera: lights split into hard samples,
    their silhouettes and shadow volumes (built on first use, then reused), the ROI hull points.

    Parameters
    ----------
    caster : arshadow.geometry.mesh.ShadowCaster
        The occluder, world frame.
    options : arshadow.scene.RenderOptions
    lights : sequence of arshadow.lights.spec.Light, optional
        Initial lights (:meth:`set_lights`).
    """

    def __init__(
        self,
        caster: ShadowCaster,
        options: RenderOptions,
        lights: Iterable[Light] | None = None,
        raster_source: Callable[[], GroundRaster | None] | None = None,
    ) -> None:
        self.caster = caster
        self.options = options
        b = np.asarray(caster.bounds, dtype=np.float64)
        self.bounds = b
        self.corners = _box_corners(b)
        # the ROI is bounded with the mesh's own vertices (tight) up to this many, else the box corners
        self.roi_points = (
            extreme_points(np.asarray(caster.vertices, dtype=np.float64))
            if len(caster.vertices) <= ROI_MAX_POINTS
            else None
        )
        self.size = float(np.linalg.norm(b[1] - b[0]))
        self.lights: list[LightState] = []
        self.lights_in: list[Light] = []
        self.notes: list[str] = []
        self._hull: tuple[tuple[bytes, ...] | None, np.ndarray | None] = (
            None,
            None,
        )  # (lights' key, scene_hull_points) for the current lights
        #: who rasterises the ground occlusion map: a callable giving a renderer's
        #: :class:`arshadow.shading.sky.GroundRaster` (made on first use; the Session hands its renderer's),
        #: None or a None result: numpy (:func:`arshadow.shading.sky.ground_raster_cpu`)
        self.raster_source = raster_source
        # the ground's reflected light measured on the first photo (set_ground_light; None until then), the
        # same per ground point over it (None: not read), the sky-visibility map with its key
        self._ground_light: float | None = None
        self._ground_field: GroundLight | None = None
        self._sky_ground: tuple[Any, GroundOcclusion] | None = None
        if lights is not None:
            self.set_lights(lights)

    def set_lights(self, lights: Iterable[Light]) -> int:
        """Replace the lights, keeping the cached geometry of every (sample) light that stays.

        A (sample) light whose homogeneous vector ``light_h`` equals one of the current lights' keeps
        that light's silhouette and shadow volumes (only its weight share is updated); any other light is
        recomputed on first use. Lights below the horizon give no light and no shadow (a note says so).

        Returns
        -------
        int
            Number of (sample) lights whose silhouette and volumes must be recomputed.

        Raises
        ------
        LightError
            No light.
        """
        lights = list(lights)
        if not lights:
            raise LightError("no light given (use --light)")
        old = {tuple(ls.light_h.tolist()): ls for ls in self.lights}
        old_list = list(self.lights)
        reuse = self.options.plan != "general" and "reuse" not in self.options.plan_off
        total = float(sum(lt.weight for lt in lights if lt.above_horizon))
        notes: list[str] = []
        states: list[LightState] = []
        n_new = 0
        for lt in lights:
            if not lt.above_horizon:
                notes.append(f"light {lt.label or lt.kind} is below the horizon: no light, no shadow")
                continue
            samples = (
                sample_area_light(lt, int(self.options.soft_samples))
                if getattr(lt, "radius", 0.0) > 0 and self.options.soft_samples > 1
                else [lt]
            )
            for s in samples:
                h = np.asarray(s.homogeneous, float)
                prev = old.get(tuple(h.tolist()))
                if prev is None and reuse and len(states) < len(old_list) and old_list[len(states)].sil is not None:
                    # a moved light (same slot): keep what provably gives the same pixels
                    from .rules import reuse_light_geometry

                    o = old_list[len(states)]
                    tz = self.truncate_z(True)
                    sil, vols, why = reuse_light_geometry(
                        self.caster, h, o.sil, {c: v for (c, t), v in o.volumes.items() if t}, truncate_z=tz
                    )
                    if sil is not None:
                        states.append(
                            LightState(
                                s, float(s.weight) / total, h, sil, {(c, True): v for c, v in vols.items()}, reuse=why
                            )
                        )
                        continue
                if prev is None:
                    n_new += 1
                    states.append(LightState(s, float(s.weight) / total, h))
                else:
                    states.append(LightState(s, float(s.weight) / total, prev.light_h, prev.sil, prev.volumes))
        self.lights_in, self.notes, self.lights = lights, notes, states
        return n_new

    # -- history: picklable state ----------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The cached geometry, picklable: ``{"lights": [...], "geometry": [(light_h, sil, volumes)]}``.

        :meth:`restore` of it (in this or another process, same caster and options) gives the same lights
        and skips recomputing their silhouettes and volumes."""
        return {
            "lights": list(self.lights_in),
            "geometry": [(ls.light_h.copy(), ls.sil, dict(ls.volumes)) for ls in self.lights],
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Set the lights and cached geometry saved by :meth:`state`."""
        self.lights = []
        self.set_lights(state["lights"])
        cached = {tuple(np.asarray(h, float).tolist()): (sil, vols) for h, sil, vols in state["geometry"]}
        for ls in self.lights:
            hit = cached.get(tuple(ls.light_h.tolist()))
            if hit is not None:
                ls.sil, ls.volumes = hit[0], dict(hit[1])

    # -- geometry on demand ------------------------------------------------------------------------------
    def silhouette(self, ls: LightState, timings: StageTimings | None = None) -> Silhouette:
        """The light's silhouette (built once; ``timings.silhouette`` gets the build time, an :class:`arshadow.frame.report.StageTimings`)."""
        if ls.sil is None:
            from ..geometry.silhouette import silhouette

            t = time.perf_counter()
            ls.sil = silhouette(self.caster, ls.light_h, method=self.options.silhouette)
            if timings is not None:
                timings.silhouette += (time.perf_counter() - t) * 1e3
        return ls.sil

    def truncate_z(self, truncate: bool = True) -> float | None:
        """The plane volumes are truncated at (just below the ground), or None (to infinity)."""
        return -1e-3 * max(self.size, 1e-6) if truncate else None

    def volume(
        self, ls: LightState, caps: bool, timings: StageTimings | None = None, truncate: bool | None = None
    ) -> ShadowVolume:
        """The light's shadow volume with or without caps, truncated below the ground or extruded to
        infinity (default ``options.truncate``); built once per variant (``timings.volume``)."""
        truncate = bool(self.options.truncate if truncate is None else truncate)
        vol = ls.volumes.get((caps, truncate))
        if vol is None:
            from ..geometry.volume import shadow_volume

            sil = self.silhouette(ls, timings)
            t = time.perf_counter()
            vol = ls.volumes[(caps, truncate)] = shadow_volume(
                self.caster, ls.light_h, sil, caps=caps, truncate_z=self.truncate_z(truncate)
            )
            if timings is not None:
                timings.volume += (time.perf_counter() - t) * 1e3
        return vol

    def forget(self) -> None:
        """Drop every light's cached silhouette and volumes (the ``general`` plan rebuilds them per frame)."""
        for ls in self.lights:
            ls.sil, ls.volumes, ls.reuse = None, {}, None

    @property
    def sky_on(self) -> bool:
        """Sky occlusion is drawn (:func:`arshadow.shading.decide.decide_ambient_occlusion`)."""
        from ..shading.decide import decide_ambient_occlusion

        return decide_ambient_occlusion(self.options)[0]

    def sky_ground(self, timings: StageTimings | None = None) -> GroundOcclusion:
        """The occluder's :class:`arshadow.shading.sky.GroundOcclusion` (computed once per scene, in the
        ground frame; ``timings.silhouette`` gets its build time, with the other per-scene geometry). Remade
        when the lights change or when the ground's reflectance is first measured (:meth:`set_ground_light`).
        Rasterised by :attr:`raster_source`'s rasteriser (the renderer's GPU one in a Session)."""
        key = (tuple(ls.light_h.tobytes() for ls in self.lights), self._ground_light)
        g = self._sky_ground
        if g is None or g[0] != key:  # the object's interreflection depends on the light
            from ..shading.sky import ground_sky_visibility  # looked up when made (the tests count the calls)

            t = time.perf_counter()
            raster = self.raster_source() if self.raster_source is not None else None
            vis = ground_sky_visibility(self.caster, bounce=self._bounce_light(), raster=raster)
            g = self._sky_ground = (key, vis)
            if timings is not None:
                timings.silhouette += (time.perf_counter() - t) * 1e3
        occlusion: GroundOcclusion = g[1]
        return occlusion

    def set_ground_light(
        self, reflected: np.ndarray | Sequence[float], field_of: Callable[[], GroundLight] | None = None
    ) -> None:
        """Record the light the ground round the object reflects, ``reflected (3,)`` linear RGB in the
        renderer's units (:func:`arshadow.shading.decide.ground_bounce`: its albedo times its irradiance), once per
        scene (the first measurement is kept: the map is not remade every frame). It lights the object's
        lower faces, which reflect part of it back onto the ground beside them. ``field_of``: makes the same
        light per ground point as the photo shows it (:func:`arshadow.shading.decide.ground_light`; called
        once, with the first measurement; kept relative to ``reflected``): each face then sees the ground it
        faces (a white paper beside the object), ``reflected`` where the photo does not show it."""
        if self._ground_light is None:
            self._ground_light = round(float(np.mean(reflected)), 3)
            f = field_of() if field_of is not None and self._ground_light > 0 else None
            # relative to the ring's value: the map converts that one to its units (ground_units)
            self._ground_field = None if f is None else replace(f, values=f.values / self._ground_light)

    @property
    def ground_field(self) -> GroundLight | None:
        """The photo's ground light round the object over the ring's value (:meth:`set_ground_light`; None until
        measured, or where the photo showed none of it)."""
        field: GroundLight | None = self._ground_field
        return field

    def _bounce_light(self) -> Interreflection | None:
        """The object's :class:`arshadow.shading.sky.Interreflection` onto the ground: the strongest light's
        direction from the object, the mean sky share, the object's mean reflectance (:meth:`object_reflectance`),
        the ground's reflected light (its albedo times its irradiance, a share of the open ground's:
        :meth:`set_ground_light`, 0 until measured) and as the photo shows it per ground point, and for a
        point light ``(its position, the ground point where the sky share holds)`` (``ratio_at`` with a
        measured light, else under the object's centre); None without a light or a sky share."""
        from ..shading.decide import sky_share

        opts = self.options
        r = float(np.mean(sky_share(opts.opacity, opts.shadow_color)))
        if not self.lights or r <= 0.0 or not opts.draw_occluder:
            return None
        h = max(self.lights, key=lambda ls: ls.weight).light_h
        centre = 0.5 * (self.bounds[0] + self.bounds[1])
        light = h[:3] if h[3] == 0 else h[:3] / h[3] - centre
        if light[2] <= 0:
            return None
        at = opts.ratio_at if opts.ambient_measured and opts.ratio_at is not None else centre[:2]
        ref = np.array([float(at[0]), float(at[1]), 0.0])  # where r holds: the map's unit of light
        ground = float(self._ground_light or 0.0) * ground_units(h, r, ref, opts.ambient)
        lamp = (h[:3] / h[3], ref) if h[3] != 0 else None  # a point light: each face at its own distance
        albedo = float(np.mean(self.object_reflectance()))
        return Interreflection(light, r, albedo, ground, lamp, self._ground_field)

    def object_reflectance(self) -> np.ndarray:
        """``(3,) float64`` the object's mean reflectance, linear RGB (absolute: the paper's white is
        ``paper_albedo``): :meth:`object_albedo` times the paper's reflectance, the share of the light it
        receives that it sends on (onto the ground, onto its own parts)."""
        out: np.ndarray = float(self.options.paper_albedo) * self.object_albedo()
        return out

    def object_albedo(self) -> np.ndarray:
        """``(3,) float64`` the object's linear colour relative to the paper: ``occluder_color`` over the exposure
        gain (the option holds the colour times the gain), else the mesh's own mean reflectance
        (:attr:`arshadow.geometry.caster.ShadowCaster.mean_albedo`) over the paper's, ``paper_albedo`` (as
        :func:`arshadow.frame.execute.frame_shading` renders it), else the renderer's default grey; at most
        ``1 / paper_albedo`` (a reflectance of 1)."""
        from ..compose.composite import srgb_to_linear

        opts = self.options
        paper = float(opts.paper_albedo)
        if opts.occluder_color is not None:
            col = srgb_to_linear(np.asarray(opts.occluder_color, np.float64))
            if opts.exposure_gain is not None:
                col = col / np.maximum(np.asarray(opts.exposure_gain, np.float64), 1e-6)
        else:
            own = self.caster.mean_albedo
            col = own / paper if own is not None else srgb_to_linear(np.array([0.8, 0.8, 0.8]))
        out: np.ndarray = np.clip(np.asarray(col, np.float64), 0.0, 1.0 / paper)
        return out

    @functools.cached_property
    def object_bleed(self) -> tuple[float, float, float] | None:
        """Colour bleeding: ``(3,)`` the object's linear RGB colour (:meth:`object_albedo`: the option's
        colour, or the mesh's own mean colour or texture) over its mean, minus 1; None for a grey object
        (every channel within :data:`BLEED_MIN` of the mean: the sky channel stays one plane)."""
        if not self.options.draw_occluder:
            return None
        col = self.object_albedo()
        m = float(col.mean())
        if m <= 0.0 or float(np.max(np.abs(col / m - 1.0))) < BLEED_MIN:
            return None
        a, b, c = (float(v) for v in col / m - 1.0)
        return (a, b, c)

    def footprint_rect(
        self, ls: LightState, intr: Intrinsics, cam_from_world: npt.ArrayLike, znear: float
    ) -> tuple[float, float, float, float] | None:
        """Pinhole screen box of one light's ground footprint (clipped to ``ground_size``), or None
        (unbounded, or a point behind the camera); an empty box far off screen when the shadow misses the
        ground square."""
        if ls.footprint is False:
            fp = shadow_footprint(self.bounds, ls.light_h, points=self.roi_points)
            gs = self.options.ground_size
            if gs is not None:
                half = 0.5 * float(gs)
                if fp is None:
                    fp = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], float)
                else:
                    lo = np.maximum(fp[:, :2].min(axis=0), -half)
                    hi = np.minimum(fp[:, :2].max(axis=0), half)
                    fp = (
                        np.zeros((0, 3))
                        if np.any(hi < lo)
                        else np.array(
                            [[lo[0], lo[1], 0], [hi[0], lo[1], 0], [hi[0], hi[1], 0], [lo[0], hi[1], 0]], float
                        )
                    )
            ls.footprint = fp
        fp = ls.footprint
        if fp is None:
            return None
        if len(fp) == 0:
            return (-1e9, -1e9, -1e9, -1e9)
        return pinhole_rect(intr, cam_from_world, fp, znear)

    def hull(self) -> np.ndarray | None:
        """:func:`scene_hull_points` of the current lights (recomputed only when the lights change)."""
        key = tuple(ls.light_h.tobytes() for ls in self.lights)
        if self._hull[0] != key:
            hull = scene_hull_points(
                self.bounds, [ls.light_h for ls in self.lights], self.options.ground_size, points=self.roi_points
            )
            if hull is not None and self.sky_on:
                # sky occlusion darkens the ground round the object: the outline of where its map is not 1
                # joins the region (not the map's square: its corners are open ground, 1.5 x the pixels)
                hull = np.vstack([hull, self.sky_ground().outline()])
            self._hull = (key, hull)
        return self._hull[1]

    def znear_for(self, cam_from_world: npt.ArrayLike) -> float:
        """A near plane that clips nothing visible: a fraction of the distance to the object and ground.

        No upper bound: the depth resolution of a 24-bit buffer with an infinite far plane is about
        ``z**2 / znear * 6e-8``, so a fixed 5 cm near plane lost the contact of an object 1 km away (metres
        of depth error); a quarter of the distance keeps it at ~1e-7 of the distance."""
        eye = invert_rigid(cam_from_world)[:3, 3]
        depth = transform_points(cam_from_world, self.corners)[:, 2]
        d = float(depth.min()) if np.all(depth > 0) else self.size
        h = abs(float(eye[2]))
        return float(max(0.25 * min(d, h if h > 0 else d), 1e-4))

    def modes_for(
        self,
        cam_from_world: npt.ArrayLike,
        znear: float,
        intr: Intrinsics | None = None,
        canvas: Sequence[float] | None = None,
    ) -> list[str]:
        """Per light: ``"zpass"`` if the camera is provably outside its volume, else ``"zfail"``
        (``"planar"`` for every light with ``shadow_method="planar"``).

        The test needs the radius of the near-plane rectangle of the canvas actually rendered
        (``canvas = (u0, v0, w, h)`` pinhole pixels of ``intr``), not ``znear`` alone; without ``intr`` the
        radius of a 90-degree-per-axis frustum is used (conservative for any narrower camera).
        """
        if self.options.shadow_method in ("planar", "shadowmap"):
            return [self.options.shadow_method] * len(self.lights)
        from ..geometry.volume import camera_may_be_in_shadow, near_plane_radius

        if intr is not None and canvas is not None and canvas[2] > 0 and canvas[3] > 0:
            u0, v0, w, h = canvas
            near = near_plane_radius(znear, int(w), int(h), intr.fx, intr.fy, intr.cx - u0, intr.cy - v0)
        else:
            near = znear * np.sqrt(3.0)
        eye = invert_rigid(cam_from_world)[:3, 3]
        return [
            "zfail" if camera_may_be_in_shadow(self.caster, ls.light_h, eye, near) else "zpass" for ls in self.lights
        ]
