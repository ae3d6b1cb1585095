"""The light's angular size from the softness of the probe's real shadow (the penumbra).

Analysis by synthesis again: with the fitted light's centre direction fixed, the probe's shadow of a disc
light of angular radius ``r`` is the mean of the exact hard shadows of directions spread uniformly (in solid
angle) over the cone of half-angle ``r`` (:func:`disc_coverage`); its high-passed coverage is matched to the
high-passed photo (:func:`arshadow.estimate.shadow.fit_levels`) for ``r`` on a grid of 0..10 degrees, and the
minimum is refined by a parabola through its neighbours. The camera's own blur softens the photographed
edge too: ``r`` is then an upper bound of the light's size (a blur of ``b`` pixels at ground distance
``D`` from the camera reads as about ``b * D / f`` metres of penumbra).

Directional lights (and the sun, whose size is known) only; a point light's sphere radius is not fitted.
"""

from __future__ import annotations

import math

import numpy as np

from .shadow import Evidence, fit_levels, shadow_coverage

__all__ = ["RADII_DEG", "cone_directions", "disc_coverage", "fit_angular_radius"]

#: the angular radii (degrees) scored before the parabolic refinement
RADII_DEG = (0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.5, 8.0, 10.0)


def cone_directions(direction: np.ndarray, radius_deg: float, n: int = 32) -> np.ndarray:
    """``n`` unit directions uniform in solid angle within the cone of half-angle ``radius_deg`` around
    ``direction`` (a sunflower pattern; deterministic): (n, 3) float64; ``direction[None]`` for radius 0.

    >>> d = cone_directions([0.0, 0.0, 1.0], 2.0)
    >>> d.shape, bool(np.all(d[:, 2] >= math.cos(math.radians(2.0)) - 1e-12))
    ((32, 3), True)
    """
    z = np.asarray(direction, np.float64)
    z = z / np.linalg.norm(z)
    if radius_deg <= 0.0:
        return z[None]
    k = np.arange(n) + 0.5
    cos_t = 1.0 - (k / n) * (1.0 - math.cos(math.radians(radius_deg)))
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t**2))
    a = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(z, a)
    out: np.ndarray = cos_t[:, None] * z + sin_t[:, None] * (np.cos(phi)[:, None] * a + np.sin(phi)[:, None] * b)
    return out


def disc_coverage(ev: Evidence, direction: np.ndarray, radius_deg: float) -> np.ndarray | None:
    """The probe's ground shadow of a disc light (angular radius ``radius_deg`` around ``direction``) as
    coverage of the evidence's grid: (ny, nx) float32 in [0, 1], or None (a direction casts no shadow)."""
    acc = None
    dirs = cone_directions(direction, radius_deg)
    for d in dirs:
        S = shadow_coverage(ev, np.append(d, 0.0))
        if S is None:
            return None
        acc = S if acc is None else acc + S
    return None if acc is None else acc / np.float32(len(dirs))


def _score(evs: list[Evidence], direction: np.ndarray, r: float) -> float:
    total = 0.0
    for ev in evs:
        S = disc_coverage(ev, direction, r)
        if S is None:
            return math.inf
        rss, _, rss0, _ = fit_levels(ev, S)
        total += rss / rss0 if math.isfinite(rss0) and rss0 > 0 else 1.0
    return total


def fit_angular_radius(evs: list[Evidence], direction: np.ndarray) -> tuple[float, dict]:
    """The light's angular radius (degrees) that best explains the shadow's softness in the evidence grids
    ``evs`` (one per frame) for the light's centre ``direction`` (3,).

    Returns
    -------
    radius_deg : float
        0 when the hard shadow explains the photo best.
    scores : dict
        ``{radius: score}`` of the grid (sum over frames of RSS / RSS without a shadow).
    """
    radii = np.array(RADII_DEG)
    scores = np.array([_score(evs, direction, r) for r in radii])
    i = int(np.argmin(scores))
    r = float(radii[i])
    if 0 < i < len(radii) - 1 and np.all(np.isfinite(scores[i - 1 : i + 2])):
        x0, x1, x2 = radii[i - 1 : i + 2]
        y0, y1, y2 = scores[i - 1 : i + 2]
        # the vertex of the parabola through the three points (non-uniform spacing)
        den = (x0 - x1) * (x0 - x2) * (x1 - x2)
        A = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
        B = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / den
        if A > 0:
            r = float(np.clip(-B / (2 * A), x0, x2))
    return r, {float(k): round(float(v), 5) for k, v in zip(radii, scores, strict=True)}
