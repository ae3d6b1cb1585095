"""The checks of a fitted light that do not come from its shadow fit, and what they refuse or warn.

The probe's outline on the photo's edges (:func:`arshadow.estimate.outline.outline_agreement`, pooled over
the frames: a refusal below :data:`OUTLINE_REFUSE`), the fitted shadow's edge darker inside all along it,
the probe's faces against the light's shading (:func:`arshadow.estimate.shading.face_shading_residual`), the
floor's pattern under the shadow ratio (:func:`arshadow.estimate.ratio.texture_uncertainty`), and a point
light's distance. A failed check is a warning and ``confident: false`` (docs/light.md, "Never a confident
wrong light").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..errors import EstimateError
from .light import FitResult
from .ratio import ProbeGround, texture_uncertainty
from .shading import ProbeViews, face_shading_residual
from .shadow import LUMA, Evidence, edge_pairs, shadow_coverage

__all__ = [
    "EDGE_DARKER",
    "OUTLINE_FLAG",
    "OUTLINE_REFUSE",
    "POINT_FAR",
    "POINT_NEAR",
    "POINT_REL_SIGMA",
    "RATIO_TEXTURE",
    "SHADING_LOG",
    "check_outline",
    "check_warnings",
    "light_checks",
    "point_warnings",
]

#: the probe's outline (:func:`arshadow.estimate.outline.outline_agreement`) below this share on the photo's
#: edges is a refusal: the probe is not there (tuning seeds: 0.11..0.28 on synthetic photos without the
#: probe or with it given 3..5 cm away; 0.64..1 with it in place, its shadow hidden or not; ~0.2 by chance)
OUTLINE_REFUSE = 0.4
#: ... and below this, a warning
OUTLINE_FLAG = 0.55
#: a fitted shadow darker than the ground outside on less than this share of its edge is flagged (a real
#: shadow: 0.97..1 on synthetic photos; a pattern of the floor or a mostly hidden shadow: 0.67..0.93)
EDGE_DARKER = 0.95
#: a face of the probe brighter or darker than the fitted light shades it by more than this (log) is flagged
#: (tuning seeds: 0.008..0.057 for the right light, 0.10..0.37 for lights fitted to the floor's pattern)
SHADING_LOG = 0.1
#: the floor's pattern moving the shadow ratio by more than this (relative, 1 sigma:
#: :func:`arshadow.estimate.ratio.texture_uncertainty`) is flagged: 2 sigma is then over 16 % of the shadow's
#: light (the path-traced reference, the ratio read with the lit floor's change: 0.025 and 0.048 on two tiles
#: plates, 2.5 % and 4.4 % off; 0.10-0.12 on the "noise" floors, 0.1-21 % off, 0.049 on the mildest, 3.7 % off;
#: a plain synthetic floor: under 0.003; arshadow.synth's patterned floor at 720p: median 0.07)
RATIO_TEXTURE = 0.08
#: a point light whose 1-sigma position uncertainty exceeds this share of its distance is flagged (a
#: position 15 % off is then at least a 1.5-sigma event)
POINT_REL_SIGMA = 0.1
#: a point light fitted farther than this from the probe (metres) is flagged (the search goes to 3 m)
POINT_FAR = 2.0
#: a point light fitted nearer than this to the probe's top (metres) is flagged (the search starts at 0.15 m)
POINT_NEAR = 0.2


def _edge_consistency(evs: list[Evidence], h: np.ndarray, px: Sequence[float]) -> tuple:
    """How consistently the fitted shadow's edge is a shadow's: the share of pairs of ground points straddling
    it (:func:`arshadow.estimate.shadow.edge_pairs`, 5 mm or 3 px each side) whose inside is darker than
    their outside, and the pairs' count. A real shadow is darker all along its edge (about 0.9 and more);
    a pattern of the floor's texture that a wrong shadow explains is darker on some stretches only."""
    darker, count = 0, 0
    for ev, p in zip(evs, px, strict=True):
        S = shadow_coverage(ev, h)
        if S is None:
            continue
        a, b = edge_pairs(ev, S, max(0.005, 3.0 * p))
        darker += int(np.count_nonzero(a @ LUMA < b @ LUMA))
        count += len(a)
    return (darker / count if count else math.nan), count


def _pooled(outline: Sequence[tuple[float, int]]) -> float:
    """The outline's agreement over the frames (weighted by the points read), NaN when none was read."""
    pts = sum(n for _, n in outline)
    return sum(a * n for a, n in outline if n) / pts if pts else math.nan


def check_outline(outline: Sequence[tuple[float, int]]) -> None:
    """Refuse when the probe's projected outline is not on the photo's edges (:func:`outline_agreement`):
    the probe is not where it is given, or not in the photo."""
    agree = _pooled(outline)
    if math.isfinite(agree) and agree < OUTLINE_REFUSE:
        raise EstimateError(
            f"the probe is not in the photo where it is given: only {100 * agree:.0f} % of its outline lies on an edge of the "
            f"photo (chance: ~20 %; a probe in place: over {100 * OUTLINE_FLAG:.0f} %): check --probe-place, "
            "--probe-rotate and --probe, or that the probe is in the photo"
        )


def light_checks(
    res: FitResult,
    read: tuple[tuple, tuple[float, float] | None],
    pxs: Sequence[float],
    outline: Sequence[tuple[float, int]],
    probe: ProbeViews,
    ground: ProbeGround | None,
) -> dict:
    """The checks of a fitted light that do not come from its shadow fit: the probe's outline on the photo
    (pooled over the frames), the share of the fitted shadow's edge darker inside, the probe's faces
    against the light's shading (the median over its views; NaN when not measured)
    and how far the floor's pattern moves the shadow ratio (:func:`.ratio.texture_uncertainty`).
    ``read``: the shadow ratio and where it was read (:func:`.ratio.shadow_ratio`); ``ground``: the sky the
    probe hides and the light it reflects (:func:`.ratio.probe_ground`; None: not allowed for, as for the
    ratio)."""
    edge_darker, edge_n = _edge_consistency(res.fine, res.light_h, pxs)
    r = float(np.asarray(read[0]) @ LUMA)
    texture, _ = texture_uncertainty(res.fine, res.light_h, pxs, ground, float(np.clip(r, 0.0, 0.95)))
    shade = [
        face_shading_residual(im, it, T, probe.verts, probe.faces, res.light_h, r, read[1])[0]
        for im, it, T in probe.views
    ]
    shade = [x for x in shade if math.isfinite(x)]
    return {
        "outline": _pooled(outline),
        "edge_darker": edge_darker,
        "edge_pairs": edge_n,
        "face_shading": float(np.median(shade)) if shade else math.nan,
        "ratio_texture": texture,
    }


def check_warnings(checks: dict) -> list:
    """The warnings (``confident: false``) of failed :func:`_checks`."""
    out = []
    agree, edge_darker, shade_res = checks["outline"], checks["edge_darker"], checks["face_shading"]
    if math.isfinite(agree) and agree < OUTLINE_FLAG:
        out.append(
            f"low confidence: only {100 * agree:.0f} % of the probe's outline lies on an edge of the photo: "
            "check --probe-place and --probe-rotate"
        )
    if math.isfinite(shade_res) and shade_res > SHADING_LOG:
        out.append(
            f"low confidence: the probe's faces are not shaded as this light shades them (a face "
            f"{100 * math.expm1(shade_res):.0f} % off): the shadow fitted may not be the probe's, or the probe "
            "is not matte and of one colour"
        )
    texture = checks["ratio_texture"]
    if math.isfinite(texture) and texture > RATIO_TEXTURE:
        out.append(
            f"low confidence: the floor's pattern beside the probe's shadow moves the shadow ratio by about "
            f"+-{100 * texture:.0f} % (one standard deviation, read where nothing is shadowed): the inserted "
            "shadows may be that much too dark or too light; the probe's shadow on a plain surface (a sheet of "
            "paper) measures it"
        )
    if math.isfinite(edge_darker) and edge_darker < EDGE_DARKER:
        out.append(
            f"low confidence: the fitted shadow is darker inside its edge on only {100 * edge_darker:.0f} % of it "
            "(a real shadow: all along it): it may be the floor's pattern, the real shadow hidden or out of view"
        )
    return out


def point_warnings(res: FitResult, dist: float) -> list:
    """A point light's warnings: fitted at the search's far or near edge, or its distance ``dist`` (metres
    from the probe's top) uncertain; each names the 2-sigma interval of the distance."""
    lo, hi = res.distance_interval if res.distance_interval is not None else (math.nan, math.nan)
    span = f"between {lo:.2f} and {hi:.2f} m from the probe's top (2 sigma)"
    assert res.position_sigma is not None  # a point light's fit
    rel = res.position_sigma / max(dist, 1e-9)
    if dist > POINT_FAR:
        return [
            f"low confidence: the point light fit went {dist:.1f} m away, {span} (a far light looks "
            "directional from one probe); fit --kind directional"
        ]
    if dist < POINT_NEAR:
        return [
            f"low confidence: the point light fit went {100 * dist:.0f} cm from the probe's top, the edge of the "
            f"search, {span} (a faint shadow is explained as well by a light almost anywhere)"
        ]
    if rel > POINT_REL_SIGMA:
        return [
            f"low confidence: the point light's distance is uncertain (+/- {100 * rel:.0f} % of it): "
            f"{dist:.2f} m, {span}; add photos or frames from other sides (arshadow light a.jpg b.jpg ...), "
            "or fit --kind directional"
        ]
    return []
