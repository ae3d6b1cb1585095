"""PNG plots of the benchmark results (matplotlib: the optional extra ``arshadow[bench]``, imported lazily).

Every plot carries the machine line (CPU, GL_RENDERER, versions, commit) at its foot.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..io import atomic_path
from .render import pareto

# matplotlib is an optional dependency (the bench extra): it is imported where a plot is drawn, deliberately
HINT = "plots need matplotlib: pip install arshadow[bench]"


def available() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return False
    return True


def _fig(title: str, label: str, size: tuple[float, float] = (9.5, 6.0)) -> tuple[Any, Any]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size, dpi=110)
    ax.set_title(title, fontsize=12)
    ax.grid(True, which="both", alpha=0.3)
    fig.text(0.01, 0.01, label, fontsize=6.5, color="0.35", ha="left", va="bottom", wrap=True)
    return fig, ax


def _save(fig: Any, path: Path | str) -> Path:
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return Path(path)


_FAMILY_STYLE = {
    "stencil": ("tab:blue", "o"),
    "planar": ("tab:purple", "D"),
    "stencil AA": ("tab:green", "s"),
    "stencil scaled": ("tab:orange", "v"),
    "shadow map": ("tab:red", "^"),
    "shadow map, bias off": ("tab:pink", "x"),
    "soft shadow": ("tab:brown", "P"),
}


def _short(config: str) -> str:
    return (
        config.replace("shadow map ", "SM ")
        .replace(", truncated", " trunc")
        .replace("render at ", "")
        .replace(" resolution, bilinear upscale", " res")
        .replace("supersample", "SS")
        .replace("planar projection ([Kolivand-Stencil])", "planar")
        .replace(" (caps)", "")
    )


def render_pareto(rows: list[dict], out_dir: Path, label: str) -> list[Path]:
    """Per scene: render time against (left) 1 + pixels differing from the exact shadow, with the Pareto
    front, and (right) the edge coverage error that anti-aliasing reduces."""
    paths = []
    for i, scene in enumerate(dict.fromkeys(r["scene"] for r in rows)):
        rs = [r for r in rows if r["scene"] == scene]
        fig, ax = _fig(
            f"Shadow render time vs error - {scene} ({rs[0]['roi_w']}x{rs[0]['roi_h']} px ROI of 1280x720)",
            label,
            size=(13.5, 6.2),
        )
        fig.delaxes(ax)
        axes = fig.subplots(1, 2)
        for ax, key, ylab in (
            (axes[0], "xor_px", "1 + pixels differing from the exact shadow (mask >= 0.5; log)"),
            (
                axes[1],
                "coverage_mae",
                "edge coverage error: mean |mask - exact area coverage|\n"
                "within 2 px of the edge (lower = smoother, truer edge)",
            ),
        ):
            ax.grid(True, which="both", alpha=0.3)
            for fam, (col, mk) in _FAMILY_STYLE.items():
                pts = sorted((r for r in rs if r["family"] == fam), key=lambda r: r["time_ms"])
                if not pts:
                    continue
                x = [r["time_ms"] for r in pts]
                y = [r[key] + (1 if key == "xor_px" else 0) for r in pts]
                err = [[r["time_ms"] - r["time_q25"] for r in pts], [r["time_q75"] - r["time_ms"] for r in pts]]
                ax.errorbar(x, y, xerr=err, fmt=mk, color=col, label=fam, ms=7, capsize=2, lw=1)
                for k, (r, xx, yy) in enumerate(zip(pts, x, y, strict=True)):
                    dy = (6, -11, 15, -20)[k % 4]
                    ax.annotate(
                        _short(r["config"]), (xx, yy), textcoords="offset points", xytext=(6, dy), fontsize=7, color=col
                    )
            front = pareto(rs, key)
            ax.plot(
                [r["time_ms"] for r in front],
                [r[key] + (1 if key == "xor_px" else 0) for r in front],
                "k--",
                lw=1,
                alpha=0.6,
                label="Pareto front",
            )
            ax.set_xscale("log")
            if key == "xor_px":
                ax.set_yscale("log")
            ax.set_xlabel("render time per frame, ms (median, bars = IQR; log)")
            ax.set_ylabel(ylab, fontsize=9)
        axes[0].legend(fontsize=8, loc="upper right")
        axes[0].set_title("hard-edge accuracy", fontsize=10)
        axes[1].set_title("anti-aliased edge accuracy", fontsize=10)
        fig.suptitle(f"Shadow render time vs error - {scene} ({rs[0]['roi_w']}x{rs[0]['roi_h']} px ROI of 1280x720)")
        paths.append(_save(fig, Path(out_dir) / f"render_pareto_{i}.png"))
    return paths


def silhouette_time_vs_faces(rows: list[dict], out_dir: Path, label: str) -> Path:
    fig, ax = _fig("Silhouette detection time per light vs mesh size", label)
    for m in dict.fromkeys(r["method"] for r in rows):
        pts = sorted((r for r in rows if r["method"] == m), key=lambda r: r["faces"])
        ax.errorbar(
            [r["faces"] for r in pts],
            [r["time_ms"] for r in pts],
            yerr=[[r["time_ms"] - r["time_q25"] for r in pts], [r["time_q75"] - r["time_ms"] for r in pts]],
            marker="o",
            capsize=2,
            label=m,
        )
    ax.axvline(1470, color="0.6", ls=":", lw=1)
    ax.text(
        1470,
        0.02,
        " bunny size\n (~2 200 edges)",
        fontsize=7,
        color="0.4",
        va="bottom",
        transform=ax.get_xaxis_transform(),
    )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("faces (log)")
    ax.set_ylabel("time per light, ms (median, bars = IQR; log)")
    ax.legend(fontsize=8)
    return _save(fig, Path(out_dir) / "silhouette_time_vs_faces.png")


def reference_ops(rows: list[dict], out_dir: Path, label: str) -> Path:
    """Counted operations of the reference detectors against the papers' formulas, vs faces."""
    fig, ax = _fig("Reference detectors: counted operations vs the papers' formulas", label)
    colors = {"TA": "tab:blue", "VnV": "tab:orange", "Delta+": "tab:red"}
    for alg, col in colors.items():
        pts = sorted((r for r in rows if r["algorithm"] == alg), key=lambda r: r["faces"])
        if not pts:
            continue
        x = [r["faces"] for r in pts]
        ax.plot(x, [r["counted_ops"] for r in pts], "o-", color=col, label=f"{alg}: counted {pts[0]['counted_what']}")
        if alg == "Delta+":
            ax.plot(
                x,
                [r["paper_n_log2_n"] for r in pts],
                "x:",
                color=col,
                label="Delta+: [Kolivand-DeltaPlus]'s n log2 n (n = vertices)",
            )
            ax.plot(
                x,
                [r["fast_bvh_tests"] for r in pts],
                "s-.",
                color=col,
                alpha=0.6,
                label="Delta+ with a BVH (arshadow): box + triangle tests",
            )
        else:
            ax.plot(
                x,
                [r["formula_main_term"] for r in pts],
                "x:",
                color=col,
                label=f"{alg}: [Kolivand-HSD] formula, main term ({'compares' if alg == 'TA' else 'mults'})",
            )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("faces (log)")
    ax.set_ylabel("operations for one light (log)")
    ax.legend(fontsize=7.5)
    return _save(fig, Path(out_dir) / "silhouette_reference_ops.png")


def pipeline_time_vs_resolution(rows: list[dict], out_dir: Path, label: str) -> Path:
    fig, ax = _fig("Pipeline time per photo vs resolution (8 536-face knot, 1 light)", label)
    stages = ("detect", "pose", "silhouette", "volume", "render", "readback", "warp", "composite")
    res = list(dict.fromkeys(r["resolution"] for r in rows))
    methods = list(dict.fromkeys(r["shadow_method"] for r in rows))

    width = 0.8 / len(methods)
    cmap = __import__("matplotlib").colormaps["tab10"]
    for j, m in enumerate(methods):
        bottom = np.zeros(len(res))
        for k, s in enumerate(stages):
            vals = np.array(
                [
                    next(r for r in rows if r["resolution"] == rr and r["shadow_method"] == m).get(f"{s}_ms", 0.0)
                    for rr in res
                ]
            )
            ax.bar(
                np.arange(len(res)) + (j - (len(methods) - 1) / 2) * width,
                vals,
                width * 0.95,
                bottom=bottom,
                color=cmap(k),
                label=s if j == 0 else None,
                edgecolor="white",
                lw=0.5,
            )
            bottom += vals
        for i, rr in enumerate(res):
            r = next(r for r in rows if r["resolution"] == rr and r["shadow_method"] == m)
            ax.text(
                i + (j - (len(methods) - 1) / 2) * width,
                r["wall_ms"],
                f"{m}\n{r['wall_ms']:.0f} ms",
                ha="center",
                va="bottom",
                fontsize=7,
            )
    ax.set_xticks(range(len(res)), res)
    ax.set_ylabel("ms per photo (median of each stage; label = median wall time)")
    ax.set_ylim(0, ax.get_ylim()[1] * 1.15)
    ax.legend(fontsize=8, ncol=4, loc="upper left")
    return _save(fig, Path(out_dir) / "pipeline_time_vs_resolution.png")


def fps_vs_lights(rows: list[dict], out_dir: Path, label: str) -> Path:
    fig, ax = _fig(
        "Frames per second vs number of lights (1280x720, 8 536 faces; cf. [Kolivand-Stencil] Fig. 8)", label
    )
    for m, col in (("volume", "tab:blue"), ("shadowmap", "tab:red")):
        pts = sorted((r for r in rows if r["shadow_method"] == m), key=lambda r: r["lights"])
        if pts:
            ax.plot(
                [r["lights"] for r in pts],
                [r["fps"] for r in pts],
                "o-",
                color=col,
                label="stencil volumes" if m == "volume" else "shadow map 2048",
            )
            for r in pts:
                ax.annotate(
                    f"{r['fps']:.1f}",
                    (r["lights"], r["fps"]),
                    textcoords="offset points",
                    xytext=(4, 4),
                    fontsize=7,
                    color=col,
                )
    ax.set_xlabel("lights")
    ax.set_ylabel("frames per second (1000 / median wall time)")
    ax.set_ylim(0, None)
    ax.legend(fontsize=8)
    return _save(fig, Path(out_dir) / "fps_vs_lights.png")


def tracking(rows: list[dict], out_dir: Path, label: str) -> Path:
    """One panel per resolution: time against rotation error, one colour per configuration (legend)."""
    rows = [r for r in rows if r["rot_deg_median"] is not None]  # real footage: no true pose to plot against
    res = list(dict.fromkeys(r["resolution"] for r in rows))
    fig, ax0 = _fig(
        "Tracking: detection + pose time vs rotation error (synthetic photos, true pose known)",
        label,
        size=(5.0 * len(res) + 1.5, 5.8),
    )
    fig.delaxes(ax0)
    axes = fig.subplots(1, len(res), sharey=True, squeeze=False)[0]
    configs = list(dict.fromkeys(r["config"] for r in rows))
    cmap = __import__("matplotlib").colormaps["tab10"]
    col = {c: cmap(k % 10) for k, c in enumerate(configs)}
    for ax, rr in zip(axes, res, strict=True):
        ax.grid(True, which="both", alpha=0.3)
        for r in (r for r in rows if r["resolution"] == rr and r["rot_deg_median"] is not None):
            ax.errorbar(
                r["time_ms"],
                r["rot_deg_median"],
                xerr=[[r["time_ms"] - r["time_q25"]], [r["time_q75"] - r["time_ms"]]],
                fmt="o",
                color=col[r["config"]],
                capsize=2,
                ms=7,
                label=r["config"],
            )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(rr, fontsize=10)
        from matplotlib.ticker import NullFormatter

        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel("time per photo, ms (median, bars = IQR; log)")
    axes[0].set_ylabel("rotation error, degrees (median over photos; log)")
    handles = {h.get_label(): h for ax in axes for h in ax.get_legend_handles_labels()[0]}
    fig.legend(
        [handles[c] for c in configs if c in handles],
        [c for c in configs if c in handles],
        fontsize=8,
        loc="lower center",
        ncol=4,
        bbox_to_anchor=(0.5, 0.03),
    )
    fig.suptitle("Tracking: detection + pose time vs rotation error (synthetic photos, true pose known)")

    fig.tight_layout(rect=(0, 0.14, 1, 1))
    path = Path(out_dir) / "tracking_time_vs_error.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path


def realism(rows: list[dict], out_dir: Path, label: str) -> Path:
    """Residual against the path tracer (median over the own reference scenes) vs ms per 720p frame, one
    point per realism option and region (ground, contact band, object)."""
    fig, ax = _fig("Realism options: cost vs residual against a path tracer (own reference scenes)", label)
    styles = {"ground": ("tab:brown", "o"), "contact": ("tab:red", "s"), "object": ("tab:blue", "^")}
    for region, (color, marker) in styles.items():
        xs = [r["ms_720p"] for r in rows]
        ys = [r[f"own_{region}"] for r in rows]
        ax.scatter(xs, ys, color=color, marker=marker, label=region, s=36)
        if region == "ground":
            for r, x, y in zip(rows, xs, ys, strict=True):
                ax.annotate(r["option"], (x, y), fontsize=7, xytext=(4, 3), textcoords="offset points")
    ax.set_xlabel("time per 720p frame, ms (median)")
    ax.set_ylabel("residual to the path tracer (median; 0 perfect, 1 = no insert)")
    ax.legend(fontsize=8)
    return _save(fig, Path(out_dir) / "realism_cost_vs_residual.png")


def all_plots(results: dict, out_dir: Path, label: str, log: Callable[[str], None]) -> dict:
    """Every plot the results allow; ``{name: path}``."""
    out = {}
    if "silhouettes" in results:
        out["silhouette_time_vs_faces"] = silhouette_time_vs_faces(results["silhouettes"]["detectors"], out_dir, label)
        out["silhouette_reference_ops"] = reference_ops(results["silhouettes"]["reference"], out_dir, label)
    if "render" in results:
        for i, p in enumerate(render_pareto(results["render"], out_dir, label)):
            out[f"render_pareto_{i}"] = p
    if "tracking" in results:
        out["tracking"] = tracking(results["tracking"], out_dir, label)
    if "pipeline" in results:
        out["pipeline_time_vs_resolution"] = pipeline_time_vs_resolution(results["pipeline"]["stages"], out_dir, label)
        out["fps_vs_lights"] = fps_vs_lights(results["pipeline"]["lights"], out_dir, label)
    if results.get("realism"):
        out["realism"] = realism(results["realism"], out_dir, label)
    log(f"  {len(out)} plots written")
    return out
