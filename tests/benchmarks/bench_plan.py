"""Benchmark: what the frame planner saves, per decision, and the numpy vs shader compose paths.

    python tests/benchmarks/bench_plan.py [--runs 15] [--scenes knot_point,box_soft_sun] [--out R.json]
                                          [--skip-decisions] [--skip-photo] [--skip-compose]

Three parts, every variant measured in interleaved rounds (one run of each variant per round, so the
shared machine's load moves all of them alike); medians, IQR ``[q25, q75]``, min/max:

1. **Per decision** on every sample scene (samples/scenes.json, at its true pose, no detection):
   ``general`` (the reference), ``auto``, and ``auto`` with one decision switched off
   (``RenderOptions.plan_off``): ``planar``, ``zpass``, ``truncate``, ``cull``, ``roi``, ``reuse``.
   The speed-up of a decision is time(auto without it) / time(auto), per frame, measured on the
   **render stage** (silhouette + volume + render + readback) and on the whole ``render`` call
   (render stage + warp + composite). Compose is forced to numpy so only the plan varies.
2. **Whole 720p photo** (``Session.process``: detection -> composite) of knot_point.jpg, ``--aa 0`` and
   ``--aa 4``, auto vs general.
3. **Compose paths**: ``Session.render`` with ``compose="cpu"`` vs ``"gpu"`` (shader) per scene,
   ``--aa 0`` and ``--aa 4``, and which one ``compose="auto"`` picked on this backend.

Prints JSON (and writes it atomically with ``--out``), with metadata (commit, versions, GL_RENDERER,
load average). On this CPU-only machine GL is Mesa llvmpipe: the shader path runs on the same cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import _common
import numpy as np

ROOT = _common.ROOT
DECISIONS = ("planar", "zpass", "truncate", "cull", "roi", "reuse")


def _specs(names):
    from arshadow.scene.spec import SCENE_KEYS, scene_from_dict

    data = json.loads((ROOT / "samples" / "scenes.json").read_text())
    out = []
    for sc in data["scenes"]:
        stem = Path(sc["photo"]).stem
        if names and stem not in names:
            continue
        d = {k: v for k, v in sc.items() if k in SCENE_KEYS}
        out.append(
            (
                stem,
                scene_from_dict(d, base_dir=ROOT),
                np.asarray(sc["true_cam_from_world"], float),
                ROOT / "samples" / sc["photo"],
            )
        )
    return out


def _session(spec, ctx, **opts):
    from arshadow.frame.session import Session

    return Session(dataclasses.replace(spec, options=dataclasses.replace(spec.options, **opts)), context=ctx)


def _render_stage(t):
    return t["silhouette"] + t["volume"] + t["render"] + t["readback"]


def _interleave(variants: dict, runs: int, warmup: int = 2):
    """``variants``: name -> callable returning a timings dict; returns name -> list of timings dicts."""
    res = {k: [] for k in variants}
    for r in range(warmup + runs):
        for name, fn in variants.items():
            t = fn()
            if r >= warmup:
                res[name].append(t)
    return res


def bench_decisions(ctx, specs, runs):
    from arshadow.io import read_image

    rows = []
    for stem, spec, pose, photo in specs:
        image = read_image(photo)
        sessions = {
            "general": _session(spec, ctx, plan="general", compose="cpu"),
            "auto": _session(spec, ctx, plan="auto", compose="cpu"),
        }
        for d in DECISIONS:
            sessions[f"auto-{d}"] = _session(spec, ctx, plan="auto", compose="cpu", plan_off=(d,))
        out = np.empty_like(image)
        plans = {}

        def runner(name, s):
            def go():
                t0 = time.perf_counter()
                r = s.render(image, pose, want_mask=True, out=out)
                t = dict(r.timings_ms)
                t["call"] = (time.perf_counter() - t0) * 1e3
                plans[name] = r.item.plan
                return t

            return go

        res = _interleave({k: runner(k, s) for k, s in sessions.items()}, runs)
        for s in sessions.values():
            s.close()
        row = {"scene": stem, "auto_plan": plans["auto"], "variants": {}}
        for name, ts in res.items():
            row["variants"][name] = {
                "render_stage_ms": _common.summary([_render_stage(t) for t in ts]),
                "call_ms": _common.summary([t["call"] for t in ts]),
            }
        auto_rs = np.array([_render_stage(t) for t in res["auto"]])
        auto_call = np.array([t["call"] for t in res["auto"]])
        sp = {}
        for name in ["general"] + [f"auto-{d}" for d in DECISIONS]:
            rs = np.array([_render_stage(t) for t in res[name]])
            call = np.array([t["call"] for t in res[name]])
            # per-round ratios (interleaved runs share the machine's load)
            sp[name] = {"render_stage": _common.summary(rs / auto_rs), "call": _common.summary(call / auto_call)}
        row["speedup_of_auto_over"] = sp
        rows.append(row)
        print(
            f"# {stem}: " + ", ".join(f"{k} x{v['render_stage']['median']:.2f}" for k, v in sp.items()), file=sys.stderr
        )
    return rows


def bench_photo(ctx, specs, runs):
    from arshadow.io import read_image

    rows = []
    for stem, spec, _pose, photo in specs:
        if stem != "knot_point":
            continue
        image = read_image(photo)
        out = np.empty_like(image)
        mask = np.empty(image.shape[:2], np.uint8)
        for aa in (0, 4):
            sessions = {p: _session(spec, ctx, plan=p, aa=aa) for p in ("auto", "general")}
            chosen = {}

            def runner(name, s):
                def go():
                    r = s.process(image, want_mask=True, out=out, mask_out=mask)
                    chosen[name] = r.item.compose
                    return dict(r.timings_ms)

                return go

            res = _interleave({k: runner(k, s) for k, s in sessions.items()}, runs)
            for s in sessions.values():
                s.close()
            for name, ts in res.items():
                rows.append(
                    {
                        "photo": stem,
                        "aa": aa,
                        "plan": name,
                        "compose": chosen[name],
                        "total_ms": _common.summary([t["total"] for t in ts]),
                        "stages_median_ms": {k: round(float(np.median([t[k] for t in ts])), 3) for k in ts[0]},
                    }
                )
            ratio = np.array([t["total"] for t in res["general"]]) / np.array([t["total"] for t in res["auto"]])
            rows.append({"photo": stem, "aa": aa, "speedup_auto_over_general_total": _common.summary(ratio)})
    return rows


def bench_compose(ctx, specs, runs):
    from arshadow.io import read_image

    rows = []
    for stem, spec, pose, photo in specs:
        image = read_image(photo)
        out = np.empty_like(image)
        mask = np.empty(image.shape[:2], np.uint8)
        for aa in (0, 4):
            sessions = {c: _session(spec, ctx, compose=c, aa=aa) for c in ("cpu", "gpu", "auto")}
            picked = {}

            def runner(name, s):
                def go():
                    t0 = time.perf_counter()
                    r = s.render(image, pose, want_mask=True, out=out, mask_out=mask)
                    picked[name] = (r.item.compose, (r.item.plan or {}).get("compose"))
                    t = dict(r.timings_ms)
                    t["call"] = (time.perf_counter() - t0) * 1e3
                    return t

                return go

            res = _interleave({k: runner(k, s) for k, s in sessions.items() if k != "auto"}, runs)
            runner("auto", sessions["auto"])()  # the calibration timing of the automatic choice
            for s in sessions.values():
                s.close()
            row = {"scene": stem, "aa": aa, "auto_picked": picked["auto"][0], "auto_measured": picked["auto"][1]}
            for name, ts in res.items():
                row[name] = {
                    "render_call_ms": _common.summary([t["call"] for t in ts]),
                    "stages_median_ms": {
                        k: round(float(np.median([t[k] for t in ts])), 3)
                        for k in ("render", "readback", "warp", "composite")
                    },
                }
            row["cpu_over_gpu"] = _common.summary(
                np.array([t["call"] for t in res["cpu"]]) / np.array([t["call"] for t in res["gpu"]])
            )
            rows.append(row)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=15)
    ap.add_argument("--scenes", default="", help="comma-separated photo stems (default: all sample scenes)")
    ap.add_argument("--skip-decisions", action="store_true")
    ap.add_argument("--skip-photo", action="store_true")
    ap.add_argument("--skip-compose", action="store_true")
    ap.add_argument("--out", help="also write the JSON here")
    args = ap.parse_args(argv)
    from arshadow.gl.context import create_context

    ctx = create_context()
    names = [s for s in args.scenes.split(",") if s]
    specs = _specs(names)
    result = {"meta": _common.metadata(ctx), "runs": args.runs}
    if not args.skip_decisions:
        result["decisions"] = bench_decisions(ctx, specs, args.runs)
    if not args.skip_photo:
        result["photo_720p"] = bench_photo(ctx, _specs(["knot_point"]), args.runs)
    if not args.skip_compose:
        result["compose"] = bench_compose(ctx, specs, args.runs)
    result["gpu_figures"] = (
        "not measured: no GPU machine was available to this task (device tool: "
        "can_start_another=false); the compose choice is automatic per backend"
    )
    _common.emit(result, args.out)
    ctx.release()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
