"""The per-photo pipeline: detect + pose -> silhouette + volume -> render -> lens warp -> composite.

A :class:`Compositor` is built once per run (calibration, tracker options, occluder, lights, options, and
an OpenGL context handed in) and then called once per photo::

    comp = Compositor(ctx, intrinsics, caster, lights, tracker=dict(marker_length=0.05))
    out_bgr, mask_u8, item = comp.process(image_bgr)

What is computed once, not per photo
    The occluder and the lights are both fixed in the world (marker) frame, so each light's silhouette
    and shadow volume do not depend on the camera pose: they are built on first use and reused (with and
    without caps, as the z-pass / z-fail choice needs); likewise the world points bounding the region of
    interest (the object and its shadow footprints, :func:`scene_hull_points`). Per photo remain the
    pose, the z-pass / z-fail decision (:func:`arshadow.volume.camera_may_be_in_shadow`), the region of
    interest's projection, the render, the lens warp and the composite.

Region of interest (ROI)
    Only the part of the photo the occluder and its ground shadow can cover is rendered: the occluder's
    bounding box and its shadow footprint (the box's corners projected from each light onto z = 0,
    clipped to ``ground_size``) are projected into the photo. A light at or below the top of the object
    (or a directional light at the horizon) makes the footprint unbounded: then the whole photo (or the
    ``ground_size`` square) is used. The occluder's image and its shadow's image lie inside the convex
    hull of those projected points, so nothing is lost.

Lens distortion
    The renderer draws a pinhole image; with a distorted calibration the ROI is chosen in the distorted
    photo and the pinhole canvas that it samples is rendered, then warped by :class:`arshadow.lens.LensWarp`.

Mask (CONVENTIONS.md)
    ``(H, W) uint8``: ``round(255 * blocked weight / total weight)`` at pixels that see the ground and are
    not covered by the object, 0 elsewhere.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ._check import check_shape
from .composite import Workspace, clip_roi, composite
from .errors import ImageError, LightError, MarkerNotFoundError, UsageError
from .report import ReportItem
from .transforms import CV_TO_GL, invert_rigid, transform_points

log = logging.getLogger(__name__)

__all__ = ["RenderOptions", "Compositor", "shadow_footprint", "scene_hull_points", "pinhole_rect_for_scene"]

#: meshes with at most this many vertices bound the ROI by their vertices (~0.2 ms per light at 20k)
ROI_MAX_POINTS = 20000

STAGES = ("detect", "pose", "silhouette", "volume", "render", "readback", "warp", "composite", "total")


#: MSAA sample counts :class:`RenderOptions` accepts (what ``--aa`` documents)
AA_CHOICES = (0, 2, 4)


@dataclass
class RenderOptions:
    """What to render and how to composite it (the ``arshadow render`` options).

    Attributes
    ----------
    opacity : float
        How dark a fully blocked ground pixel gets (``1 - opacity`` of its light is kept).
    shadow_color : (3,) float
        Linear RGB tint of a full shadow (black: plain darkening).
    shadow_method : str
        ``"volume"`` (stencil shadow volumes, exact) or ``"planar"`` (projection shadows, paper 002/004).
    silhouette : str
        Silhouette detector name (``adjacency``, ``triangular``, ``vnv``, ``hsd``, ``delta_plus``).
    soft_samples : int
        Samples per area light (lights with a radius); 1 = hard shadows from the light's centre.
    aa : int
        MSAA samples of the renderer (0 = none).
    ground_size : float or None
        Side of the square proxy ground plane centred on the origin (None: unlimited).
    draw_occluder : bool
        Draw the shaded object over the shadow.
    truncate : bool
        Extrude volumes only to just below the ground instead of to infinity (paper 002).
    roi : bool
        Render only the region the object and its shadow can cover (False: always the whole photo).
    occluder_color : (3,) float, optional
        Override of the occluder's colour handed to the renderer.
    fast_detect : bool
        Try the one-window ArUco detector first (:func:`fast_detector_params`), the full search only if
        it finds nothing.
    """

    opacity: float = 0.7
    shadow_color: tuple = (0.0, 0.0, 0.0)
    shadow_method: str = "volume"
    silhouette: str = "adjacency"
    soft_samples: int = 1
    aa: int = 0
    ground_size: float | None = None
    draw_occluder: bool = True
    truncate: bool = True
    roi: bool = True
    occluder_color: tuple | None = None
    fast_detect: bool = True

    def check(self) -> RenderOptions:
        if not (0.0 <= float(self.opacity) <= 1.0):
            raise UsageError(f"--opacity {self.opacity}: must be in [0, 1]")
        if self.shadow_method not in ("volume", "planar"):
            raise UsageError(f"--shadow-method {self.shadow_method!r}: choose volume or planar")
        if int(self.soft_samples) < 1:
            raise UsageError(f"--soft-samples {self.soft_samples}: must be >= 1")
        if self.aa not in AA_CHOICES:
            raise UsageError(f"--aa {self.aa}: choose {', '.join(map(str, AA_CHOICES))} (multisample anti-aliasing "
                             "samples; 0 = off)")
        if self.ground_size is not None and not (math.isfinite(self.ground_size) and self.ground_size > 0):
            raise UsageError(f"--ground-size {self.ground_size}: must be a positive number of metres")
        return self


# --------------------------------------------------------------------------------------------------
# region of interest: pure geometry
# --------------------------------------------------------------------------------------------------
def _box_corners(bounds) -> np.ndarray:
    lo, hi = np.asarray(bounds, dtype=np.float64)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def shadow_footprint(bounds, light_h, *, points=None, eps: float = 1e-9) -> np.ndarray | None:
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
        return L + (corners - L) * t[:, None]
    d = lh[:3]
    n = np.linalg.norm(d)
    if not (n > 0.0) or d[2] / n <= eps:
        return None
    return corners - d * (corners[:, 2] / d[2])[:, None]


def scene_hull_points(bounds, lights_h, ground_size=None, points=None) -> np.ndarray | None:
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


def pinhole_rect_for_scene(intrinsics, cam_from_world, bounds, lights_h, ground_size=None, znear=1e-3,
                           points=None):
    """Pinhole pixel rectangle ``(u0, v0, u1, v1)`` covering the occluder and its shadows, or None (all).

    None means "the whole image": a footprint is unbounded and no ``ground_size`` limits it, or a point
    of the hull is behind the camera. ``points`` (the mesh's vertices) replaces the box corners when given.
    """
    hull = scene_hull_points(bounds, lights_h, ground_size, points)
    return None if hull is None else _pinhole_rect(intrinsics, cam_from_world, hull, znear)


def _pinhole_rect(intrinsics, cam_from_world, hull, znear):
    """Pinhole bounding rectangle of world points ``hull (n, 3)``; None if one is not beyond ``znear``."""
    pc = transform_points(cam_from_world, hull)
    if not np.all(pc[:, 2] > znear):
        return None
    u = intrinsics.fx * pc[:, 0] / pc[:, 2] + intrinsics.cx
    v = intrinsics.fy * pc[:, 1] / pc[:, 2] + intrinsics.cy
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(v))):
        return None
    return (float(u.min()), float(v.min()), float(u.max()), float(v.max()))


# --------------------------------------------------------------------------------------------------
# the compositor
# --------------------------------------------------------------------------------------------------
@dataclass
class _Calib:
    """Per image size: scaled intrinsics, tracker, lens warp."""

    intrinsics: object
    was_scaled: bool
    tracker: object
    lens: object | None
    fast_tracker: object = None


@dataclass
class _LightState:
    light: object  # arshadow.lights.Light (hard)
    weight: float  # share of the total weight
    light_h: np.ndarray
    sil: object = None
    volumes: dict = field(default_factory=dict)  # caps(bool) -> ShadowVolume


class Compositor:
    """Everything that stays fixed over a run, and :meth:`process` for each photo.

    Parameters
    ----------
    ctx : moderngl.Context
        From :func:`arshadow.gl.context.create_context`; the renderer is built on it (never creates one).
    intrinsics : arshadow.camera.Intrinsics
        The calibration; photos of another size with the same aspect ratio get a scaled copy.
    caster : arshadow.mesh.ShadowCaster
        The occluder in the world (marker) frame.
    lights : sequence of arshadow.lights.Light
        At least one. Area lights are split into ``options.soft_samples`` hard samples.
    options : RenderOptions, optional
    tracker : dict, optional
        Keyword arguments of :class:`arshadow.marker.MarkerTracker` (dictionary, marker_length,
        marker_id, board, ...).
    renderer : arshadow.gl.renderer.ShadowRenderer, optional
        Share an existing renderer (else one is made on ``ctx``).
    """

    def __init__(self, ctx, intrinsics, caster, lights, options: RenderOptions | None = None, tracker=None,
                 renderer=None):
        self.ctx = ctx
        self.intrinsics = intrinsics
        self.caster = caster
        self.options = (options or RenderOptions()).check()
        self.tracker_kwargs = dict(tracker or {})
        self._lights: list[_LightState] = []
        self.set_lights(lights)
        self._calibs: dict = {}
        self._lenses: dict = {}
        self._work = Workspace()
        self._renderer = renderer
        self._own_renderer = renderer is None
        b = np.asarray(caster.bounds, dtype=np.float64)
        self._bounds = b
        self._corners = _box_corners(b)
        # the ROI is bounded with the mesh's own vertices (tight) up to this many, else the box corners
        self._roi_points = (np.asarray(caster.vertices, dtype=np.float64)
                            if len(caster.vertices) <= ROI_MAX_POINTS else None)
        self._size = float(np.linalg.norm(b[1] - b[0]))
        self._hull = (None, None)  # (lights' key, scene_hull_points) for the current lights

    # -- cached per run ------------------------------------------------------------------------------
    @property
    def renderer(self):
        if self._renderer is None:
            from .gl.renderer import ShadowRenderer

            self._renderer = ShadowRenderer(self.ctx, samples=int(self.options.aa))
        return self._renderer

    def close(self):
        if self._own_renderer and self._renderer is not None:
            self._renderer.release()
        self._renderer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- video time-lapse (added for arshadow/video.py + arshadow/cli/video.py) -----------------------
    def set_lights(self, lights) -> int:
        """Replace the lights between frames (``arshadow video --time-lapse``), keeping cached work.

        A (sample) light whose homogeneous vector ``light_h`` equals one of the current lights' keeps
        that light's silhouette and shadow volumes (only its weight share is updated); any other light
        is recomputed on first use. A sun track hands the direction of its last recompute
        (``TrackFrame.world_used``) until the sun has moved more than the set angle, so in between
        nothing is recomputed.

        Parameters
        ----------
        lights : sequence of arshadow.lights.Light
            At least one (lights below the horizon give no light and no shadow).

        Returns
        -------
        int
            Number of (sample) lights whose silhouette and volumes must be recomputed.
        """
        from .lights import sample_area_light

        lights = list(lights)
        if not lights:
            raise LightError("no light given (use --light)")
        old = {tuple(ls.light_h.tolist()): ls for ls in self._lights}
        total = float(sum(lt.weight for lt in lights if lt.above_horizon))
        notes, states, n_new = [], [], 0
        for lt in lights:
            if not lt.above_horizon:
                notes.append(f"light {lt.label or lt.kind} is below the horizon: no light, no shadow")
                continue
            samples = (sample_area_light(lt, int(self.options.soft_samples))
                       if getattr(lt, "radius", 0.0) > 0 and self.options.soft_samples > 1 else [lt])
            for s in samples:
                h = np.asarray(s.homogeneous, float)
                prev = old.get(tuple(h.tolist()))
                if prev is None:
                    n_new += 1
                    states.append(_LightState(s, float(s.weight) / total, h))
                else:
                    states.append(_LightState(s, float(s.weight) / total, prev.light_h, prev.sil, prev.volumes))
        self.lights_in, self.notes, self._lights = lights, notes, states
        return n_new

    def calib_for(self, width: int, height: int) -> _Calib:
        """Intrinsics, tracker and lens warp for a photo size (built once per size)."""
        key = (int(width), int(height))
        c = self._calibs.get(key)
        if c is None:
            from .marker import MarkerTracker

            intr, scaled = self.intrinsics.for_image(width, height)
            tracker = MarkerTracker(intr, **self.tracker_kwargs)
            fast = None
            if self.options.fast_detect and "detector_params" not in self.tracker_kwargs:
                fast = make_fast_tracker(intr, **self.tracker_kwargs)
            lens = self._lens_for(intr) if intr.has_distortion else None
            c = self._calibs[key] = _Calib(intr, scaled, tracker, lens, fast)
        return c

    def _silhouette(self, ls: _LightState, timings):
        if ls.sil is None:
            from .silhouette import silhouette

            t = time.perf_counter()
            ls.sil = silhouette(self.caster, ls.light_h, method=self.options.silhouette)
            timings["silhouette"] += (time.perf_counter() - t) * 1e3
        return ls.sil

    def _volume(self, ls: _LightState, caps: bool, timings):
        vol = ls.volumes.get(caps)
        if vol is None:
            from .volume import shadow_volume

            sil = self._silhouette(ls, timings)
            t = time.perf_counter()
            trunc = -1e-3 * max(self._size, 1e-6) if self.options.truncate else None
            vol = ls.volumes[caps] = shadow_volume(self.caster, ls.light_h, sil, caps=caps, truncate_z=trunc)
            timings["volume"] += (time.perf_counter() - t) * 1e3
        return vol

    def znear_for(self, cam_from_world) -> float:
        """A near plane that clips nothing visible: a fraction of the distance to the object and ground.

        No upper bound: the depth resolution of a 24-bit buffer with an infinite far plane is about
        ``z**2 / znear * 6e-8``, so a fixed 5 cm near plane lost the contact of an object 1 km away (metres
        of depth error); a quarter of the distance keeps it at ~1e-7 of the distance."""
        eye = invert_rigid(cam_from_world)[:3, 3]
        depth = transform_points(cam_from_world, self._corners)[:, 2]
        d = float(depth.min()) if np.all(depth > 0) else self._size
        h = abs(float(eye[2]))
        return float(max(0.25 * min(d, h if h > 0 else d), 1e-4))

    # -- per photo ------------------------------------------------------------------------------------
    def process(self, image, name: str = "", want_mask: bool = True, out=None, mask_out=None):
        """Composite the occluder and its shadow into one photo.

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified).
        name : str
            Used in the report item and messages.
        want_mask : bool
            Also return the full-size mask (else None).
        out : (H, W, 3) uint8, optional
            Buffer for the result (reused across frames by callers that consume each result at once,
            e.g. encode it: saves allocating and page-faulting a photo-sized array per frame).
        mask_out : (H, W) uint8, optional
            Buffer for the mask, likewise.

        Returns
        -------
        out : (H, W, 3) uint8
            The composited photo (a new array).
        mask : (H, W) uint8 or None
            The shadow mask of CONVENTIONS.md.
        item : arshadow.report.ReportItem
            Pose, mode, silhouette edges, per-stage timings (``output``/``mask`` left for the caller).

        Raises
        ------
        MarkerNotFoundError
            No marker / board found.
        ImageError, CalibrationError
            Unusable image, or a size the calibration cannot be scaled to.
        """
        t_start = time.perf_counter()
        timings = dict.fromkeys(STAGES, 0.0)
        image = np.asarray(image)
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise ImageError(f"{name or 'image'}: expected an (H, W, 3) uint8 BGR image, got {image.shape} "
                             f"{image.dtype}")
        H, W = image.shape[:2]
        item = ReportItem(input=name)
        cal = self.calib_for(W, H)
        intr = cal.intrinsics
        if cal.was_scaled:
            item.extra["calibration_scaled"] = {"from": [self.intrinsics.width, self.intrinsics.height],
                                                "to": [W, H]}
        if self.notes:
            item.extra["notes"] = list(self.notes)

        # 1. marker detection and pose
        pose = None
        if cal.fast_tracker is not None:
            try:
                pose = self._estimate(cal.fast_tracker, image, timings)
            except MarkerNotFoundError:
                item.extra["detector"] = "full (fast pass found nothing)"
        if pose is None:
            pose = self._estimate(cal.tracker, image, timings)
        item.set_pose(pose)
        cam_from_world = np.asarray(pose.cam_from_world, dtype=np.float64)

        out, mask, info = self.render_pose(image, intr, cam_from_world, lens=cal.lens, timings=timings,
                                           want_mask=want_mask, out=out, mask_out=mask_out)
        item.mode = info["mode"]
        item.silhouette_edges = info["silhouette_edges"]
        item.extra.update({k: v for k, v in info.items() if k not in ("mode", "silhouette_edges")})
        timings["total"] = (time.perf_counter() - t_start) * 1e3
        item.timings_ms = {k: round(v, 3) for k, v in timings.items()}
        return out, mask, item

    def _estimate(self, tracker, image, timings):
        t = time.perf_counter()
        pose = tracker.estimate(image)
        total = (time.perf_counter() - t) * 1e3
        # the tracker splits its own time into marker search and pose (MarkerPose.timings_ms)
        pose_ms = float((getattr(pose, "timings_ms", None) or {}).get("pose", 0.0))
        timings["detect"] += total - pose_ms
        timings["pose"] += pose_ms
        return pose

    def modes_for(self, cam_from_world, znear, intr=None, canvas=None):
        """Per light: ``"zpass"`` if the camera is provably outside its volume, else ``"zfail"``.

        The test needs the radius of the near-plane rectangle of the canvas actually rendered
        (``canvas = (u0, v0, w, h)`` pinhole pixels of ``intr``), not ``znear`` alone; without ``intr`` the
        radius of a 90-degree-per-axis frustum is used (conservative for any narrower camera).
        """
        if self.options.shadow_method == "planar":
            return ["planar"] * len(self._lights)
        from .volume import camera_may_be_in_shadow, near_plane_radius

        if intr is not None and canvas is not None and canvas[2] > 0 and canvas[3] > 0:
            u0, v0, w, h = canvas
            near = near_plane_radius(znear, int(w), int(h), intr.fx, intr.fy, intr.cx - u0, intr.cy - v0)
        else:
            near = znear * np.sqrt(3.0)
        eye = invert_rigid(cam_from_world)[:3, 3]
        return ["zfail" if camera_may_be_in_shadow(self.caster, ls.light_h, eye, near) else "zpass"
                for ls in self._lights]

    def render_pose(self, image, intr, cam_from_world, *, lens=None, timings=None, want_mask=True,
                    modes=None, out=None, mask_out=None):
        """Render and composite for a known pose (the part of :meth:`process` after the tracker).

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified).
        intr : arshadow.camera.Intrinsics
            Calibration for this photo size.
        cam_from_world : (4, 4) float64
            Pose.
        lens : arshadow.lens.LensWarp or None
            Needed when ``intr`` has distortion (built from ``intr`` if missing).
        modes : list of str, optional
            Force the volume mode per light (tests compare z-pass and z-fail); default: decided per
            light by :func:`arshadow.volume.camera_may_be_in_shadow`.

        Returns
        -------
        out, mask, info
            As :meth:`process`; ``info`` has ``mode``, ``modes``, ``silhouette_edges``, ``roi``, ``canvas``.
        """
        from .gl.renderer import LightPass

        timings = timings if timings is not None else dict.fromkeys(STAGES, 0.0)
        H, W = image.shape[:2]
        if intr.has_distortion and lens is None:
            lens = self._lens_for(intr)
        znear = self.znear_for(cam_from_world)
        opts = self.options
        if not getattr(self, "_warned_inside", False):
            from .mesh import placement_warnings

            for msg in placement_warnings(self.caster, eye_world=invert_rigid(cam_from_world)[:3, 3]):
                log.warning(msg)
                self._warned_inside = True  # once per run, not per frame

        # 2. region of interest (photo) and pinhole canvas
        rect = None
        if opts.roi:
            hull = self._scene_hull()
            rect = None if hull is None else _pinhole_rect(intr, cam_from_world, hull, znear)
        if lens is None:
            if rect is None:
                roi = (0, 0, W, H)
            else:
                roi = clip_roi(_int_rect(rect, 2), W, H)
            canvas = roi
        else:
            if rect is None:
                roi = (0, 0, W, H)
                canvas = lens.canvas_for(roi)
            else:
                roi = lens.distorted_roi(rect, margin=2)
                canvas = lens.canvas_for(roi, rect) if roi[2] and roi[3] else (0, 0, 0, 0)
        # 3. per light: mode, silhouette, volume (cached per run)
        if modes is None:
            modes = self.modes_for(cam_from_world, znear, intr, canvas)
        passes, n_edges = [], 0
        for ls, mode in zip(self._lights, modes):
            if mode == "planar":
                vol = None
                sil = None
            else:
                vol = self._volume(ls, caps=(mode == "zfail"), timings=timings)
                sil = ls.sil
            if sil is not None:
                n_edges += int(len(sil.edges))
            passes.append(LightPass(light_h=ls.light_h, weight=ls.weight, volume=vol, mode=mode))
        mode = None if not modes else ("planar" if "planar" in modes else ("zfail" if "zfail" in modes else "zpass"))

        info = {"mode": mode, "modes": list(modes), "silhouette_edges": n_edges, "roi": list(roi),
                "canvas": list(canvas), "znear": znear}

        if out is None:
            out = image.copy()
        else:
            check_shape(out, f"{H},{W},3", "out")
            np.copyto(out, image)
        mask_full = None
        if want_mask:
            if mask_out is None:
                mask_full = np.zeros((H, W), np.uint8)
            else:
                mask_full = check_shape(mask_out, f"{H},{W}", "mask_out")
                mask_full.fill(0)
        if roi[2] == 0 or roi[3] == 0 or canvas[2] == 0 or canvas[3] == 0:
            return out, mask_full, info  # nothing of the scene is in view

        # 4. render the canvas
        proj = intr.gl_projection(znear, None, canvas=canvas)
        view = CV_TO_GL @ cam_from_world
        t = time.perf_counter()
        res = self.renderer.render(projection=proj, view=view, width=int(canvas[2]), height=int(canvas[3]),
                                   caster=self.caster, passes=passes, ground_size=opts.ground_size,
                                   draw_occluder=opts.draw_occluder, occluder_color=opts.occluder_color)
        dt = (time.perf_counter() - t) * 1e3
        rt = getattr(res, "timings_ms", None) or {}
        if "readback" in rt:
            timings["readback"] += float(rt["readback"])
            timings["render"] += dt - float(rt["readback"])
        else:
            timings["render"] += dt
        raw = _gl_layers(res)
        # 5. lens warp (pinhole canvas -> distorted photo ROI)
        t = time.perf_counter()
        if raw is not None:
            # the renderer's own bottom-up RGBA (colour, alpha) and RG (mask, ground) arrays: one remap
            # or flip each instead of three strided arrays; and only over the part that has content
            c0, c1 = raw
            ch, cw = c0.shape[:2]
            act = c1[:, :, 0] > 0
            act |= c0[:, :, 3] > 0
            rows = np.flatnonzero(act.any(axis=1))
            if rows.size == 0:  # nothing drawn: the photo is unchanged
                timings["warp"] += (time.perf_counter() - t) * 1e3
                info["content"] = None
                return out, mask_full, info
            cols = np.flatnonzero(act.any(axis=0))
            r0, r1 = ch - 1 - int(rows[-1]), ch - 1 - int(rows[0])  # top-down canvas rows
            k0, k1 = int(cols[0]), int(cols[-1])
            info["content"] = [int(canvas[0]) + k0, int(canvas[1]) + r0, k1 - k0 + 1, r1 - r0 + 1]
            if lens is not None:
                # photo pixels whose pinhole point can see the content (+1 px: bilinear support)
                rect = (canvas[0] + k0 - 1.0, canvas[1] + r0 - 1.0, canvas[0] + k1 + 1.0, canvas[1] + r1 + 1.0)
                sub = clip_roi(lens.distorted_roi(rect, margin=1), W, H)
                x0 = max(sub[0], roi[0])
                y0 = max(sub[1], roi[1])
                x1 = min(sub[0] + sub[2], roi[0] + roi[2])
                y1 = min(sub[1] + sub[3], roi[1] + roi[3])
                if x1 <= x0 or y1 <= y0:
                    timings["warp"] += (time.perf_counter() - t) * 1e3
                    return out, mask_full, info
                roi = (x0, y0, x1 - x0, y1 - y0)
                l0, l1 = lens.warp(roi, canvas, c0, c1, work=self._work, bottom_up=True)
            else:
                import cv2

                roi = (int(canvas[0]) + k0, int(canvas[1]) + r0, k1 - k0 + 1, r1 - r0 + 1)
                b0, b1 = ch - 1 - r1, ch - r0  # the same rows, bottom-up
                s0, s1 = c0[b0:b1, k0 : k1 + 1], c1[b0:b1, k0 : k1 + 1]
                l0 = cv2.flip(s0, 0, dst=self._work.get("flip0", s0.shape, np.float32))
                l1 = cv2.flip(s1, 0, dst=self._work.get("flip1", s1.shape, np.float32))
            info["composited"] = list(roi)
            mask, alpha, color = l1[:, :, 0], l0[:, :, 3], l0
        else:
            mask, alpha, color = res.mask, res.alpha, res.color
            if lens is not None:
                mask, alpha, color = lens.warp(roi, canvas, mask, alpha, color, work=self._work)
        timings["warp"] += (time.perf_counter() - t) * 1e3

        # 6. composite
        t = time.perf_counter()
        composite(out, mask, roi, color=color if opts.draw_occluder else None,
                  alpha=alpha if opts.draw_occluder else None, opacity=opts.opacity,
                  shadow_color=opts.shadow_color, premultiplied=getattr(res, "premultiplied", True), out=out, work=self._work)
        if want_mask:
            x0, y0, w, h = roi
            m = self._work.get("mask255", (h, w), np.float32)
            np.multiply(mask, np.float32(255.0), out=m)
            m += np.float32(0.5)
            np.clip(m, np.float32(0.0), np.float32(255.0), out=m)
            np.copyto(mask_full[y0 : y0 + h, x0 : x0 + w], m, casting="unsafe")
        timings["composite"] += (time.perf_counter() - t) * 1e3
        return out, mask_full, info

    def _scene_hull(self):
        """:func:`scene_hull_points` of the current lights (recomputed only when the lights change)."""
        key = tuple(ls.light_h.tobytes() for ls in self._lights)
        if self._hull[0] != key:
            hull = scene_hull_points(self._bounds, [ls.light_h for ls in self._lights], self.options.ground_size,
                                     points=self._roi_points)
            self._hull = (key, hull)
        return self._hull[1]

    def _lens_for(self, intr):
        """The cached :class:`LensWarp` of a calibration (one map per distinct calibration)."""
        lens = self._lenses.get(intr)
        if lens is None:
            from .lens import LensWarp

            lens = self._lenses[intr] = LensWarp(intr)
        return lens


def _int_rect(rect, margin: int):
    """Float pinhole rect (u0, v0, u1, v1) -> integer (x0, y0, w, h) with ``margin`` pixels around it."""
    u0, v0, u1, v1 = rect
    x0, y0 = math.floor(u0) - margin, math.floor(v0) - margin
    x1, y1 = math.ceil(u1) + margin, math.ceil(v1) + margin
    return (x0, y0, x1 - x0 + 1, y1 - y0 + 1)


def _gl_layers(res):
    """The renderer's raw bottom-up ``(h, w, 4)`` RGBA and ``(h, w, 2)`` (mask, ground) arrays, if the
    :class:`RenderResult`'s ``color``/``alpha``/``mask`` are exactly the flipped views of them (checked
    pointer by pointer); else None (then the result's own arrays are used)."""
    c0, c1 = getattr(res.color, "base", None), getattr(res.mask, "base", None)
    try:
        ok = (isinstance(c0, np.ndarray) and isinstance(c1, np.ndarray) and c0.dtype == np.float32
              and c1.dtype == np.float32 and c0.ndim == 3 and c0.shape[2] == 4 and c1.ndim == 3
              and c1.shape[2] == 2 and c0.flags.c_contiguous and c1.flags.c_contiguous
              and c0.shape[:2] == c1.shape[:2] == res.mask.shape)
        if ok:
            f0, f1 = c0[::-1], c1[::-1]
            ok = (_same_view(f0[:, :, :3], res.color) and _same_view(f0[:, :, 3], res.alpha)
                  and _same_view(f1[:, :, 0], res.mask))
    except (AttributeError, TypeError):
        ok = False
    return (c0, c1) if ok else None


def _same_view(a, b) -> bool:
    ia, ib = a.__array_interface__, b.__array_interface__
    return ia["data"][0] == ib["data"][0] and a.shape == b.shape and a.strides == b.strides


class HalfResolutionDetector:
    """Drop-in for ``cv2.aruco.ArucoDetector`` in a :class:`~arshadow.marker.MarkerTracker`: detect on the
    image downscaled 2x (one 5-px threshold window, no refinement), then refine every corner at full
    resolution with ``cv2.cornerSubPix`` (11 x 11 window, 0.01 px / 50 iterations, as the tracker's own
    sub-pixel refinement). Other methods (``refineDetectedMarkers``...) go to the full-resolution detector.
    When nothing is found, or a detected marker has a side shorter than :data:`MIN_SIDE_PX` (small or
    steeply tilted), the full-resolution detector (same one window) runs instead: a 40-px marker's half-resolution corners are too coarse a start
    (measured at 640 x 360: 2.8 deg rotation error instead of 0.9 deg).

    Measured on 40 synthetic photos (5 cm marker at 0.3-0.8 m, tilt 0-70 deg, noise 2, blur 0.6,
    JPEG 90): 40 of 40 found, rotation error median 0.114 deg (full resolution, 7-px window: 0.141 deg),
    0.96 ms instead of 2.63 ms for ``detectMarkers`` on the 1280 x 720 benchmark photo.
    """

    #: shortest marker side (full-resolution pixels) for which the half-resolution corners are used
    MIN_SIDE_PX = 64.0

    def __init__(self, base, dictionary):
        import cv2

        self._base = base
        p = cv2.aruco.DetectorParameters()
        p.adaptiveThreshWinSizeMin = 5
        p.adaptiveThreshWinSizeMax = 5
        p.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        self._small = cv2.aruco.ArucoDetector(dictionary, p)
        self._criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 0.01)

    def detectMarkers(self, gray):  # noqa: N802 (OpenCV's name)
        import cv2

        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        h, w = gray.shape[:2]
        if min(h, w) < 2 * self.MIN_SIDE_PX:  # too small to halve (a 1-pixel image crashed cv2.resize)
            return self._base.detectMarkers(gray)
        small = cv2.resize(gray, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
        corners, ids, rejected = self._small.detectMarkers(small)
        if ids is None or len(ids) == 0:  # nothing at half resolution: try full resolution (same window)
            return self._base.detectMarkers(gray)
        # small pixel i covers full pixels 2i and 2i + 1: centre 2i + 0.5
        pts = np.concatenate([np.asarray(c, np.float32).reshape(-1, 2) for c in corners]) * 2.0 + 0.5
        sides = np.linalg.norm(pts.reshape(-1, 4, 2) - np.roll(pts.reshape(-1, 4, 2), 1, axis=1), axis=2)
        if sides.min() < self.MIN_SIDE_PX:
            # small (or steeply tilted) markers: the half-resolution corners are too coarse a start for
            # the 11 x 11 refinement window; detect at full resolution with the tracker's own refinement
            return self._base.detectMarkers(gray)
        pts = np.ascontiguousarray(pts.reshape(-1, 1, 2), dtype=np.float32)
        cv2.cornerSubPix(gray, pts, (5, 5), (-1, -1), self._criteria)
        full = tuple(pts[4 * i : 4 * i + 4].reshape(1, 4, 2) for i in range(len(corners)))
        rej = tuple(np.asarray(r, np.float32) * 2.0 + 0.5 for r in rejected) if rejected is not None else rejected
        return full, ids, rej

    def __getattr__(self, name):
        return getattr(self._base, name)


def make_fast_tracker(intrinsics, **tracker_kwargs):
    """The tracker of the pipeline's fast first pass (see :class:`Compositor`).

    A :class:`~arshadow.marker.MarkerTracker` with one 7-px threshold window
    (:func:`fast_detector_params`) and, for single markers and grid boards, detection at half resolution
    (:class:`HalfResolutionDetector`). The Compositor falls back to the tracker's full search when this
    finds nothing. With several markers in view and no ``marker_id``, the reference is the lowest id found,
    so give ``marker_id`` for a frame that cannot change between passes.
    """
    import cv2

    from .marker import MarkerTracker

    trk = MarkerTracker(intrinsics, **tracker_kwargs, detector_params=fast_detector_params())
    det = getattr(trk, "_detector", None)
    if isinstance(det, cv2.aruco.ArucoDetector) and getattr(trk, "board", None) is None:
        trk._detector = HalfResolutionDetector(det, det.getDictionary())
    return trk


def fast_detector_params():
    """ArUco detector parameters for the fast first pass: one adaptive-threshold window (7 px).

    OpenCV's default tries windows 3, 13 and 23 px (three thresholdings and contour searches); one
    window finds the same corners on the benchmark set (tests/benchmarks/bench_pipeline.py
    ``--detectors``: 60 of 60 synthetic photos, identical pose errors) about 5x faster. The
    :class:`Compositor` falls back to the full search when this pass finds nothing, so robustness is kept.
    The tracker's corner refinement is applied on top (``make_detector_params``).
    """
    import cv2

    from .marker import MIN_MARKER_DISTANCE_RATE

    p = cv2.aruco.DetectorParameters()
    p.adaptiveThreshWinSizeMin = 7
    p.adaptiveThreshWinSizeMax = 7
    # OpenCV 5's default (0.125) drops markers printed with a narrow paper margin (docs/tracking.md)
    p.minMarkerDistanceRate = MIN_MARKER_DISTANCE_RATE
    return p
