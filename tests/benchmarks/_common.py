"""What every benchmark script repeats: run metadata, summary statistics of repeated timings, JSON output.

The shared helpers live in :mod:`arshadow.bench.common` (``arshadow bench`` uses them too); this module
re-exports them for the scripts in this folder (``import _common``) and adds :func:`emit`.
"""

from __future__ import annotations

import json
import os

from arshadow.bench.common import ROOT, git_commit, metadata, summary, timed  # noqa: F401 (re-exported)


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
