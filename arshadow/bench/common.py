"""What every benchmark repeats: run metadata, summary statistics of repeated timings, CSV output.

Shared by ``arshadow bench`` (:mod:`arshadow.bench`) and the scripts in ``tests/benchmarks/``.
"""

from __future__ import annotations

import csv
import io
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import trimesh

from arshadow import __version__
from arshadow.gl.context import gl_info
from arshadow.io import write_bytes

from ..demo.data import data_root

#: the folder holding samples/ and calib/: the repository root in a checkout, the installed copy otherwise
ROOT = data_root()
#: the checkout's root (for git); not a checkout when arshadow is installed
REPO = Path(__file__).resolve().parents[2]

__all__ = ["ROOT", "git_commit", "metadata", "summary", "timed", "write_csv", "machine_label"]


def git_commit() -> tuple[str | None, bool | None]:
    """``(short commit hash, arshadow/ has uncommitted changes)`` of the work tree; ``(None, None)``
    without git or outside a checkout (an installed wheel)."""
    if not (REPO / ".git").exists():
        return None, None
    try:
        commit = (
            subprocess.run(
                ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"],
                capture_output=True,
                text=True,
                check=False,
                timeout=10,
            ).stdout.strip()
            or None
        )
        dirty = bool(
            subprocess.run(
                ["git", "-C", str(REPO), "status", "--porcelain", "--", "arshadow"],
                capture_output=True,
                text=True,
                check=False,
                timeout=10,
            ).stdout.strip()
        )
    except (OSError, subprocess.TimeoutExpired):
        return None, None
    return commit, dirty


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def metadata(ctx: Any = None) -> dict:
    """Commit, versions, machine (CPU model, count) and load at the start; ``GL_RENDERER`` / ``GL_VERSION``
    of ``ctx`` (a moderngl context) when given."""

    commit, dirty = git_commit()
    meta = {
        "git_commit": commit,
        "arshadow_dirty": dirty,
        "arshadow": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "trimesh": trimesh.__version__,
        "machine": platform.machine(),
        "cpu": _cpu_model(),
        "cpus": os.cpu_count(),
        "loadavg_start": list(os.getloadavg()),
        "command": " ".join(sys.argv),
    }
    if ctx is not None:
        info = gl_info(ctx)
        meta.update(
            moderngl=version("moderngl"), GL_RENDERER=info.get("GL_RENDERER"), GL_VERSION=info.get("GL_VERSION")
        )
    return meta


def machine_label(meta: dict) -> str:
    """One line for plots and tables: CPU, cores, GL renderer, versions, commit."""
    gl = meta.get("GL_RENDERER") or "no GL"
    return (
        f"{meta.get('cpu')} x{meta.get('cpus')} | {gl} | arshadow {meta.get('arshadow')} "
        f"({meta.get('git_commit')}{'+' if meta.get('arshadow_dirty') else ''}) | numpy {meta.get('numpy')} "
        f"| OpenCV {meta.get('opencv')} | moderngl {meta.get('moderngl', '-')} | Python {meta.get('python')}"
    )


def summary(values: Sequence[float], ndigits: int = 3) -> dict:
    """Median, interquartile range ``[q25, q75]``, min, max and count of repeated measurements."""
    a = np.asarray(values, dtype=np.float64)
    q1, med, q3 = np.percentile(a, [25, 50, 75])
    return {
        "median": round(float(med), ndigits),
        "iqr": [round(float(q1), ndigits), round(float(q3), ndigits)],
        "min": round(float(a.min()), ndigits),
        "max": round(float(a.max()), ndigits),
        "n": int(a.size),
    }


def timed(fn: Callable[[], object], repeat: int, warmup: int = 1) -> list[float]:
    """Wall times (ms) of ``repeat`` calls of ``fn()`` after ``warmup`` untimed calls."""
    for _ in range(warmup):
        fn()
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def write_csv(path: Path | str, rows: list[dict]) -> Path:
    """Write ``rows`` (dicts; the union of their keys as columns, in first-seen order) atomically."""
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    return write_bytes(path, buf.getvalue().encode())


def t_fields(prefix: str, times_ms: Sequence[float]) -> dict:
    """CSV columns ``<prefix>_ms`` (median), ``<prefix>_q25``, ``<prefix>_q75``, ``<prefix>_n`` of times."""
    s = summary(times_ms, 4)
    return {
        f"{prefix}_ms": s["median"],
        f"{prefix}_q25": s["iqr"][0],
        f"{prefix}_q75": s["iqr"][1],
        f"{prefix}_n": s["n"],
    }
