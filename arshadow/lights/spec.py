"""Lights: point, directional and sun lights with weights, and their area-light samples.

A light reaches the geometry as a homogeneous ``(4,)`` float64 vector in the world frame
(:attr:`Light.homogeneous`): ``(x, y, z, 1)`` for a point light, ``(dx, dy, dz, 0)`` for a directional
light, ``(dx, dy, dz)`` a unit vector pointing TOWARDS the light. A face with plane ``(n, d)`` faces the
light iff ``n . light_h[:3] + d * light_h[3] > 0``.

Command-line / API specifications (CONVENTIONS.md, "Lights")::

    point:X,Y,Z[,radius=R][@W]              point light at (X, Y, Z) metres; R = sphere radius, metres
    directional:X,Y,Z[,radius=A][@W]        light at infinity towards (X, Y, Z); A = angular radius, degrees
    sun:LAT,LON,TIME[,NORTH][,key=value...][@W]

``sun`` keys: ``elevation`` (m), ``pressure`` (mbar), ``temperature`` (deg C), ``delta_t`` (s),
``model`` (``spa`` | ``paper`` | ``paper-printed``), ``refraction`` (``on``/``off``, default off: the
direction is the geometric one, see docs/lights.md), ``radius`` (angular radius, degrees; default the
sun's 0.266). ``TIME`` is ISO 8601 *with* a UTC offset (``2011-04-22T10:59+08:00``, ``...Z``); it may be
left out when the caller passes ``default_time`` (e.g. a video frame's timestamp).

Soft shadows: :func:`arshadow.lights.area.sample_area_light` replaces one light of non-zero radius by ``n`` stratified hard
lights whose weights sum to the light's weight; the shadow mask, being the blocked fraction of light
weight, then shows a true penumbra.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import LightError
from .sun import SunPosition, sun_light_direction, sun_position
from .suntrack import SunTrack, TrackFrame

__all__ = [
    "Light",
    "SUN_ANGULAR_RADIUS_DEG",
    "parse_light",
    "parse_sun_track",
    "SunLightTrack",
    "parse_time",
    "sun_radius_deg",
    "lights_homogeneous",
    "total_weight",
]

#: mean apparent angular radius of the sun's disc, degrees (varies 0.262..0.271 over the year)
SUN_ANGULAR_RADIUS_DEG = 0.266
#: the sun's angular semi-diameter at 1 AU, degrees (959.63 arcsec)
SUN_SEMI_DIAMETER_1AU_DEG = 959.63 / 3600.0


def _ro(a: npt.ArrayLike) -> np.ndarray:
    a = np.array(a, dtype=np.float64)  # always a copy: never alias the caller's array
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Light:
    """One light in the world frame.

    Parameters
    ----------
    kind : {"point", "directional"}
    vector : (3,) float64
        Position of a point light (world frame, metres), or the direction TOWARDS a directional light
        (normalised to unit length here).
    weight : float
        Relative intensity, > 0. The shadow mask is the blocked fraction of the total weight.
    radius : float
        Area-light size: a point light's sphere radius in metres; a directional light's angular radius in
        RADIANS. 0 = hard light.
    label : str
        For reports and error messages (the spec string when parsed).
    above_horizon : bool
        False for a sun below the horizon: it casts no shadow and gives no light.
    sun : SunPosition or None
        The sun's position when the light is a sun.

    Examples
    --------
    >>> Light("directional", [0, 0, 2]).homogeneous.tolist()
    [0.0, 0.0, 1.0, 0.0]
    """

    kind: str
    vector: np.ndarray
    weight: float = 1.0
    radius: float = 0.0
    label: str = ""
    above_horizon: bool = True
    sun: SunPosition | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in ("point", "directional"):
            raise LightError(f"light kind must be 'point' or 'directional', got {self.kind!r}")
        v = np.asarray(self.vector, dtype=np.float64).ravel()
        if v.shape != (3,):
            raise LightError(f"light {self.label or self.kind}: vector must have 3 components, got {v.size}")
        if not np.all(np.isfinite(v)):
            raise LightError(f"light {self.label or self.kind}: vector contains NaN or inf: {v.tolist()}")
        if self.kind == "directional":
            norm = float(np.linalg.norm(v))
            if not norm > 0.0:
                raise LightError(f"light {self.label or 'directional'}: direction is the zero vector")
            v = v / norm
        w = float(self.weight)
        if not (math.isfinite(w) and w > 0.0):
            raise LightError(
                f"light {self.label or self.kind}: weight must be a finite number > 0, got {self.weight!r}"
            )
        r = float(self.radius)
        if not (math.isfinite(r) and r >= 0.0):
            raise LightError(f"light {self.label or self.kind}: radius must be finite and >= 0, got {self.radius!r}")
        if self.kind == "directional" and r >= math.pi / 2:
            raise LightError(f"light {self.label or 'directional'}: angular radius must be < 90 degrees")
        object.__setattr__(self, "vector", _ro(v))
        object.__setattr__(self, "weight", w)
        object.__setattr__(self, "radius", r)
        object.__setattr__(self, "above_horizon", bool(self.above_horizon))

    # value semantics despite the ndarray field
    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Light):
            return NotImplemented
        return (
            self.kind == other.kind
            and np.array_equal(self.vector, other.vector)
            and self.weight == other.weight
            and self.radius == other.radius
            and self.label == other.label
            and self.above_horizon == other.above_horizon
            and self.sun == other.sun
        )

    def __hash__(self) -> int:
        return hash((self.kind, tuple(self.vector.tolist()), self.weight, self.radius, self.label, self.above_horizon))

    @property
    def homogeneous(self) -> np.ndarray:
        """``(4,)`` float64: ``(x, y, z, 1)`` for a point light, ``(dx, dy, dz, 0)`` (unit, towards the
        light) for a directional one. A fresh array each call."""
        return np.append(self.vector, 1.0 if self.kind == "point" else 0.0)

    @property
    def is_soft(self) -> bool:
        """True when the light has an area (``radius > 0``) and needs several samples for a penumbra."""
        return self.radius > 0.0


# ----------------------------------------------------------------------------------------------------------
# parsing


def _float(text: str, what: str, spec: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise LightError(f"light {spec!r}: {what} {text.strip()!r} is not a number") from None
    if not math.isfinite(v):
        raise LightError(f"light {spec!r}: {what} must be finite, got {text.strip()!r}")
    return v


def parse_time(text: str, what: str = "time") -> datetime:
    """Parse an ISO 8601 time that carries a UTC offset into an aware :class:`datetime`.

    A time without an offset is refused: a sun direction is only defined for an instant, and guessing
    the time zone would put the shadow in the wrong place by up to 15 degrees an hour.

    Parameters
    ----------
    text : str
        E.g. ``"2011-04-22T10:59+08:00"``, ``"2003-10-17 12:30:30-07:00"``, ``"2020-06-21T12:00Z"``.

    Returns
    -------
    datetime
        Timezone-aware.

    Raises
    ------
    LightError
        Unparseable text, or no UTC offset (the message says what to add).

    Examples
    --------
    >>> parse_time("2011-04-22T10:59+08:00").utcoffset().total_seconds()
    28800.0
    """
    s = text.strip()
    s2 = s[:-1] + "+00:00" if s.endswith(("Z", "z")) else s
    try:
        t = datetime.fromisoformat(s2)
    except ValueError:
        raise LightError(f"{what} {s!r} is not an ISO 8601 date-time (expected e.g. 2011-04-22T10:59+08:00)") from None
    if t.tzinfo is None or t.utcoffset() is None:
        raise LightError(
            f"{what} {s!r} has no UTC offset: add one, e.g. {s}+00:00 (or {s}Z) for UTC, "
            f"or the local offset such as {s}+08:00"
        )
    return t


def _split_weight(rest: str, spec: str) -> tuple[str, float]:
    """Split ``rest`` (the part after ``KIND:``) into its body and the ``@W`` weight; ``spec`` (the whole
    light) names the light in errors."""
    body, sep, w = rest.rpartition("@")
    if not sep:
        return rest, 1.0
    if not w.strip():
        raise LightError(f"light {spec!r}: empty weight after '@'")
    weight = _float(w, "weight", spec)
    if weight <= 0.0:
        raise LightError(f"light {spec!r}: weight must be > 0 (got {weight:g}); leave the light out instead")
    return body, weight


_KEY_RE = re.compile(r"^\s*([A-Za-z_]+)\s*=\s*(.*?)\s*$")


def _split_fields(body: str, spec: str) -> tuple[list[str], dict[str, str]]:
    pos, kw = [], {}
    for part in body.split(","):
        m = _KEY_RE.match(part)
        if m:
            key = m.group(1).lower()
            if key in kw:
                raise LightError(f"light {spec!r}: option {key!r} given twice")
            kw[key] = m.group(2)
        else:
            if kw:
                raise LightError(f"light {spec!r}: positional value {part.strip()!r} after key=value options")
            pos.append(part)
    return pos, kw


def _check_keys(kw: dict, allowed: tuple, spec: str) -> None:
    bad = sorted(set(kw) - set(allowed))
    if bad:
        raise LightError(f"light {spec!r}: unknown option(s) {', '.join(bad)} (allowed: {', '.join(allowed)})")


def _on_off(text: str, what: str, spec: str) -> bool:
    t = text.strip().lower()
    if t in ("on", "1", "true", "yes"):
        return True
    if t in ("off", "0", "false", "no"):
        return False
    raise LightError(f"light {spec!r}: {what} must be on or off, got {text!r}")


def parse_light(spec: str, default_time: datetime | str | None = None) -> Light:
    """Parse a light specification (CONVENTIONS.md) into a :class:`Light`.

    Parameters
    ----------
    spec : str
        ``point:X,Y,Z``, ``directional:X,Y,Z`` or ``sun:LAT,LON,TIME[,NORTH]``, each optionally followed
        by ``,key=value`` options and an ``@W`` weight suffix (see the module docstring).
    default_time : datetime or str, optional
        Used for a ``sun`` spec without TIME (``sun:LAT,LON`` or ``sun:LAT,LON,,NORTH``); must carry a
        UTC offset.

    Returns
    -------
    Light
        A sun below the horizon gives ``Light(above_horizon=False)`` (casts no shadow), not an error.

    Raises
    ------
    LightError
        Unknown kind, wrong number of values, non-numbers, zero or negative weight, a point light at or
        below the ground (z <= 0) or a directional light not above the horizon (z <= 0), latitude outside
        [-90, 90], longitude outside [-180, 180], unparseable time or time without a UTC offset.

    Examples
    --------
    >>> parse_light("point:0,0,2@3").homogeneous.tolist(), parse_light("point:0,0,2@3").weight
    ([0.0, 0.0, 2.0, 1.0], 3.0)
    >>> parse_light("directional:1,0,1").vector.round(4).tolist()
    [0.7071, 0.0, 0.7071]
    """
    if not isinstance(spec, str) or not spec.strip():
        raise LightError(
            f"empty light specification {spec!r} (expected point:X,Y,Z, directional:X,Y,Z or sun:LAT,LON,TIME)"
        )
    spec = spec.strip()
    kind, colon, rest = spec.partition(":")
    kind = kind.strip().lower()
    if not colon:
        raise LightError(f"light {spec!r}: expected KIND:VALUES with KIND point, directional or sun")
    body, weight = _split_weight(rest, spec)
    pos, kw = _split_fields(body, spec)

    if kind in ("point", "directional"):
        _check_keys(kw, ("radius",), spec)
        if len(pos) != 3:
            raise LightError(f"light {spec!r}: {kind} needs 3 values X,Y,Z, got {len(pos)}")
        v = np.array([_float(p, n, spec) for p, n in zip(pos, "XYZ", strict=True)])
        radius = _float(kw["radius"], "radius", spec) if "radius" in kw else 0.0
        if radius < 0:
            raise LightError(f"light {spec!r}: radius must be >= 0, got {radius:g}")
        if kind == "point":
            if v[2] <= 0.0:
                raise LightError(
                    f"light {spec!r}: a point light must be above the ground plane z = 0 (got z = {v[2]:g})"
                )
            if radius >= v[2]:
                raise LightError(
                    f"light {spec!r}: the light's sphere (radius {radius:g}) reaches the ground plane z = 0 "
                    f"(centre at z = {v[2]:g})"
                )
            return Light("point", v, weight=weight, radius=radius, label=spec)
        if not np.any(v):
            raise LightError(f"light {spec!r}: direction (0, 0, 0) has no direction")
        if v[2] <= 0.0:
            raise LightError(
                f"light {spec!r}: the direction towards a directional light must point up (z > 0), "
                f"got z = {v[2]:g}; the ground would get no light"
            )
        if radius >= 90.0:
            raise LightError(f"light {spec!r}: angular radius must be < 90 degrees, got {radius:g}")
        return Light("directional", v, weight=weight, radius=math.radians(radius), label=spec)

    if kind == "sun":
        return _parse_sun(spec, pos, kw, weight, default_time)

    raise LightError(f"light {spec!r}: unknown kind {kind!r} (expected point, directional or sun)")


_SUN_KEYS = ("elevation", "pressure", "temperature", "delta_t", "model", "refraction", "radius")


def _sun_params(
    spec: str, pos: list[str], kw: dict[str, str], default_time: datetime | str | None, need_time: bool = True
) -> dict[str, Any]:
    """Validated parameters of a ``sun:`` spec (LightError naming the spec on bad input)."""
    _check_keys(kw, _SUN_KEYS, spec)
    if not 2 <= len(pos) <= 4:
        raise LightError(f"light {spec!r}: sun needs LAT,LON,TIME[,NORTH], got {len(pos)} value(s)")
    lat = _float(pos[0], "latitude", spec)
    lon = _float(pos[1], "longitude", spec)
    if not -90.0 <= lat <= 90.0:
        raise LightError(f"light {spec!r}: latitude {lat:g} is outside [-90, 90]")
    if not -180.0 <= lon <= 180.0:
        raise LightError(f"light {spec!r}: longitude {lon:g} is outside [-180, 180] (east positive)")
    time_text = pos[2].strip() if len(pos) >= 3 else ""
    when = None
    if time_text:
        when = parse_time(time_text, what=f"light {spec!r}: time")
    elif default_time is not None:
        when = parse_time(default_time, "default time") if isinstance(default_time, str) else default_time
        if not isinstance(when, datetime) or when.utcoffset() is None:
            raise LightError(
                f"light {spec!r}: default time {default_time!r} must be an aware datetime (with a UTC offset)"
            )
    elif need_time:
        raise LightError(f"light {spec!r}: no TIME given (sun:LAT,LON,TIME with e.g. 2011-04-22T10:59+08:00)")
    north = _float(pos[3], "north bearing", spec) if len(pos) == 4 and pos[3].strip() else 0.0

    opts = {}
    for key in ("elevation", "pressure", "temperature", "delta_t"):
        if key in kw:
            opts[key] = _float(kw[key], key, spec)
    model = kw.get("model", "spa").strip().lower()
    refraction = _on_off(kw["refraction"], "refraction", spec) if "refraction" in kw else False
    radius_deg = _float(kw["radius"], "radius", spec) if "radius" in kw else None
    if radius_deg is not None and not 0.0 <= radius_deg < 90.0:
        raise LightError(f"light {spec!r}: angular radius must be in [0, 90) degrees, got {radius_deg:g}")
    kwargs = {"elevation": opts.get("elevation", 0.0), "model": model}
    if "pressure" in opts:
        kwargs["pressure_mbar"] = opts["pressure"]
    if "temperature" in opts:
        kwargs["temperature_c"] = opts["temperature"]
    if "delta_t" in opts:
        kwargs["delta_t"] = opts["delta_t"]
    return {
        "lat": lat,
        "lon": lon,
        "when": when,
        "north": north,
        "kwargs": kwargs,
        "refraction": refraction,
        "radius_deg": radius_deg,
    }


def sun_radius_deg(pos_sun: SunPosition | None, radius_deg: float | None = None) -> float:
    """Angular radius (degrees) to give a sun light: ``radius_deg`` when given (a spec's ``radius=``),
    else the sun's true angular radius for the date of ``pos_sun`` (SPA: 0.26656 deg / R[AU]; it varies
    0.262..0.271 over the year), else (paper models: no distance) the mean 0.266 deg."""
    if radius_deg is not None:
        return radius_deg
    r_au = pos_sun.extra.get("earth_sun_distance_au") if pos_sun is not None else None
    return SUN_SEMI_DIAMETER_1AU_DEG / r_au if r_au else SUN_ANGULAR_RADIUS_DEG


def _parse_sun(
    spec: str, pos: list[str], kw: dict[str, str], weight: float, default_time: datetime | str | None
) -> Light:
    p = _sun_params(spec, pos, kw, default_time)
    try:
        pos_sun = sun_position(p["when"], p["lat"], p["lon"], **p["kwargs"])
    except LightError as exc:
        raise LightError(f"light {spec!r}: {exc}") from None
    world, above = sun_light_direction(pos_sun, p["north"], refraction=p["refraction"])
    if not above:
        logging.getLogger(__name__).warning(
            f"light {spec!r}: the sun is below the horizon then (elevation "
            f"{90.0 - float(pos_sun.zenith_deg):.2f} deg): it casts no shadow and gives no light"
        )
    return Light(
        "directional",
        world,
        weight=weight,
        radius=math.radians(sun_radius_deg(pos_sun, p["radius_deg"])),
        label=spec,
        above_horizon=above,
        sun=pos_sun,
    )


def parse_sun_track(spec: str, recompute_deg: float = 0.1) -> SunLightTrack:
    """A :class:`SunLightTrack` for a ``sun:LAT,LON[,TIME][,NORTH]...[@W]`` spec (video time-lapse).

    The spec's place, NORTH, options and weight are used; TIME may be omitted (the frame times come from
    the video; a given TIME is kept as ``track.start``). ``track.light(frame)`` gives the :class:`Light` to
    render for a :class:`arshadow.lights.suntrack.TrackFrame` (direction ``frame.world_used``: the silhouette is
    recomputed only when ``frame.recompute``).

    Examples
    --------
    >>> from datetime import timedelta
    >>> tr = parse_sun_track("sun:48,11,2021-06-21T09:00+02:00,0@2", recompute_deg=0.5)
    >>> frames = tr.track([tr.start + timedelta(minutes=m) for m in range(10)])
    >>> li = tr.light(frames[-1]); li.weight, li.kind
    (2.0, 'directional')
    """
    if not isinstance(spec, str) or not spec.strip().lower().startswith("sun:"):
        raise LightError(f"a sun track needs a sun:LAT,LON[,TIME][,NORTH] spec, got {spec!r}")
    spec = spec.strip()
    body, weight = _split_weight(spec.partition(":")[2], spec)
    pos, kw = _split_fields(body, spec)
    p = _sun_params(spec, pos, kw, None, need_time=False)
    try:
        return SunLightTrack(
            p["lat"],
            p["lon"],
            north_deg=p["north"],
            recompute_deg=recompute_deg,
            refraction=p["refraction"],
            start=p["when"],
            weight=weight,
            label=spec,
            radius_deg=p["radius_deg"],
            **p["kwargs"],
        )
    except LightError as exc:
        raise LightError(f"light {spec!r}: {exc}") from None


class SunLightTrack(SunTrack):
    """A :class:`arshadow.lights.suntrack.SunTrack` that knows the light it stands for (:func:`parse_sun_track`).

    Parameters
    ----------
    lat, lon, ..., **kwargs
        As :class:`arshadow.lights.suntrack.SunTrack`.
    start : datetime or None
        The spec's TIME, if it had one.
    weight : float
        The light's weight.
    label : str
        The light's label (its spec).
    radius_deg : float or None
        Angular radius of the sun disc (None: the sun's true radius for each frame's date).
    """

    def __init__(
        self,
        *args: Any,
        start: datetime | None = None,
        weight: float = 1.0,
        label: str = "sun",
        radius_deg: float | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(*args, **kwargs)
        self.start, self.weight, self.label, self.radius_deg = start, float(weight), label, radius_deg

    def light(self, frame: TrackFrame) -> Light:
        """The :class:`Light` to render for a :class:`arshadow.lights.suntrack.TrackFrame`: direction
        ``frame.world_used`` (the one the cached silhouette belongs to), this track's weight and label, and
        angular radius ``radius_deg`` or, when None, the sun's true radius for the frame's date."""
        return Light(
            "directional",
            frame.world_used,
            weight=self.weight,
            radius=math.radians(sun_radius_deg(frame.position, self.radius_deg)),
            label=self.label,
            above_horizon=frame.above_horizon,
            sun=frame.position,
        )


def lights_homogeneous(lights: Iterable[Light]) -> np.ndarray:
    """``(k, 4)`` float64: the homogeneous vectors of ``lights`` (all of them, in order)."""
    return np.array([li.homogeneous for li in lights], dtype=np.float64).reshape(-1, 4)


def total_weight(lights: Iterable[Light]) -> float:
    """Sum of the weights of the lights that give light (a sun below the horizon gives none)."""
    return float(sum(li.weight for li in lights if li.above_horizon))


def __getattr__(name: str) -> object:
    """``sample_area_light`` and ``stratified_disc`` moved to :mod:`arshadow.lights.area` (the façade work); they stay
    importable from here for code written against this module."""
    if name in ("sample_area_light", "stratified_disc"):
        from . import area  # deferred: arshadow.lights.area imports this module (Light)

        return getattr(area, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
