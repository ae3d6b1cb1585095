"""The sun's position for an instant and a place, and its direction in the world frame.

The sun over a video's frames (:class:`~arshadow.lights.suntrack.SunTrack`, ``frame_times``) is in
:mod:`arshadow.lights.suntrack`; NREL's SPA itself in :mod:`arshadow.lights.spa`, its tables in
:mod:`arshadow.lights._spa_tables`.

Models
------
``"spa"`` (default)
    NREL's Solar Position Algorithm: I. Reda and A. Andreas, "Solar Position Algorithm for Solar
    Radiation Applications", NREL/TP-560-34302 (2003, revised 2008); stated uncertainty +-0.0003 deg for
    the years -2000..6000. Written here in numpy from the report, vectorised over times; the periodic-term
    tables (:mod:`arshadow.lights._spa_tables`) are transcribed from pvlib-python's ``pvlib/spa.py`` (BSD 3-Clause,
    Copyright (c) 2023 pvlib python Contributors). The zenith is topocentric (parallax and observer
    elevation included). ``zenith_deg`` is geometric (no refraction); ``apparent_zenith_deg`` applies the
    SPA's refraction correction (Bennett-type, scaled by pressure / 1010 mbar and 283 K / temperature,
    applied while the geometric elevation is above -(0.26667 + 0.5667) deg, the sun's radius plus the
    refraction at the horizon).
``"paper"``
    [Kolivand-Sun] (Kolivand et al. 2011), taken from Preetham et al. 1999 / Iqbal 1983: equations (2)-(5),
    with the azimuth CORRECTED: ``phi = atan2(-cos d sin(pi t/12), cos l sin d + sin l cos d cos(pi t/12))``
    (the paper prints ``-`` before the second term of the denominator and uses ``atan``, which loses the
    quadrant). ``phi`` is measured from north towards the WEST, so the compass azimuth is ``-phi``. The
    longitude term ``12 (SM - L) / pi`` needs west-positive longitudes (our longitudes are east-positive:
    ``L = -lon``); we evaluate it in UTC (standard meridian SM = 0, standard time = UTC hours, J = UTC
    day of the year). No refraction model: apparent = geometric.
``"paper-printed"``
    [Kolivand-Sun]'s azimuth exactly as printed (``atan``, ``-`` sign), same convention; for comparison only.

Frames
------
ENU: x east, y north, z up (unit vector TOWARDS the sun). World: the marker frame (z up); the world +y
axis has compass bearing ``north_deg`` (degrees clockwise from true north; 0: +y = north, +x = east), see
:func:`enu_to_world`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import LightError
from .spa import spa

__all__ = [
    "SunPosition",
    "MODELS",
    "sun_position",
    "sun_positions",
    "enu_to_world",
    "world_to_enu",
    "sun_light_direction",
    "pole_shadow",
    "delta_t_estimate",
    "standard_pressure_mbar",
    "angle_between_deg",
    "as_utc",
    "check_place",
]

MODELS = ("spa", "paper", "paper-printed")

_UNIX_EPOCH = datetime(1970, 1, 1, tzinfo=UTC)


# ----------------------------------------------------------------------------------------------- helpers


def standard_pressure_mbar(elevation_m: float) -> float:
    """Mean air pressure (mbar) at ``elevation_m`` metres, ICAO standard atmosphere (troposphere).

    Examples
    --------
    >>> round(standard_pressure_mbar(0.0), 2), round(standard_pressure_mbar(1830.14), 1)
    (1013.25, 811.9)
    """
    p: float = 1013.25 * (1.0 - 2.25577e-5 * float(elevation_m)) ** 5.25588
    return p


def delta_t_estimate(year: float) -> float:
    """TT - UT in seconds for a (decimal) year: Espenak & Meeus (NASA, 2006) polynomials, 1900..2150,
    and their long-term parabola outside. Its effect on the sun's direction is tiny (1 s of Delta T moves
    the sun by 4e-5 deg along the ecliptic).

    Examples
    --------
    >>> 60 < delta_t_estimate(2003.8) < 70
    True
    """
    y = float(year)
    if 1900 <= y < 1920:
        t = y - 1900
        return -2.79 + 1.494119 * t - 0.0598939 * t**2 + 0.0061966 * t**3 - 0.000197 * t**4
    if 1920 <= y < 1941:
        t = y - 1920
        return 21.20 + 0.84493 * t - 0.076100 * t**2 + 0.0020936 * t**3
    if 1941 <= y < 1961:
        t = y - 1950
        return 29.07 + 0.407 * t - t**2 / 233 + t**3 / 2547
    if 1961 <= y < 1986:
        t = y - 1975
        return 45.45 + 1.067 * t - t**2 / 260 - t**3 / 718
    if 1986 <= y < 2005:
        t = y - 2000
        return 63.86 + 0.3345 * t - 0.060374 * t**2 + 0.0017275 * t**3 + 0.000651814 * t**4 + 0.00002373599 * t**5
    if 2005 <= y < 2050:
        t = y - 2000
        return 62.92 + 0.32217 * t + 0.005589 * t**2
    if 2050 <= y < 2150:
        return -20 + 32 * ((y - 1820) / 100) ** 2 - 0.5628 * (2150 - y)
    u = (y - 1820) / 100
    return -20 + 32 * u * u


def as_utc(when: object) -> datetime:
    if not isinstance(when, datetime):
        raise LightError(f"time must be a datetime with a UTC offset, got {type(when).__name__}")
    if when.tzinfo is None or when.utcoffset() is None:
        raise LightError(
            f"time {when.isoformat()} has no UTC offset: pass an aware datetime "
            "(e.g. datetime(..., tzinfo=timezone.utc)) or add +HH:MM / Z to the ISO string"
        )
    return when.astimezone(UTC)


def check_place(lat: float, lon: float, elevation: float) -> tuple[float, float, float]:
    lat, lon, elevation = float(lat), float(lon), float(elevation)
    if not math.isfinite(lat) or not -90.0 <= lat <= 90.0:
        raise LightError(f"latitude {lat:g} is outside [-90, 90]")
    if not math.isfinite(lon) or not -180.0 <= lon <= 180.0:
        raise LightError(f"longitude {lon:g} is outside [-180, 180] (east positive)")
    if not math.isfinite(elevation) or not -500.0 <= elevation <= 50000.0:
        raise LightError(f"elevation {elevation:g} m is outside [-500, 50000]")
    return lat, lon, elevation


def _enu(zenith_deg: npt.ArrayLike, azimuth_deg: npt.ArrayLike) -> np.ndarray:
    z, a = np.radians(zenith_deg), np.radians(azimuth_deg)
    s = np.sin(z)
    return np.stack([s * np.sin(a), s * np.cos(a), np.cos(z)], axis=-1)


def angle_between_deg(a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    """Angle in degrees between unit vectors ``a`` and ``b`` (``(..., 3)``), accurate for tiny angles."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    deg: np.ndarray = np.degrees(2.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1)))
    return deg


# ------------------------------------------------------------------------------------------ [Kolivand-Sun]


def _paper(when_utc: list[datetime], lat: float, lon: float, printed: bool) -> dict[str, np.ndarray]:
    """[Kolivand-Sun] eq. (2)-(5) in UTC (SM = 0), west-positive longitude ``L = -lon``."""
    j = np.array([w.timetuple().tm_yday for w in when_utc], dtype=np.float64)  # day of the year, 1..366
    ts = np.array([w.hour + w.minute / 60 + (w.second + w.microsecond / 1e6) / 3600 for w in when_utc])
    sm, L = 0.0, math.radians(-lon)
    t = (
        ts
        + 0.170 * np.sin(4 * np.pi * (j - 80) / 373)
        - 0.129 * np.sin(2 * np.pi * (j - 8) / 355)
        + 12 * (sm - L) / np.pi
    )
    d = 0.4093 * np.sin(2 * np.pi * (j - 81) / 368)
    la = math.radians(lat)
    w = np.pi * t / 12
    zen = np.pi / 2 - np.arcsin(np.clip(np.sin(la) * np.sin(d) - np.cos(la) * np.cos(d) * np.cos(w), -1, 1))
    num = -np.cos(d) * np.sin(w)
    if printed:
        den = np.cos(la) * np.sin(d) - np.sin(la) * np.cos(d) * np.cos(w)
        with np.errstate(divide="ignore", invalid="ignore"):
            phi = np.arctan(num / den)
        phi = np.where(np.isfinite(phi), phi, np.sign(num) * np.pi / 2)
    else:
        den = np.cos(la) * np.sin(d) + np.sin(la) * np.cos(d) * np.cos(w)
        phi = np.arctan2(num, den)
    azimuth = np.degrees(-phi) % 360.0  # phi is counted from north towards west
    zen = np.degrees(zen)
    return {
        "zenith": zen,
        "apparent_zenith": zen,
        "azimuth": azimuth,
        "declination": np.degrees(d),
        "hour_angle": np.degrees(w - np.pi),
    }


# --------------------------------------------------------------------------------------------- public


@dataclass(frozen=True, eq=False)
class SunPosition:
    """The sun seen from one place at one instant.

    Attributes
    ----------
    zenith_deg : float
        Topocentric zenith angle without refraction (geometric), degrees.
    apparent_zenith_deg : float
        With the model's refraction correction (``== zenith_deg`` for the paper models).
    azimuth_deg : float
        Compass azimuth, degrees clockwise from true north, in [0, 360).
    enu : (3,) float64
        Unit vector towards the (geometric) sun in east-north-up coordinates.
    above_horizon : bool
        ``zenith_deg < 90`` (geometric).
    when : datetime
        The instant (aware; as given).
    latitude, longitude, elevation : float
        Degrees (north +, east +) and metres.
    model : str
    declination_deg, hour_angle_deg : float
        Topocentric declination and local hour angle (0 at solar noon, + westward).
    """

    zenith_deg: float
    apparent_zenith_deg: float
    azimuth_deg: float
    enu: np.ndarray
    above_horizon: bool
    when: datetime | None = None
    latitude: float = 0.0
    longitude: float = 0.0
    elevation: float = 0.0
    model: str = "spa"
    declination_deg: float = float("nan")
    hour_angle_deg: float = float("nan")
    extra: dict[str, Any] = field(default_factory=dict, repr=False)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SunPosition):
            return NotImplemented
        return (
            self.zenith_deg,
            self.apparent_zenith_deg,
            self.azimuth_deg,
            self.when,
            self.latitude,
            self.longitude,
            self.elevation,
            self.model,
        ) == (
            other.zenith_deg,
            other.apparent_zenith_deg,
            other.azimuth_deg,
            other.when,
            other.latitude,
            other.longitude,
            other.elevation,
            other.model,
        )

    def __hash__(self) -> int:
        return hash((self.zenith_deg, self.azimuth_deg, self.when, self.model))

    @property
    def elevation_deg(self) -> float:
        """Geometric elevation angle above the horizon, degrees."""
        return 90.0 - self.zenith_deg

    @property
    def apparent_enu(self) -> np.ndarray:
        """``(3,)`` unit vector towards the apparent (refracted) sun, ENU."""
        return _enu(self.apparent_zenith_deg, self.azimuth_deg)

    @property
    def apparent_above_horizon(self) -> bool:
        """``apparent_zenith_deg < 90``: the refracted sun centre is above the horizon."""
        return bool(self.apparent_zenith_deg < 90.0)


def sun_positions(
    times: Iterable[datetime],
    lat: float,
    lon: float,
    elevation: float = 0.0,
    model: str = "spa",
    pressure_mbar: float | None = None,
    temperature_c: float = 12.0,
    delta_t: float | None = None,
) -> list[SunPosition]:
    """Vectorised :func:`sun_position` for a sequence of aware datetimes (one place)."""
    times = list(times)
    model = str(model).lower()
    if model not in MODELS:
        raise LightError(f"unknown sun model {model!r} (choose from {', '.join(MODELS)})")
    lat, lon, elevation = check_place(lat, lon, elevation)
    pressure = standard_pressure_mbar(elevation) if pressure_mbar is None else float(pressure_mbar)
    temp = float(temperature_c)
    if not (math.isfinite(pressure) and 0.0 <= pressure <= 2000.0):
        raise LightError(f"pressure {pressure:g} mbar is outside [0, 2000]")
    if not (math.isfinite(temp) and -100.0 < temp < 100.0):
        raise LightError(f"temperature {temp:g} deg C is outside (-100, 100)")
    if not times:
        return []
    utc = [as_utc(w) for w in times]
    if model == "spa":
        jd = np.array([(u - _UNIX_EPOCH) / timedelta(days=1) + 2440587.5 for u in utc])
        if delta_t is None:
            dt = np.array([delta_t_estimate(u.year + (u.timetuple().tm_yday - 0.5) / 365.25) for u in utc])
        else:
            dt_s = float(delta_t)
            if not (math.isfinite(dt_s) and abs(dt_s) < 1e5):
                raise LightError(f"delta_t {delta_t!r} s is not a plausible TT - UT")
            dt = np.full(len(utc), dt_s)
        r = spa(jd, dt, lat, lon, elevation, pressure, temp)
        r_au = r["earth_sun_distance_au"]
    else:
        dt = np.full(len(utc), np.nan)
        r = _paper(utc, lat, lon, printed=(model == "paper-printed"))
        r_au = np.full(len(utc), np.nan)
    enu = _enu(r["zenith"], r["azimuth"])
    out = []
    for i, w in enumerate(times):
        v = enu[i].copy()
        v.setflags(write=False)
        out.append(
            SunPosition(
                zenith_deg=float(r["zenith"][i]),
                apparent_zenith_deg=float(r["apparent_zenith"][i]),
                azimuth_deg=float(r["azimuth"][i]),
                enu=v,
                above_horizon=bool(r["zenith"][i] < 90.0),
                when=w,
                latitude=lat,
                longitude=lon,
                elevation=elevation,
                model=model,
                declination_deg=float(r["declination"][i]),
                hour_angle_deg=float(((r["hour_angle"][i] + 180.0) % 360.0) - 180.0),
                extra={
                    "pressure_mbar": pressure,
                    "temperature_c": temp,
                    "delta_t": float(dt[i]),
                    "earth_sun_distance_au": None if np.isnan(r_au[i]) else float(r_au[i]),
                },
            )
        )
    return out


def sun_position(
    when: datetime,
    lat: float,
    lon: float,
    elevation: float = 0.0,
    model: str = "spa",
    pressure_mbar: float | None = None,
    temperature_c: float = 12.0,
    delta_t: float | None = None,
) -> SunPosition:
    """Zenith, azimuth and direction of the sun at an instant, seen from a place.

    Parameters
    ----------
    when : datetime
        Timezone-aware instant (a naive datetime is refused: LightError).
    lat, lon : float
        Degrees, north and EAST positive.
    elevation : float
        Observer height above sea level, metres (SPA parallax and default pressure).
    model : {"spa", "paper", "paper-printed"}
        See the module docstring.
    pressure_mbar : float, optional
        Annual mean local pressure for the refraction correction; default: standard atmosphere at
        ``elevation``.
    temperature_c : float
        Annual mean local temperature for the refraction correction (default 12).
    delta_t : float, optional
        TT - UT in seconds; default :func:`delta_t_estimate` for the date.

    Returns
    -------
    SunPosition

    Raises
    ------
    LightError
        Naive time, latitude outside [-90, 90], longitude outside [-180, 180], unknown model, absurd
        pressure / temperature / elevation.

    Examples
    --------
    SPA report worked example (Reda & Andreas, Table A5.1):

    >>> from datetime import datetime, timedelta, timezone
    >>> t = datetime(2003, 10, 17, 12, 30, 30, tzinfo=timezone(timedelta(hours=-7)))
    >>> s = sun_position(t, 39.742476, -105.1786, 1830.14, pressure_mbar=820, temperature_c=11, delta_t=67)
    >>> round(s.apparent_zenith_deg, 5), round(s.zenith_deg, 5), round(s.azimuth_deg, 5)
    (50.11162, 50.12795, 194.34024)
    """
    return sun_positions([when], lat, lon, elevation, model, pressure_mbar, temperature_c, delta_t)[0]


def enu_to_world(enu: npt.ArrayLike, north_deg: float = 0.0) -> np.ndarray:
    """Rotate an east-north-up vector into the world frame whose +y axis has compass bearing ``north_deg``.

    ``north_deg`` is the bearing of world +y in degrees clockwise from true north (CONVENTIONS.md); world
    +x then has bearing ``north_deg + 90`` and world +z is up. A rotation about z by ``+north_deg``
    (counter-clockwise seen from above)::

        x =  e cos N - n sin N,   y = e sin N + n cos N,   z = u

    Parameters
    ----------
    enu : (3,) or (n, 3) float64
    north_deg : float

    Returns
    -------
    (3,) or (n, 3) float64

    Examples
    --------
    >>> enu_to_world([1.0, 0.0, 0.0], 90.0).round(12).tolist()   # east, world +y points east
    [0.0, 1.0, 0.0]
    """
    v = np.array(enu, dtype=np.float64)
    if v.shape[-1:] != (3,) or v.ndim > 2:
        raise LightError(f"enu vector must have shape (3,) or (n, 3), got {v.shape}")
    n = float(north_deg)
    if not math.isfinite(n):
        raise LightError(f"north bearing {north_deg!r} is not finite")
    c, s = math.cos(math.radians(n)), math.sin(math.radians(n))
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    out: np.ndarray = v @ rot.T
    return out


def world_to_enu(world: npt.ArrayLike, north_deg: float = 0.0) -> np.ndarray:
    """Inverse of :func:`enu_to_world`."""
    return enu_to_world(world, -float(north_deg))


def sun_light_direction(pos: SunPosition, north_deg: float = 0.0, refraction: bool = False) -> tuple[np.ndarray, bool]:
    """The world-frame unit direction towards the sun and whether it is above the horizon.

    ``refraction=False`` (default): the geometric direction and ``pos.above_horizon``, matching
    ``zenith_deg``; ``True``: the apparent (refracted) direction and ``pos.apparent_above_horizon``.

    Returns
    -------
    ((3,) float64, bool)
    """
    enu = pos.apparent_enu if refraction else np.array(pos.enu)
    above = pos.apparent_above_horizon if refraction else pos.above_horizon
    return enu_to_world(enu, north_deg), bool(above)


def pole_shadow(direction_world: npt.ArrayLike, height: float = 1.0, north_deg: float = 0.0) -> dict[str, Any] | None:
    """Shadow of a vertical pole of ``height`` standing at the world origin, cast on the ground z = 0.

    Parameters
    ----------
    direction_world : (3,) float64
        Unit direction towards the (directional) light, world frame.

    Returns
    -------
    dict or None
        ``None`` when the light is not above the horizon (``z <= 0``: no shadow). Otherwise
        ``{"tip_world": [x, y], "length": L, "bearing_deg": B}``: the shadow tip on the ground, its length
        in metres, and its compass bearing (clockwise from true north) from the foot of the pole.

    Examples
    --------
    >>> s = pole_shadow([0.0, -0.6, 0.8])           # sun in the south, 36.87 deg high
    >>> round(s["length"], 6), round(s["bearing_deg"], 6)
    (0.75, 0.0)
    """
    d = np.asarray(direction_world, dtype=np.float64)
    if d[2] <= 0.0:
        return None
    tip = -d[:2] * (float(height) / d[2])  # top (0,0,h) moved along -d until z = 0
    e, n, _ = world_to_enu(np.array([tip[0], tip[1], 0.0]), north_deg)
    return {
        "tip_world": tip.tolist(),
        "length": float(np.hypot(tip[0], tip[1])),
        "bearing_deg": float(math.degrees(math.atan2(e, n)) % 360.0),
    }


def __getattr__(name: str) -> object:
    """``SunTrack``, ``TrackFrame`` and ``frame_times`` moved to :mod:`arshadow.lights.suntrack`; still
    importable from here (earlier releases and user code import them from this module)."""
    if name in ("SunTrack", "TrackFrame", "frame_times"):
        from . import suntrack  # deferred: suntrack imports this module (a top-level import would be a cycle)

        return getattr(suntrack, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
