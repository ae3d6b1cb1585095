"""Fit the light to the probe's real shadow by analysis by synthesis.

For a candidate light the probe's exact ground shadow is drawn on each frame's ground grid as the photo's
samples see it (:func:`arshadow.estimate.shadow.shadow_coverage`) and the photo explained by it
(:func:`arshadow.estimate.shadow.fit_levels`); the objective is the sum over frames of ``RSS / RSS0`` (the
residual left by the shadow model, relative to no shadow at all). The light is fixed in the world, so
frames of a video add up.

Search, coarse to fine: an exhaustive grid on a coarse ground grid (directional: azimuth x elevation every
8 x 6 degrees; sun: NORTH every 3 degrees), then Nelder-Mead on the fine grid from the three best distinct
coarse minima, then again on the winner's own fine grid with the shadow's soft edges modelled in log
(:func:`log_coverage`: a linear-coverage model makes the shadow too small, the light too high); a point
light is fitted as (azimuth, elevation, log distance) from the probe's top (the directional fit, the
objective's profile over the distance on the coarse grid, a coarse 3-D grid, then Nelder-Mead in 3-D, in
log too), up to :data:`MAX_POINT_DISTANCE` (a fit that runs there is a directional light's: refused).
The uncertainty is the Laplace approximation of the least-squares fit (numerical Hessian of the RSS, the
noise variance from the residual, inflated by the residual's spatial correlation).

Refusals (:class:`arshadow.errors.EstimateError`): no shadow darker than 5 % or explaining < 2 % of the
variance (flat light), a second distinct minimum nearly as good (ambiguous), a fit whose own uncertainty
leaves the light unconstrained (> :data:`UNCONSTRAINED_DEG`: too little of the shadow in view or not
hidden behind the probe; the visible share alone refuses nothing).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import EstimateError
from ..lights.sun import enu_to_world
from .shadow import Evidence, fit_levels, shadow_coverage

#: parameters (k,) -> the light's homogeneous (4,) vector, None outside the fit's domain
ToLight = Callable[[np.ndarray], "np.ndarray | None"]
#: parameters (k,) -> the unit direction (3,) towards the light
ToDir = Callable[[np.ndarray], np.ndarray]
#: lights' homogeneous vectors -> per frame, a fine evidence grid covering their shadows
MakeFine = Callable[[list], list[Evidence]]

__all__ = ["FitResult", "direction_of", "fit_directional", "fit_point", "fit_sun", "log_coverage", "objective"]

#: minimum darkening (1 - shadow ratio) of a shadow worth fitting
MIN_DARKENING = 0.05
#: minimum share of the ground's variance that the shadow must explain
MIN_EXPLAINED = 0.02
#: a point light's fit stops this far from the probe's top (metres): its shadow is a directional light's
MAX_POINT_DISTANCE = 100.0
#: a fit whose 1-sigma direction uncertainty exceeds this (degrees) leaves the light unconstrained: refused
UNCONSTRAINED_DEG = 10.0
#: a second minimum this close (relative explained variance) and > 15 degrees away is ambiguous
AMBIGUOUS = 0.85


def _minimize(*args: Any, **kwargs: Any) -> Any:
    """``scipy.optimize.minimize``, imported on first use: every video or photo session imports this
    package (the exposure match), and ``scipy.optimize`` costs ~0.4 s of start-up that only a light fit
    needs (a ``--jobs`` worker paid it too)."""
    from scipy.optimize import minimize  # deferred: see the docstring

    return minimize(*args, **kwargs)


@dataclass
class FitResult:
    """A fitted light: ``light_h`` (4,), its parameters, the objective, the shadow's log darkness per frame,
    a 1-sigma uncertainty (degrees of direction; metres of position for a point light), diagnostics, the
    fine evidence it was refined on and (point light) the 2-sigma interval of its distance from the probe's
    top, metres."""

    light_h: np.ndarray
    params: np.ndarray
    score: float
    deltas: list
    uncertainty_deg: float
    position_sigma: float | None
    explained: float
    visible: float
    runner_up: float | None
    evaluations: int
    fine: list
    distance_interval: tuple | None = None


def direction_of(az_deg: float, el_deg: float) -> np.ndarray:
    """Unit vector towards a light at azimuth ``az_deg`` (from +x towards +y) and elevation ``el_deg``."""
    a, e = math.radians(az_deg), math.radians(el_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def log_coverage(S: np.ndarray, delta: float) -> np.ndarray:
    """The shadow's coverage ``S`` (ny, nx) as it darkens the log luminance of a shadow of log darkness
    ``delta`` (< 0): ``log(1 - a S) / log(1 - a)``, ``a = 1 - exp(delta)``; 0 and 1 where ``S`` is, but at a
    soft edge (the photo's blur mixes light linearly) deeper than ``S``. Fitting ``S`` itself to the log
    luminance would make every edge of the shadow look a fraction of the blur inside its place: a shadow
    too small by a constant margin, which a point light fits by moving away (a less divergent shadow)."""
    a = float(np.clip(1.0 - math.exp(delta), 0.02, 0.98))
    return (np.log1p(-a * S) / math.log1p(-a)).astype(np.float32)


def objective(evs: list[Evidence], light_h: np.ndarray | None, darkness: Sequence[float] | None = None) -> tuple:
    """``(score, deltas, rss list)``: sum over frames of RSS / RSS0, and each frame's log darkness.
    ``darkness``: optional per-frame log darkness; given, the shadow model is :func:`log_coverage`."""
    score, deltas, parts = 0.0, [], []
    if light_h is None:  # a parameter outside the fit's domain (ToLight): no light, as no shadow
        return math.inf, [], []
    for i, ev in enumerate(evs):
        S = shadow_coverage(ev, light_h)
        if S is None:
            return math.inf, [], []
        if darkness is not None:
            S = log_coverage(S, darkness[i])
        rss, delta, rss0, n = fit_levels(ev, S)
        if not math.isfinite(rss0) or rss0 <= 0:
            score += 1.0
            deltas.append(0.0)
            parts.append((rss0, rss0, n))
            continue
        if delta >= 0.0:  # a "shadow" brighter than the ground: no shadow
            rss = rss0
        score += rss / rss0
        deltas.append(delta)
        parts.append((rss, rss0, n))
    return score, deltas, parts


class _Counter:
    def __init__(self, evs: list[Evidence], to_light: ToLight, darkness: Sequence[float] | None = None) -> None:
        self.evs, self.to_light, self.n, self.darkness = evs, to_light, 0, darkness

    def __call__(self, p: np.ndarray) -> float:
        self.n += 1
        h = self.to_light(np.asarray(p, np.float64))
        return math.inf if h is None else float(objective(self.evs, h, self.darkness)[0])


def _visible_share(evs: list[Evidence], light_h: np.ndarray) -> float:
    """Used share of the fitted shadow's area (the rest is off-image, behind the probe or saturated)."""
    tot = vis = 0.0
    for ev in evs:
        S = shadow_coverage(ev, light_h)
        if S is None:
            return 0.0
        tot += float(S.sum())
        vis += float(S[ev.used].sum())
    return vis / tot if tot > 0 else 0.0


def _correlation_factor(evs: list[Evidence], light_h: np.ndarray, darkness: Sequence[float] | None = None) -> float:
    """How many cells one independent residual spans: ((1 + rho) / (1 - rho))^2, rho the lag-1 correlation
    of the fit's residual along the grid's rows and columns (capped to [1, 400])."""
    f = []
    for i, ev in enumerate(evs):
        S = shadow_coverage(ev, light_h)
        assert S is not None  # the fitted light, whose objective was finite: it casts a shadow
        if darkness is not None:
            S = log_coverage(S, darkness[i])
        _, delta, _, _ = fit_levels(ev, S)
        r = np.where(ev.used, ev.log_y - delta * S, np.nan)
        r = r - np.nanmean(r)
        pairs = [(r[:, 1:], r[:, :-1]), (r[1:, :], r[:-1, :])]
        num = sum(np.nansum(a * b) for a, b in pairs)
        den = sum(np.nansum(np.where(np.isfinite(a * b), a * a, 0.0)) for a, b in pairs)
        rho = float(np.clip(num / den if den > 0 else 0.0, 0.0, 0.95))
        f.append(((1 + rho) / (1 - rho)) ** 2)
    return float(np.clip(np.mean(f), 1.0, 400.0))


def _laplace(
    evs: list[Evidence], to_light: ToLight, p: np.ndarray, steps: np.ndarray, darkness: Sequence[float] | None = None
) -> np.ndarray:
    """Covariance of the parameters ``p`` from the numerical Hessian of the summed RSS.

    The RSS of a rasterised shadow is piecewise smooth at the finest steps: a Hessian that is not positive
    definite there is measured again at 3x and 10x the steps (a curvature over a wider span) before the fit is
    called unconstrained (an infinite covariance)."""
    cov = np.full((len(p), len(p)), np.inf)
    for scale in (1.0, 3.0, 10.0):
        cov = _laplace_at(evs, to_light, p, np.asarray(steps, np.float64) * scale, darkness)
        if np.all(np.isfinite(cov)):
            return cov
    return cov


def _laplace_at(
    evs: list[Evidence], to_light: ToLight, p: np.ndarray, steps: np.ndarray, darkness: Sequence[float] | None = None
) -> np.ndarray:
    """:func:`_laplace` at one set of finite-difference steps."""

    def rss(q: np.ndarray) -> float:
        h = to_light(np.asarray(q, np.float64))
        if h is None:
            return math.inf
        return float(sum(a for a, _, _ in objective(evs, h, darkness)[2]))

    k = len(p)
    f0 = rss(p)
    Hm = np.zeros((k, k))
    for i in range(k):
        for j in range(i, k):
            ei, ej = np.eye(k)[i] * steps[i], np.eye(k)[j] * steps[j]
            if i == j:
                Hm[i, i] = (rss(p + ei) - 2 * f0 + rss(p - ei)) / steps[i] ** 2
            else:
                Hm[i, j] = Hm[j, i] = (rss(p + ei + ej) - rss(p + ei - ej) - rss(p - ei + ej) + rss(p - ei - ej)) / (
                    4 * steps[i] * steps[j]
                )
    h0 = to_light(p)
    assert h0 is not None  # p is the fit's optimum, a valid light
    n = sum(c for _, _, c in objective(evs, h0, darkness)[2])
    sigma2 = f0 / max(n - k - 2, 1) * _correlation_factor(evs, h0, darkness)
    try:
        cov = 2.0 * sigma2 * np.linalg.inv(Hm)
    except np.linalg.LinAlgError:
        return np.full((k, k), np.inf)
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) < 0):
        return np.full((k, k), np.inf)
    out: np.ndarray = cov
    return out


def _distinct_minima(cands: np.ndarray, scores: np.ndarray, sep_deg: float, k: int, to_dir: ToDir) -> list:
    order = np.argsort(scores)
    keep: list = []
    for i in order:
        if not np.isfinite(scores[i]):
            break
        d = to_dir(cands[i])
        if all(math.degrees(math.acos(np.clip(d @ to_dir(cands[j]), -1, 1))) > sep_deg for j in keep):
            keep.append(i)
        if len(keep) >= k:
            break
    return keep


def _check(
    evs: list[Evidence], h: np.ndarray, score: float, deltas: list, runner_up: float | None
) -> tuple[float, float, float | None]:
    """Refuse a fit that is not a shadow, not in view, or ambiguous (``runner_up``: :func:`_runner_up`).
    Returns (explained, visible, runner)."""
    nf = len(evs)
    explained = 1.0 - score / nf
    dark = 1.0 - math.exp(float(np.median(deltas))) if deltas else 0.0
    if dark < MIN_DARKENING or explained < MIN_EXPLAINED:
        raise EstimateError(
            f"no shadow of the probe found (best fit darkens the ground by {100 * dark:.0f} %, "
            f"explains {100 * max(explained, 0):.1f} % of its variation): flat light, or the "
            "shadow is hidden or out of view"
        )
    visible = _visible_share(evs, h)
    if runner_up is not None and runner_up > AMBIGUOUS:
        raise EstimateError(
            f"ambiguous fit: a light more than 15 degrees away explains the shadow almost as "
            f"well ({100 * runner_up:.0f} %); add frames from other viewpoints or a taller probe"
        )
    return explained, visible, runner_up


def _constrained(unc_deg: float, visible: float) -> None:
    """Refuse a fit whose own uncertainty (1 sigma, degrees) leaves the light unconstrained: what is visible
    of the shadow (``visible``, a share of its area) does not fix it. The visible share alone decides
    nothing: a third of a shadow's outline can fix the light as well as all of it."""
    if not math.isfinite(unc_deg) or unc_deg > UNCONSTRAINED_DEG:
        raise EstimateError(
            f"the visible part of the probe's shadow ({100 * visible:.0f} % of it) leaves the light unconstrained "
            f"(+/- {unc_deg:.0f} degrees): frame the whole shadow, or photograph it from its side (not hidden "
            "behind the probe)"
        )


def _refine(
    fine: list[Evidence],
    to_light: ToLight,
    starts: Sequence[np.ndarray],
    simplex_step: Sequence[float],
    xatol: float,
    darkness: Sequence[float] | None = None,
) -> tuple[Any, int]:
    best = None
    count = _Counter(fine, to_light, darkness)
    for p0 in starts:
        init = np.vstack([p0] + [p0 + np.eye(len(p0))[i] * simplex_step[i] for i in range(len(p0))])
        res = _minimize(
            count,
            p0,
            method="Nelder-Mead",
            options={"initial_simplex": init, "xatol": xatol, "fatol": 1e-7, "maxiter": 400},
        )
        if best is None or res.fun < best.fun:
            best = res
    return best, count.n


def fit_directional(
    coarse: list[Evidence], make_fine: MakeFine, el_range: tuple[float, float] = (12.0, 84.0)
) -> FitResult:
    """Fit a directional light (azimuth, elevation) to the evidence: ``coarse`` (one grid per frame) and
    ``make_fine(lights_h) -> list`` (per frame, a fine grid covering those lights' shadows)."""
    az = np.arange(0.0, 360.0, 8.0)
    el = np.arange(el_range[0], el_range[1] + 1e-9, 6.0)
    cands = np.array([(a, e) for e in el for a in az])

    def to_light(p: np.ndarray) -> np.ndarray | None:
        return np.append(direction_of(p[0], p[1]), 0.0) if el_range[0] - 6 < p[1] < 89.5 else None

    def to_dir(p: np.ndarray) -> np.ndarray:
        return direction_of(p[0], p[1])

    scores = np.array([objective(coarse, to_light(c))[0] for c in cands])
    keep = _distinct_minima(cands, scores, 15.0, 3, to_dir)
    if not keep:
        raise EstimateError("no light direction casts a shadow of the probe in view")
    fine = make_fine([to_light(cands[i]) for i in keep])
    res, n = _refine(fine, to_light, [cands[i] for i in keep], (2.5, 2.0), 0.02)
    runner = _runner_up(fine, to_light, cands, keep, res.x, to_dir)
    # then on the winner's own grids (the runners-up's shadows no longer widen them), with the shadow's soft
    # edges as the photo's linear blur darkens them in log (log_coverage), its depth now known: without, the
    # fitted shadow is a fraction of the blur too small on every side, the light too high (docs/light.md,
    # "the shadow's edges")
    own = make_fine([to_light(res.x)])
    dark = [float(x) for x in objective(own, to_light(res.x))[1]]
    res, n2 = _refine(own, to_light, [res.x], (0.5, 0.5), 0.005, dark)
    p = res.x.copy()
    p[0] %= 360.0
    h = to_light(p)
    assert h is not None  # Nelder-Mead ends no worse than its (finite-scored) start: inside the domain
    score, deltas, _ = objective(own, h, dark)
    explained, visible, rr = _check(own, h, score, deltas, runner)
    cov = _laplace(own, to_light, p, np.array([0.3, 0.3]), dark)
    unc = math.sqrt(max(cov[1, 1] + cov[0, 0] * math.cos(math.radians(p[1])) ** 2, 0.0))
    _constrained(unc, visible)
    return FitResult(h, p, score, deltas, unc, None, explained, visible, rr, len(cands) + n + n2, own)


def _runner_up(
    fine: list[Evidence], to_light: ToLight, cands: np.ndarray, keep: list, p: np.ndarray, to_dir: ToDir
) -> float | None:
    """How well the best of the coarse minima more than 15 degrees from the optimum ``p`` explains the fine
    grids, as a share of what ``p`` explains there (both on ``fine``); None without such a minimum."""
    d = to_dir(p)
    others = [cands[i] for i in keep if math.degrees(math.acos(np.clip(d @ to_dir(cands[i]), -1, 1))) > 15.0]
    h = to_light(p)
    if not others or h is None:
        return None
    nf = len(fine)
    best = 1.0 - float(objective(fine, h)[0]) / nf
    other = 1.0 - float(min(objective(fine, to_light(q))[0] for q in others)) / nf
    return other / best if best > 0.0 and math.isfinite(other) else None


def fit_sun(coarse: list[Evidence], make_fine: MakeFine, enu: np.ndarray) -> FitResult:
    """Fit the world's bearing NORTH (1 DOF) for a known sun direction ``enu`` (east, north, up)."""
    enu = np.asarray(enu, np.float64)
    if enu[2] <= 0.0:
        raise EstimateError("the sun is below the horizon at that time and place: no shadow to fit")

    def to_light(p: np.ndarray) -> np.ndarray | None:
        return np.append(enu_to_world(enu, float(p[0])), 0.0)

    def to_dir(p: np.ndarray) -> np.ndarray:
        return enu_to_world(enu, float(p[0]))

    cands = np.arange(0.0, 360.0, 3.0)[:, None]
    scores = np.array([objective(coarse, to_light(c))[0] for c in cands])
    keep = _distinct_minima(cands, scores, 15.0, 3, to_dir)
    if not keep:
        raise EstimateError("no bearing of the world casts the sun's shadow of the probe in view")
    fine = make_fine([to_light(cands[i]) for i in keep])
    res, n = _refine(fine, to_light, [cands[i] for i in keep], (1.5,), 0.01)
    p = np.array([res.x[0] % 360.0])
    h = to_light(p)
    assert h is not None  # Nelder-Mead ends no worse than its (finite-scored) start: inside the domain
    score, deltas, _ = objective(fine, h)
    runner = _runner_up(fine, to_light, cands, keep, p, to_dir)
    explained, visible, rr = _check(fine, h, score, deltas, runner)
    cov = _laplace(fine, to_light, p, np.array([0.3]))
    unc = math.sqrt(max(cov[0, 0], 0.0)) * math.cos(math.asin(min(1.0, enu[2] / np.linalg.norm(enu))))
    _constrained(unc, visible)
    return FitResult(h, p, score, deltas, unc, None, explained, visible, rr, len(cands) + n, fine)


def fit_point(coarse: list[Evidence], make_fine: MakeFine, anchor: np.ndarray) -> FitResult:
    """Fit a point light's position (3 DOF) as (azimuth, elevation, log distance) from the probe's top
    ``anchor`` (3,): the directional fit, the objective's profile over 9 distances (3..0.15 m, warm-started; azimuth and
    elevation re-fitted at each, on the coarse grids) and a coarse 3-D grid around it, then Nelder-Mead in 3-D on the fine grids
    from the two best distances of the profile and the grid's best; the lowest objective wins."""
    d = fit_directional(coarse, make_fine)
    fine = d.fine
    anchor = np.asarray(anchor, np.float64)
    top = float(max(ev.verts[:, 2].max() for ev in fine))
    az0, el0 = float(d.params[0]), float(d.params[1])

    def position(q: np.ndarray) -> np.ndarray:
        return anchor + math.exp(q[2]) * direction_of(q[0], q[1])

    def to_light(q: np.ndarray) -> np.ndarray | None:
        if q[2] > math.log(MAX_POINT_DISTANCE):  # as good as directional: the fit's far edge
            return None
        pos = position(q)
        return None if pos[2] <= top + 0.01 or q[1] >= 89.5 else np.append(pos, 1.0)

    # the profile of the objective over the distance: (azimuth, elevation) re-fitted on the coarse grids at
    # each distance (the shadow's outline moves with both), from the directional fit; it only proposes
    # starts, the fine grids (4x the cost of an evaluation) judge them
    dark = [float(x) for x in d.deltas]  # the shadow's depth per frame, for its soft edges in log
    count = _Counter(fine, to_light, dark)
    count_c = _Counter(coarse, to_light, dark)
    profile = []
    ae = np.array([az0, el0])
    for t in np.geomspace(3.0, 0.15, 9):  # far to near, each distance warm-started from the previous one
        q0 = np.r_[ae, math.log(t)]
        if to_light(q0) is None:
            continue
        init = np.vstack([q0[:2], q0[:2] + [2.0, 0.0], q0[:2] + [0.0, 2.0]])
        r = _minimize(
            lambda a, lt=q0[2]: count_c(np.r_[a, lt]),
            q0[:2],
            method="Nelder-Mead",
            options={"initial_simplex": init, "xatol": 0.1, "fatol": 1e-6, "maxiter": 45},
        )
        profile.append((r.fun, np.r_[r.x, q0[2]]))
        if np.isfinite(r.fun):
            ae = r.x
    profile.sort(key=lambda x: x[0])
    starts = [q for f, q in profile[:2] if np.isfinite(f)]
    # and the best of a coarse 3-D grid around the directional fit (another basin, when the profile misses it)
    grid = np.array(
        [
            (a, e, math.log(t))
            for t in np.geomspace(0.15, 3.0, 14)
            for a in az0 + np.arange(-12.0, 12.1, 4.0)
            for e in el0 + np.arange(-12.0, 12.1, 4.0)
        ]
    )
    scores = np.array([objective(coarse, h, dark)[0] if (h := to_light(q)) is not None else math.inf for q in grid])
    if np.isfinite(scores.min()):
        starts.append(grid[int(np.argmin(scores))])
    if not starts:
        raise EstimateError("no point light above the probe explains its shadow")
    # the 3-D refinement from the two starts that explain the fine grids best (each costs up to 400 evaluations)
    starts = sorted(starts, key=lambda q: count(q))[:2]
    res, n = _refine(fine, to_light, starts, (2.0, 2.0, 0.15), 1e-3, dark)
    q = res.x.copy()
    if q[2] > math.log(MAX_POINT_DISTANCE) - 0.01:
        raise EstimateError(
            f"the point light fit went to its far edge ({MAX_POINT_DISTANCE:.0f} m from the probe): the shadow is "
            "a directional light's, or this view does not fix the distance; fit --kind directional, or add "
            "photos from other sides"
        )
    h = to_light(q)
    if h is None:
        raise EstimateError("the point light fit ended below the probe's top: no point light explains the shadow")
    score, deltas, _ = objective(fine, h, dark)
    explained, visible, _ = _check(fine, h, score, deltas, None)
    cov = _laplace(fine, to_light, q, np.array([0.3, 0.3, 0.02]), dark)
    dist = math.exp(q[2])
    unc = math.sqrt(max(cov[1, 1] + cov[0, 0] * math.cos(math.radians(q[1])) ** 2, 0.0))
    _constrained(unc, visible)
    # position: the direction's spread across, the log distance's along
    sig = dist * math.sqrt(max(math.radians(unc) ** 2 + cov[2, 2], 0.0))
    s_log = math.sqrt(max(cov[2, 2], 0.0)) if math.isfinite(cov[2, 2]) else math.inf
    interval = (dist * math.exp(-2.0 * s_log), dist * math.exp(min(2.0 * s_log, 50.0)))  # 2 sigma, log-normal
    return FitResult(
        h,
        position(q),
        score,
        deltas,
        unc,
        sig,
        explained,
        visible,
        None,
        d.evaluations + count.n + count_c.n + len(grid) + n,
        fine,
        interval,
    )
