"""``arshadow bench``: run time against error for every knob that trades one for the other.

One module per section, each built on the Python API:

- :mod:`.silhouettes` - detectors vs mesh size, error vs the exact silhouette, paper-faithful reference
  versions' operation counts vs the papers' formulas;
- :mod:`.render` - render time vs shadow error (stencil variants, anti-aliasing, resolution scale, planar,
  the shadow-map baseline) against the exact GL-independent shadow (:mod:`arshadow.geometry.exact`);
- :mod:`.tracking` - detection + pose time vs pose error;
- :mod:`.pipeline` - per-stage times, FPS vs lights, [Kolivand-DeltaPlus]'s AR scene (through :class:`arshadow.Session`);
- :mod:`.realism` - each rendering option's cost per 720p frame against its residual on the path-traced
  reference scenes (:mod:`.reference`), with the planner's choices;
- :mod:`.plots` (matplotlib, optional) and :mod:`.summary` (Markdown).

:func:`run` writes ``<section>.csv`` files, ``results.json``, PNG plots and ``summary.md`` into a folder.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..errors import UsageError
from ..gl.context import create_context
from ..io import write_bytes
from . import pipeline, realism, render, silhouettes, tracking
from . import plots as P
from .common import machine_label, metadata, write_csv
from .summary import markdown

__all__ = ["QUICK", "FULL", "SECTIONS", "run"]

SECTIONS = ("silhouettes", "render", "tracking", "pipeline", "realism")

#: settings of ``arshadow bench --quick`` (under 3 minutes on a loaded 2-core machine)
QUICK = dict(
    quick=True,
    sizes=(1470, 10000),
    lights=4,
    repeat=3,
    ref_sizes=(200, 1470),
    vnv_max_faces=1470,
    warmup=2,
    render_repeat=7,
    track_resolutions=((1280, 720),),
    poses=4,
    resolutions=((640, 480), (1280, 720), (1920, 1080)),
    frames=6,
    light_counts=(1, 2, 4),
    soft_samples=(1, 4, 16),
)
#: settings of the full run
FULL = dict(
    quick=False,
    sizes=(1470, 10000, 100000, 1000000),
    lights=8,
    repeat=5,
    ref_sizes=(200, 1470, 10000),
    vnv_max_faces=1470,
    warmup=3,
    render_repeat=20,
    track_resolutions=((640, 480), (1280, 720), (1920, 1080)),
    poses=20,
    resolutions=((640, 480), (1280, 720), (1920, 1080)),
    frames=30,
    light_counts=(1, 2, 4, 8),
    soft_samples=(1, 2, 4, 8, 16, 32, 64),
)


def _csv_rows(results: dict) -> dict:
    """``{file stem: rows}`` of everything tabular in ``results``."""
    out: dict[str, list] = {}
    if "silhouettes" in results:
        s = results["silhouettes"]
        out.update(
            silhouette_detectors=s["detectors"],
            silhouette_reference=s["reference"],
            silhouette_paper_formulas=s["paper"],
            silhouette_hsd_vs_ta=s["hsd_vs_ta"],
        )
    if "render" in results:
        out["render"] = results["render"]
    if "tracking" in results:
        out["tracking"] = results["tracking"]
    if "pipeline" in results:
        p = results["pipeline"]
        out.update(pipeline_stages=p["stages"], pipeline_lights=p["lights"], pipeline_paper003=p["paper003"])
    if results.get("realism"):
        out["realism"] = results["realism"]
    return out


def run(
    out_dir: Path,
    *,
    quick: bool = False,
    sections: Sequence[str] = SECTIONS,
    log: Callable[[str], None] = print,
    plots: bool = True,
) -> dict:
    """Run the benchmark and write its outputs into ``out_dir`` (created if needed).

    Parameters
    ----------
    out_dir : path
    quick : bool
        :data:`QUICK` settings instead of :data:`FULL`.
    sections : sequence of str
        Subset of :data:`SECTIONS`.
    log : callable
        Progress lines (``print`` by default).
    plots : bool
        Write PNG plots (needs matplotlib; without it the run says so and writes CSV + Markdown only).

    Returns
    -------
    dict
        ``{"meta", "results", "files", "duration_s"}``.
    """
    bad = [s for s in sections if s not in SECTIONS]
    if bad:
        raise UsageError(f"unknown bench section(s) {', '.join(bad)} (choose from {', '.join(SECTIONS)})")
    cfg = dict(QUICK if quick else FULL)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    ctx = None
    if any(s in sections for s in ("render", "pipeline", "realism")):
        ctx = create_context()
    try:
        meta = metadata(ctx)
        meta["settings"] = "quick" if quick else "full"
        results: dict[str, Any] = {}
        timings: dict[str, float] = {}
        for name in SECTIONS:
            if name not in sections:
                continue
            ts = time.perf_counter()
            log(f"[{name}]")
            if name == "silhouettes":
                results[name] = silhouettes.run(cfg, log)
            elif name == "render":
                results[name] = render.run(cfg, ctx, log)
            elif name == "tracking":
                results[name] = tracking.run(cfg, log)
            elif name == "realism":
                results[name] = realism.run(cfg, ctx, log)
            else:
                results[name] = pipeline.run(cfg, ctx, log)
            timings[name] = round(time.perf_counter() - ts, 1)
    finally:
        if ctx is not None:
            ctx.release()

    meta["loadavg_end"] = list(os.getloadavg())
    meta["section_seconds"] = timings
    files = []
    for stem, rows in _csv_rows(results).items():
        files.append(write_csv(out / f"{stem}.csv", rows))
    label = machine_label(meta)
    plot_paths = {}
    if plots and P.available():
        plot_paths = P.all_plots(results, out, label, log)
    elif plots:
        log(P.HINT)
    files += list(plot_paths.values())
    duration = time.perf_counter() - t0
    files.append(
        write_bytes(
            out / "results.json",
            (json.dumps({"meta": meta, "results": results}, indent=1, default=float) + "\n").encode(),
        )
    )
    md = markdown(
        results,
        meta,
        {k: Path(v).name for k, v in plot_paths.items()},
        duration,
        plots_hint=None if plot_paths or not plots else P.HINT,
    )
    files.append(write_bytes(out / "summary.md", md.encode()))
    log(f"done in {duration:.0f} s: {out / 'summary.md'}")
    return {"meta": meta, "results": results, "files": [str(f) for f in files], "duration_s": duration}
