"""Render options: what to render and how to composite it (:class:`RenderOptions`, the ``arshadow render``
options), with the choices they accept. Part of the scene (:class:`arshadow.scene.SceneSpec` holds one);
kept apart so that the scene module stays the spec and its builders.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import UsageError
from ..geometry.ground import parse_ground
from ..plan.rules import PLAN_OFF, PLANS
from ..shading.decide import PAPER_ALBEDO

__all__ = ["RenderOptions", "SHADOW_METHODS", "AA_CHOICES", "AMBIENT_OCCLUSION", "DEFAULT_AA"]

#: ``--ambient-occlusion`` choices: auto (on with a measured, non-negligible sky share), on, off
AMBIENT_OCCLUSION = ("auto", "on", "off")

#: shadow techniques: stencil volumes (exact), planar projection (exact on the ground for convex
#: occluders), the shadow-map baseline (approximate)
SHADOW_METHODS = ("volume", "planar", "shadowmap")
#: MSAA sample counts :class:`RenderOptions` accepts (what ``--aa`` documents)
AA_CHOICES = (0, 2, 4)
#: the MSAA default of every command and of the API (``render``, ``video``, ``batch`` and ``demo`` agree): pixel-centre
#: sampling, the exact and fastest path (docs/compositing.md); ``--aa 4`` for smoother edges
DEFAULT_AA = 0


@dataclass(frozen=True)
class RenderOptions:
    """What to render and how to composite it (the ``arshadow render`` options).

    Attributes
    ----------
    opacity : float
        How dark a fully blocked ground pixel gets (``1 - opacity`` of its light is kept).
    shadow_color : (3,) float
        Linear RGB tint of a full shadow (black: plain darkening).
    shadow_method : str
        ``"volume"`` (stencil shadow volumes, exact), ``"planar"`` (projection shadows, [Kolivand-Stencil] and [Kolivand-Sun]) or
        ``"shadowmap"`` (the shadow-map baseline, :class:`arshadow.gl.shadowmap.ShadowMapRenderer`).
    shadowmap_size : int
        Shadow map side in texels (``shadow_method="shadowmap"`` only).
    silhouette : str
        Silhouette detector name (``adjacency``, ``triangular``, ``vnv``, ``hsd``, ``delta_plus``).
    soft_samples : int
        Samples per area light (lights with a radius); 1 = hard shadows from the light's centre.
    aa : int
        MSAA samples of the renderer (0 = none).
    outline_aa : str
        With ``aa`` 0 and the object drawn, the object's outline gets each pixel's coverage of its silhouette
        (:mod:`arshadow.compose.outline`: the planner's ``outline_aa`` decision; MSAA has its own coverage):
        ``auto`` (default): in photos, and in videos with sky occlusion on (the realism options; a video
        without them keeps its speed, 1-2 ms a frame); ``on``: always; ``off``: pixel-centre samples only.
    ground_size : float or None
        Side of the square proxy ground plane centred on the origin (None: unlimited).
    ground : str
        Where the ground plane is, relative to the marker (:func:`arshadow.geometry.ground.parse_ground`):
        ``marker`` (the marker plane, the default), ``wall:H`` or ``plane:PX,PY,PZ,NX,NY,NZ``. The model
        and the lights are placed in its frame.
    draw_occluder : bool
        Draw the shaded object over the shadow.
    truncate : bool
        Extrude volumes only to just below the ground instead of to infinity ([Kolivand-Stencil]).
    roi : bool
        Render only the region the object and its shadow can cover (False: always the whole photo).
    occluder_color : (3,) float, optional
        Override of the occluder's colour handed to the renderer.
    ambient, specular : float
        The object's ambient term and specular weight (the renderer's shading; ``light_from`` sets them from
        the measured light: the measured ambient share, a matte object like the paper).
    ambient_tint, direct_tint : (3,) float
        Linear RGB tints of the object's ambient (sky) term and of its lights' direct term, 1 = grey
        (``light_from``: the measured sky's and sun's colour, each relative to the paper's mixed light, so
        that a face the sun does not reach takes the sky's colour: ``r_c / mean(r)`` and
        ``(1 - r_c) / (1 - mean(r))``, ``r`` the shadow ratio at the paper).
    fast_detect : bool
        Try the fast detection pass first (``MarkerTracker(detector="fast")``,
        :mod:`arshadow.tracking.fastdetect`), the full search only if it finds nothing.
    plan : str
        Frame planner (:mod:`arshadow.plan.rules`, docs/planner.md): ``auto`` (the cheapest exact path per
        frame and light), ``general`` (the reference: z-fail, volumes to infinity, whole photo, every pass,
        geometry rebuilt every frame, no culling), or force ``zpass`` / ``zfail`` / ``planar``.
    plan_off : tuple of str
        ``auto`` decisions to switch off (benchmarks, tests): ``planar``, ``zpass``, ``truncate``,
        ``cull``, ``roi``, ``reuse``.
    compose : str
        ``auto`` (time the numpy and the shader lens-warp + composite on first use per photo size and
        keep numpy unless the shader is > 15 % faster: :class:`arshadow.gl.gpu_compose.PathChooser`), ``cpu`` or
        ``gpu``.
    track_roi : bool
        Video: search the marker in a window around the last detection first (full-frame fallback).
    exposure : bool
        Match the marker paper's exposure / white balance on every photo and video frame
        (:mod:`arshadow.estimate.match`; ``--no-exposure`` turns it off).
    exposure_gain : (3,) float, optional
        The gain already in ``occluder_color`` (``light_from``): the per-photo gain is applied relative to it.
    ambient_occlusion : str
        Sky occlusion (:mod:`arshadow.shading.sky`, docs/shading.md): ``auto`` (on when the light is
        measured and its sky share is not negligible: the planner's ``ambient_occlusion`` decision),
        ``on`` or ``off``.
    camera_effects : str
        ``on``: the object and shadow layers are blurred by the photo's measured point-spread width and get
        noise matched to the photo's (:mod:`arshadow.estimate.optics`); ``off`` (default).
    motion_blur : str
        ``on`` (default): with ``camera_effects`` on, a video frame's layers are also blurred along the image
        motion of the camera's pose change during the exposure (:mod:`arshadow.frame.motion`; photos never:
        they have no neighbouring frames); ``off``.
    shutter : float
        The exposure time over the frame interval, in (0, 1] (default 0.5: the 180° shutter of most video).
    paper_albedo : float
        The marker paper's reflectance, in (0, 1] (default :data:`arshadow.shading.decide.PAPER_ALBEDO`, 0.8:
        printer paper's 0.8-0.9): the white a measured exposure makes the object's colours relative to. A mesh's
        own colours (reflectances) are divided by it, and the light the object and the ground reflect is
        that share times it (docs/shading.md, "Materials").
    ambient_measured : bool
        The ambient share (``shadow_color``, ``ambient``) comes from a measured light (``light_from``).
    material_gain : (3,) float, optional
        ``light_from`` without ``--color``: the exposure gain (linear RGB) a mesh with its own colours or
        texture is rendered with instead of ``occluder_color`` (the default grey for meshes without); the
        renderer divides it by the paper's reflectance (:func:`arshadow.frame.execute.frame_shading`: the
        mesh's colours are reflectances).
    ratio_at : (2,) float, optional
        With a measured point light (``light_from``): the ground point (ground frame, metres: where the
        object stands) at which ``shadow_color`` is the shadow ratio. A lamp's irradiance falls off across
        the floor while the sky's does not, so elsewhere the renderer scales the shadow and the sky
        occlusion to the ratio there (:class:`arshadow.renderer.request.Shading` ``ratio_falloff``); None:
        the same ratio everywhere (a sun, a given light).
    """

    opacity: float = 0.7
    shadow_color: tuple = (0.0, 0.0, 0.0)
    shadow_method: str = "volume"
    shadowmap_size: int = 2048
    silhouette: str = "adjacency"
    soft_samples: int = 1
    aa: int = DEFAULT_AA
    outline_aa: str = "auto"
    ground_size: float | None = None
    ground: str = "marker"
    draw_occluder: bool = True
    truncate: bool = True
    roi: bool = True
    occluder_color: tuple | None = None
    ambient: float = 0.25
    specular: float = 0.25
    ambient_tint: tuple = (1.0, 1.0, 1.0)
    direct_tint: tuple = (1.0, 1.0, 1.0)
    fast_detect: bool = True
    plan: str = "auto"
    plan_off: tuple = ()
    compose: str = "auto"
    track_roi: bool = False
    exposure: bool = True
    exposure_gain: tuple | None = None
    ambient_occlusion: str = "auto"
    camera_effects: str = "off"
    motion_blur: str = "on"
    shutter: float = 0.5
    paper_albedo: float = PAPER_ALBEDO
    ambient_measured: bool = False
    material_gain: tuple | None = None
    ratio_at: tuple | None = None

    def check(self) -> RenderOptions:
        """Validate (UsageError naming the ``arshadow render`` option); returns self."""
        if self.plan not in PLANS:
            raise UsageError(f"--plan {self.plan!r}: choose one of {', '.join(PLANS)}")
        bad = set(self.plan_off) - set(PLAN_OFF)
        if bad:
            raise UsageError(f"plan_off: unknown decision(s) {', '.join(sorted(bad))} (known: {', '.join(PLAN_OFF)})")
        if self.compose not in ("auto", "cpu", "gpu"):
            raise UsageError(f"--compose {self.compose!r}: choose auto, cpu or gpu")
        if not (0.0 <= float(self.opacity) <= 1.0):
            raise UsageError(f"--opacity {self.opacity}: must be in [0, 1]")
        if self.shadow_method not in SHADOW_METHODS:
            raise UsageError(f"--shadow-method {self.shadow_method!r}: choose {', '.join(SHADOW_METHODS)}")
        if self.shadow_method == "shadowmap" and not (16 <= int(self.shadowmap_size) <= 16384):
            raise UsageError(f"--shadowmap-size {self.shadowmap_size}: must be 16..16384 texels")
        if int(self.soft_samples) < 1:
            raise UsageError(f"--soft-samples {self.soft_samples}: must be >= 1")
        if self.aa not in AA_CHOICES:
            raise UsageError(
                f"--aa {self.aa}: choose {', '.join(map(str, AA_CHOICES))} (multisample anti-aliasing samples; 0 = off)"
            )
        if self.outline_aa not in ("auto", "on", "off"):
            raise UsageError(f"--outline-aa {self.outline_aa!r}: choose auto, on or off")
        if self.ground_size is not None and not (math.isfinite(self.ground_size) and self.ground_size > 0):
            raise UsageError(f"--ground-size {self.ground_size}: must be a positive number of metres")
        parse_ground(self.ground)
        if self.ambient_occlusion not in AMBIENT_OCCLUSION:
            raise UsageError(f"--ambient-occlusion {self.ambient_occlusion!r}: choose {', '.join(AMBIENT_OCCLUSION)}")
        if self.camera_effects not in ("on", "off"):
            raise UsageError(f"--camera-effects {self.camera_effects!r}: choose on or off")
        if self.motion_blur not in ("on", "off"):
            raise UsageError(f"--motion-blur {self.motion_blur!r}: choose on or off")
        if not (math.isfinite(float(self.shutter)) and 0.0 < float(self.shutter) <= 1.0):
            raise UsageError(f"--shutter {self.shutter}: must be in (0, 1] (exposure time / frame interval)")
        _check_shading(self)
        return self


def _check_shading(o: RenderOptions) -> None:
    """The paper's reflectance and the shading vectors of ``o`` (UsageError naming the field)."""
    p = float(o.paper_albedo)
    if not (math.isfinite(p) and 0.0 < p <= 1.0):
        hint = f" (a percentage? {p / 100:g})" if 1.0 < p <= 100.0 else ""
        raise UsageError(f"--paper-albedo {o.paper_albedo}: must be a reflectance in (0, 1]{hint}")
    for name in ("ambient_tint", "direct_tint"):
        t = tuple(getattr(o, name))
        if len(t) != 3 or not all(math.isfinite(float(v)) and float(v) >= 0.0 for v in t):
            raise UsageError(f"{name} {t!r}: expected 3 finite linear RGB gains >= 0")
    if o.ratio_at is not None:
        t = tuple(o.ratio_at)
        if len(t) != 2 or not all(math.isfinite(float(v)) for v in t):
            raise UsageError(f"ratio_at {t!r}: expected a ground point (x, y) in metres")
