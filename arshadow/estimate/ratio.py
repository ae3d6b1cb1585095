"""The shadow ratio read on a probe's shadow edge: its level and, optionally, its colour beyond the chroma blur.

The ratio is the sky's share of the open ground's light, per linear RGB channel: shadowed / lit ground,
read on pairs of ground points straddling the probe's fitted shadow edge (:func:`.shadow.edge_pairs`),
allowing for the sky the probe hides from both points and the light it reflects onto them
(``q = (r V_in + R_in) / (1 - r + r V_out + R_out)``, :class:`ProbeGround`). The reflected light needs the
probe's and the floor's reflectances, read off the photo against the marker's paper
(:func:`arshadow.estimate.shading.probe_albedo`, :func:`floor_albedo`). On plain-floor path-traced plates
(12 scenes) the ratio reads +0.018 of the truth on average (median |error| 0.010) with it, +0.045 (0.030)
with the sky occlusion alone: the grey probe lights the shadow beside it (docs/reference.md, "The probe's
reflected light and the paper's class").

It is read on pairs a few millimetres from the edge (:data:`EDGE_DISTANCES`), where the floor's texture is
nearly the same on both sides. A camera records colour at a lower resolution than brightness -- JPEG's 4:2:0
chroma subsampling (cv2's JPEGs and most phones': chroma at half the resolution, coded in 8 x 8 blocks of
16 x 16 pixels and upsampled), a phone's chroma denoising -- so within a few pixels of the edge the lit
side's (warmer) colour leaks into the shadow side and the shadow's (bluer) colour into the lit side: the
ratio reads grey where the pairs are only 3-7 px from the edge (the path-traced reference's 400 x 300
plates, 1.15 mm per pixel). ``shadow_ratio(..., chroma_px=CHROMA_PX)`` keeps the near pairs' luminance (the
luma stays sharp: within 0.5 % of the linear render's there) and reads the colour (each channel over its
luminance) on pairs pushed to at least :data:`CHROMA_PX` pixels from the edge. Measured 2026-11-29 and not
the default (docs/reference.md, "the shadow's colour"): the colour comes out closer to the truth, but with
the level still darkened by the floor's texture the realism residuals do not improve.

A floor that gets darker (or lighter) towards the shadow reads, pair by pair, as a darker (lighter)
shadow. Its slope is read on the lit side, on the same pairs moved ``2 d`` outward (both points lit, the
light's own change between them allowed for), per side of the shadow, and carried across the edge
(:func:`_lit_change`; ``shadow_ratio(..., lit_gradient=False)`` reads the pairs as they are). On the
path-traced reference's own sun plates the lit floor darkens towards the shadow by 11-12 % over 2 d and
their ratio read 11-12 % low; with the slope, within 1.2 % (docs/reference.md, "What is left of the
ground's error", item 5). A step of the albedo at the edge itself cannot be told from the shadow.

How far the floor's pattern moves the ratio is measured where nothing is shadowed: the same reading across
the shadow's edge moved onto the lit floor round it (:func:`texture_uncertainty`, the estimate's
``fit.ratio_texture``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ..shading.decide import PAPER_ALBEDO
from ..shading.sky import GroundOcclusion, Interreflection, ground_sky_visibility
from .record import lamp_irradiance
from .shadow import LUMA, Evidence, edge_pairs, fit_levels, shadow_coverage

__all__ = [
    "CHROMA_PX",
    "EDGE_DISTANCES",
    "MIN_PAIRS",
    "MIN_PLACEBOS",
    "ProbeGround",
    "floor_albedo",
    "probe_ground",
    "shadow_ratio",
    "texture_uncertainty",
]

#: distances from a shadow's edge at which its two sides are compared for the ratio's level (metres, at
#: least 3 pixels)
EDGE_DISTANCES = (0.003, 0.005, 0.008)
#: the least distances (pixels of the photo at the probe), one per :data:`EDGE_DISTANCES` entry, at which
#: ``chroma_px=CHROMA_PX`` reads the ratio's colour: beyond the chroma blur of a 4:2:0 JPEG (chroma pixels of
#: 2 px, upsampled over 2 more; 8 px is 4 chroma pixels, half a chroma DCT block)
CHROMA_PX = (8.0, 10.0, 12.0)
#: pairs needed for a median (fewer: the ratio from the fit; the colour from the near pairs)
MIN_PAIRS = 30
#: placements of the shadow's edge on lit floor needed for :func:`texture_uncertainty` (fewer: NaN)
MIN_PLACEBOS = 3
#: a side of the shadow (its edge's direction in 45-degree bins) takes its own lit floor's change
#: (:func:`_lit_change`) with at least this many lit pairs, else the whole edge's (measured on the own
#: path-traced plates: docs/reference.md, "What is left of the ground's error", item 5)
MIN_SIDE_PAIRS = 10


#: the sky shares at which the probe's reflected light is mapped (it is linear in the share: :class:`ProbeGround`)
_REFLECT_AT = (0.25, 0.75)


@dataclass(frozen=True)
class ProbeGround:
    """What the probe does to the ground's light round it, in shares of the open ground's light: it hides
    ``1 - V(x)`` of the sky and reflects ``R0(x) + r R1(x)`` (``r`` the sky's share). The reflected light is
    linear in ``r``: the probe's faces get ``1 - r`` of the direct light, ``r`` of the sky and the ground's
    light, itself ``(1 - r) lit + r V`` (:class:`arshadow.shading.sky.Interreflection`).

    Attributes
    ----------
    sky : GroundOcclusion
        ``V``: the probe's sky visibility of the ground (exact, no taper).
    reflected : (GroundOcclusion, GroundOcclusion) or None
        The same maps with the probe's reflected light (``V + R / r``) at the shares :data:`_REFLECT_AT`;
        None: no reflected light (a probe of unknown reflectance).
    """

    sky: GroundOcclusion
    reflected: tuple[GroundOcclusion, GroundOcclusion] | None = None

    def visibility(self, x: np.ndarray) -> np.ndarray:
        """``(k,) float64`` ``V`` at ground points ``x (k, 2)`` (metres, world; 1 off the map)."""
        return self.sky.sample(x)

    def reflection(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(R0 (k,), R1 (k,))`` float64 at ground points ``x (k, 2)``: the reflected light is ``R0 + r R1``
        (0 without :attr:`reflected`)."""
        if self.reflected is None:
            return np.zeros(len(x)), np.zeros(len(x))
        v = self.sky.sample(x)
        (ra, a), (rb, b) = ((r, (m.sample(x) - v) * r) for r, m in zip(_REFLECT_AT, self.reflected, strict=True))
        r1 = (b - a) / (rb - ra)
        return a - ra * r1, r1


def probe_ground(
    probe: Any,
    h: np.ndarray,
    reflectance: tuple[float, float] | None = None,
    ref: Sequence[float] | None = None,
    sky: GroundOcclusion | None = None,
) -> ProbeGround | None:
    """The probe's :class:`ProbeGround`; None without a probe (``arshadow.synth.lit``'s photos).

    ``probe``: its ShadowCaster (world frame, metres); ``h``: the fitted light (homogeneous, (4,));
    ``reflectance``: ``(probe, floor)``, their reflectances (luminance; :func:`.shading.probe_albedo`,
    :func:`floor_albedo`), None: the sky it hides only; ``ref``: a point light's ground point ``(x, y)``
    where the shares hold (where the ratio is read), default the probe's foot; ``sky``: its sky map when
    already made (a :class:`ProbeGround`'s ``sky``)."""
    if probe is None:
        return None
    sky = sky if sky is not None else ground_sky_visibility(probe, n_dirs=128, resolution=128, taper=None)
    if reflectance is None:
        return ProbeGround(sky)
    h = np.asarray(h, np.float64)
    v = np.asarray(probe.vertices, np.float64)
    foot = 0.5 * (v[:, :2].min(axis=0) + v[:, :2].max(axis=0))
    at = np.r_[np.asarray(ref if ref is not None else foot, np.float64).reshape(2), 0.0]
    maps = []
    for r in _REFLECT_AT:
        if h[3] == 0.0:
            b = Interreflection(h[:3], r, reflectance[0], reflectance[1])
        else:
            lamp = h[:3] / h[3]
            b = Interreflection(lamp - at, r, reflectance[0], reflectance[1], (lamp, at))
        maps.append(ground_sky_visibility(probe, n_dirs=128, resolution=128, taper=None, bounce=b))
    return ProbeGround(sky, (maps[0], maps[1]))


def floor_albedo(
    evs: list[Evidence],
    h: np.ndarray,
    r: float,
    ground: ProbeGround | None,
    paper_luminance: float,
    paper_albedo: float = PAPER_ALBEDO,
) -> float:
    """The floor's reflectance round the probe (luminance): the median over the evidence's lit floor cells
    (not the paper's, not in the fitted shadow) of ``paper_albedo * floor / paper``, each allowing for its
    own light against the paper's (at the marker's centre; :class:`_OpenLight`: a point light's fall-off, the
    sky the probe hides, ``ground``); NaN with no such cell or no paper. ``evs``: the frames' fine evidence;
    ``h``: the fitted light (homogeneous, (4,)); ``r``: the sky's share; ``paper_luminance``: the lit paper's
    linear luminance (:class:`arshadow.estimate.exposure.Exposure`)."""
    paper = float(paper_luminance)
    if not (math.isfinite(paper) and paper > 0.0):
        return math.nan
    h = np.asarray(h, np.float64)
    values = []
    for ev in evs:
        S = shadow_coverage(ev, h)
        lit = ev.used & ~ev.paper & (S < 0.01 if S is not None else True)
        rows, cols = np.nonzero(lit)
        if rows.size == 0:
            continue
        x = np.column_stack([ev.x0 + cols * ev.step, ev.y0 + rows * ev.step])
        e = _OpenLight(h, r, ground).at(np.vstack([x, np.zeros((1, 2))]))  # the cells', then the paper's
        light = e[-1] / e[:-1]
        values.append(paper_albedo * (ev.rgb[rows, cols] @ LUMA) / paper * light)
    return float(np.median(np.concatenate(values))) if values else math.nan


def _pair_ratios(
    evs: list[Evidence],
    h: np.ndarray,
    distances: Sequence[Sequence[float]],
    ground: ProbeGround | None,
    lit_r: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Each pair's sky share, (k, 3) float64, and the pairs' ground points, (2k, 2) float64 (metres, world
    frame; the inside points, then the outside ones): ``distances[i]`` are frame ``i``'s (metres).

    A pair reads ``q = (r V_in + R_in) / (1 - r + r V_out + R_out)`` (the sky the probe leaves each point
    ``V`` and the light it reflects there ``R = R0 + r R1``, :class:`ProbeGround`; None: ``V = 1``, ``R =
    0``), so ``r = (q (1 + R0_out) - R0_in) / (V_in + R1_in + q (1 - V_out - R1_out))``. ``lit_r``: the sky's
    share to allow for in the lit floor's own change (:func:`_lit_change`), each pair's ``q`` divided by its
    side's; None: the pairs as they read."""
    rs, xin, xout = [np.zeros((0, 3))], [np.zeros((0, 2))], [np.zeros((0, 2))]
    for ev, ds in zip(evs, distances, strict=True):
        S = shadow_coverage(ev, h)
        if S is None:  # no shadow on this frame's ground grid
            continue
        for d in ds:
            a, b, xa, xb = edge_pairs(ev, S, d, points=True)
            if not len(a):
                continue
            q = np.maximum(a, 1e-6) / np.maximum(b, 1e-6)
            if lit_r is not None:
                lp, ls = _lit_pair_logs(ev, S, d, _OpenLight(h, lit_r, ground), outward=2.0 * d)
                q *= np.exp(-_lit_change(lp, ls, _sides(xa, xb)))[:, None]
            v_in, v_out = (_visibility(ground, x)[:, None] for x in (xa, xb))
            (r0_in, r1_in), (r0_out, r1_out) = (tuple(c[:, None] for c in _reflection(ground, x)) for x in (xa, xb))
            rs.append((q * (1.0 + r0_out) - r0_in) / np.maximum(v_in + r1_in + q * (1.0 - v_out - r1_out), 1e-6))
            xin.append(xa)
            xout.append(xb)
    return np.concatenate(rs), np.concatenate(xin + xout)


def _lit_change(lp: np.ndarray, ls: np.ndarray, sides: np.ndarray) -> np.ndarray:
    """``(k,)`` log: for pairs on ``sides (k,)`` (:func:`_sides`), how much the floor's albedo changes over a
    pair's span beside the edge, read on the lit side: the median of the lit pairs' ``lp`` (log, the light's
    own change allowed for: :func:`_lit_pair_logs` moved ``2 d`` outward) on the same side, with at least
    :data:`MIN_SIDE_PAIRS` of them, else over the whole edge; 0 with fewer than :data:`MIN_PAIRS` in all.
    A floor getting darker towards the shadow reads, at first order, as much darker inside it: the pairs'
    ``q`` is divided by ``exp`` of this."""
    out = np.zeros(len(sides))
    if len(lp) < MIN_PAIRS:
        return out
    out[:] = float(np.median(lp))
    for k in np.unique(sides):
        m = ls == k
        if np.count_nonzero(m) >= MIN_SIDE_PAIRS:
            out[sides == k] = float(np.median(lp[m]))
    return out


def _sides(xin: np.ndarray, xout: np.ndarray) -> np.ndarray:
    """``(k,) int``: each pair's side of the shadow, the direction from its outside point ``xout (k, 2)`` to its
    inside one ``xin (k, 2)`` in 45-degree bins (0-7)."""
    n = xin - xout
    out: np.ndarray = np.round(np.degrees(np.arctan2(n[:, 1], n[:, 0])) / 45.0).astype(np.intp) % 8
    return out


@dataclass(frozen=True)
class _OpenLight:
    """The unshadowed ground's light, relative: ``(1 - r) g + r V + R``: ``h`` the fitted light (homogeneous,
    (4,); a lamp's ``g`` its irradiance over the median at the points, else 1), ``r`` the sky's share,
    ``ground`` the sky the probe leaves the ground and the light it reflects there (:class:`ProbeGround`;
    None: all the sky, ``V = 1``, and none, ``R = 0``)."""

    h: np.ndarray
    r: float
    ground: ProbeGround | None = None

    def at(self, x: np.ndarray) -> np.ndarray:
        """``(n,) float64`` at ground points ``x (n, 2)`` (metres, world)."""
        g = np.ones(len(x))
        if self.h[3] != 0.0:
            g = lamp_irradiance(self.h[:3] / self.h[3], x)
            g = g / max(float(np.median(g)), 1e-300)
        r0, r1 = _reflection(self.ground, x)
        out: np.ndarray = np.maximum((1.0 - self.r) * g + self.r * (_visibility(self.ground, x) + r1) + r0, 1e-9)
        return out


def _visibility(ground: ProbeGround | None, x: np.ndarray) -> np.ndarray:
    """``(k,)``: :meth:`ProbeGround.visibility` at ``x (k, 2)``, 1 without a probe."""
    return ground.visibility(x) if ground is not None else np.ones(len(x))


def _reflection(ground: ProbeGround | None, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`ProbeGround.reflection` at ``x (k, 2)``, zeros without a probe."""
    return ground.reflection(x) if ground is not None else (np.zeros(len(x)), np.zeros(len(x)))


def _fit_ratio(evs: list[Evidence], h: np.ndarray) -> tuple[float, ...]:
    """The high-passed fit's ratio within 3 cm of the shadow (too few pairs), (R, G, B)."""
    num = np.zeros(3)
    den = 0.0
    for ev in evs:
        S = shadow_coverage(ev, h)
        if S is None:
            continue
        band = (
            cv2.dilate((S > 0).astype(np.uint8), np.ones((3, 3), np.uint8), iterations=max(1, round(0.03 / ev.step)))
            > 0
        )
        n = int(np.count_nonzero(ev.used & band))
        for c in range(3):
            _, d, _, _ = fit_levels(ev, S, values=np.log(np.maximum(ev.rgb[:, :, c], 1e-6)), weight=band)
            num[c] += n * d
        den += n
    return tuple(float(math.exp(v / max(den, 1))) for v in num)


def shadow_ratio(
    evs: list[Evidence],
    h: np.ndarray,
    px: Sequence[float],
    probe: ProbeGround | None = None,
    chroma_px: Sequence[float] = (),
    lit_gradient: bool = True,
) -> tuple[tuple[float, ...], tuple[float, float] | None]:
    """Per-channel shadow / lit of the ground (the sky's share of the open ground's light).

    ``evs``: the frames' fine evidence; ``h``: the fitted light (homogeneous, (4,)); ``px``: each frame's
    metres per pixel at the probe; ``probe``: the sky it hides from the ground and the light it reflects
    there (:func:`probe_ground`; None: neither, for ``arshadow.synth.lit``'s photos); ``chroma_px``: empty
    (the default) reads the colour with the level; :data:`CHROMA_PX` reads it beyond the chroma blur (not
    adopted: the module's docstring);
    ``lit_gradient`` (the default): each pair allows for the floor's albedo changing towards the shadow on
    its side, read on the lit side (:func:`_lit_change`; the module's docstring); False: the pairs as they
    read.

    The ratio: the per-channel median, over the pairs at :data:`EDGE_DISTANCES` (at least 3 px each), of
    each pair's ``r``. With ``chroma_px``: its luminance (:data:`.shadow.LUMA`) times the per-channel median
    of each far pair's ``r`` over its luminance, the far pairs at ``max(EDGE_DISTANCES[i], chroma_px[i]
    px)``, when at least :data:`MIN_PAIRS` of them are in view. With fewer than :data:`MIN_PAIRS` near
    pairs, the high-passed fit within 3 cm of the shadow (no sky occlusion).

    Returns ``(ratio (R, G, B), at)``: ``at`` the mean ground point ``(x, y)`` (metres, world frame) of the
    near pairs, where the ratio was read (a point light's ratio changes across the floor:
    :func:`arshadow.estimate.record.ratio_at`); None from the fit."""
    h = np.asarray(h, np.float64)
    near_d = [[max(d, 3.0 * p) for d in EDGE_DISTANCES] for p in px]
    near, xs = _pair_ratios(evs, h, near_d, probe)
    if len(near) < MIN_PAIRS:
        return _fit_ratio(evs, h), None
    lit_r = None
    if lit_gradient:  # the pairs again, each distance's q allowing for the lit floor's own change
        lit_r = float(np.clip(np.median(near @ LUMA), 0.0, 0.95))
        near, xs = _pair_ratios(evs, h, near_d, probe, lit_r)
    ratio = np.median(near, axis=0)
    if len(chroma_px):
        far_d = [[max(d, k * p) for d, k in zip(EDGE_DISTANCES, chroma_px, strict=False)] for p in px]
        far, _ = _pair_ratios(evs, h, far_d, probe, lit_r)
        if len(far) >= MIN_PAIRS:
            colour = np.median(far / np.maximum(far @ LUMA, 1e-9)[:, None], axis=0)
            ratio = float(ratio @ LUMA) * colour / float(colour @ LUMA)
    at = xs.mean(axis=0)
    return tuple(float(v) for v in ratio), (float(at[0]), float(at[1]))


def texture_uncertainty(
    evs: list[Evidence],
    h: np.ndarray,
    px: Sequence[float],
    probe: ProbeGround | None = None,
    r: float = 0.0,
    lit_gradient: bool = True,
) -> tuple[float, int]:
    """How far the floor's pattern alone moves the shadow ratio: the same reading where nothing is shadowed.

    A pair compares the floor a few millimetres inside the shadow's edge with the floor as far outside; on a
    patterned floor the two points' albedos differ, and a patch darker or brighter along the edge reads as a
    darker or lighter shadow (on the path-traced reference's "noise" floor, 6-22 % of the ratio;
    docs/light.md, "The floor's pattern and the shadow ratio"). Nothing in one photo tells such a patch from
    the shadow, but the floor round it shows how large the effect is there: the probe's modelled shadow is
    moved by its own extent plus the pairs' reach to each of the 8 neighbouring placements, and the ratio is
    read there as :func:`shadow_ratio` reads it (the pairs across the moved edge, both points lit and of one
    albedo class, the light's own change between them allowed for, and with ``lit_gradient`` less the lit
    floor's change beside the moved edge, :func:`_lit_change`). On a plain floor each placement reads 0
    (log).

    Parameters
    ----------
    evs : list of Evidence
        The frames' fine evidence (ground frame).
    h : (4,) float
        The fitted light (homogeneous).
    px : sequence of float
        Each frame's metres per pixel at the probe (the pairs' distances, as :func:`shadow_ratio`'s).
    probe : ProbeGround, optional
        The sky the probe hides from the floor round it and the light it reflects there
        (:func:`probe_ground`); None: neither.
    r : float
        The sky's share of the open ground's light (the light's change between two lit points).
    lit_gradient : bool
        As :func:`shadow_ratio`'s.

    Returns
    -------
    (rms, n) : (float, int)
        The root mean square of the placements' medians (a relative 1-sigma: the ratio reads ``r (1 +- rms)``)
        over the ``n`` placements (frames x directions) with at least :data:`MIN_PAIRS` pairs; ``(NaN, n)``
        with fewer than :data:`MIN_PLACEBOS`.
    """
    h = np.asarray(h, np.float64)
    light = _OpenLight(h, r, probe)
    medians = []
    for ev, p in zip(evs, px, strict=True):
        S = shadow_coverage(ev, h)
        if S is None:
            continue
        rows, cols = np.nonzero(S > 0.5)
        if rows.size == 0:
            continue
        dists = [max(d, 3.0 * p) for d in EDGE_DISTANCES]
        reach = int(math.ceil(max(dists) / ev.step)) + 2
        wx, wy = int(np.ptp(cols)) + 1 + reach, int(np.ptp(rows)) + 1 + reach
        lit = cv2.erode((S < 0.01).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        for sx, sy in ((-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)):
            moved = _shifted(S, sx * wx, sy * wy)
            logs = []
            for d in dists:
                lq, sq = _lit_pair_logs(ev, moved, d, light, lit=lit)
                if lit_gradient and len(lq):
                    lq = lq - _lit_change(*_lit_pair_logs(ev, moved, d, light, 2.0 * d, lit), sq)
                logs.append(lq)
            lq = np.concatenate(logs)
            if lq.size >= MIN_PAIRS:
                medians.append(float(np.median(lq)))
    if len(medians) < MIN_PLACEBOS:
        return math.nan, len(medians)
    return float(np.sqrt(np.mean(np.square(medians)))), len(medians)


def _shifted(a: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """``a (h, w)`` moved by ``dx`` columns and ``dy`` rows, 0 where nothing moved in."""
    out = np.zeros_like(a)
    h, w = a.shape
    if abs(dx) < w and abs(dy) < h:
        out[max(dy, 0) : h + min(dy, 0), max(dx, 0) : w + min(dx, 0)] = a[
            max(-dy, 0) : h - max(dy, 0), max(-dx, 0) : w - max(dx, 0)
        ]
    return out


def _lit_pair_logs(
    ev: Evidence, S: np.ndarray, d: float, light: _OpenLight, outward: float = 0.0, lit: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The pairs across ``S``'s edge at ``d`` metres, moved ``outward`` metres out (:func:`.shadow.edge_pairs`;
    ``lit``: only those whose both points are in it, the cells the real shadow leaves lit): their
    ``log(inside / outside)`` luminance less the light's own change between the two points (``light``),
    ``(k,) float64``, and their sides (:func:`_sides`), ``(k,) int``."""
    a, b, xa, xb = edge_pairs(ev, S, d, points=True, outward=outward, within=lit)
    if not len(a):
        return np.zeros(0), np.zeros(0, np.intp)
    e = light.at(np.concatenate([xa, xb]))
    k = len(a)
    logs = np.log(np.maximum(a @ LUMA, 1e-9) / np.maximum(b @ LUMA, 1e-9)) - np.log(e[:k] / e[k:])
    return logs, _sides(xa, xb)
