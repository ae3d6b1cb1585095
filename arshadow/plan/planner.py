"""Planning a frame, without GL: (scene, pose, lights, frame size) -> :class:`FramePlan`.

The planner decides everything about a frame before anything is drawn, and records why:

- the region of interest (ROI) in the photo and the pinhole canvas the renderer draws (see below);
- the near plane (:meth:`SceneGeometry.znear_for`);
- per light, the technique and mode: ``"planar"`` when projection shadows are asked for, else z-pass
  when :func:`arshadow.geometry.volume.camera_may_be_in_shadow` proves the camera outside the light's shadow
  volume (no caps needed), z-fail otherwise (capped volume);
- which silhouettes and volumes are reused from the cache (:class:`SceneGeometry`) and which are built.

Each decision is a :class:`Decision` (name, value, reason) in ``FramePlan.decisions``; a new decision is
one more ``plan.decide(...)`` call in :func:`plan_frame` (or a function it calls). The executor
(:mod:`arshadow.frame.execute`) carries the plan out: CPU geometry, the renderer, lens warp, composite.

What is computed once, not per photo
    The occluder and the lights are both fixed in the world (marker) frame, so each light's silhouette
    and shadow volume do not depend on the camera pose: :class:`SceneGeometry` builds them on first use
    and reuses them (with and without caps, as the z-pass / z-fail choice needs); likewise the world
    points bounding the region of interest (the object and its shadow footprints,
    :func:`scene_hull_points`). Per photo remain the pose, the z-pass / z-fail decision, the region of
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
    photo and the pinhole canvas that it samples is rendered, then warped by :class:`arshadow.compose.lens.LensWarp`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ..compose.composite import clip_roi
from ..geometry.volume import near_plane_radius
from ..transforms import invert_rigid, transform_points
from .rules import LightDecision, LightSwitches, decide_lights, outside_view
from .scene_geometry import (
    ROI_MAX_POINTS,
    LightState,
    SceneGeometry,
    int_rect,
    pinhole_rect,
    pinhole_rect_for_scene,
    scene_hull_points,
    shadow_footprint,
)

if TYPE_CHECKING:  # annotations only
    from ..camera.model import Intrinsics
    from ..compose.lens import LensWarp

_T = TypeVar("_T")

__all__ = [
    "Decision",
    "LightPlan",
    "FramePlan",
    "SceneGeometry",
    "LightState",
    "plan_frame",
    "decide_compose",
    "decide_outline_aa",
    "shadow_footprint",
    "scene_hull_points",
    "pinhole_rect_for_scene",
    "ROI_MAX_POINTS",
]


# --------------------------------------------------------------------------------------------------
# the frame plan
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Decision:
    """One planning decision: what was chosen and why (``name``, ``value``, ``reason``)."""

    name: str
    value: object
    reason: str


@dataclass
class LightPlan:
    """What to do for one (sample) light.

    Attributes
    ----------
    index : int
        Position in ``SceneGeometry.lights``.
    light_h : (4,) float64
    weight : float
        Share of the total weight.
    technique : str
        ``"volume"`` (stencil shadow volume), ``"planar"`` (projection shadow) or ``"none"`` (culled: no
        shadow pass; the occluder still gets this light's shading).
    mode : str
        ``"zpass"`` | ``"zfail"`` | ``"planar"`` | ``"none"``.
    caps : bool
        The volume needs caps (z-fail).
    reuse : bool
        The geometry it needs is cached already (no silhouette / volume to build).
    reason : str
        Why this mode.
    truncate : bool
        Build the volume truncated just below the ground (else extruded to infinity).
    why : dict
        Every decision for this light (``cull``, ``planar``, ``mode``, ``truncate``, ``reuse``) -> reason.
    """

    index: int
    light_h: np.ndarray
    weight: float
    technique: str
    mode: str
    caps: bool
    reuse: bool
    reason: str
    truncate: bool = True
    why: dict = field(default_factory=dict)


@dataclass
class FramePlan:
    """Everything decided about one frame before drawing (no GL objects; cheap to build and inspect).

    Attributes
    ----------
    size : (int, int)
        Photo (width, height).
    cam_from_world : (4, 4) float64
    znear : float
    roi : (x0, y0, w, h)
        Photo pixels that may change.
    canvas : (u0, v0, w, h)
        Pinhole pixels the renderer draws (equal to ``roi`` without lens distortion).
    lights : list of LightPlan
    distorted : bool
        A lens warp maps the canvas into the photo.
    decisions : list of Decision
        Every choice with its reason, in the order made.
    """

    size: tuple
    cam_from_world: np.ndarray
    znear: float
    roi: tuple = (0, 0, 0, 0)
    canvas: tuple = (0, 0, 0, 0)
    lights: list = field(default_factory=list)
    distorted: bool = False
    decisions: list = field(default_factory=list)

    def decide(self, name: str, value: _T, reason: str) -> _T:
        """Record a decision; returns ``value``."""
        self.decisions.append(Decision(name, value, reason))
        return value

    @property
    def modes(self) -> list[str]:
        """The mode of each light, in order."""
        return [lp.mode for lp in self.lights]

    @property
    def mode(self) -> str | None:
        """The frame's summary mode for the report: ``planar`` if any light is, else ``zfail`` if any
        light is, else ``zpass``; None without lights."""
        modes = [m for m in self.modes if m != "none"]
        if not modes:
            return None
        return next((m for m in ("shadowmap", "planar", "zfail") if m in modes), "zpass")

    @property
    def compose(self) -> str | None:
        """The ``compose`` decision (:func:`decide_compose`): ``"cpu"``, ``"gpu"``, ``"measure"``, or None
        when not decided (an empty frame composites nothing)."""
        return next((d.value for d in reversed(self.decisions) if d.name == "compose"), None)

    @property
    def empty(self) -> bool:
        """Nothing of the scene is in view: nothing to render."""
        return bool(self.roi[2] == 0 or self.roi[3] == 0 or self.canvas[2] == 0 or self.canvas[3] == 0)


def plan_frame(
    geometry: SceneGeometry,
    intr: Intrinsics,
    cam_from_world: ArrayLike,
    width: int,
    height: int,
    *,
    lens: LensWarp | None = None,
    modes: Sequence[str] | None = None,
) -> FramePlan:
    """Plan one frame.

    Parameters
    ----------
    geometry : SceneGeometry
        The scene's lights and cached geometry (read, not changed).
    intr : arshadow.camera.Intrinsics
        Calibration for this photo size.
    cam_from_world : (4, 4) float64
        The pose.
    width, height : int
        Photo size.
    lens : arshadow.compose.lens.LensWarp or None
        The lens warp of ``intr`` when it has distortion.
    modes : list of str, optional
        Force the mode per light (tests compare z-pass and z-fail).

    Returns
    -------
    FramePlan
    """
    W, H = int(width), int(height)
    cam_from_world = np.asarray(cam_from_world, dtype=np.float64)
    opts = geometry.options
    znear = geometry.znear_for(cam_from_world)
    plan = FramePlan(size=(W, H), cam_from_world=cam_from_world, znear=znear, distorted=lens is not None)
    plan.decide(
        "znear", znear, "a quarter of the distance to the nearest of the object's box and the ground, at least 1e-4 m"
    )
    _plan_view(plan, geometry, intr, lens)
    from ..shading.decide import decide_ambient_occlusion  # sky occlusion (the realism work): once per frame, here

    sky, why = decide_ambient_occlusion(opts)
    plan.decide("ambient_occlusion", sky, why)
    plan.decide("outline_aa", *decide_outline_aa(opts, sky))
    general, off = opts.plan == "general", set(opts.plan_off)
    if opts.shadow_method == "volume":
        trunc = bool(opts.truncate) and not general and "truncate" not in off
        plan.decide(
            "truncate",
            trunc,
            "volumes end just below the ground (RenderOptions.truncate)"
            if trunc
            else "volumes extruded to infinity ("
            + (
                "the general plan"
                if general
                else "switched off (plan_off)"
                if "truncate" in off
                else "RenderOptions.truncate=False"
            )
            + ")",
        )
    _plan_lights(plan, geometry, _light_decisions(plan, geometry, intr, modes))
    return plan


def _plan_view(plan: FramePlan, geometry: SceneGeometry, intr: Any, lens: Any) -> None:
    """The region of interest (photo pixels) and the pinhole canvas the renderer draws."""
    (W, H), cam_from_world, znear = plan.size, plan.cam_from_world, plan.znear
    opts = geometry.options
    general = opts.plan == "general"
    off = set(opts.plan_off)
    rect = None
    off_screen = False
    if opts.roi and not general and "roi" not in off:
        hull = geometry.hull()
        rect = None if hull is None else pinhole_rect(intr, cam_from_world, hull, znear)
        why = (
            "a shadow footprint is unbounded (a light not above the object) and no ground size limits it"
            if hull is None
            else "a point of the object or its shadow is not in front of the camera"
            if rect is None
            else "the object and its shadows project into this rectangle"
        )
        if rect is None and hull is not None and "cull" not in off:
            # part of the hull is behind the camera: nothing to draw still, if it is all outside the view
            ext = lens.pinhole_extent if lens is not None else (-0.5, -0.5, W - 0.5, H - 0.5)
            off_screen = outside_view(
                transform_points(cam_from_world, hull), intr.fx, intr.fy, intr.cx, intr.cy, ext, znear
            )
    else:
        why = (
            "general plan (reference): whole photo"
            if general
            else "ROI switched off (plan_off)"
            if "roi" in off
            else "ROI off (RenderOptions.roi=False)"
        )
    if off_screen:
        roi = canvas = (0, 0, 0, 0)
        why = "the object and its shadows are outside the view (one frustum plane excludes them all)"
    elif lens is None:
        roi = (0, 0, W, H) if rect is None else clip_roi(int_rect(rect, 2), W, H)
        canvas = roi
    elif rect is None:
        roi = (0, 0, W, H)
        canvas = lens.canvas_for(roi)
    else:
        roi = lens.distorted_roi(rect, margin=2)
        canvas = lens.canvas_for(roi, rect) if roi[2] and roi[3] else (0, 0, 0, 0)
    plan.roi = plan.decide("roi", roi, why if rect is not None or off_screen else f"whole photo: {why}")
    plan.canvas = plan.decide(
        "canvas",
        canvas,
        "the pinhole pixels the distorted ROI samples" if lens is not None else "the ROI (no lens distortion)",
    )


def _light_decisions(plan: FramePlan, geometry: SceneGeometry, intr: Any, modes: Sequence[str] | None) -> list[Any]:
    """Per light: culling, technique, mode, truncation (:func:`arshadow.plan.rules.decide_lights`)."""
    opts = geometry.options
    off = set(opts.plan_off)
    if modes is not None:
        return [LightDecision(m, bool(opts.truncate), {"mode": "forced by the caller"}) for m in modes]
    if opts.shadow_method == "shadowmap":
        return [
            LightDecision("shadowmap", False, {"mode": "shadow-map baseline asked for (shadow_method='shadowmap')"})
            for _ in geometry.lights
        ]
    if plan.empty:
        return [
            LightDecision("none", False, {"cull": "nothing of the scene in view: no render at all"})
            for _ in geometry.lights
        ]
    cam_from_world, znear, canvas = plan.cam_from_world, plan.znear, plan.canvas
    which = "planar" if opts.shadow_method == "planar" and opts.plan == "auto" else opts.plan
    u0, v0, cw, ch = canvas
    near = near_plane_radius(znear, int(cw), int(ch), intr.fx, intr.fy, intr.cx - u0, intr.cy - v0)
    eye = invert_rigid(cam_from_world)[:3, 3]
    rects = None
    if which == "auto" and "cull" not in off:
        rects = [geometry.footprint_rect(ls, intr, cam_from_world, znear) for ls in geometry.lights]
    switches = LightSwitches(which, opts.draw_occluder, opts.truncate and "truncate" not in off, frozenset(off))
    return decide_lights(
        switches,
        geometry.caster,
        [ls.light_h for ls in geometry.lights],
        convex=geometry.caster.is_convex if which == "auto" and "planar" not in off else False,
        eye_world=eye,
        near=near,
        footprint_rects=rects,
        canvas=canvas,
    )


def _plan_lights(plan: FramePlan, geometry: SceneGeometry, decisions: list[Any]) -> None:
    """A :class:`LightPlan` per light from its decision, and the decisions recorded with their reasons."""
    for i, (ls, d) in enumerate(zip(geometry.lights, decisions, strict=True)):
        mode = d.mode
        planar, culled = mode in ("planar", "shadowmap"), mode == "none"
        caps = mode == "zfail"
        reuse = planar or culled or (caps, d.truncate) in ls.volumes
        light_why = dict(d.reasons)
        if ls.reuse:
            light_why["reuse"] = ls.reuse
        reason = light_why.get("mode") or light_why.get("planar") or light_why.get("cull") or ""
        if planar:
            reason = light_why.get("planar", reason)
        elif culled:
            reason = light_why.get("cull", reason)
        lp = LightPlan(
            i,
            ls.light_h,
            ls.weight,
            mode if planar else "none" if culled else "volume",
            mode,
            caps,
            reuse,
            reason,
            truncate=d.truncate,
            why=light_why,
        )
        plan.lights.append(lp)
        plan.decide(f"light{i}.mode", mode, reason)
        if not (planar or culled):
            plan.decide(f"light{i}.truncate", d.truncate, light_why.get("truncate", ""))
            plan.decide(
                f"light{i}.volume",
                "reuse" if reuse else "build",
                ls.reuse
                if ls.reuse
                else "cached for this light"
                if reuse
                else "first use of this light " + ("with caps" if caps else "without caps"),
            )


#: the reason of a ``compose`` decision taken from an earlier measurement (the report's ``plan.compose``)
MEASURED = "measured on first use in this process: {ms} ms (median)"
SOFTWARE_COMPOSE = (
    "numpy: the renderer rasterises on the CPU (llvmpipe), where the shader path runs on the same cores "
    "(measured within 15 % of each other; not timed)"
)


def decide_outline_aa(options: Any, sky: bool = False) -> tuple[bool, str]:
    """``(on, reason)``: whether the object's outline gets its pixels' coverage after the render
    (:mod:`arshadow.compose.outline`), for :class:`arshadow.scene.options.RenderOptions` ``options`` and the
    frame's sky occlusion decision ``sky``.

    With pixel-centre sampling (``aa`` 0) and the object drawn: ``auto`` (the default) turns it on in a
    photo, and in a video (``track_roi``) with sky occlusion on (the realism options; without them a video
    keeps the speed it had: 1-2 ms a frame, 7-15 % on the benchmark's knot); ``on`` always. Off with MSAA (its
    samples already give the outline its coverage), without the object, or with ``outline_aa`` off.

    >>> from arshadow.scene.options import RenderOptions
    >>> decide_outline_aa(RenderOptions())[0], decide_outline_aa(RenderOptions(aa=4))[1]
    (True, 'off: MSAA (--aa 4) gives the outline its coverage')
    >>> decide_outline_aa(RenderOptions(track_roi=True)), decide_outline_aa(RenderOptions(track_roi=True), True)[0]
    ((False, 'off: a video without sky occlusion (--outline-aa on for it)'), True)
    """
    if options.outline_aa == "off":
        return False, "off (--outline-aa off)"
    if not options.draw_occluder:
        return False, "off: no object drawn"
    if int(options.aa) > 0:
        return False, f"off: MSAA (--aa {int(options.aa)}) gives the outline its coverage"
    if options.outline_aa == "auto" and options.track_roi and not sky:
        return False, "off: a video without sky occlusion (--outline-aa on for it)"
    return True, "on: the object's outline gets each pixel's coverage of its silhouette (--aa 0)"


def decide_compose(
    plan: FramePlan,
    *,
    force: str | None,
    shader_available: bool,
    measured: dict[str, Any] | None = None,
    software: bool = False,
) -> str:
    """Decide how the frame's lens warp + composite runs, and record it in ``plan`` (``"compose"``).

    Parameters
    ----------
    plan : FramePlan
    force : str or None
        ``RenderOptions.compose`` when not ``"auto"``: ``"cpu"`` (numpy) or ``"gpu"`` (shader).
    shader_available : bool
        The renderer can keep its layers on the GPU and the output buffers are contiguous.
    measured : dict, optional
        An earlier measurement for this photo size, anti-aliasing, lens, sky occlusion, camera effects and
        backend
        (:class:`arshadow.gl.gpu_compose.PathChooser` ``decisions[key]``: ``{"choice", "ms"}``).
    software : bool
        The renderer rasterises on the CPU (llvmpipe): the shader path would run on the pipeline's own
        cores, so the numpy path is taken without timing either.

    Returns
    -------
    str
        ``"cpu"``, ``"gpu"`` or ``"measure"`` (time both on this frame, keep the faster: the executor).

    >>> p = FramePlan(size=(4, 4), cam_from_world=np.eye(4), znear=0.1)
    >>> decide_compose(p, force=None, shader_available=False), p.decisions[-1].reason
    ('cpu', 'numpy (the shader path is not available here)')
    >>> decide_compose(p, force=None, shader_available=True, measured={"choice": "gpu", "ms": {"gpu": 1.0}})
    'gpu'
    >>> decide_compose(p, force=None, shader_available=True, software=True)
    'cpu'
    """
    if not shader_available:
        return plan.decide("compose", "cpu", "numpy (the shader path is not available here)")
    if force is not None:
        return plan.decide("compose", force, f"forced {force}")
    if measured is not None:
        return plan.decide("compose", str(measured["choice"]), MEASURED.format(ms=measured["ms"]))
    if software:
        return plan.decide("compose", "cpu", SOFTWARE_COMPOSE)
    return plan.decide(
        "compose",
        "measure",
        "not measured yet for this photo size, anti-aliasing, lens, sky occlusion, camera effects and "
        "backend: both paths are timed on this frame, the faster is kept",
    )
