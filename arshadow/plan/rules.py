"""The planner's decisions, one pure function each (no GL): what a frame can skip and why.

Every rule returns its verdict and a short reason that goes into the report's ``plan`` field. The rules are
conservative: a rule says "skip" or "cheaper path" only when the result provably cannot differ from the
reference plan (``general``: z-fail, volumes to infinity, every pass, no reuse, no culling) at any pixel of
the ground mask; where that cannot be shown cheaply, the general path is taken.

Rules
-----
planar (:func:`planar_applies`)
    Projection shadows ([Kolivand-Stencil] and [Kolivand-Sun]) draw the mesh flattened onto z = 0 from the light; a ground point
    is darkened iff the segment from it to the light meets the mesh -- exactly what the shadow volume
    gives on the ground -- provided every vertex is at or above the ground and the light is strictly
    above every vertex (a point light) or shines down (a directional light). The volume also shadows the
    occluder itself; the planar path cannot, so it is taken only when the occluder is not drawn, or when
    it is convex and closed: then the only parts of it in its own shadow are the faces turned away from
    the light, which the renderer leaves unlit anyway (it lights only light-facing faces of closed meshes).
z-pass (:func:`zpass_safe`)
    :func:`arshadow.geometry.volume.camera_may_be_in_shadow` with the near rectangle's radius: False proves the
    near plane is outside the volume (z-pass counts right, no caps needed); otherwise z-fail.
truncated volumes
    :func:`arshadow.geometry.volume.shadow_volume` ends the volume just below the ground when every extruded ray
    descends (``MIN_DESCENT``); nothing under the ground is visible, so the ground and the occluder get the
    same counts as with infinite volumes, with less fill.
light culling (:func:`light_shadow_in_view`)
    A light's volume can change only pixels that see its ground footprint or the occluder. When the
    footprint's screen box misses the canvas and the occluder cannot be self-shadowed visibly (not drawn,
    or convex), the light's volume pass is dropped (its Phong term on the occluder stays).
reuse (:func:`same_silhouette`)
    Silhouette and volume depend on the light in the occluder's frame only. A moved light keeps the
    cached silhouette when no face changes its facing (one sign test per face), and keeps the cached,
    uploaded volume when its float32 vertices (what the GPU draws) are bit-identical: the same GPU input
    cannot change a pixel.
tracking ROI (:func:`arshadow.tracking.roi_track.tracking_roi`)
    Video: detect the marker in a window around the last detection, the whole frame when it is not found
    there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..geometry.silhouette import as_light_h

if TYPE_CHECKING:
    from ..geometry.caster import ShadowCaster
    from ..geometry.silhouette import Silhouette
    from ..geometry.volume import ShadowVolume

__all__ = [
    "planar_applies",
    "zpass_safe",
    "light_shadow_in_view",
    "same_silhouette",
    "reuse_light_geometry",
    "outside_view",
    "decide_lights",
    "LightDecision",
    "LightSwitches",
    "PLANS",
    "PLAN_OFF",
]

#: the ``--plan`` choices: ``auto`` decides per frame and light, the others force one path
PLANS = ("auto", "general", "zpass", "zfail", "planar")
#: the ``auto`` decisions that ``RenderOptions.plan_off`` can switch off one by one (benchmarks, tests)
PLAN_OFF = ("planar", "zpass", "truncate", "cull", "roi", "reuse")


def planar_applies(
    caster: ShadowCaster, light_h: npt.ArrayLike, *, convex: bool, draw_occluder: bool, margin_rel: float = 1e-6
) -> tuple[bool, str]:
    """Whether projection shadows are exact for this light; returns ``(bool, reason)``.

    Parameters
    ----------
    caster : ShadowCaster
    light_h : (4,) float64
    convex : bool
        :attr:`arshadow.geometry.caster.ShadowCaster.is_convex` of the caster (computed once).
    draw_occluder : bool
        The occluder is drawn (its self-shadowing matters).
    margin_rel : float
        The light must clear the mesh's top by this fraction of its size (a point light), or come down at
        least this steeply (a directional light's unit z), else the projection degenerates.
    """
    if draw_occluder and not convex:
        return False, "occluder drawn and not convex: self-shadowing needs volumes"
    v = np.asarray(caster.vertices, np.float64)
    if float(v[:, 2].min()) < 0.0:
        return False, "mesh reaches below the ground: the projection would shade from below"
    h = as_light_h(light_h)
    if h[3] == 0.0:
        dz = h[2] / float(np.linalg.norm(h[:3]))
        if not dz > margin_rel:
            return False, "directional light does not shine down onto the ground"
    else:
        top = float(v[:, 2].max())
        if not h[2] > top + margin_rel * max(float(caster.scale), 1e-300):
            return False, "point light not above the mesh: unbounded projection"
    why = "occluder not drawn" if not draw_occluder else "convex closed occluder"
    return True, f"only the ground receives ({why}); mesh above the ground, light above the mesh"


def zpass_safe(caster: ShadowCaster, light_h: npt.ArrayLike, eye_world: npt.ArrayLike, near: float) -> tuple[bool, str]:
    """``(bool, reason)``: z-pass is safe when the camera's near rectangle is provably outside the volume."""
    from ..geometry.volume import camera_may_be_in_shadow

    if camera_may_be_in_shadow(caster, light_h, eye_world, near):
        return False, "camera may be inside the volume (eye-to-light segment meets the grown box)"
    return True, "near rectangle provably outside the volume"


def light_shadow_in_view(
    footprint_rect: Sequence[float] | None, canvas: Sequence[float], *, occluder_matters: bool
) -> tuple[bool, str]:
    """``(bool, reason)``: whether a light's volume pass can change a pixel of the canvas.

    Parameters
    ----------
    footprint_rect : (u0, v0, u1, v1) float or None
        Pinhole screen box of the light's ground footprint (None: unbounded or behind the camera).
    canvas : (u0, v0, w, h) int
        Pinhole canvas rendered.
    occluder_matters : bool
        The occluder is drawn and may shadow itself (not convex).
    """
    if occluder_matters:
        return True, "occluder may shadow itself"
    if footprint_rect is None:
        return True, "footprint unbounded or behind the camera"
    u0, v0, u1, v1 = footprint_rect
    cu0, cv0, cw, ch = canvas
    if u1 < cu0 - 1 or v1 < cv0 - 1 or u0 > cu0 + cw or v0 > cv0 + ch:
        return False, "ground footprint outside the canvas"
    return True, "ground footprint in view"


def outside_view(
    points_cam: npt.ArrayLike, fx: float, fy: float, cx: float, cy: float, extent: Sequence[float], znear: float
) -> bool:
    """Whether the convex hull of camera-frame points is entirely outside the view frustum.

    True when every point lies outside the same one of the five half-spaces bounding the frustum (in
    front of the near plane, and inside the four planes through the eye and the edges of the pinhole
    rectangle ``extent``): then so does their convex hull, and nothing of it can be seen.

    Parameters
    ----------
    points_cam : (n, 3) float64
        Points in the OpenCV camera frame (e.g. the occluder's and its shadows' hull points).
    fx, fy, cx, cy : float
        Pinhole intrinsics.
    extent : (u0, v0, u1, v1) float
        Pinhole pixel rectangle the photo can see (the image's pixel edges; with lens distortion the
        pinhole extent of the distorted image).
    znear : float
    """
    p = np.asarray(points_cam, np.float64).reshape(-1, 3)
    if p.size == 0:
        return True
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    u0, v0, u1, v1 = extent
    tests = (
        z <= znear,
        fx * x - (u0 - cx) * z < 0.0,  # planes through the eye: each half-space holds the whole frustum
        fx * x - (u1 - cx) * z > 0.0,
        fy * y - (v0 - cy) * z < 0.0,
        fy * y - (v1 - cy) * z > 0.0,
    )
    return any(bool(np.all(t)) for t in tests)


def same_silhouette(face_planes: npt.ArrayLike, facing: npt.ArrayLike, light_h: npt.ArrayLike) -> bool:
    """Whether a light gives exactly the cached facing of every face (so the same silhouette edges).

    ``face_planes (m, 4)``, ``facing (m,) bool`` (the cached silhouette's), ``light_h (4,)``: the exact
    per-face sign test the detectors use (``face_planes @ light_h > 0``).
    """
    return bool(np.array_equal(np.asarray(face_planes) @ as_light_h(light_h) > 0.0, facing))


def reuse_light_geometry(
    caster: ShadowCaster,
    light_h: npt.ArrayLike,
    sil: Silhouette | None,
    volumes: dict[bool, ShadowVolume],
    *,
    truncate_z: float | None = None,
) -> tuple[Silhouette | None, dict[bool, ShadowVolume], str]:
    """Carry a light's cached silhouette and volumes over to a moved light where that is exact.

    Parameters
    ----------
    caster : ShadowCaster
    light_h : (4,) float64
        The new light (occluder/world frame).
    sil : arshadow.geometry.silhouette.Silhouette
        The cached silhouette (of the old light).
    volumes : dict
        ``caps (bool) -> ShadowVolume`` cached for the old light.
    truncate_z : float or None
        As the cached volumes were built.

    Returns
    -------
    sil, volumes, reason
        ``sil`` None when a face changes its facing (recompute from scratch). Otherwise the same edges
        for the new light, and per cached volume: the cached object itself when the new volume's float32
        vertices (what is uploaded) and triangles are identical (the uploaded buffers are reused: the same
        GPU input cannot change a pixel), else the new volume (re-extruded from the kept edges, no
        silhouette detection).
    """
    from dataclasses import replace

    from ..geometry.volume import shadow_volume

    h = as_light_h(light_h)
    if sil is None or not same_silhouette(caster.face_planes, sil.facing, h):
        return None, {}, "a face changed its facing: silhouette recomputed"
    sil2 = replace(sil, light_h=h)
    out: dict[bool, ShadowVolume] = {}
    kept = 0
    for caps, vol in volumes.items():
        new = shadow_volume(caster, h, sil2, caps=caps, truncate_z=truncate_z)
        same = (
            new.truncated == vol.truncated
            and np.array_equal(new.triangles, vol.triangles)
            and np.array_equal(new.vertices.astype(np.float32), vol.vertices.astype(np.float32))
        )
        out[caps] = vol if same else new
        kept += same
    if volumes and kept == len(volumes):
        return sil2, out, "same facing and float32-identical volume: cached geometry and GPU buffers reused"
    return sil2, out, "same facing: silhouette reused, volume re-extruded"


@dataclass
class LightDecision:
    """What the planner decided for one (sample) light of a frame.

    Attributes
    ----------
    mode : str
        ``"zpass"`` | ``"zfail"`` | ``"planar"``; ``"none"`` when the volume pass is culled (the renderer
        then lights the occluder unshadowed by this light: exact for a convex or undrawn occluder).
    truncate : bool
        Build the volume truncated just below the ground (whether it could be is the volume's
        ``truncated``).
    reasons : dict
        decision name -> reason (the report's ``plan`` field).
    """

    mode: str
    truncate: bool
    reasons: dict = field(default_factory=dict)

    @property
    def culled(self) -> bool:
        return self.mode == "none"


@dataclass(frozen=True)
class LightSwitches:
    """What the options decide for :func:`decide_lights`.

    Attributes
    ----------
    plan : str
        One of :data:`PLANS`. ``general`` is the reference: z-fail, volumes to infinity, every pass.
        ``zpass`` / ``zfail`` / ``planar`` force that mode for every light (``zpass`` is then the user's
        responsibility: wrong counts where the camera is inside a volume).
    draw_occluder : bool
    truncate : bool
        ``RenderOptions.truncate``.
    off : collection of str
        ``auto`` decisions switched off (``planar``, ``zpass``, ``cull``): benchmarks and tests.
    """

    plan: str
    draw_occluder: bool
    truncate: bool
    off: frozenset[str] = frozenset()


def decide_lights(
    switches: LightSwitches,
    caster: ShadowCaster,
    lights_h: Sequence[npt.ArrayLike],
    *,
    convex: bool,
    eye_world: npt.ArrayLike,
    near: float,
    footprint_rects: Sequence[Sequence[float] | None] | None = None,
    canvas: Sequence[float] | None = None,
) -> list[LightDecision]:
    """Per light: volume mode (or planar, or culled) and truncation, with the reasons.

    Parameters
    ----------
    switches : LightSwitches
        The plan, whether the occluder is drawn, truncation, the decisions switched off.
    caster : ShadowCaster
    lights_h : sequence of (4,) float64
    convex : bool
        :attr:`arshadow.geometry.caster.ShadowCaster.is_convex` (once per mesh).
    eye_world : (3,) float64
        Camera centre, world frame.
    near : float
        Radius of the near rectangle (:func:`arshadow.geometry.volume.near_plane_radius`).
    footprint_rects : sequence of ((u0, v0, u1, v1) or None), optional
        Per light, the pinhole screen box of its ground footprint (for culling); None: no culling.
    canvas : (u0, v0, w, h), optional
        The pinhole canvas rendered (for culling).
    """
    plan, draw_occluder, truncate, off = switches.plan, switches.draw_occluder, switches.truncate, switches.off
    if plan not in PLANS:
        from ..errors import UsageError

        raise UsageError(f"--plan {plan!r}: choose one of {', '.join(PLANS)}")
    out = []
    for i, h in enumerate(lights_h):
        if plan == "general":
            out.append(
                LightDecision(
                    "zfail",
                    False,
                    {"mode": "forced general (reference): z-fail", "truncate": "general: volumes to infinity"},
                )
            )
            continue
        trunc_why = "truncated just below the ground" if truncate else "--no-truncate: volumes to infinity"
        if plan in ("zpass", "zfail", "planar"):
            out.append(LightDecision(plan, bool(truncate), {"mode": f"forced --plan {plan}", "truncate": trunc_why}))
            continue
        reasons = {}
        if footprint_rects is not None and canvas is not None and "cull" not in off:
            in_view, why = light_shadow_in_view(
                footprint_rects[i], canvas, occluder_matters=draw_occluder and not convex
            )
            reasons["cull"] = why
            if not in_view:
                out.append(LightDecision("none", bool(truncate), reasons))
                continue
        ok, why = (
            (False, "switched off")
            if "planar" in off
            else planar_applies(caster, h, convex=convex, draw_occluder=draw_occluder)
        )
        reasons["planar"] = why
        if ok:
            out.append(LightDecision("planar", False, reasons))
            continue
        safe, why = (False, "z-pass switched off") if "zpass" in off else zpass_safe(caster, h, eye_world, near)
        reasons["mode"] = why
        reasons["truncate"] = trunc_why
        out.append(LightDecision("zpass" if safe else "zfail", bool(truncate), reasons))
    return out
