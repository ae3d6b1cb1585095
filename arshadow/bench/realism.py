"""The realism table of ``arshadow bench`` (the realism work): each rendering option's cost against its residual.

For every entry of :data:`OPTIONS` (a name, the scene keys it sets, and whether the light is measured by
``arshadow light`` or given): the cost (ms per 720p frame, :class:`arshadow.Session` on a synthetic 1280 x 720
photo of the marker, median and IQR of repeats; its render stage alone too), the residual against the
path-traced reference cases (:mod:`arshadow.bench.reference`: median over the project's own scenes, and over
the held-out ones with ``heldout=True``) and the planner's choices for that frame (``FramePlan.decisions``).

A new realism option is one more entry in :data:`OPTIONS`; the table, the CSV, the plot and the summary follow.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import EstimateError
from .common import REPO, summary, timed

if TYPE_CHECKING:
    from ..camera.model import Intrinsics

__all__ = ["OPTIONS", "REFERENCE_DIR", "run"]

#: the committed reference cases (a checkout's tests/data/reference)
REFERENCE_DIR = REPO / "tests" / "data" / "reference"

#: (name, scene keys, light): light "measured" (arshadow light on the plate, --light-from) or "true" (--light)
OPTIONS: list[tuple[str, dict, str]] = [
    ("measured light (defaults)", {}, "measured"),
    ("measured, aa off", {"aa": 0}, "measured"),
    ("measured, aa 4", {"aa": 4}, "measured"),
    ("measured, soft samples 8", {"soft_samples": 8}, "measured"),
    ("measured, black shadow", {"shadow_color": "0,0,0"}, "measured"),
    ("measured, no exposure match", {"no_exposure": True}, "measured"),
    ("true light (defaults)", {}, "true"),
    ("true light, opacity 0.5", {"opacity": 0.5}, "true"),
    # the realism work (docs/shading.md): sky occlusion is on by default with a measured light
    ("measured, ambient occlusion off", {"ambient_occlusion": "off"}, "measured"),
    ("measured, camera effects on", {"camera_effects": "on"}, "measured"),
    ("true light, ambient occlusion on", {"ambient_occlusion": "on"}, "true"),
]


def _photo_720p(marker_length: float = 0.08) -> tuple[np.ndarray, Intrinsics]:
    """A synthetic 1280 x 720 photo of the marker (and a probe, lit), its camera: ``(image, intrinsics)``."""
    from ..camera.model import Intrinsics
    from ..synth.lit import render_lit_photo
    from ..synth.markers import look_at_pose

    K = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    pose = look_at_pose((0.0, -0.34, 0.28), (0.0, 0.04, 0.0))
    photo = render_lit_photo(
        K, pose, marker_length=marker_length, probe="box:0.04,0.04,0.08", probe_place=(-0.12, 0.06, 0.0), seed=1
    )
    return photo.image, K


def _times(keys: dict, light: str, est: Any, repeat: int, warmup: int) -> tuple[list, list, str]:
    """One session with the option on the 720p photo: (total ms per frame, render-stage ms, the plan's
    choices)."""
    from ..frame.session import Session
    from ..scene.spec import scene_from_dict

    image, K = _photo_720p()
    d: dict[str, Any] = {"calib": K, "marker_length": 0.08, "model": "box:0.045,0.065,0.07", "place": [0.1, 0.09, 0]}
    if light == "measured":
        d["light_from"] = est
    else:
        d["lights"] = ["directional:-0.6,-0.35,0.65"]
    d.update(keys)
    render_ms: list[float] = []
    last: list = []
    with Session(scene_from_dict(d)) as s:

        def frame() -> None:
            r = s.process(image, want_mask=False)
            render_ms.append(r.timings_ms.get("render", float("nan")))
            last[:] = [r]

        total = timed(frame, repeat=repeat, warmup=warmup)
    plan = last[0].plan
    choices = "; ".join(f"{dd.name}={dd.value}" for dd in plan.decisions) if plan is not None else ""
    return total, render_ms[-len(total) :], choices


def _costs(est: Any, cfg: dict) -> list[dict]:
    """Median / IQR ms of one 720p frame (total and render stage) and the plan's choices, per option.

    The options are timed in interleaved rounds (each round: every option, a few frames): on a shared machine
    the load changes by the minute, and timing the options one after the other would give that to them.
    """
    rounds = 3
    per = max(1, int(cfg.get("render_repeat", 7)) // rounds)
    totals: list[list] = [[] for _ in OPTIONS]
    renders: list[list] = [[] for _ in OPTIONS]
    choices = [""] * len(OPTIONS)
    for _ in range(rounds):
        for i, (_name, keys, light) in enumerate(OPTIONS):
            t, r, choices[i] = _times(keys, light, est, per, int(cfg.get("warmup", 2)))
            totals[i] += t
            renders[i] += r
    out = []
    for t, r, c in zip(totals, renders, choices, strict=True):
        st, sr = summary(t), summary(r)
        out.append(
            {
                "ms_720p": st["median"],
                "ms_720p_q25": st["iqr"][0],
                "ms_720p_q75": st["iqr"][1],
                "render_ms_720p": sr["median"],
                "planner": c,
            }
        )
    return out


def _residuals(cases: list, estimates: Any, keys: dict, light: str) -> dict:
    from .reference import run_case

    rs = [run_case(c, light, keys, est=e) for c, e in zip(cases, estimates, strict=True)]
    return {k: float(np.median([r[k] for r in rs])) for k in ("ground", "contact", "object")}


def _estimated(cases: list, log: Callable[[str], None]) -> tuple[list, list]:
    """``(cases, estimates)``: the cases whose plate the light estimate accepts, and its estimates."""
    from .reference import measure_light

    kept, ests = [], []
    for c in cases:
        try:
            ests.append(measure_light(c.plate8, c.scene))
        except EstimateError as e:
            log(f"  {c.scene.name}: the light estimate refuses the plate ({e}): left out")
            continue
        kept.append(c)
    return kept, ests


def run(cfg: dict, ctx: Any, log: Callable[[str], None], folder: Path | None = None) -> list[dict]:
    """One row per :data:`OPTIONS` entry (``[]`` when the reference cases are not there, e.g. an installed
    wheel: they live in the checkout's tests/data/reference). Quick settings: three of the own scenes only."""
    from .reference import load_cases

    folder = Path(folder or REFERENCE_DIR)
    if not (folder / "own" / "cases.json").is_file():
        log(f"  no reference cases in {folder}: the realism table needs a checkout (tests/data/reference)")
        return []
    # the light estimate of each plate once (it does not depend on the rendering options); a plate the
    # estimate refuses (EstimateError: both own point-light plates since the trust fixes ('s)'s's gate) is left out
    own, est_own = _estimated(load_cases(folder / "own"), log)
    own, est_own = (own[:3], est_own[:3]) if cfg.get("quick") else (own, est_own)
    heldout, est_held = ([], []) if cfg.get("quick") else _estimated(load_cases(folder / "heldout"), log)
    costs = _costs(est_own[0], cfg)
    rows = []
    for (name, keys, light), cost in zip(OPTIONS, costs, strict=True):
        row: dict[str, Any] = {"option": name, "keys": ",".join(f"{k}={v}" for k, v in keys.items()), "light": light}
        row.update(cost)
        row.update({f"own_{k}": v for k, v in _residuals(own, est_own, keys, light).items()})
        if heldout:
            row.update({f"heldout_{k}": v for k, v in _residuals(heldout, est_held, keys, light).items()})
        log(
            f"  {name}: {row['ms_720p']:.1f} ms/720p frame, residual own ground {row['own_ground']:.3f} "
            f"contact {row['own_contact']:.3f} object {row['own_object']:.3f}"
        )
        rows.append(row)
    return rows
