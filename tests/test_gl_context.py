"""Context creation: backend resolution, clear errors naming the missing library, gl_info, arshadow info."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from arshadow.errors import GLContextError
from arshadow.gl import context as glc


def test_import_creates_no_context():
    code = (
        "import sys, arshadow.gl, arshadow.gl.context, arshadow.gl.stencil, arshadow.gl.resources, arshadow.gl.shadowmap, arshadow.gl.gpu_compose, arshadow.gl.glraw\n"
        "assert 'moderngl' not in sys.modules, 'moderngl imported at import time'\n"
        "import arshadow.gl.glraw as g; assert g._GL is None\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_backend_resolution(monkeypatch):
    monkeypatch.delenv(glc.ENV_VAR, raising=False)
    assert glc.resolve_backend() == "egl"
    monkeypatch.setenv(glc.ENV_VAR, "x11")
    assert glc.resolve_backend() == "x11"
    assert glc.resolve_backend("egl") == "egl"  # argument wins over the environment
    monkeypatch.setenv(glc.ENV_VAR, "vulkan")
    with pytest.raises(GLContextError, match="vulkan"):
        glc.resolve_backend()
    with pytest.raises(GLContextError, match="choose one of"):
        glc.create_context("metal")


def test_missing_library_is_named(monkeypatch):
    import ctypes.util

    import moderngl

    def fail(**kw):
        raise Exception("libEGL.so.1: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_context", fail)
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None if name == "EGL" else f"lib{name}.so")
    with pytest.raises(GLContextError) as ei:
        glc.create_context("egl")
    msg = str(ei.value)
    assert "libEGL is missing" in msg and "libegl1" in msg and "libgl1-mesa-dri" in msg
    assert "libOpenGL is missing" not in msg
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: None)
    with pytest.raises(GLContextError, match="libopengl0"):
        glc.create_context("egl")


@pytest.mark.gl
def test_gl_info(ctx):
    info = glc.gl_info(ctx)
    assert info["backend"] == "egl"
    assert info["GL_RENDERER"] and info["GL_VERSION"]
    assert info["version_code"] >= 330
    assert info["stencil_bits"] == 8
    assert info["depth_bits"] == 24
    assert info["max_samples"] >= 0


@pytest.mark.gl
def test_cli_info_json(gl_ctx):
    out = subprocess.run(
        [sys.executable, "-m", "arshadow", "info", "--json"], capture_output=True, text=True, check=True
    )
    info = json.loads(out.stdout)
    for key in ("arshadow", "python", "numpy", "cv2", "trimesh", "moderngl"):
        assert info[key]
    assert info["gl"]["stencil_bits"] == 8
    assert info["gl"]["GL_RENDERER"]
    assert info["detected"]["libEGL"] and info["detected"]["libOpenGL"]
    text = subprocess.run([sys.executable, "-m", "arshadow", "info"], capture_output=True, text=True, check=True)
    assert "GL_RENDERER" in text.stdout and "stencil bits" in text.stdout and "libEGL" in text.stdout


def test_cli_info_reports_failure(monkeypatch):
    out = subprocess.run(
        [sys.executable, "-m", "arshadow", "info", "--backend", "nonsense"], capture_output=True, text=True
    )
    assert out.returncode == 2
    assert "nonsense" in out.stderr and "Traceback" not in out.stderr
