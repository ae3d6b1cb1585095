"""Raw OpenGL entry points through ctypes, for what moderngl does not expose (stencil, renderbuffers
with a depth-stencil format, framebuffer blits, depth clamp).

The functions are loaded from ``libOpenGL.so.0`` (the GLVND dispatch library) and act on whichever
context is current, i.e. moderngl's own. Every function has ``argtypes``/``restype`` set so a wrong
argument fails in Python instead of corrupting the stack.

Nothing is loaded at import: call :func:`load` (the renderer does), which raises
:class:`~arshadow.errors.GLContextError` naming the library if it is missing.

moderngl caches some GL state on its side (bound framebuffer, depth function, enable flags, colour and
depth masks per framebuffer). Code that mixes these raw calls with moderngl must set moderngl's view of
the state explicitly before each pass (``ctx.enable_only``, ``ctx.depth_func``, ``fbo.use()``) and
restore what it changed with raw calls (stencil state, depth clamp) when it is done.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from ..errors import GLContextError

if TYPE_CHECKING:
    # typeshed's type of ``ctypes.byref(x)`` (it has no public name)
    from ctypes import _CArgObject

    #: what a ``GLuint *`` / ``GLint *`` parameter takes: ``ctypes.byref(c_uint(...))`` or a ``c_uint`` array
    UIntPointer = ctypes.Array[ctypes.c_uint] | _CArgObject
    IntPointer = ctypes.Array[ctypes.c_int] | _CArgObject

# ---- enums (OpenGL 4.5 core) -------------------------------------------------------------------------
GL_NO_ERROR = 0
GL_NEVER, GL_LESS, GL_EQUAL, GL_LEQUAL, GL_GREATER, GL_NOTEQUAL, GL_GEQUAL, GL_ALWAYS = range(0x0200, 0x0208)
GL_KEEP = 0x1E00
GL_ZERO = 0
GL_REPLACE = 0x1E01
GL_INCR = 0x1E02
GL_DECR = 0x1E03
GL_INVERT = 0x150A
GL_INCR_WRAP = 0x8507
GL_DECR_WRAP = 0x8508
GL_FRONT = 0x0404
GL_BACK = 0x0405
GL_FRONT_AND_BACK = 0x0408
GL_CW = 0x0900
GL_CCW = 0x0901
GL_STENCIL_TEST = 0x0B90
GL_DEPTH_TEST = 0x0B71
GL_DEPTH_CLAMP = 0x864F
GL_BLEND = 0x0BE2
GL_CULL_FACE = 0x0B44
GL_SCISSOR_TEST = 0x0C11
GL_MULTISAMPLE = 0x809D
GL_POLYGON_OFFSET_FILL = 0x8037
GL_SAMPLE_ALPHA_TO_COVERAGE = 0x809E
GL_COLOR_BUFFER_BIT = 0x00004000
GL_DEPTH_BUFFER_BIT = 0x00000100
GL_STENCIL_BUFFER_BIT = 0x00000400
GL_NEAREST = 0x2600
GL_LINEAR = 0x2601
GL_FRAMEBUFFER = 0x8D40
GL_READ_FRAMEBUFFER = 0x8CA8
GL_DRAW_FRAMEBUFFER = 0x8CA9
GL_RENDERBUFFER = 0x8D41
GL_TEXTURE_2D = 0x0DE1
GL_NONE = 0
GL_FRAMEBUFFER_COMPLETE = 0x8CD5
GL_COLOR_ATTACHMENT0 = 0x8CE0
GL_DEPTH_ATTACHMENT = 0x8D00
GL_STENCIL_ATTACHMENT = 0x8D20
GL_DEPTH_STENCIL_ATTACHMENT = 0x821A
GL_DEPTH24_STENCIL8 = 0x88F0
GL_DEPTH32F_STENCIL8 = 0x8CAD
GL_RGBA8 = 0x8058
GL_RGBA16F = 0x881A
GL_RGBA32F = 0x8814
GL_RG16F = 0x822F
GL_RG32F = 0x8230
GL_R16F = 0x822D
GL_R32F = 0x822E
GL_RG8 = 0x822B
GL_R8 = 0x8229
GL_RED = 0x1903
GL_RG = 0x8227
GL_RGB = 0x1907
GL_RGBA = 0x1908
GL_STENCIL_INDEX = 0x1901
GL_DEPTH_COMPONENT = 0x1902
GL_UNSIGNED_BYTE = 0x1401
GL_FLOAT = 0x1406
GL_HALF_FLOAT = 0x140B
GL_UNSIGNED_INT = 0x1405
GL_PACK_ALIGNMENT = 0x0D05
GL_PACK_ROW_LENGTH = 0x0D02
GL_PIXEL_PACK_BUFFER = 0x88EB
GL_STENCIL_BITS = 0x0D57
GL_MAX_SAMPLES = 0x8D57
GL_FRAMEBUFFER_ATTACHMENT_STENCIL_SIZE = 0x8217
GL_FRAMEBUFFER_ATTACHMENT_DEPTH_SIZE = 0x8216
GL_RENDERBUFFER_STENCIL_SIZE = 0x8D55
GL_RENDERBUFFER_DEPTH_SIZE = 0x8D54
GL_RENDERBUFFER_SAMPLES = 0x8CAB
GL_FRAMEBUFFER_BINDING = 0x8CA6
GL_RENDERBUFFER_BINDING = 0x8CA7
GL_RENDERER = 0x1F01
GL_VENDOR = 0x1F00
GL_VERSION = 0x1F02
GL_SHADING_LANGUAGE_VERSION = 0x8B8C
GL_TRUE = 1
GL_FALSE = 0

_FRAMEBUFFER_STATUS = {
    0x8CD5: "GL_FRAMEBUFFER_COMPLETE",
    0x8219: "GL_FRAMEBUFFER_UNDEFINED",
    0x8CD6: "GL_FRAMEBUFFER_INCOMPLETE_ATTACHMENT",
    0x8CD7: "GL_FRAMEBUFFER_INCOMPLETE_MISSING_ATTACHMENT",
    0x8CDB: "GL_FRAMEBUFFER_INCOMPLETE_DRAW_BUFFER",
    0x8CDC: "GL_FRAMEBUFFER_INCOMPLETE_READ_BUFFER",
    0x8CDD: "GL_FRAMEBUFFER_UNSUPPORTED",
    0x8D56: "GL_FRAMEBUFFER_INCOMPLETE_MULTISAMPLE",
    0x8DA8: "GL_FRAMEBUFFER_INCOMPLETE_LAYER_TARGETS",
}


def framebuffer_status_name(code: int) -> str:
    """Name of a ``glCheckFramebufferStatus`` result (e.g. ``"GL_FRAMEBUFFER_UNSUPPORTED"``)."""
    return _FRAMEBUFFER_STATUS.get(int(code), f"0x{int(code):04X}")


_u = ctypes.c_uint
_i = ctypes.c_int
_f = ctypes.c_float
_ub = ctypes.c_ubyte
_p = ctypes.c_void_p
_pu = ctypes.POINTER(ctypes.c_uint)
_pi = ctypes.POINTER(ctypes.c_int)

#: name -> (restype, argtypes)
_SIGNATURES = {
    "glGetError": (_u, []),
    "glGetIntegerv": (None, [_u, _pi]),
    "glGetString": (ctypes.c_char_p, [_u]),
    "glEnable": (None, [_u]),
    "glDisable": (None, [_u]),
    "glIsEnabled": (_ub, [_u]),
    "glGenRenderbuffers": (None, [_i, _pu]),
    "glDeleteRenderbuffers": (None, [_i, _pu]),
    "glBindRenderbuffer": (None, [_u, _u]),
    "glRenderbufferStorage": (None, [_u, _u, _i, _i]),
    "glRenderbufferStorageMultisample": (None, [_u, _i, _u, _i, _i]),
    "glGetRenderbufferParameteriv": (None, [_u, _u, _pi]),
    "glGenFramebuffers": (None, [_i, _pu]),
    "glDeleteFramebuffers": (None, [_i, _pu]),
    "glBindFramebuffer": (None, [_u, _u]),
    "glFramebufferRenderbuffer": (None, [_u, _u, _u, _u]),
    "glFramebufferTexture2D": (None, [_u, _u, _u, _u, _i]),
    "glCheckFramebufferStatus": (_u, [_u]),
    "glGetFramebufferAttachmentParameteriv": (None, [_u, _u, _u, _pi]),
    "glDrawBuffers": (None, [_i, _pu]),
    "glReadBuffer": (None, [_u]),
    "glBlitFramebuffer": (None, [_i, _i, _i, _i, _i, _i, _i, _i, _u, _u]),
    "glStencilFunc": (None, [_u, _i, _u]),
    "glStencilFuncSeparate": (None, [_u, _u, _i, _u]),
    "glStencilOp": (None, [_u, _u, _u]),
    "glStencilOpSeparate": (None, [_u, _u, _u, _u]),
    "glStencilMask": (None, [_u]),
    "glClearStencil": (None, [_i]),
    "glClearDepth": (None, [ctypes.c_double]),
    "glClearColor": (None, [_f, _f, _f, _f]),
    "glClear": (None, [_u]),
    "glDepthMask": (None, [_ub]),
    "glDepthFunc": (None, [_u]),
    "glColorMask": (None, [_ub, _ub, _ub, _ub]),
    "glColorMaski": (None, [_u, _ub, _ub, _ub, _ub]),
    "glFrontFace": (None, [_u]),
    "glPolygonOffset": (None, [_f, _f]),
    "glViewport": (None, [_i, _i, _i, _i]),
    "glScissor": (None, [_i, _i, _i, _i]),
    "glPixelStorei": (None, [_u, _i]),
    "glBindBuffer": (None, [_u, _u]),
    "glReadPixels": (None, [_i, _i, _i, _i, _u, _u, _p]),
    "glFinish": (None, []),
    "glFlush": (None, []),
}


class GL:
    """Namespace of loaded GL functions (attributes named like the C functions).

    The functions of ``_SIGNATURES`` are set per instance, by name; their types are declared below, as
    ctypes converts them: ``GLenum``, ``GLuint``, ``GLint``, ``GLsizei``, ``GLbitfield`` and ``GLboolean`` are
    Python ints, ``GLfloat`` / ``GLdouble`` floats, a ``void *`` an address (``ndarray.ctypes.data``), a
    ``const GLubyte *`` result bytes (None for NULL). Every loaded function has its declaration:

    >>> sorted(set(_SIGNATURES) - set(GL.__annotations__))
    []
    """

    library: str
    glGetError: Callable[[], int]
    glGetIntegerv: Callable[[int, IntPointer], None]
    glGetString: Callable[[int], bytes | None]
    glEnable: Callable[[int], None]
    glDisable: Callable[[int], None]
    glIsEnabled: Callable[[int], int]
    glGenRenderbuffers: Callable[[int, UIntPointer], None]
    glDeleteRenderbuffers: Callable[[int, UIntPointer], None]
    glBindRenderbuffer: Callable[[int, int], None]
    glRenderbufferStorage: Callable[[int, int, int, int], None]
    glRenderbufferStorageMultisample: Callable[[int, int, int, int, int], None]
    glGetRenderbufferParameteriv: Callable[[int, int, IntPointer], None]
    glGenFramebuffers: Callable[[int, UIntPointer], None]
    glDeleteFramebuffers: Callable[[int, UIntPointer], None]
    glBindFramebuffer: Callable[[int, int], None]
    glFramebufferRenderbuffer: Callable[[int, int, int, int], None]
    glFramebufferTexture2D: Callable[[int, int, int, int, int], None]
    glCheckFramebufferStatus: Callable[[int], int]
    glGetFramebufferAttachmentParameteriv: Callable[[int, int, int, IntPointer], None]
    glDrawBuffers: Callable[[int, UIntPointer], None]
    glReadBuffer: Callable[[int], None]
    glBlitFramebuffer: Callable[[int, int, int, int, int, int, int, int, int, int], None]
    glStencilFunc: Callable[[int, int, int], None]
    glStencilFuncSeparate: Callable[[int, int, int, int], None]
    glStencilOp: Callable[[int, int, int], None]
    glStencilOpSeparate: Callable[[int, int, int, int], None]
    glStencilMask: Callable[[int], None]
    glClearStencil: Callable[[int], None]
    glClearDepth: Callable[[float], None]
    glClearColor: Callable[[float, float, float, float], None]
    glClear: Callable[[int], None]
    glDepthMask: Callable[[int], None]
    glDepthFunc: Callable[[int], None]
    glColorMask: Callable[[int, int, int, int], None]
    glColorMaski: Callable[[int, int, int, int, int], None]
    glFrontFace: Callable[[int], None]
    glPolygonOffset: Callable[[float, float], None]
    glViewport: Callable[[int, int, int, int], None]
    glScissor: Callable[[int, int, int, int], None]
    glPixelStorei: Callable[[int, int], None]
    glBindBuffer: Callable[[int, int], None]
    glReadPixels: Callable[[int, int, int, int, int, int, int], None]
    glFinish: Callable[[], None]
    glFlush: Callable[[], None]

    def __init__(self, lib: ctypes.CDLL, path: str) -> None:
        self.library = path
        for name, (restype, argtypes) in _SIGNATURES.items():
            try:
                fn = getattr(lib, name)
            except AttributeError as exc:  # pragma: no cover - every GL >= 3.3 library has them
                raise GLContextError(f"{path} does not export {name} (OpenGL >= 3.3 needed)") from exc
            fn.restype = restype
            fn.argtypes = argtypes
            setattr(self, name, fn)

    # small conveniences -----------------------------------------------------------------------------
    def gen_renderbuffer(self) -> int:
        v = ctypes.c_uint(0)
        self.glGenRenderbuffers(1, ctypes.byref(v))
        return int(v.value)

    def delete_renderbuffer(self, name: int) -> None:
        v = ctypes.c_uint(name)
        self.glDeleteRenderbuffers(1, ctypes.byref(v))

    def gen_framebuffer(self) -> int:
        v = ctypes.c_uint(0)
        self.glGenFramebuffers(1, ctypes.byref(v))
        return int(v.value)

    def delete_framebuffer(self, name: int) -> None:
        v = ctypes.c_uint(name)
        self.glDeleteFramebuffers(1, ctypes.byref(v))

    def draw_buffers(self, n: int, only: int | None = None) -> None:
        """``glDrawBuffers`` for attachments 0..n-1 (or, with ``only``, that attachment and GL_NONE)."""
        arr = (ctypes.c_uint * n)(
            *[(GL_COLOR_ATTACHMENT0 + i) if (only is None or i == only) else GL_NONE for i in range(n)]
        )
        self.glDrawBuffers(n, arr)

    def draw_buffer_list(self, attachments: Sequence[int | None]) -> None:
        """``glDrawBuffers`` with fragment output i -> colour attachment ``attachments[i]`` (None: GL_NONE)."""
        n = len(attachments)
        arr = (ctypes.c_uint * n)(*[GL_NONE if a is None else GL_COLOR_ATTACHMENT0 + int(a) for a in attachments])
        self.glDrawBuffers(n, arr)

    def renderbuffer_param(self, rb: int, pname: int) -> int:
        v = ctypes.c_int(0)
        self.glBindRenderbuffer(GL_RENDERBUFFER, rb)
        self.glGetRenderbufferParameteriv(GL_RENDERBUFFER, pname, ctypes.byref(v))
        self.glBindRenderbuffer(GL_RENDERBUFFER, 0)
        return int(v.value)

    def attachment_param(self, attachment: int, pname: int) -> int:
        """Query a parameter of an attachment of the framebuffer bound to ``GL_FRAMEBUFFER``."""
        v = ctypes.c_int(0)
        self.glGetFramebufferAttachmentParameteriv(GL_FRAMEBUFFER, attachment, pname, ctypes.byref(v))
        return int(v.value)

    def string(self, pname: int) -> str:
        s = self.glGetString(pname)
        return s.decode("utf-8", "replace") if s else ""


_lock = threading.Lock()
_GL: GL | None = None


def find_gl_library() -> str | None:
    """Path/soname of the OpenGL dispatch library, or None when it is not installed."""
    return ctypes.util.find_library("OpenGL") or None


def load() -> GL:
    """Load (once) and return the GL function table.

    Raises
    ------
    GLContextError
        When ``libOpenGL.so.0`` cannot be loaded (Debian package ``libopengl0``).
    """
    global _GL
    with _lock:
        if _GL is None:
            errors = []
            for name in ("libOpenGL.so.0", find_gl_library(), "libGL.so.1"):
                if not name:
                    continue
                try:
                    lib = ctypes.CDLL(name)
                except OSError as exc:
                    errors.append(f"{name}: {exc}")
                    continue
                _GL = GL(lib, name)
                break
            else:
                raise GLContextError(
                    "cannot load the OpenGL library libOpenGL.so.0 ("
                    + "; ".join(errors)
                    + "); install it, e.g. Debian/Ubuntu: apt-get install libopengl0 libgl1-mesa-dri"
                )
        return _GL
