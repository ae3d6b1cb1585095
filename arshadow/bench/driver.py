"""The one place the benchmarks drive the whole pipeline (detection -> composite).

Today that is :class:`arshadow.pipeline.Compositor`; when ``arshadow.Session`` lands, only these functions
change.
"""

from __future__ import annotations

import time

import numpy as np


def open_pipeline(ctx, intrinsics, caster, lights, *, marker_length=0.05, **options):
    """A pipeline for one camera, object and light set; ``options`` are
    :class:`arshadow.pipeline.RenderOptions` fields. Use as a context manager."""
    from ..pipeline import Compositor, RenderOptions

    return Compositor(ctx, intrinsics, caster, lights, RenderOptions(**options), tracker={"marker_length": marker_length})


def process(pipe, image, out=None) -> tuple[float, dict]:
    """Run one photo: ``(wall time ms, per-stage times ms)``."""
    t = time.perf_counter()
    _, _, item = pipe.process(image, want_mask=False, out=out)
    return (time.perf_counter() - t) * 1e3, dict(item.timings_ms)


def forget_geometry(pipe) -> None:
    """Drop the cached silhouettes and volumes (a moving light or object recomputes them every frame)."""
    for ls in pipe._lights:
        ls.sil, ls.volumes = None, {}


def run_frames(pipe, image, runs: int, warmup: int, cold: bool = False) -> tuple[list[float], dict]:
    """``runs`` timed photos after ``warmup``: wall times and ``{stage: [ms, ...]}``."""
    out = np.empty_like(image)
    walls, stages = [], {}
    for i in range(warmup + runs):
        if cold:
            forget_geometry(pipe)
        w, st = process(pipe, image, out)
        if i >= warmup:
            walls.append(w)
            for k, v in st.items():
                stages.setdefault(k, []).append(v)
    return walls, stages
