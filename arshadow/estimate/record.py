"""The typed result of a light estimate, and its JSON form (what ``arshadow light --json`` prints and
``--light-from`` reads)."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import UsageError
from .exposure import Exposure

__all__ = [
    "DEFAULT_OBJECT_COLOR",
    "LightEstimate",
    "load_estimate",
    "measured_ambient",
    "measured_tints",
    "lamp_irradiance",
    "ratio_at",
    "moved_ratio",
    "scene_overrides",
    "shading_gain",
]


def _r(v: Any, nd: int = 6) -> Any:
    if v is None:
        return None
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_r(x, nd) for x in v]
    return round(float(v), nd)


@dataclass
class LightEstimate:
    """A light measured from photos of a probe's shadow.

    Attributes
    ----------
    kind : str
        ``"directional"``, ``"point"`` or ``"sun"``.
    light : str
        A spec that ``--light`` accepts (:func:`arshadow.lights.spec.parse_light`).
    direction : (3,) float or None
        Unit vector towards the light, world frame (directional and sun).
    position : (3,) float or None
        The point light's position, world frame, metres.
    north_deg : float or None
        Sun: the fitted compass bearing of world +y (degrees clockwise from north).
    shadow_ratio : (3,) float
        Linear RGB of the ground in the probe's shadow over the same ground lit.
    uncertainty_deg : float
        1-sigma uncertainty of the light's direction, degrees (point light: of its direction seen from
        the probe).
    position_uncertainty : float or None
        Point light: 1-sigma uncertainty of its position, metres.
    exposure : Exposure or None
        The marker paper's measurement (the median over the frames).
    frames : int
        Frames used.
    fit : dict
        Diagnostics: explained variance, visible share of the shadow, runner-up, evaluations, time.
    warnings : list of str
        Plausible problems (a low-confidence result says so here).
    angular_diameter_deg : float or None
        Directional: the light's angular diameter fitted to the shadow's penumbra (an upper bound: the
        camera's blur softens the edge too); the light spec then carries ``radius=`` (half of it) when it is
        at least 0.25 degrees (radius), for ``--soft-samples``.
    distance_interval : (2,) float or None
        Point light: the 2-sigma interval of its distance from the probe's top, metres (the fit's own
        uncertainty, log-normal).
    """

    kind: str
    light: str
    direction: tuple | None = None
    position: tuple | None = None
    north_deg: float | None = None
    shadow_ratio: tuple = (1.0, 1.0, 1.0)
    uncertainty_deg: float = math.inf
    position_uncertainty: float | None = None
    exposure: Exposure | None = None
    frames: int = 1
    fit: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    angular_diameter_deg: float | None = None
    distance_interval: tuple | None = None
    #: a point light's: the ground point (x, y), metres, world frame, where ``shadow_ratio`` was read (its
    #: probe's shadow edge); the ratio elsewhere follows from the lamp's fall-off (:func:`ratio_at`)
    ratio_at: tuple | None = None

    @property
    def confident(self) -> bool:
        """No warning was raised and the uncertainty is below 3 degrees."""
        return not self.warnings and self.uncertainty_deg <= 3.0

    def to_dict(self) -> dict:
        return {
            "light": self.light,
            "kind": self.kind,
            "direction": _r(self.direction),
            "position": _r(self.position),
            "north_deg": _r(self.north_deg, 4),
            "shadow_ratio": _r(self.shadow_ratio, 4),
            "uncertainty_deg": _r(self.uncertainty_deg, 4),
            "position_uncertainty": _r(self.position_uncertainty),
            "exposure": None if self.exposure is None else self.exposure.to_dict(),
            "frames": int(self.frames),
            "confident": self.confident,
            "fit": self.fit,
            "warnings": list(self.warnings),
            "angular_diameter_deg": _r(self.angular_diameter_deg, 4),
            "distance_interval": _r(self.distance_interval, 4),
            "ratio_at": _r(self.ratio_at, 5),
        }

    def to_json(self, indent: int | None = 1) -> str:
        return json.dumps(self.to_dict(), indent=indent)

    @classmethod
    def from_dict(cls, d: dict) -> LightEstimate:
        try:
            return cls(
                kind=str(d["kind"]),
                light=str(d["light"]),
                direction=None if d.get("direction") is None else tuple(d["direction"]),
                position=None if d.get("position") is None else tuple(d["position"]),
                north_deg=d.get("north_deg"),
                shadow_ratio=tuple(float(v) for v in d["shadow_ratio"]),
                uncertainty_deg=float(d.get("uncertainty_deg", math.inf)),
                position_uncertainty=d.get("position_uncertainty"),
                exposure=None if d.get("exposure") is None else Exposure.from_dict(d["exposure"]),
                frames=int(d.get("frames", 1)),
                fit=dict(d.get("fit", {})),
                warnings=list(d.get("warnings", [])),
                angular_diameter_deg=d.get("angular_diameter_deg"),
                distance_interval=None if d.get("distance_interval") is None else tuple(d["distance_interval"]),
                ratio_at=None if d.get("ratio_at") is None else tuple(float(v) for v in d["ratio_at"]),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise UsageError(
                f"not a light estimate ({type(exc).__name__}: {exc}); make one with arshadow light --json"
            ) from None

    @classmethod
    def from_json(cls, text: str) -> LightEstimate:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise UsageError(f"light estimate: not JSON ({exc})") from None
        if not isinstance(d, dict):
            raise UsageError("light estimate: expected a JSON object")
        return cls.from_dict(d)


def _sin_elevation(est: LightEstimate) -> float:
    if est.direction is not None:
        return max(float(est.direction[2]), 0.0)
    if est.position is not None:
        p = np.asarray(est.position, np.float64)
        return max(float(p[2] / np.linalg.norm(p)), 0.0)
    return 1.0


def ratio_at(est: LightEstimate, xy: Sequence[float]) -> tuple[float, ...]:
    """The shadow ratio (R, G, B) at the ground point ``xy (2,)`` (metres, world frame).

    A sun's or a directional light's irradiance is the same everywhere: its measured ``shadow_ratio``. A
    point light's falls off as ``z / d^3`` (``cos / d^2``) while the sky's does not, so the sky-to-lamp ratio
    ``s = r / (1 - r)`` read at ``est.ratio_at`` scales by ``E(ratio_at) / E(xy)`` (without ``ratio_at``, an
    estimate from before it was recorded: the measured ratio).

    >>> e = LightEstimate("point", "point:0,0,1", position=(0.0, 0.0, 1.0), shadow_ratio=(0.5, 0.5, 0.5), ratio_at=(0.0, 0.0))
    >>> [round(v, 4) for v in ratio_at(e, (1.0, 0.0))]  # the lamp's irradiance 2^-1.5 of it: s = 2.83
    [0.7388, 0.7388, 0.7388]
    """
    if est.kind != "point" or est.position is None or est.ratio_at is None:
        return tuple(float(v) for v in est.shadow_ratio)
    return tuple(float(v) for v in moved_ratio(est.shadow_ratio, est.position, est.ratio_at, xy))


def lamp_irradiance(lamp: Sequence[float], xy: npt.ArrayLike) -> np.ndarray:
    """A point lamp's irradiance on horizontal surfaces facing up at the points ``xy`` (world frame, metres):
    ``(n, 2)`` on the ground (z = 0) or ``(n, 3)``; ``max(0, dz) / d^3`` for the lamp at ``lamp (3,)`` (its
    intensity 1), ``(n,) float64``.

    >>> lamp_irradiance((0.0, 0.0, 1.0), [[0.0, 0.0], [1.0, 0.0]]).round(4).tolist()
    [1.0, 0.3536]
    >>> lamp_irradiance((0.0, 0.0, 1.0), [[0.0, 0.0, 0.5]]).round(4).tolist()  # a surface half-way up
    [4.0]
    """
    p = np.asarray(lamp, np.float64).reshape(3)
    q = np.asarray(xy, np.float64)
    q = q.reshape(-1, q.shape[-1])
    rel = p[None, :] - (q if q.shape[1] == 3 else np.column_stack([q, np.zeros(len(q))]))
    out: np.ndarray = np.maximum(rel[:, 2], 0.0) / np.linalg.norm(rel, axis=1) ** 3
    return out


def moved_ratio(
    ratio: Sequence[float] | np.ndarray, lamp: Sequence[float], src: Sequence[float], dst: Sequence[float]
) -> np.ndarray:
    """A point light's shadow ratio ``ratio (c,)`` read at the ground point ``src (2,)``, moved to ``dst (2,)``
    (world frame, metres): the lamp at ``lamp (3,)`` lights the floor with ``z / d^3`` while the sky's light is
    the same everywhere, so the sky-to-lamp ratio ``r / (1 - r)`` scales by ``E(src) / E(dst)``; ``(c,)``.

    >>> [round(float(v), 4) for v in moved_ratio([0.5], (0.0, 0.0, 1.0), (0.0, 0.0), (1.0, 0.0))]
    [0.7388]
    """
    e_src, e_dst = lamp_irradiance(lamp, [src[:2], dst[:2]])
    r = np.clip(np.asarray(ratio, np.float64), 1e-6, 1.0 - 1e-6)
    sky = r / (1.0 - r) * float(e_src) / float(e_dst)
    out: np.ndarray = sky / (1.0 + sky)
    return out


def measured_ambient(est: LightEstimate) -> float:
    """The renderer's ambient term (light weight 1) that gives a horizontal surface at the world origin (the
    marker's paper, where the exposure is matched) the measured shadow ratio there (:func:`ratio_at`):
    ``a / (a + sin(elevation)) = r`` -> ``a = r sin(e) / (1 - r)``, ``r`` the mean of the channels (clipped
    to 0..4)."""
    r = float(np.clip(np.mean(ratio_at(est, (0.0, 0.0))), 0.0, 0.95))
    return float(np.clip(r * _sin_elevation(est) / (1.0 - r), 0.0, 4.0))


def measured_tints(est: LightEstimate) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``(ambient_tint, direct_tint)``, (3,) linear RGB each: the measured sky's and direct light's colours
    relative to the paper's mixed light, ``r_c / mean(r)`` and ``(1 - r_c) / (1 - mean(r))`` with ``r`` the
    shadow ratio at the world origin (:func:`ratio_at`; clipped as :func:`measured_ambient` clips its mean).
    A horizontal face at the paper keeps the paper's colour (``a t_a + s t_d`` sums to the grey ``a + s``
    per channel when ``a / (a + s) = mean(r)``), a face the light does not reach takes the sky's.

    >>> e = LightEstimate("directional", "directional:0,0,1", direction=(0.0, 0.0, 1.0), shadow_ratio=(0.3, 0.4, 0.5))
    >>> [[round(v, 3) for v in t] for t in measured_tints(e)]
    [[0.75, 1.0, 1.25], [1.167, 1.0, 0.833]]
    """
    r = np.clip(np.asarray(ratio_at(est, (0.0, 0.0)), np.float64), 0.0, 0.95)
    m = float(np.clip(r.mean(), 1e-6, 0.95))
    return tuple(float(v) for v in r / m), tuple(float(v) for v in (1.0 - r) / (1.0 - m))


def load_estimate(path: str | Path) -> LightEstimate:
    """Read a light estimate written by ``arshadow light --json`` (UsageError naming the file otherwise)."""
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise UsageError(f"--light-from {p}: cannot read ({exc.strerror or exc})") from None
    try:
        return LightEstimate.from_json(text)
    except UsageError as exc:
        raise UsageError(f"--light-from {p}: {exc}") from None


def shading_gain(est: LightEstimate, ambient: float = 0.25) -> tuple | None:
    """Per-channel (R, G, B) gain on the virtual object's linear colour so that a white (255) horizontal
    face under the estimated light, shaded as the renderer shades it (``ambient + weight * n.l``, weight 1),
    records the marker paper's measured linear RGB. None without an exposure measurement."""
    if est.exposure is None:
        return None
    shade = ambient + _sin_elevation(est)
    return tuple(float(c) / shade for c in est.exposure.paper_rgb)


def _encode_unclipped(x: np.ndarray) -> np.ndarray:
    """The sRGB curve without clipping above 1 (the renderer decodes it back exactly; a gain may push a
    colour past the 8-bit range in linear light)."""
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    return np.where(x <= 0.0031308, x * 12.92, 1.055 * x ** (1.0 / 2.4) - 0.055)


#: the renderer's colour of a mesh without one (sRGB 0..1), :data:`arshadow.gl.resources.DEFAULT_COLOR`
DEFAULT_OBJECT_COLOR = (0.8, 0.8, 0.8)


def scene_overrides(
    est: LightEstimate, color: Any = None, exposure: bool = True, place: Sequence[float] | None = None
) -> dict:
    """What an estimate changes in a scene (``--light-from``).

    Parameters
    ----------
    est : LightEstimate
    color : str or None
        The model's ``--color`` (8-bit sRGB ``"R,G,B"``), None for the default grey.
    exposure : bool
        Apply the marker's exposure / white balance to the object's colour.
    place : (3,) float or None
        Where the object stands (world frame, metres; None: the origin): a point light's shadow ratio is
        the one there (:func:`ratio_at`).

    Returns
    -------
    dict
        ``lights`` (tuple of one spec), ``opacity`` 1.0 and ``shadow_color`` (the measured ratio at the
        object, linear RGB): a full shadow keeps exactly the measured share of each channel; ``ambient``
        (:func:`measured_ambient`) and ``specular`` 0 (matte, like the paper) for the object's shading;
        ``ambient_tint`` and ``direct_tint`` (:func:`measured_tints`): the sky's and the light's colours on
        the object; ``occluder_color`` (sRGB 0..1, unclipped) when ``exposure``: the colour times :func:`shading_gain`
        in linear light. ``ratio_at`` for a point light: ``place``, where ``shadow_color`` holds (the renderer follows
        the lamp's fall-off elsewhere on the floor).

    Examples
    --------
    >>> e = LightEstimate("directional", "directional:0,0,1", direction=(0.0, 0.0, 1.0), shadow_ratio=(0.4, 0.5, 0.6),
    ...                   exposure=Exposure((0.625, 0.625, 0.625), (0.02, 0.02, 0.02), 20))
    >>> o = scene_overrides(e, "255,255,255")
    >>> o["lights"], o["opacity"], o["shadow_color"], round(o["ambient"], 4), o["specular"]
    (('directional:0,0,1',), 1.0, (0.4, 0.5, 0.6), 1.0, 0.0)
    >>> [round(c, 4) for c in o["occluder_color"]]  # 0.625 / (1.0 + 1) = 0.3125 in linear light
    [0.5948, 0.5948, 0.5948]
    """
    ambient = measured_ambient(est)
    out: dict[str, Any] = {
        "lights": (est.light,),
        "opacity": 1.0,
        "shadow_color": tuple(float(np.clip(v, 0.0, 1.0)) for v in ratio_at(est, (place or (0.0, 0.0))[:2])),
        "ambient": ambient,
        "specular": 0.0,
    }
    out["ambient_tint"], out["direct_tint"] = measured_tints(est)
    if est.kind == "point" and est.position is not None:  # the lamp's ratio changes across the floor
        out["ratio_at"] = tuple(float(v) for v in (place or (0.0, 0.0))[:2])
    gain = shading_gain(est, ambient) if exposure else None
    if gain is not None:
        base = DEFAULT_OBJECT_COLOR if color is None else tuple(float(v) / 255.0 for v in str(color).split(","))
        lin = np.where(
            np.asarray(base) <= 0.04045, np.asarray(base) / 12.92, ((np.asarray(base) + 0.055) / 1.055) ** 2.4
        ) * np.asarray(gain)
        out["occluder_color"] = tuple(float(v) for v in _encode_unclipped(lin))
    return out
