"""What every benchmark script repeats: run metadata, summary statistics of repeated timings, JSON output.

Use from a script in this folder (``import _common``: the script's folder is on ``sys.path`` both when
it is run directly and when pytest collects it)::

    res = {"meta": _common.metadata(ctx), ...}
    res["frame_ms"] = _common.summary(times_ms)
    _common.emit(res, args.out)
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def git_commit() -> tuple[str | None, bool | None]:
    """``(short commit hash, arshadow/ has uncommitted changes)`` of the work tree; ``(None, None)``
    without git."""
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=False, timeout=10).stdout.strip() or None
        dirty = bool(subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--", "arshadow"],
                                    capture_output=True, text=True, check=False, timeout=10).stdout.strip())
    except (OSError, subprocess.TimeoutExpired):
        return None, None
    return commit, dirty


def metadata(ctx=None) -> dict:
    """Commit, versions, machine and load at the start; ``GL_RENDERER`` / ``GL_VERSION`` of ``ctx`` (a
    moderngl context) when given. :func:`emit` adds the load at the end."""
    import cv2
    import trimesh

    from arshadow import __version__

    commit, dirty = git_commit()
    meta = {"git_commit": commit, "arshadow_dirty": dirty, "arshadow": __version__,
            "python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
            "trimesh": trimesh.__version__, "machine": platform.machine(), "cpus": os.cpu_count(),
            "loadavg_start": list(os.getloadavg()), "command": " ".join(sys.argv)}
    if ctx is not None:
        import moderngl

        from arshadow.gl.context import gl_info

        info = gl_info(ctx)
        meta.update(moderngl=moderngl.__version__, GL_RENDERER=info.get("GL_RENDERER"),
                    GL_VERSION=info.get("GL_VERSION"))
    return meta


def summary(values, ndigits: int = 3) -> dict:
    """Median, interquartile range ``[q25, q75]``, min, max and count of repeated measurements."""
    a = np.asarray(values, dtype=np.float64)
    q1, med, q3 = np.percentile(a, [25, 50, 75])
    return {"median": round(float(med), ndigits), "iqr": [round(float(q1), ndigits), round(float(q3), ndigits)],
            "min": round(float(a.min()), ndigits), "max": round(float(a.max()), ndigits), "n": int(a.size)}


def emit(result: dict, out=None) -> None:
    """Print ``result`` as JSON (after stamping ``meta.loadavg_end``) and, when ``out`` is a path, also
    write it there atomically."""
    if isinstance(result.get("meta"), dict):
        result["meta"]["loadavg_end"] = list(os.getloadavg())
    text = json.dumps(result, indent=1)
    print(text)
    if out:
        from arshadow.io import write_bytes

        write_bytes(out, (text + "\n").encode())
