"""The NREL Solar Position Algorithm (SPA; Reda & Andreas 2004, NREL/TP-560-34302), vectorised over time.

Pure numpy: Julian days in, the sun's topocentric zenith / azimuth (and the intermediate quantities) out,
with the report's periodic-term tables (:mod:`arshadow.lights._spa_tables`). :mod:`arshadow.lights.sun` turns
datetimes and places into the arguments and the result into :class:`arshadow.lights.sun.SunPosition`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from . import _spa_tables as T

__all__ = ["spa", "ATMOS_REFRACT_DEG"]

#: the SPA's default atmospheric refraction at sunrise/sunset, degrees
ATMOS_REFRACT_DEG = 0.5667
#: the sun's radius used by the SPA's refraction switch, degrees
_SPA_SUN_RADIUS_DEG = 0.26667


def _periodic(table: np.ndarray, jme: np.ndarray) -> np.ndarray:
    # sum_i A_i cos(B_i + C_i * JME)  (SPA eq. 9)
    s: np.ndarray = np.sum(table[:, 0] * np.cos(table[:, 1] + table[:, 2] * jme[..., None]), axis=-1)
    return s


def _series(tables: Sequence[np.ndarray], jme: np.ndarray) -> np.ndarray:
    # (L0 + L1 JME + L2 JME^2 + ...) / 1e8  (SPA eq. 10-11)
    s: np.ndarray = sum(_periodic(t, jme) * jme**i for i, t in enumerate(tables)) / 1e8
    return s


def spa(
    jd: npt.ArrayLike, delta_t: np.ndarray | float, lat: float, lon: float, elev: float, pressure: float, temp: float
) -> dict[str, np.ndarray]:
    """NREL SPA (report section 3) for Julian days ``jd`` (UT). Returns a dict of arrays (degrees)."""
    jd = np.asarray(jd, dtype=np.float64)
    jde = jd + delta_t / 86400.0  # 3.1.2
    jc = (jd - 2451545.0) / 36525.0  # 3.1.3
    jce = (jde - 2451545.0) / 36525.0  # 3.1.4
    jme = jce / 10.0  # 3.1.5

    # 3.2 heliocentric longitude, latitude, radius vector
    L = np.degrees(_series((T.L0, T.L1, T.L2, T.L3, T.L4, T.L5), jme)) % 360.0
    B = np.degrees(_series((T.B0, T.B1), jme))
    R = _series((T.R0, T.R1, T.R2, T.R3, T.R4), jme)

    # 3.3 geocentric longitude and latitude
    theta = (L + 180.0) % 360.0
    beta = -B

    # 3.4 nutation in longitude and obliquity
    x = np.stack(
        [
            297.85036 + 445267.111480 * jce - 0.0019142 * jce**2 + jce**3 / 189474.0,  # mean elongation moon-sun
            357.52772 + 35999.050340 * jce - 0.0001603 * jce**2 - jce**3 / 300000.0,  # mean anomaly sun
            134.96298 + 477198.867398 * jce + 0.0086972 * jce**2 + jce**3 / 56250.0,  # mean anomaly moon
            93.27191 + 483202.017538 * jce - 0.0036825 * jce**2 + jce**3 / 327270.0,  # moon arg. of latitude
            125.04452 - 1934.136261 * jce + 0.0020708 * jce**2 + jce**3 / 450000.0,  # moon ascending node
        ],
        axis=-1,
    )
    arg = np.radians(x @ T.NUTATION_YTERM_ARRAY.T.astype(np.float64))  # (..., 63)
    abcd = T.NUTATION_ABCD_ARRAY
    d_psi = np.sum((abcd[:, 0] + abcd[:, 1] * jce[..., None]) * np.sin(arg), axis=-1) / 36e6
    d_eps = np.sum((abcd[:, 2] + abcd[:, 3] * jce[..., None]) * np.cos(arg), axis=-1) / 36e6

    # 3.5 true obliquity of the ecliptic
    u = jme / 10.0
    eps0 = np.polyval([2.45, 5.79, 27.87, 7.12, -39.05, -249.67, -51.38, 1999.25, -1.55, -4680.93, 84381.448], u)
    eps = eps0 / 3600.0 + d_eps

    # 3.6-3.7 aberration, apparent sun longitude
    d_tau = -20.4898 / (3600.0 * R)
    lam = theta + d_psi + d_tau

    # 3.8 apparent sidereal time at Greenwich
    nu0 = (280.46061837 + 360.98564736629 * (jd - 2451545.0) + 0.000387933 * jc**2 - jc**3 / 38710000.0) % 360.0
    nu = nu0 + d_psi * np.cos(np.radians(eps))

    # 3.9-3.10 geocentric right ascension and declination
    lam_r, eps_r, beta_r = np.radians(lam), np.radians(eps), np.radians(beta)
    alpha = (
        np.degrees(np.arctan2(np.sin(lam_r) * np.cos(eps_r) - np.tan(beta_r) * np.sin(eps_r), np.cos(lam_r))) % 360.0
    )
    delta = np.degrees(np.arcsin(np.sin(beta_r) * np.cos(eps_r) + np.cos(beta_r) * np.sin(eps_r) * np.sin(lam_r)))

    # 3.11 observer local hour angle (westward from south)
    H = (nu + lon - alpha) % 360.0

    # 3.12 topocentric right ascension and declination (parallax)
    xi = np.radians(8.794 / (3600.0 * R))
    lat_r = math.radians(lat)
    uu = math.atan(0.99664719 * math.tan(lat_r))
    xx = math.cos(uu) + elev / 6378140.0 * math.cos(lat_r)
    yy = 0.99664719 * math.sin(uu) + elev / 6378140.0 * math.sin(lat_r)
    H_r, delta_r = np.radians(H), np.radians(delta)
    d_alpha = np.arctan2(-xx * np.sin(xi) * np.sin(H_r), np.cos(delta_r) - xx * np.sin(xi) * np.cos(H_r))
    delta_p = np.arctan2(
        (np.sin(delta_r) - yy * np.sin(xi)) * np.cos(d_alpha), np.cos(delta_r) - xx * np.sin(xi) * np.cos(H_r)
    )

    # 3.13 topocentric local hour angle
    H_p = H_r - d_alpha

    # 3.14 topocentric zenith angle
    e0 = np.degrees(np.arcsin(np.sin(lat_r) * np.sin(delta_p) + np.cos(lat_r) * np.cos(delta_p) * np.cos(H_p)))
    refr = np.where(
        e0 >= -(_SPA_SUN_RADIUS_DEG + ATMOS_REFRACT_DEG),
        (pressure / 1010.0) * (283.0 / (273.0 + temp)) * 1.02 / (60.0 * np.tan(np.radians(e0 + 10.3 / (e0 + 5.11)))),
        0.0,
    )
    e = e0 + refr

    # 3.15 topocentric azimuth (astronomers' from south, westward) -> navigators' (from north, eastward)
    gamma = np.degrees(np.arctan2(np.sin(H_p), np.cos(H_p) * np.sin(lat_r) - np.tan(delta_p) * np.cos(lat_r)))
    azimuth = (gamma + 180.0) % 360.0
    return {
        "zenith": 90.0 - e0,
        "apparent_zenith": 90.0 - e,
        "azimuth": azimuth,
        "declination": np.degrees(delta_p),
        "hour_angle": np.degrees(H_p),
        "earth_sun_distance_au": R,
    }
