"""The one place that creates an OpenGL context.

``create_context`` makes a headless moderngl context (EGL by default: Mesa llvmpipe on a CPU-only
machine, the GPU driver elsewhere). It is called once by the application and the context is handed to
:class:`arshadow.gl.stencil.ShadowRenderer`, which never creates one. Importing this module does not
create a context.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import glob
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Concatenate, ParamSpec, TypeVar, cast

from ..errors import GLContextError
from . import glraw

if TYPE_CHECKING:  # annotations only: importing this module must not import moderngl (create_context does)
    import moderngl

_Self = TypeVar("_Self")
_P = ParamSpec("_P")
_R = TypeVar("_R")

#: backends accepted by :func:`create_context` (``$ARSHADOW_GL_BACKEND`` takes the same names)
BACKENDS = ("egl", "x11", "default")
ENV_VAR = "ARSHADOW_GL_BACKEND"
#: minimum OpenGL version (core profile) the renderer needs
REQUIRE = 330

# Debian/Ubuntu packages that provide the libraries, for the error message
_PACKAGES = {
    "EGL": "libegl1 (the GLVND EGL loader) and libegl-mesa0 libgl1-mesa-dri (the Mesa EGL driver, llvmpipe)",
    "OpenGL": "libopengl0 (the GLVND OpenGL dispatch library)",
    "GL": "libgl1 and libglx-mesa0 (for the x11 backend)",
}
#: where GLVND looks for EGL vendor (ICD) files
_EGL_VENDOR_DIRS = ("/usr/share/glvnd/egl_vendor.d", "/etc/glvnd/egl_vendor.d", "/usr/local/share/glvnd/egl_vendor.d")


def resolve_backend(backend: str | None = None) -> str:
    """The backend to use: the argument, else ``$ARSHADOW_GL_BACKEND``, else ``"egl"``.

    Raises
    ------
    GLContextError
        For a name that is not one of :data:`BACKENDS`.

    Examples
    --------
    >>> resolve_backend("egl")
    'egl'
    """
    name = backend if backend else os.environ.get(ENV_VAR, "") or "egl"
    name = name.strip().lower()
    if name not in BACKENDS:
        src = "backend argument" if backend else f"${ENV_VAR}"
        raise GLContextError(f"unknown OpenGL backend {name!r} ({src}); choose one of {', '.join(BACKENDS)}")
    return name


def _mesa_egl_driver_present() -> bool:
    """True if a GLVND EGL vendor (ICD) JSON file is installed (e.g. Mesa's 50_mesa.json)."""
    extra = os.environ.get("__EGL_VENDOR_LIBRARY_DIRS") or os.environ.get("__EGL_VENDOR_LIBRARY_FILENAMES")
    if extra:
        return True
    return any(glob.glob(os.path.join(d, "*.json")) for d in _EGL_VENDOR_DIRS)


def detect_libraries() -> dict[str, str | list[str] | None]:
    """What the system offers, without creating a context: the GL/EGL libraries ``ctypes`` finds, the
    registered EGL vendor files (GLVND ICDs) and ``$ARSHADOW_GL_BACKEND``."""
    return {
        "libEGL": ctypes.util.find_library("EGL"),
        "libOpenGL": ctypes.util.find_library("OpenGL"),
        "libGL": ctypes.util.find_library("GL"),
        "egl_vendors": sorted(
            os.path.basename(f) for d in _EGL_VENDOR_DIRS for f in glob.glob(os.path.join(d, "*.json"))
        ),
        ENV_VAR: os.environ.get(ENV_VAR) or None,
    }


def diagnose(backend: str = "egl") -> list[str]:
    """Missing system libraries/drivers for ``backend``, as human-readable strings (empty if none found)."""
    problems = []
    need = {"egl": ["EGL", "OpenGL"], "x11": ["GL"], "default": ["EGL", "OpenGL"]}[backend]
    for lib in need:
        if not ctypes.util.find_library(lib):
            problems.append(f"lib{lib} is missing (Debian/Ubuntu: apt-get install {_PACKAGES[lib]})")
    if backend in ("egl", "default") and ctypes.util.find_library("EGL") and not _mesa_egl_driver_present():
        problems.append(
            "no EGL driver is registered (no file in /usr/share/glvnd/egl_vendor.d; "
            "Debian/Ubuntu: apt-get install libegl-mesa0 libgl1-mesa-dri)"
        )
    if backend == "x11" and not os.environ.get("DISPLAY"):
        problems.append("$DISPLAY is not set (the x11 backend needs an X server; use backend 'egl' headless)")
    return problems


_made = [0]  # contexts this process has created (see contexts_made)


def contexts_made() -> int:
    """How many OpenGL contexts this process has created. One that has made any must not ``fork`` a
    worker: an EGL display and Mesa's rasterizer threads do not survive ``fork`` (the video chunk pool
    then starts its workers with ``spawn``).

    >>> contexts_made() >= 0
    True
    """
    return _made[0]


def create_context(backend: str | None = None) -> moderngl.Context:
    """Create a standalone (offscreen) moderngl context.

    Parameters
    ----------
    backend : str, optional
        ``"egl"`` (headless, default), ``"x11"`` (GLX, needs ``$DISPLAY``) or ``"default"`` (moderngl's
        platform default). Resolution order: this argument, ``$ARSHADOW_GL_BACKEND``, ``"egl"``.

    Returns
    -------
    moderngl.Context
        OpenGL >= 3.3 core. ``ctx.extra`` is a dict with ``{"backend": name}``.

    Raises
    ------
    GLContextError
        When no context can be made; the message names the missing library or driver and the Debian
        packages that provide it.
    """
    name = resolve_backend(backend)
    try:
        # deferred: importing arshadow.gl must not import moderngl (tests/test_gl_context.py); the context
        # is the first thing that needs it
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a runtime dependency
        raise GLContextError(f"moderngl is not installed ({exc}); pip install moderngl") from exc
    kwargs: dict[str, Any] = {"standalone": True, "require": REQUIRE}
    if name != "default":
        kwargs["backend"] = name
    _made[0] += 1  # counted before the attempt: a failed one may have loaded and started the driver
    try:
        ctx = moderngl.create_context(**kwargs)
    except Exception as exc:  # moderngl/glcontext raise plain Exceptions with the loader's message
        problems = diagnose(name)
        hint = "; ".join(problems) if problems else "the libraries are present: the driver refused to create a context"
        raise GLContextError(
            f"cannot create an OpenGL {REQUIRE // 100}.{REQUIRE % 100 // 10} context with backend "
            f"{name!r}: {exc}. {hint}"
        ) from exc
    ctx.extra = {"backend": name}
    return ctx


#: ``GL_RENDERER`` words of the rasterisers that run on the CPU (Mesa's llvmpipe, softpipe, swrast)
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast")


def is_software(ctx: moderngl.Context) -> bool:
    """Whether the context rasterises on the CPU (``GL_RENDERER`` names Mesa's llvmpipe, softpipe or
    swrast): then "GPU" work shares the cores with the rest of the pipeline."""
    renderer = str(getattr(ctx, "info", {}).get("GL_RENDERER", "")).lower()
    return any(w in renderer for w in SOFTWARE_RENDERERS)


def gl_info(ctx: moderngl.Context) -> dict[str, str | int]:
    """Facts about a context: renderer, version, vendor, backend, stencil bits, MSAA samples.

    The stencil bits are those actually obtained for a ``GL_DEPTH24_STENCIL8`` renderbuffer (the
    renderer's format), queried from a 1x1 renderbuffer made for the purpose.

    Parameters
    ----------
    ctx : moderngl.Context

    Returns
    -------
    dict
        ``GL_RENDERER``, ``GL_VERSION``, ``GL_VENDOR``, ``GLSL``, ``backend``, ``version_code``,
        ``stencil_bits``, ``depth_bits``, ``max_samples``, ``max_renderbuffer_size``, ``gl_library``.
    """
    gl = glraw.load()
    info = ctx.info
    rb = gl.gen_renderbuffer()
    try:
        gl.glBindRenderbuffer(glraw.GL_RENDERBUFFER, rb)
        gl.glRenderbufferStorage(glraw.GL_RENDERBUFFER, glraw.GL_DEPTH24_STENCIL8, 1, 1)
        stencil = gl.renderbuffer_param(rb, glraw.GL_RENDERBUFFER_STENCIL_SIZE)
        depth = gl.renderbuffer_param(rb, glraw.GL_RENDERBUFFER_DEPTH_SIZE)
    finally:
        gl.glBindRenderbuffer(glraw.GL_RENDERBUFFER, 0)
        gl.delete_renderbuffer(rb)
    extra = ctx.extra if isinstance(getattr(ctx, "extra", None), dict) else {}
    return {
        "backend": extra.get("backend", "unknown"),
        "GL_RENDERER": info.get("GL_RENDERER", ""),
        "GL_VERSION": info.get("GL_VERSION", ""),
        "GL_VENDOR": info.get("GL_VENDOR", ""),
        "GLSL": gl.string(glraw.GL_SHADING_LANGUAGE_VERSION),
        "version_code": int(ctx.version_code),
        "stencil_bits": stencil,
        "depth_bits": depth,
        "max_samples": int(ctx.max_samples),
        "max_renderbuffer_size": int(info.get("GL_MAX_RENDERBUFFER_SIZE", 0)),
        "gl_library": gl.library,
    }


def current(method: Callable[Concatenate[_Self, _P], _R]) -> Callable[Concatenate[_Self, _P], _R]:
    """Decorator: make the object's own context current before a GL method runs (and leave it current).

    Every arshadow GL object (renderer, compositor) works on the context it was handed; OpenGL calls go to
    whichever context is current on the thread. With several contexts in one process (two sessions, or
    a one-shot :func:`arshadow.render_photo` beside a session) the last one created stays current, and
    the other's calls hit the wrong context (deleted-name errors, blank masks). Each entry point makes its
    object's context current (``eglMakeCurrent``, ~2 us a call on llvmpipe) and leaves it current, so
    that what the caller does next with the results (reading a returned texture) happens on that
    context too. The context is ``self.ctx``, or the first argument of ``__init__``.
    """

    @functools.wraps(method)
    def wrapper(self: _Self, /, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        ctx: moderngl.Context | None = getattr(self, "ctx", None)
        if ctx is None:
            ctx = cast("moderngl.Context", args[0] if args else kwargs["ctx"])
        ctx.__enter__()  # make current; not restored on return (see above)
        return method(self, *args, **kwargs)

    return wrapper
