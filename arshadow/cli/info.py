"""``arshadow info``: versions, the OpenGL backend and renderer, stencil bits, MSAA samples."""

from __future__ import annotations

import argparse
import json
import platform
import sys
from typing import Any


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "info",
        help="print versions, the OpenGL backend/renderer and what was detected",
        description="Print the versions of arshadow and its dependencies, the OpenGL backend, GL_RENDERER, "
        "GL_VERSION, the stencil bits of a GL_DEPTH24_STENCIL8 buffer and the maximum MSAA samples. "
        "Exit status 2 when no OpenGL context can be created (the message names the missing library).",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument(
        "--backend", default=None, help="OpenGL backend: egl (default), x11, default; else $ARSHADOW_GL_BACKEND"
    )
    p.set_defaults(func=run)


def _version(mod_name: str) -> str | None:
    try:
        mod = __import__(mod_name)
    except Exception:  # a missing optional package is reported, not fatal
        return None
    return str(getattr(mod, "__version__", "unknown"))


def collect(backend: str | None = None) -> dict:
    """Everything ``arshadow info`` reports, as a dict (``gl`` holds the error when no context)."""
    from .. import __version__
    from ..errors import GLContextError
    from ..gl.context import create_context, detect_libraries, diagnose, gl_info, resolve_backend

    out: dict[str, object] = {
        "arshadow": __version__,
        "python": platform.python_version(),
        "platform": platform.platform(),
        "numpy": _version("numpy"),
        "cv2": _version("cv2"),
        "trimesh": _version("trimesh"),
        "moderngl": _version("moderngl"),
        "detected": detect_libraries(),
    }
    name = resolve_backend(backend)
    try:
        ctx = create_context(name)
    except GLContextError as exc:
        out["gl"] = {"backend": name, "error": str(exc), "missing": diagnose(name)}
        return out
    try:
        out["gl"] = gl_info(ctx)
    finally:
        ctx.release()
    return out


def run(args: argparse.Namespace) -> int:
    info = collect(args.backend)
    gl = info["gl"]
    if args.json:
        print(json.dumps(info, indent=1, sort_keys=False))
    else:
        for k in ("arshadow", "python", "platform", "numpy", "cv2", "trimesh", "moderngl"):
            print(f"{k:<22}{info[k] if info[k] is not None else 'not installed'}")
        det = info["detected"]
        for k in ("libEGL", "libOpenGL", "libGL"):
            print(f"{k:<22}{det[k] or 'not found'}")
        print(f"{'EGL vendors':<22}{', '.join(det['egl_vendors']) or 'none registered'}")
        if "error" in gl:
            print(f"{'gl backend':<22}{gl['backend']}")
            print(f"{'gl':<22}NOT AVAILABLE: {gl['error']}")
        else:
            rows = [
                ("gl backend", gl["backend"]),
                ("GL_RENDERER", gl["GL_RENDERER"]),
                ("GL_VERSION", gl["GL_VERSION"]),
                ("GL_VENDOR", gl["GL_VENDOR"]),
                ("GLSL", gl["GLSL"]),
                ("stencil bits", f"{gl['stencil_bits']} (GL_DEPTH24_STENCIL8, depth {gl['depth_bits']} bits)"),
                ("MSAA max samples", gl["max_samples"]),
                ("max renderbuffer", gl["max_renderbuffer_size"]),
                ("gl library", gl["gl_library"]),
            ]
            for k, v in rows:
                print(f"{k:<22}{v}")
    if "error" in gl:
        print(f"arshadow info: error: {gl['error']}", file=sys.stderr)
        return 2
    return 0
