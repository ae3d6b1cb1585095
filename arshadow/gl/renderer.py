"""Offscreen stencil shadow-volume renderer (moderngl + raw GL stencil through ctypes).

The renderer is handed a moderngl context (see :mod:`arshadow.gl.context`); it never creates one.

Frame layout (one framebuffer, all renderbuffers, optional MSAA)::

    colour 0  RGBA16F   rgb = shaded occluder (linear), a = occluder coverage
    colour 1  RG16F     r = blocked light weight (the shadow mask), g = ground coverage
    depth/stencil       GL_DEPTH24_STENCIL8, made with glRenderbufferStorage(Multisample) through ctypes

Stencil bits: bit 7 = "this sample sees the ground plane" (set by the ground depth pass), bit 6 = "this
sample sees the occluder", bits 0-5 = the shadow-volume count of the current light (modulo 64, two-sided
INCR_WRAP/DECR_WRAP with write mask 0x3F). Modulo 64 is exact only while no sample lies in more than 63
volume layers; :func:`arshadow.geometry.volume.shadow_volume` bounds the layers (:func:`~arshadow.geometry.volume.layer_bound`)
and otherwise hands closed sub-volumes (``ShadowVolume.batches``) of <= 31 layers each: those are counted
one at a time in bits 0-4 and OR-ed into bit 5 (``SHADOWED_BIT``), so any depth complexity is exact.

Passes per frame
----------------
1. base: clear; occluder (depth + ambient colour + coverage); ground plane z = 0 (depth, ground bit; an
   unlimited plane drawn through homogeneous coordinates as four triangles with vertices at infinity, or a
   ``ground_size`` square); no polygon offset by default (measured: docs/rendering.md, ``ground_offset``).
2. per light: clear the count bits; draw the light's shadow volume with depth test on (GL_LESS), depth
   and colour writes off, depth clamp on, and two-sided stencil:
   z-pass  front: depth-pass -> INCR_WRAP, back: depth-pass -> DECR_WRAP (sides only);
   z-fail  back: depth-fail -> INCR_WRAP, front: depth-fail -> DECR_WRAP (sides + both caps);
   planar  the caster flattened onto z = 0 by the projection-shadow matrix (paper 002) -> REPLACE 1.
   Then a full-viewport triangle adds the light's weight to the mask where ``stencil > 0x80`` (ground bit
   set and count != 0), and the occluder is redrawn with GL_EQUAL depth adding this light's Phong
   diffuse + specular where the stencil is exactly 0x40 (occluder, count 0: self-shadowing).
3. MSAA resolve / supersampling downsample (glBlitFramebuffer), one readback per attachment of just the
   canvas, rows flipped to top-down.

moderngl keeps its own copy of some GL state (bound framebuffer, enable flags, depth function, colour and
depth masks). Each pass sets moderngl's flags explicitly (``ctx.enable_only``, ``ctx.depth_func``) and the
raw state (stencil, depth clamp, draw buffers, colour masks, polygon offset) is set per pass and reset at
the end.
"""

from __future__ import annotations

import functools
import math
import time
import weakref
from importlib import resources

import numpy as np

from ..compose.composite import srgb_to_linear
from .._check import check_finite, check_shape
from ..errors import GLContextError, ShapeError, UsageError
from ..render_api import MODES, LightPass, RenderLayers, RenderResult
from . import glraw as G
from .context import current
from .layers import GpuLayers, TextureTarget

__all__ = ["LightPass", "RenderResult", "ShadowRenderer", "load_shader", "srgb_to_linear"]

GROUND_BIT = 0x80
OCCLUDER_BIT = 0x40
COUNT_MASK = 0x3F
#: batched volumes (more layers than a 6-bit count holds): bits 0-4 count one batch, bit 5 ORs the batches
BATCH_COUNT_MASK = 0x1F
SHADOWED_BIT = 0x20
#: default occluder colour (sRGB) when the mesh has none and none is given
DEFAULT_COLOR = (0.8, 0.8, 0.8)


@functools.cache
def load_shader(name: str) -> str:
    """Source of a shader shipped in ``arshadow/gl/shaders`` (package data)."""
    return resources.files("arshadow.gl").joinpath("shaders", name).read_text(encoding="utf-8")


def _crease_normals(vertices: np.ndarray, faces: np.ndarray, crease_deg: float) -> np.ndarray:
    """Per-corner normals ``(m, 3, 3)`` float64 and ``(m, 3)`` bool "flat": the area-weighted vertex normal
    where it is within ``crease_deg`` of the face normal, else the face normal (flat edges stay sharp,
    curved parts smooth)."""
    tri = vertices[faces]
    raw = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # |raw| = 2 area
    fn = raw / np.maximum(np.linalg.norm(raw, axis=1, keepdims=True), 1e-300)
    vn = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(vn, faces[:, k], raw)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
    corner = vn[faces]  # (m, 3, 3)
    cos = np.einsum("mkj,mj->mk", corner, fn)
    flat = cos < math.cos(math.radians(crease_deg))
    corner = np.where(flat[..., None], fn[:, None, :], corner)
    return corner, flat


class _CasterBuffers:
    """GPU copies of one caster: the occluder (unwelded corners: pos4, normal3, albedo3) and the welded
    positions (for the planar shadow). Built once per caster."""

    def __init__(self, ctx, prog_base, prog_occ, prog_pos, caster, color, crease_deg, local=True):
        v = np.asarray(caster.vertices, dtype=np.float64)
        #: the caster's local origin (its box centre; world origin with ``local=False``): positions go to
        #: float32 relative to it
        self.origin = local_origin(v) if local else np.zeros(3)
        v_local = v - self.origin
        f = np.asarray(caster.faces, dtype=np.int64)
        m = len(f)
        if color is not None:
            alb = np.broadcast_to(srgb_to_linear(np.asarray(color, np.float64)[:3]), (m, 3, 3))
        else:
            cols = getattr(caster, "colors", None)
            if cols is None:
                alb = np.broadcast_to(srgb_to_linear(np.asarray(DEFAULT_COLOR)), (m, 3, 3))
            else:
                alb = srgb_to_linear(np.asarray(cols, np.float64)[:, :3])[f]
        nrm, flat = _crease_normals(v, f, crease_deg)
        # lighting pass: one vertex per distinct (vertex, normal) -- smooth corners share the vertex
        # normal, flat (crease) corners are per face -- drawn indexed so the vertex cache works
        key = np.stack([f.ravel(), np.where(flat, np.repeat(np.arange(m), 3).reshape(m, 3), -1).ravel()], 1)
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        corner_v = f.ravel()[first]
        data = np.empty((len(first), 10), dtype=np.float32)
        data[:, :3] = v_local[corner_v]
        data[:, 3] = 1.0
        data[:, 4:7] = nrm.reshape(-1, 3)[first]
        data[:, 7:10] = alb.reshape(-1, 3)[first]
        self.n_light_vertices = len(first)
        self.vbo = ctx.buffer(data.tobytes())
        self.light_ibo = ctx.buffer(inverse.reshape(-1).astype(np.uint32).tobytes())
        self.vao = ctx.vertex_array(prog_occ, [(self.vbo, "4f 3f 3f", "in_pos", "in_normal", "in_albedo")],
                                    index_buffer=self.light_ibo, index_element_size=4)
        # base pass and planar shadow: welded, indexed vertices (positions + albedo; ~6x fewer vertex
        # shader runs). Same float32 positions as above -> bit-identical depth for the GL_EQUAL passes.
        welded = np.empty((len(v), 7), dtype=np.float32)
        welded[:, :3] = v_local
        welded[:, 3] = 1.0
        if color is None and getattr(caster, "colors", None) is not None:
            welded[:, 4:7] = srgb_to_linear(np.asarray(caster.colors, np.float64)[:, :3])
        else:
            welded[:, 4:7] = alb[0, 0]
        self.pos_vbo = ctx.buffer(welded.tobytes())
        self.ibo = ctx.buffer(f.astype(np.uint32).tobytes())
        self.base_vao = ctx.vertex_array(prog_base, [(self.pos_vbo, "4f 3f", "in_pos", "in_albedo")],
                                         index_buffer=self.ibo, index_element_size=4)
        self.planar_vao = ctx.vertex_array(prog_pos, [(self.pos_vbo, "4f 12x", "in_pos")], index_buffer=self.ibo,
                                           index_element_size=4)
        self.n_indices = 3 * m
        self.below_ground = bool(v[:, 2].min() < 0.0)
        # homogeneous corners (8, 4) of the bounding box: the per-frame screen box of the colour readback
        b = np.array([v.min(axis=0), v.max(axis=0)])
        self.box_corners = np.array([[b[i, 0], b[j, 1], b[k, 2], 1.0] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        # closed, consistently wound meshes: back faces are never visible -> cull them (half the work)
        self.cull = not bool(getattr(caster, "two_sided", True))
        # closed meshes: a face turned away from a light always lies inside that light's own shadow
        # volume, so its lighting pass only needs the light-facing faces (per light)
        self.light_tris = inverse.reshape(m, 3).astype(np.uint32)
        planes = getattr(caster, "face_planes", None)
        if planes is None:
            raw = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
            n = raw / np.maximum(np.linalg.norm(raw, axis=1, keepdims=True), 1e-300)
            planes = np.c_[n, -np.einsum("ij,ij->i", n, v[f[:, 0]])]
        self.face_planes = np.asarray(planes, np.float64)
        self.sub_ibo = ctx.buffer(reserve=max(self.light_tris.nbytes, 64), dynamic=True)
        self.sub_vao = ctx.vertex_array(prog_occ, [(self.vbo, "4f 3f 3f", "in_pos", "in_normal", "in_albedo")],
                                        index_buffer=self.sub_ibo, index_element_size=4)
        self.sub_ranges = {}
        self.sub_key = None  # the lights sub_ibo holds subsets for
        self._planar_sub_vao = None

    def planar_sub_vao(self, ctx, prog):
        """Positions of the light-facing subsets (``sub_ibo``) for the direct planar pass (made on first use)."""
        if self._planar_sub_vao is None:
            self._planar_sub_vao = ctx.vertex_array(prog, [(self.vbo, "4f 24x", "in_pos")], index_buffer=self.sub_ibo,
                                                    index_element_size=4)
        return self._planar_sub_vao

    def upload_light_subsets(self, passes) -> None:
        """Write, for each pass, the light-facing triangles (closed meshes) into ``sub_ibo``; records
        ``sub_ranges[i] = (first, count)``. Skipped when the lights are those of the previous call (lights
        fixed in the world: the subsets are per mesh and light, not per frame)."""
        if not self.cull:
            return
        lights = [np.asarray(p.light_h, np.float64) for p in passes]
        key = tuple(h.tobytes() for h in lights)
        if key == self.sub_key:
            return
        self.sub_ranges, self.sub_key = {}, key
        parts, first = [], 0
        for i, h in enumerate(lights):
            facing = self.face_planes @ h > 0.0
            sub = self.light_tris[facing]
            parts.append(sub)
            self.sub_ranges[i] = (first, 3 * len(sub))
            first += 3 * len(sub)
        if first:
            data = np.concatenate(parts) if len(parts) > 1 else parts[0]
            if data.nbytes > self.sub_ibo.size:
                # several lights (or soft-shadow samples) need several subsets: grow the buffer in place
                # (same GL buffer name, so sub_vao stays valid), with headroom against repeated growth
                self.sub_ibo.orphan(2 * data.nbytes)
            self.sub_ibo.write(data)

    def release(self):
        for o in (self.vao, self.sub_vao, self._planar_sub_vao, self.base_vao, self.planar_vao, self.vbo,
                  self.light_ibo, self.sub_ibo, self.pos_vbo, self.ibo):
            if o is not None:
                o.release()


class _Target:
    """A raw-GL framebuffer: colour renderbuffers (+ optional D24S8), wrapped by moderngl."""

    def __init__(self, ctx, gl, width, height, samples, color_formats, depth_stencil):
        self.gl = gl
        self.width, self.height, self.samples = int(width), int(height), int(samples)
        self.fbo = gl.gen_framebuffer()
        self.rbs = []
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, self.fbo)
        formats = list(color_formats) + ([G.GL_DEPTH24_STENCIL8] if depth_stencil else [])
        for i, fmt in enumerate(formats):
            rb = gl.gen_renderbuffer()
            gl.glBindRenderbuffer(G.GL_RENDERBUFFER, rb)
            if self.samples:
                gl.glRenderbufferStorageMultisample(G.GL_RENDERBUFFER, self.samples, fmt, self.width, self.height)
            else:
                gl.glRenderbufferStorage(G.GL_RENDERBUFFER, fmt, self.width, self.height)
            att = G.GL_DEPTH_STENCIL_ATTACHMENT if fmt == G.GL_DEPTH24_STENCIL8 else G.GL_COLOR_ATTACHMENT0 + i
            gl.glFramebufferRenderbuffer(G.GL_FRAMEBUFFER, att, G.GL_RENDERBUFFER, rb)
            self.rbs.append(rb)
        gl.glBindRenderbuffer(G.GL_RENDERBUFFER, 0)
        #: samples the driver actually allocated (llvmpipe rounds 2 up to 4)
        self.actual_samples = gl.renderbuffer_param(self.rbs[0], G.GL_RENDERBUFFER_SAMPLES) if self.samples else 0
        status = gl.glCheckFramebufferStatus(G.GL_FRAMEBUFFER)
        self.stencil_bits = (
            gl.attachment_param(G.GL_STENCIL_ATTACHMENT, G.GL_FRAMEBUFFER_ATTACHMENT_STENCIL_SIZE)
            if depth_stencil else 0
        )
        self.depth_bits = (
            gl.attachment_param(G.GL_DEPTH_ATTACHMENT, G.GL_FRAMEBUFFER_ATTACHMENT_DEPTH_SIZE)
            if depth_stencil else 0
        )
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, 0)
        if status != G.GL_FRAMEBUFFER_COMPLETE:
            self.release()
            raise GLContextError(
                f"offscreen framebuffer {self.width}x{self.height} (samples={self.samples}) is incomplete: "
                f"{G.framebuffer_status_name(status)}"
            )
        self.n_color = len(color_formats)
        self.mgl = ctx.detect_framebuffer(self.fbo)

    def release(self):
        gl = self.gl
        if self.fbo:
            gl.delete_framebuffer(self.fbo)
            self.fbo = 0
        for rb in self.rbs:
            gl.delete_renderbuffer(rb)
        self.rbs = []



def ground_vertices(ground_size=None, origin=None) -> np.ndarray:
    """The ground plane z = 0 as 12 homogeneous vertices ``(12, 4) float32`` (4 triangles, CCW seen from
    +z): unlimited (``None``: triangles fanning out to points at infinity, w = 0) or a square of side
    ``ground_size`` centred on the world origin (2 triangles padded with degenerate ones).

    ``origin (3,)``: the vertices relative to this point (:func:`local_origin`; points at infinity
    unchanged); the unlimited fan's centre is then the ground point under it (small local coordinates)."""
    origin = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
    if ground_size is None:
        o, px, py, nx, ny = (0, 0, 0, 1), (1, 0, 0, 0), (0, 1, 0, 0), (-1, 0, 0, 0), (0, -1, 0, 0)
        tris = [o, px, py, o, py, nx, o, nx, ny, o, ny, px]
    else:
        key = float(ground_size)
        if not (math.isfinite(key) and key > 0):
            raise UsageError(f"ground_size must be a positive length, got {ground_size}")
        h = key / 2
        a, b, c, d = (-h, -h, 0, 1), (h, -h, 0, 1), (h, h, 0, 1), (-h, h, 0, 1)
        tris = [a, b, c, a, c, d] + [(0, 0, 0, 1)] * 6
    t = np.asarray(tris, dtype=np.float64)
    if ground_size is None:
        t[t[:, 3] == 1.0, :2] = origin[:2]  # fan centre under the origin (the plane itself stays z = 0)
    t[:, :3] -= origin * t[:, 3:4]
    return t.astype(np.float32)


def _program_cache(ctx) -> dict:
    """Programs are cached per context (in ``ctx.extra``), compiled once."""
    extra = ctx.extra if isinstance(getattr(ctx, "extra", None), dict) else None
    if extra is None:
        extra = {}
        ctx.extra = extra
    return extra.setdefault("arshadow_programs", {})


def _program(ctx, vert: str, frag: str):
    cache = _program_cache(ctx)
    key = (vert, frag)
    if key not in cache:
        cache[key] = ctx.program(vertex_shader=load_shader(vert), fragment_shader=load_shader(frag))
    return cache[key]


class ShadowRenderer:
    """Render hard shadows of one caster onto the ground plane z = 0 with stencil shadow volumes.

    Parameters
    ----------
    ctx : moderngl.Context
        An OpenGL >= 3.3 context from :func:`arshadow.gl.context.create_context` (not created here).
    max_width, max_height : int
        Largest canvas accepted. Buffers are allocated lazily at the first canvas size and grown (never
        shrunk) when a larger canvas comes.
    samples : int
        MSAA samples per pixel (0 = off; at most ``ctx.max_samples``).
    supersample : int
        1, 2 or 4: render at ``supersample`` x the canvas size and box-filter down (can be combined with
        MSAA).
    ground_offset : (float, float)
        ``glPolygonOffset(factor, units)`` of the ground plane's depth (see docs/rendering.md: keeps the
        volume/ground depth comparisons at z = 0 stable where the object stands on the ground).
    crease_deg : float
        Smoothing angle of the occluder's shading normals.

    Examples
    --------
    >>> # ctx = create_context(); r = ShadowRenderer(ctx); res = r.render(projection=P, view=V, ...)
    """

    @current
    def __init__(self, ctx, *, max_width=4096, max_height=4096, samples=0, supersample=1,
                 ground_offset=(0.0, 0.0), crease_deg=40.0, max_cached_casters=8):
        self.ctx = ctx
        self.gl = G.load()
        self.max_width, self.max_height = int(max_width), int(max_height)
        samples = int(samples)
        if samples < 0 or samples > max(int(ctx.max_samples), 0):
            raise UsageError(f"samples={samples} not supported (this GL allows 0..{ctx.max_samples})")
        if samples == 1:
            samples = 0
        self.samples = samples
        if int(supersample) not in (1, 2, 4):
            raise UsageError(f"supersample must be 1, 2 or 4, got {supersample}")
        self.supersample = int(supersample)
        limit = int(ctx.info.get("GL_MAX_RENDERBUFFER_SIZE", 16384))
        if self.max_width * self.supersample > limit or self.max_height * self.supersample > limit:
            raise UsageError(f"max canvas {self.max_width}x{self.max_height} x supersample {self.supersample} "
                             f"exceeds GL_MAX_RENDERBUFFER_SIZE {limit}")
        self.ground_offset = (float(ground_offset[0]), float(ground_offset[1]))
        self.crease_deg = float(crease_deg)
        self.max_cached_casters = int(max_cached_casters)
        # programs (compiled once per context)
        self.prog_occ_base = _program(ctx, "occluder.vert", "occluder_base.frag")
        self.prog_occ_light = _program(ctx, "occluder.vert", "occluder_light.frag")
        self.prog_ground = _program(ctx, "common.vert", "ground.frag")
        self.prog_volume = _program(ctx, "common.vert", "volume.frag")
        self.prog_mask = _program(ctx, "fullscreen.vert", "mask.frag")
        self.prog_planar_mask = _program(ctx, "common.vert", "mask.frag")  # direct planar shadows
        # static geometry: unlimited ground (4 triangles fanning out to points at infinity), full viewport
        self._ground_vbo = ctx.buffer(reserve=12 * 4 * 4)
        self._ground_vao = ctx.vertex_array(self.prog_ground, [(self._ground_vbo, "4f", "in_pos")])
        self._ground_key = None
        self._fs_vao = ctx.vertex_array(self.prog_mask, [])
        # volume buffers, grown as needed
        self._vol_vbo = None
        self._vol_ibo = None
        self._vol_vao = None
        self._vol_cap = (0, 0)
        self._vol_last = None  # (volumes, ranges) of the last upload, kept when their arrays are read-only
        self._casters: dict[int, tuple[weakref.ref, object, _CasterBuffers]] = {}
        self._main = None       # _Target: render target (MSAA and/or supersampled)
        self._resolve = None    # _Target: single-sample canvas-size target (when main is MSAA/supersampled)
        self._half = None       # _Target: intermediate for supersample 4
        self._tex = None        # TextureTarget: GPU-resident result (render(readback=False))
        self._released = False
        #: render(readback=False) keeps the layers on the GPU (arshadow.gl.compose composites them there)
        self.gpu_layers = True
        #: when True, render() calls ctx.finish() after each pass and reports per-pass times (slower)
        self.profile = False
        self._marks = []

    # ------------------------------------------------------------------ resources
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()

    @current
    def release(self) -> None:
        """Free every GL object this renderer made (programs stay cached on the context)."""
        if self._released:
            return
        for t in (self._main, self._resolve, self._half, getattr(self, "_ss_resolve", None), self._tex):
            if t is not None:
                t.release()
        self._main = self._resolve = self._half = self._ss_resolve = self._tex = None
        for _, _, bufs in self._casters.values():
            bufs.release()
        self._casters.clear()
        for o in (self._vol_vao, self._vol_vbo, self._vol_ibo, self._ground_vao, self._ground_vbo, self._fs_vao):
            if o is not None:
                o.release()
        self._released = True

    @property
    def stencil_bits(self) -> int:
        """Stencil bits of the render target actually obtained (8 for GL_DEPTH24_STENCIL8); 0 before the
        first render."""
        return self._main.stencil_bits if self._main is not None else 0

    @property
    def actual_samples(self) -> int:
        """MSAA samples per pixel the driver actually allocated (0 = single-sampled; llvmpipe has only 4)."""
        return self._main.actual_samples if self._main is not None else 0

    @property
    def depth_bits(self) -> int:
        return self._main.depth_bits if self._main is not None else 0

    def _ensure_targets(self, width: int, height: int) -> None:
        s = self.supersample
        need_w, need_h = width * s, height * s
        main = self._main
        if main is None or main.width < need_w or main.height < need_h:
            w = max(need_w, main.width if main else 0)
            h = max(need_h, main.height if main else 0)
            for t in (self._main, self._resolve, self._half):
                if t is not None:
                    t.release()
            self._main = self._resolve = self._half = None
            fmts = (G.GL_RGBA16F, G.GL_RG16F)
            self._main = _Target(self.ctx, self.gl, w, h, self.samples, fmts, True)
            if self.samples or s > 1:
                self._resolve = _Target(self.ctx, self.gl, w // s, h // s, 0, fmts, False)
            if s == 4:
                self._half = _Target(self.ctx, self.gl, w // 2, h // 2, 0, fmts, False)

    def _caster_buffers(self, caster, occluder_color) -> _CasterBuffers:
        # purge dead casters
        for key in [k for k, (ref, _, _) in self._casters.items() if ref() is None]:
            self._casters.pop(key)[2].release()
        ckey = None if occluder_color is None else tuple(float(c) for c in np.ravel(occluder_color)[:3])
        entry = self._casters.get(id(caster))
        if entry is not None and entry[0]() is caster and entry[1] == (ckey, self.crease_deg):
            return entry[2]
        if entry is not None:
            self._casters.pop(id(caster))[2].release()
        while len(self._casters) >= self.max_cached_casters:
            self._casters.pop(next(iter(self._casters)))[2].release()
        bufs = _CasterBuffers(self.ctx, self.prog_occ_base, self.prog_occ_light, self.prog_volume, caster, ckey,
                              self.crease_deg)
        try:
            ref = weakref.ref(caster)
        except TypeError:  # objects without weakref support: keep a strong reference
            ref = (lambda obj: (lambda: obj))(caster)
        self._casters[id(caster)] = (ref, (ckey, self.crease_deg), bufs)
        return bufs

    def _upload_volumes(self, passes, origin=None) -> list:
        """Write every light's volume into the reused vertex/index buffers; returns per-pass
        ``(first_index, n_indices)`` (None where a pass has no volume).

        The pipeline hands the same (frozen, read-only) volume objects every frame while the lights stay
        put: when the passes' volumes are exactly those of the previous upload, the buffers already hold
        them and nothing is converted or uploaded."""
        vols = tuple(None if p.mode == "planar" else p.volume for p in passes)
        origin = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
        last = self._vol_last
        if (last is not None and len(last[0]) == len(vols) and all(a is b for a, b in zip(last[0], vols))
                and np.array_equal(last[2], origin)):
            return list(last[1])
        self._vol_last = None
        ranges, parts = [], []
        nv = ni = 0
        frozen = True
        for vol in vols:
            if vol is None:
                ranges.append(None)
                continue
            v = np.asarray(vol.vertices)
            t = np.asarray(vol.triangles)
            if v.ndim != 2 or v.shape[1] != 4 or t.ndim != 2 or t.shape[1] != 3:
                raise ShapeError("shadow volume must have vertices (p, 4) and triangles (q, 3)",
                                 actual_shape=(v.shape, t.shape), expected_shape="((p, 4), (q, 3))")
            frozen = frozen and not (v.flags.writeable or t.flags.writeable)
            if len(t) == 0:
                ranges.append(None)
                continue
            parts.append((v, t, nv, ni))
            ranges.append((ni, 3 * len(t)))
            nv += len(v)
            ni += 3 * len(t)
        if ni:
            vbytes, ibytes = 16 * nv, 4 * ni
            if self._vol_vbo is None or vbytes > self._vol_cap[0] or ibytes > self._vol_cap[1]:
                vcap = max(vbytes, 2 * self._vol_cap[0], 1 << 16)
                icap = max(ibytes, 2 * self._vol_cap[1], 1 << 16)
                for o in (self._vol_vao, self._vol_vbo, self._vol_ibo):
                    if o is not None:
                        o.release()
                self._vol_vbo = self.ctx.buffer(reserve=vcap, dynamic=True)
                self._vol_ibo = self.ctx.buffer(reserve=icap, dynamic=True)
                self._vol_vao = self.ctx.vertex_array(self.prog_volume, [(self._vol_vbo, "4f", "in_pos")],
                                                      index_buffer=self._vol_ibo, index_element_size=4)
                self._vol_cap = (vcap, icap)
            # each volume straight into its slice of the buffers (no concatenated copy)
            for v, t, v_first, i_first in parts:
                idx = t.astype(np.uint32)
                if v_first:
                    idx += np.uint32(v_first)
                loc = v.astype(np.float64)  # relative to origin: X - origin * w (points at infinity unchanged)
                loc[:, :3] -= origin * loc[:, 3:4]
                self._vol_vbo.write(loc.astype(np.float32), offset=16 * v_first)
                self._vol_ibo.write(idx, offset=4 * i_first)
        if frozen:  # read-only arrays cannot change behind our back: safe to reuse next frame
            self._vol_last = (vols, tuple(ranges), origin)
        return ranges

    def _set_ground(self, ground_size, origin=None) -> None:
        """The ground z = 0 in the frame of ``origin`` (see :func:`local_origin`)."""
        origin = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
        key = ("inf" if ground_size is None else float(ground_size), tuple(origin.tolist()))
        if key == self._ground_key:
            return
        self._ground_vbo.write(ground_vertices(ground_size, origin).tobytes())
        self._ground_key = key

    # ------------------------------------------------------------------ render
    @current
    def render(self, *, projection, view, width, height, caster, passes, ground_size=None,
               draw_occluder=True, ambient=0.25, diffuse=1.0, specular=0.25, shininess=32.0,
               occluder_color=None, readback=True):
        """Render one frame (or one canvas sub-rectangle of it).

        Parameters
        ----------
        projection : (4, 4) float64
            ``clip_from_gl_eye`` for this canvas (``Intrinsics.gl_projection(znear, None, canvas=...)``;
            an infinite far plane is needed when volumes reach infinity).
        view : (4, 4) float64
            ``gl_from_world = CV_TO_GL @ cam_from_world``.
        width, height : int
            Canvas size in pixels (<= max_width, max_height).
        caster : ShadowCaster
            The occluder (its GPU buffers are cached per caster object).
        passes : sequence of LightPass
            One per light; ``weight`` is the light's share of the total weight.
        ground_size : float or None
            Side of the square of ground (centred on the origin) that receives shadows; None = unlimited.
        draw_occluder : bool
            False: the occluder is neither drawn nor hides the ground (shadow only).
        ambient, diffuse, specular, shininess : float
            Phong coefficients (paper 002): ``I = K_a I_a + sum_l I_l (K_d (N.L) + K_s (N.H)^n)``.
        occluder_color : (3,) sRGB in [0, 1], optional
            Overrides the mesh's own colours (mesh colours and this are sRGB-encoded; output is linear).
        readback : bool
            True (default): read the layers back into numpy (:class:`RenderResult`). False: keep them on
            the GPU: the (resolved) attachments are copied into two textures and a :class:`GpuLayers` is
            returned (no ``ctx.finish()``, no readback; :mod:`arshadow.gl.compose` samples them).

        Returns
        -------
        RenderResult, or GpuLayers when ``readback`` is False
        """
        t0 = time.perf_counter()
        if self._released:
            raise UsageError("this ShadowRenderer has been released")
        width, height = int(width), int(height)
        if not (0 < width <= self.max_width and 0 < height <= self.max_height):
            raise UsageError(f"canvas {width}x{height} outside 1..{self.max_width} x 1..{self.max_height}")
        proj = check_finite(check_shape(projection, "4,4", "projection"), "projection")
        view = check_finite(check_shape(view, "4,4", "view"), "view")
        passes = list(passes)
        for p in passes:
            if p.mode not in MODES:
                raise UsageError(f"unknown shadow mode {p.mode!r} (choose {', '.join(MODES)})")
            if not (math.isfinite(float(p.weight)) and float(p.weight) >= 0):
                raise UsageError(f"light weight must be finite and >= 0, got {p.weight}")
        ctx, gl = self.ctx, self.gl
        mvp = proj @ view
        origin = caster.bounds.mean(axis=0)  # = local_origin(caster.vertices), from the cached bounds
        mvp_local = mvp @ _translation(origin)
        mvp_bytes = mvp_local.T.astype(np.float32).tobytes()  # GLSL is column-major
        eye = -view[:3, :3].T @ view[:3, 3] - origin
        # mirrored projections flip the winding: keep "front" = outward side seen from outside
        front = "cw" if np.linalg.det(mvp) > 0 else "ccw"

        bufs = self._caster_buffers(caster, occluder_color) if (draw_occluder or any(
            p.mode == "planar" for p in passes)) else None
        ranges = self._upload_volumes(passes, origin)
        if draw_occluder or any(p.mode == "planar" and p.direct for p in passes):
            bufs.upload_light_subsets(passes)
        self._set_ground(ground_size, origin)
        self._ensure_targets(width, height)
        t1 = time.perf_counter()
        self._marks = [("start", t1)]

        s = self.supersample
        rw, rh = width * s, height * s
        tgt = self._main
        fbo = tgt.mgl
        fbo.viewport = (0, 0, rw, rh)
        fbo.scissor = (0, 0, rw, rh)  # clears touch only the canvas
        fbo.use()  # binds, sets viewport/scissor, and moderngl's colour/depth masks (all on)
        gl.draw_buffers(2)
        ctx.front_face = front
        # -- clear colour, depth and stencil of the canvas (scissored: the buffers may be larger)
        import moderngl

        ctx.enable_only(moderngl.NOTHING)
        gl.glEnable(G.GL_SCISSOR_TEST)
        gl.glScissor(0, 0, rw, rh)
        gl.glStencilMask(0xFF)
        gl.glClearStencil(0)
        gl.glClearDepth(1.0)
        gl.glClearColor(0.0, 0.0, 0.0, 0.0)
        gl.glClear(G.GL_COLOR_BUFFER_BIT | G.GL_DEPTH_BUFFER_BIT | G.GL_STENCIL_BUFFER_BIT)
        self._mark("clear")
        # -- base pass: occluder then ground (depth LESS, writes on)
        ctx.enable_only(moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        if draw_occluder:
            ctx.enable_only(moderngl.DEPTH_TEST | (moderngl.CULL_FACE if bufs.cull else 0))
            ctx.cull_face = "back"
            gl.glEnable(G.GL_STENCIL_TEST)
            gl.glStencilFunc(G.GL_ALWAYS, OCCLUDER_BIT, 0xFF)
            gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_REPLACE)
            # colour 1 stays 0 on the occluder (cleared; the ground pass overwrites it where it is nearer)
            gl.draw_buffer_list([0])
            prog, vao = self.prog_occ_base, bufs.base_vao
            prog["u_mvp"].write(mvp_bytes)
            prog["u_ambient"].value = float(ambient)
            vao.render(moderngl.TRIANGLES, vertices=bufs.n_indices)
            gl.draw_buffers(2)
        self._mark("occluder")
        ctx.enable_only(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.cull_face = "back"
        gl.glEnable(G.GL_STENCIL_TEST)
        gl.glStencilFunc(G.GL_ALWAYS, GROUND_BIT, 0xFF)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_REPLACE)
        if self.ground_offset != (0.0, 0.0):
            gl.glEnable(G.GL_POLYGON_OFFSET_FILL)
            gl.glPolygonOffset(*self.ground_offset)
        if draw_occluder and not bufs.below_ground:
            gl.draw_buffer_list([None, 1])  # nothing of the occluder below z = 0 to erase: skip colour 0
        else:
            gl.draw_buffers(2)
        self.prog_ground["u_mvp"].write(mvp_bytes)
        self._ground_vao.render(moderngl.TRIANGLES, vertices=12)
        gl.draw_buffers(2)
        gl.glDisable(G.GL_POLYGON_OFFSET_FILL)

        self._mark("ground")
        # -- per light
        for i, (p, rng) in enumerate(zip(passes, ranges)):
            planar = p.mode == "planar"
            if rng is None and not planar:
                # casts nothing: the occluder gets this light unshadowed
                if draw_occluder:
                    self._light_occluder(bufs, p, i, mvp_bytes, eye, diffuse, specular, shininess, stencil=False)
                continue
            if planar and p.direct and bufs.cull and i in bufs.sub_ranges:
                # convex closed caster: its light-facing faces, flattened from the light, tile the shadow
                # exactly once -> add the weight straight into the mask where the ground is visible and
                # the occluder is not (stencil ground bit set, occluder bit clear); no count, no clear
                first, count = bufs.sub_ranges[i]
                if p.shadow_matrix is not None and p.weight > 0 and count:
                    ctx.enable_only(moderngl.BLEND)  # no depth test, no culling (projection may mirror)
                    ctx.blend_func = moderngl.ONE, moderngl.ONE
                    gl.glDepthMask(G.GL_FALSE)
                    gl.glColorMask(1, 1, 1, 1)
                    gl.glEnable(G.GL_DEPTH_CLAMP)
                    gl.glStencilMask(0)
                    gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
                    gl.glStencilFunc(G.GL_EQUAL, GROUND_BIT, GROUND_BIT | OCCLUDER_BIT)
                    gl.draw_buffer_list([None, 1])
                    smat = np.asarray(p.shadow_matrix, dtype=np.float64)
                    prog = self.prog_planar_mask
                    prog["u_mvp"].write((mvp @ smat @ _translation(origin)).T.astype(np.float32).tobytes())
                    prog["u_weight"].value = float(p.weight)
                    bufs.planar_sub_vao(self.ctx, prog).render(moderngl.TRIANGLES, vertices=count, first=first)
                    gl.draw_buffers(2)
                    gl.glDisable(G.GL_DEPTH_CLAMP)
                self._mark("mask")
                if draw_occluder:
                    self._light_occluder(bufs, p, i, mvp_bytes, eye, diffuse, specular, shininess, stencil=False)
                continue
            # clear the count bits, keep the ground bit
            gl.glStencilMask(COUNT_MASK)
            gl.glClear(G.GL_STENCIL_BUFFER_BIT)
            # volume pass: depth test on, depth/colour writes off, depth clamp on, two-sided stencil
            ctx.enable_only(moderngl.DEPTH_TEST)
            ctx.depth_func = "<"
            gl.glDepthMask(G.GL_FALSE)
            gl.glColorMask(0, 0, 0, 0)
            gl.glEnable(G.GL_DEPTH_CLAMP)
            gl.glStencilFunc(G.GL_ALWAYS, 0, 0xFF)
            if planar:
                # projection shadow (paper 002): the caster flattened onto z = 0; depth test "always",
                # the ground bit limits it to visible ground in the mask pass. A light at or below the
                # ground lights none of it from above: nothing to draw.
                # (LightPass.shadow_matrix: None when the light is not above the ground)
                if p.shadow_matrix is not None:
                    ctx.depth_func = "1"
                    gl.glStencilFunc(G.GL_ALWAYS, 1, 0xFF)
                    gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_REPLACE)
                    smat = np.asarray(p.shadow_matrix, dtype=np.float64)
                    self.prog_volume["u_mvp"].write((mvp @ smat @ _translation(origin)).T.astype(np.float32)
                                                    .tobytes())
                    bufs.planar_vao.render(moderngl.TRIANGLES, vertices=bufs.n_indices)
            elif getattr(p.volume, "batches", None):
                self._batched_volume(p.volume.batches, rng[0], mvp_bytes)
            else:
                if p.mode == "zpass":
                    gl.glStencilOpSeparate(G.GL_FRONT, G.GL_KEEP, G.GL_KEEP, G.GL_INCR_WRAP)
                    gl.glStencilOpSeparate(G.GL_BACK, G.GL_KEEP, G.GL_KEEP, G.GL_DECR_WRAP)
                else:  # zfail
                    gl.glStencilOpSeparate(G.GL_BACK, G.GL_KEEP, G.GL_INCR_WRAP, G.GL_KEEP)
                    gl.glStencilOpSeparate(G.GL_FRONT, G.GL_KEEP, G.GL_DECR_WRAP, G.GL_KEEP)
                self.prog_volume["u_mvp"].write(mvp_bytes)
                self._vol_vao.render(moderngl.TRIANGLES, vertices=rng[1], first=rng[0])
            self._mark("volume")
            gl.glDisable(G.GL_DEPTH_CLAMP)
            gl.glStencilMask(0)
            gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
            # mask pass: add the weight where ground bit set and count != 0  (0x80 < stencil)
            if p.weight > 0:
                ctx.enable_only(moderngl.BLEND)
                ctx.blend_func = moderngl.ONE, moderngl.ONE
                gl.glColorMask(1, 1, 1, 1)
                gl.draw_buffer_list([None, 1])  # adds (weight, 0): the ground channel is unchanged
                gl.glStencilFunc(G.GL_LESS, GROUND_BIT, 0xFF)
                self.prog_mask["u_weight"].value = float(p.weight)
                self._fs_vao.render(moderngl.TRIANGLES, vertices=3)
                gl.draw_buffers(2)
            self._mark("mask")
            if draw_occluder:
                self._light_occluder(bufs, p, i, mvp_bytes, eye, diffuse, specular, shininess,
                                     stencil=not planar)

        self._mark("occluder_light")
        # -- reset raw state, make moderngl's view consistent
        gl.draw_buffers(2)
        gl.glDisable(G.GL_STENCIL_TEST)
        gl.glStencilMask(0xFF)
        gl.glStencilFunc(G.GL_ALWAYS, 0, 0xFF)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
        gl.glDisable(G.GL_DEPTH_CLAMP)
        gl.glDisable(G.GL_POLYGON_OFFSET_FILL)
        gl.glDisable(G.GL_SCISSOR_TEST)
        gl.glDepthMask(G.GL_TRUE)
        gl.glColorMask(1, 1, 1, 1)
        ctx.enable_only(moderngl.NOTHING)
        ctx.depth_func = "<"
        ctx.front_face = "ccw"

        # -- resolve / downsample
        src = tgt
        if not readback and s == 1:
            # GPU-resident result: resolve (MSAA) or copy straight into the texture target
            tt = self._texture_target(width, height)
            self._blit(src, tt, rw, rh, rw, rh, G.GL_NEAREST)
            self._mark("resolve")
            t2 = time.perf_counter()
            return GpuLayers(tt.color_tex, tt.mask_tex, width, height,
                             timings_ms={"upload": (t1 - t0) * 1e3, "draw": (t2 - t1) * 1e3, "readback": 0.0,
                                         "total": (t2 - t0) * 1e3})
        if self.samples:
            dst = self._resolve if s == 1 else self._main_resolve_ss()
            self._blit(src, dst, rw, rh, rw, rh, G.GL_NEAREST)
            src = dst
        if s == 4:
            self._blit(src, self._half, rw, rh, rw // 2, rh // 2, G.GL_LINEAR)
            src = self._half
            rw, rh = rw // 2, rh // 2
        if s > 1:
            self._blit(src, self._resolve, rw, rh, width, height, G.GL_LINEAR)
            src = self._resolve
        self._mark("resolve")
        if not readback:
            tt = self._texture_target(width, height)
            self._blit(src, tt, width, height, width, height, G.GL_NEAREST)
            t2 = time.perf_counter()
            return GpuLayers(tt.color_tex, tt.mask_tex, width, height,
                             timings_ms={"upload": (t1 - t0) * 1e3, "draw": (t2 - t1) * 1e3, "readback": 0.0,
                                         "total": (t2 - t0) * 1e3})
        ctx.finish()
        t2 = time.perf_counter()

        # -- readback (one read per attachment, canvas only)
        # colour: only the occluder's conservative screen box is read (np.zeros pages elsewhere stay
        # untouched); mask/ground: the whole canvas
        c0 = np.zeros((height, width, 4), dtype=np.float32)
        c1 = np.empty((height, width, 2), dtype=np.float32)
        gl.glBindBuffer(G.GL_PIXEL_PACK_BUFFER, 0)
        gl.glPixelStorei(G.GL_PACK_ALIGNMENT, 4)
        gl.glBindFramebuffer(G.GL_READ_FRAMEBUFFER, src.fbo)
        box = _screen_box(mvp, bufs.box_corners, width, height) if draw_occluder else None
        if box is not None and box[2] > box[0] and box[3] > box[1]:
            x0, y0, x1, y1 = box
            gl.glPixelStorei(G.GL_PACK_ROW_LENGTH, width)
            gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0)
            gl.glReadPixels(x0, y0, x1 - x0, y1 - y0, G.GL_RGBA, G.GL_FLOAT, c0[y0:, x0:].ctypes.data)
        gl.glPixelStorei(G.GL_PACK_ROW_LENGTH, 0)
        gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0 + 1)
        gl.glReadPixels(0, 0, width, height, G.GL_RG, G.GL_FLOAT, c1.ctypes.data)
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, 0)
        ctx.screen.use() if ctx.screen is not None else None
        layers = RenderLayers(rgba=c0, mask_ground=c1)  # the raw bottom-up arrays
        c0 = c0[::-1]
        c1 = c1[::-1]
        mask = c1[..., 0]
        np.clip(mask, 0.0, 1.0, out=mask)
        gcov = c1[..., 1]
        t3 = time.perf_counter()
        return RenderResult(
            mask=mask,
            color=c0[..., :3],
            alpha=c0[..., 3],
            ground=gcov > 0.5,
            ground_coverage=gcov,
            layers=layers,
            timings_ms={
                "upload": (t1 - t0) * 1e3,
                "draw": (t2 - t1) * 1e3,
                "readback": (t3 - t2) * 1e3,
                "total": (t3 - t0) * 1e3,
                **({f"pass_{b[0]}": (b[1] - a[1]) * 1e3 for a, b in zip(self._marks, self._marks[1:])}
                   if self.profile else {}),
            },
        )

    def _texture_target(self, width: int, height: int):
        """Single-sample ``RGBA16F`` + ``RG16F`` textures (grown, never shrunk) for ``readback=False``."""
        t = self._tex
        if t is None or t.width < width or t.height < height:
            w, h = max(width, t.width if t else 0), max(height, t.height if t else 0)
            if t is not None:
                t.release()
            t = self._tex = TextureTarget(self.ctx, w, h)
        return t

    def _main_resolve_ss(self):
        """Single-sample target of the supersampled size (MSAA + supersampling)."""
        t = getattr(self, "_ss_resolve", None)
        if t is None or t.width < self._main.width or t.height < self._main.height:
            if t is not None:
                t.release()
            t = _Target(self.ctx, self.gl, self._main.width, self._main.height, 0, (G.GL_RGBA16F, G.GL_RG16F), False)
            self._ss_resolve = t
        return t

    def _mark(self, name):
        if self.profile:
            self.ctx.finish()
            self._marks.append((name, time.perf_counter()))

    def _blit(self, src, dst, sw, sh, dw, dh, filt):
        gl = self.gl
        gl.glDisable(G.GL_SCISSOR_TEST)
        gl.glBindFramebuffer(G.GL_READ_FRAMEBUFFER, src.fbo)
        gl.glBindFramebuffer(G.GL_DRAW_FRAMEBUFFER, dst.fbo)
        for i in range(2):
            gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0 + i)
            gl.draw_buffers(2, only=i)
            gl.glBlitFramebuffer(0, 0, sw, sh, 0, 0, dw, dh, G.GL_COLOR_BUFFER_BIT, filt)
        gl.draw_buffers(2)
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, 0)

    def _batched_volume(self, batches, first_index, mvp_bytes) -> None:
        """Count a batched volume (:attr:`arshadow.geometry.volume.ShadowVolume.batches`) exactly: each closed
        z-fail batch is counted in bits 0-4 (its count is 0..31, so exact modulo 32), then a full-viewport
        pass sets :data:`SHADOWED_BIT` where that count is not 0 and the count bits are cleared for the
        next batch. Leaves ``SHADOWED_BIT`` set where any batch (so the union: the shadow) covers the
        sample and the count bits 0, as the mask and occluder-lighting passes expect."""
        import moderngl

        ctx, gl = self.ctx, self.gl
        for first_tri, n_tri in batches:
            ctx.enable_only(moderngl.DEPTH_TEST)
            ctx.depth_func = "<"
            gl.glColorMask(0, 0, 0, 0)
            gl.glEnable(G.GL_DEPTH_CLAMP)
            gl.glStencilMask(BATCH_COUNT_MASK)
            gl.glStencilFunc(G.GL_ALWAYS, 0, 0xFF)
            gl.glStencilOpSeparate(G.GL_BACK, G.GL_KEEP, G.GL_INCR_WRAP, G.GL_KEEP)
            gl.glStencilOpSeparate(G.GL_FRONT, G.GL_KEEP, G.GL_DECR_WRAP, G.GL_KEEP)
            self.prog_volume["u_mvp"].write(mvp_bytes)
            self._vol_vao.render(moderngl.TRIANGLES, vertices=3 * n_tri, first=first_index + 3 * first_tri)
            gl.glDisable(G.GL_DEPTH_CLAMP)
            # count != 0 -> set the shadowed bit (ref & mask = 0: passes where the count is not 0; REPLACE
            # writes ref = SHADOWED_BIT through the write mask SHADOWED_BIT)
            ctx.enable_only(moderngl.NOTHING)
            gl.glStencilMask(SHADOWED_BIT)
            gl.glStencilFunc(G.GL_NOTEQUAL, SHADOWED_BIT, BATCH_COUNT_MASK)
            gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_REPLACE)
            self._fs_vao.render(moderngl.TRIANGLES, vertices=3)
            gl.glStencilMask(BATCH_COUNT_MASK)
            gl.glClear(G.GL_STENCIL_BUFFER_BIT)
        # the mask pass tests "stencil > GROUND_BIT": with the count bits 0 that is "shadowed bit set"
        ctx.enable_only(moderngl.DEPTH_TEST)

    def _light_occluder(self, bufs, p, i, mvp_bytes, eye, kd, ks, shininess, stencil: bool):
        """Add one light's Phong diffuse + specular to the occluder where its count is 0."""
        import moderngl

        ctx, gl = self.ctx, self.gl
        ctx.enable_only(moderngl.DEPTH_TEST | moderngl.BLEND | (moderngl.CULL_FACE if bufs.cull else 0))
        ctx.cull_face = "back"
        ctx.depth_func = "=="
        ctx.blend_func = moderngl.ONE, moderngl.ONE
        gl.glDepthMask(G.GL_FALSE)
        gl.glColorMask(1, 1, 1, 1)  # additive with alpha 0: coverage unchanged
        gl.glEnable(G.GL_STENCIL_TEST)
        gl.glStencilMask(0)
        gl.glStencilOp(G.GL_KEEP, G.GL_KEEP, G.GL_KEEP)
        # occluder pixels (bit 6) whose count is 0; without a volume: every occluder pixel
        gl.glStencilFunc(G.GL_EQUAL, OCCLUDER_BIT, 0xFF if stencil else 0xC0)
        gl.draw_buffer_list([0])
        prog = self.prog_occ_light
        prog["u_mvp"].write(mvp_bytes)
        lh = np.asarray(p.light_h, dtype=np.float64).copy()
        lh[:3] -= bufs.origin * lh[3]  # the caster's local frame, like v_world
        prog["u_light"].value = tuple(float(x) for x in lh)
        col = np.asarray(p.color, dtype=np.float64)[:3] * float(p.weight)
        prog["u_light_color"].value = tuple(float(x) for x in col)
        prog["u_eye"].value = tuple(float(x) for x in eye)
        prog["u_kd"].value = float(kd)
        prog["u_ks"].value = float(ks)
        prog["u_shininess"].value = float(shininess)
        # closed meshes: only the light-facing faces (the others lie in this light's own shadow; with a
        # planar or no volume pass this is also what keeps a convex occluder's terminator as the volume has it)
        if i in bufs.sub_ranges:
            first, count = bufs.sub_ranges[i]
            if count:
                bufs.sub_vao.render(moderngl.TRIANGLES, vertices=count, first=first)
        else:
            bufs.vao.render(moderngl.TRIANGLES, vertices=bufs.n_indices)
        gl.draw_buffers(2)
        ctx.depth_func = "<"


def local_origin(vertices) -> np.ndarray:
    """(3,) float64: the centre of the bounding box of ``vertices (n, 3)``, the origin of the frame the GPU
    works in. Every position is converted to float32 relative to it (and the matrices absorb the
    translation in float64): a millimetre object 1 km from the marker keeps float32's relative precision
    of its own size instead of losing ~0.06 mm (float32 at 1000) to the distance."""
    v = np.asarray(vertices, np.float64)
    return 0.5 * (v.min(axis=0) + v.max(axis=0)) if len(v) else np.zeros(3)


def _translation(o) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = o
    return t


def _screen_box(mvp, corners, width, height):
    """Conservative pixel box ``(x0, y0, x1, y1)`` (GL window coordinates, bottom-up, half-open) of the
    caster's projection: its 8 bounding-box ``corners (8, 4)`` (homogeneous world) projected; the whole
    canvas if a corner is not strictly in front of the camera."""
    clip = corners @ mvp.T
    w = clip[:, 3]
    if not np.all(w > 1e-9):
        return 0, 0, width, height
    x = (clip[:, 0] / w + 1.0) * 0.5 * width
    y = (clip[:, 1] / w + 1.0) * 0.5 * height
    x0 = int(min(max(math.floor(x.min()) - 1, 0), width))
    y0 = int(min(max(math.floor(y.min()) - 1, 0), height))
    x1 = int(max(min(math.ceil(x.max()) + 1, width), 0))
    y1 = int(max(min(math.ceil(y.max()) + 1, height), 0))
    return x0, y0, x1, y1

