"""GPU resources of the renderers: shader programs, caster buffers, raw-GL framebuffers, the ground plane.

Shared by the stencil renderer (:mod:`arshadow.gl.stencil`), the shadow-map baseline
(:mod:`arshadow.gl.shadowmap`) and the GPU compositor (:mod:`arshadow.gl.gpu_compose`); none of them imports
another. Nothing here creates a context or imports moderngl (the objects come from the context handed in).

- :func:`program`: a shader program compiled once per context (cached in ``ctx.extra``); :func:`uniform`: one of
  its uniforms (typed as such);
- :class:`CasterBuffers`: one caster's vertex/index buffers (lit occluder, welded positions, light-facing
  subsets), relative to its :func:`local_origin`;
- :class:`CasterCache`: those buffers for the last few casters;
- :class:`VolumeBuffers`: every light's shadow volume of a frame in one reused vertex/index buffer;
- :class:`RenderTarget`: a framebuffer of renderbuffers (colour + optional ``GL_DEPTH24_STENCIL8``, MSAA);
- :class:`FrameTargets`: a renderer's targets (main, resolve/downsample, GPU-resident textures);
- :func:`ground_vertices`: the ground plane z = 0 as homogeneous triangles (unlimited or a square), kept
  in a :class:`GroundBuffer`;
- :func:`screen_box`: the conservative pixel box of a caster's bounding box (the colour readback's).

(About 650 lines, over the project's ~600 since the typing work wrote the signatures out one parameter
per line: the GPU resources the three renderers share, each a small class or function.)
"""

from __future__ import annotations

import functools
import math
import weakref
from collections.abc import Callable, Iterable, Mapping, Sequence
from importlib import resources
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from ..compose.composite import srgb_to_linear
from ..errors import ShapeError, UsageError
from ..geometry.normals import crease_normals
from ..shading.interreflect import SelfView, self_view
from ..shading.objground import face_ground, vertex_ground
from ..shading.sky import object_sky_visibility

if TYPE_CHECKING:  # annotations only (nothing here imports moderngl; .sky imports this module)
    import moderngl

    from ..geometry.caster import ShadowCaster
    from ..geometry.material import Material
    from ..geometry.volume import ShadowVolume
    from ..renderer.request import LightPass
    from .sky import GLItemBuffer

__all__ = [
    "DEFAULT_COLOR",
    "GroundBuffer",
    "CasterBuffers",
    "CasterCache",
    "VolumeBuffers",
    "ground_vertices",
    "load_shader",
    "local_origin",
    "program",
    "screen_box",
    "translation",
    "uniform",
]

#: default occluder colour (sRGB) when the mesh has none and none is given
DEFAULT_COLOR = (0.8, 0.8, 0.8)


@functools.cache
def load_shader(name: str) -> str:
    """Source of a shader shipped in ``arshadow/gl/shaders`` (package data)."""
    return resources.files("arshadow.gl").joinpath("shaders", name).read_text(encoding="utf-8")


def _program_cache(ctx: moderngl.Context) -> dict[object, Any]:
    """Programs are cached per context (in ``ctx.extra``), compiled once: ``(vert, frag)`` ->
    ``moderngl.Program``; also ``"item_buffer_512"`` -> :class:`arshadow.gl.sky.GLItemBuffer`."""
    extra = ctx.extra if isinstance(getattr(ctx, "extra", None), dict) else None
    if extra is None:
        extra = {}
        ctx.extra = extra
    cache: dict[object, Any] = extra.setdefault("arshadow_programs", {})
    return cache


def program(ctx: moderngl.Context, vert: str, frag: str) -> moderngl.Program:
    """The program of shaders ``vert`` + ``frag`` (names in ``arshadow/gl/shaders``) on ``ctx``, compiled on
    first use and cached on the context."""
    cache = _program_cache(ctx)
    key = (vert, frag)
    if key not in cache:
        cache[key] = ctx.program(vertex_shader=load_shader(vert), fragment_shader=load_shader(frag))
    prog: moderngl.Program = cache[key]
    return prog


def uniform(prog: moderngl.Program, name: str) -> moderngl.Uniform:
    """``prog[name]``, a uniform of the program (moderngl types ``prog[name]`` as any kind of member: uniform,
    uniform block, attribute or varying; the names asked for here are the shaders' uniforms)."""
    return cast("moderngl.Uniform", prog[name])


def set_uniforms(progs: Iterable[moderngl.Program], values: Mapping[str, object]) -> None:
    """Write ``values`` (uniform name -> value, e.g. :meth:`arshadow.renderer.request.Shading.uniforms`) into each
    program of ``progs`` that declares the name (the others skip it)."""
    for prog in progs:
        for name, value in values.items():
            u = cast("moderngl.Uniform | None", prog.get(name, None))  # a uniform, as in uniform()
            if u is not None:
                u.value = value


class CasterBuffers:
    """GPU copies of one caster: the occluder (unwelded corners: pos4, normal3, albedo3) and the welded
    positions (for the planar shadow). Built once per caster."""

    # the three programs, the caster and how it is shaded (colour, crease, sky model, frame): one call site each
    def __init__(  # noqa: PLR0913
        self,
        ctx: moderngl.Context,
        prog_base: moderngl.Program,
        prog_occ: moderngl.Program,
        prog_pos: moderngl.Program,
        caster: ShadowCaster,
        color: npt.ArrayLike | None,
        crease_deg: float,
        local: bool = True,
        sky: str | None = None,
        rich: tuple[moderngl.Program, moderngl.Program] | None = None,
    ) -> None:
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
        # the mesh file's base-colour texture (arshadow.geometry.material), unless a colour overrides it
        material: Material | None = getattr(caster, "material", None) if color is None else None
        # its texture and per-corner UVs: both set when it is textured (Material.textured), else both None
        tex_image, tex_uv = (
            (material.texture, material.uv) if material is not None and material.textured else (None, None)
        )
        textured = tex_image is not None and tex_uv is not None
        if material is not None and textured:
            alb = np.broadcast_to(np.asarray(material.base_color, np.float64)[:3], (m, 3, 3))
        nrm = crease_normals(v, f, crease_deg)
        # lighting pass: one vertex per distinct (vertex, normal[, uv]) -- smooth corners share their
        # vertex's normal, corners at a crease (or a texture seam) have their own -- drawn indexed so the
        # vertex cache works
        nrm32 = np.ascontiguousarray(nrm.reshape(-1, 3).astype(np.float32))
        cols = [f.reshape(-1, 1).astype(np.int64), nrm32.view(np.int32).astype(np.int64)]
        if tex_uv is not None:  # = textured
            uv32 = np.ascontiguousarray(tex_uv.reshape(-1, 2).astype(np.float32))
            cols.append(uv32.view(np.int32).astype(np.int64))
        key = np.concatenate(cols, axis=1)
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
        # shading attributes per lighting vertex (uv, sky visibility, ground view) and the texture
        self.shade_vbo: moderngl.Buffer | None = None
        self.texture: moderngl.Texture | None = None
        self.shade_base_vao: moderngl.VertexArray | None = None
        self.textured, self.sky = textured, sky
        #: the faces' view of the object itself (its light on itself, arshadow.shading.interreflect): set with
        #: sky shading when some of the mesh sees itself, else None
        self.self_view: SelfView | None = None
        #: with sky shading: the shading vertices' attributes, their ground view before the ground's light,
        #: each face corner's shading vertex (set_object_ground)
        self._shade: np.ndarray | None = None
        self._ground_view: np.ndarray | None = None
        self._corners: np.ndarray | None = None
        self._caster: ShadowCaster | None = None
        self.ground_of: object = None  # the ground light the shading vertices hold (set_object_ground)
        # (buffer, format, attribute names...) per buffer of the lighting vertices
        content: list[tuple[moderngl.Buffer | str, ...]] = [(self.vbo, "4f 3f 3f", "in_pos", "in_normal", "in_albedo")]
        #: the programs of the occluder's base and light passes: ``rich = (base, light)`` (the texture / sky /
        #: albedo-gain shaders) when given, else the plain ones this was made with
        self.prog_base, self.prog_light = (prog_base, prog_occ) if rich is None else rich
        self.rich = rich is not None
        if rich is not None:
            prog_base, prog_occ = rich
            shade = np.zeros((len(first), 4), np.float32)
            if tex_uv is not None and tex_image is not None:  # = textured
                shade[:, :2] = tex_uv.reshape(-1, 2)[first]
                self.texture = _texture(ctx, tex_image)
            if sky is not None:
                shade[:, 2:] = _object_sky(ctx, caster, v[corner_v], nrm.reshape(-1, 3)[first], sky)
                self.self_view = self_view(caster, inverse.reshape(m, 3), shade[:, 2:])
                self._shade, self._ground_view = shade, shade[:, 3].copy()
                self._corners, self._caster = inverse.reshape(m, 3), caster
            self.shade_vbo = ctx.buffer(shade.tobytes())
            content.append((self.shade_vbo, "2f 2f", "in_uv", "in_vis"))
            # the base pass then draws these vertices (per corner) instead of the welded ones
            self.shade_base_vao = ctx.vertex_array(
                prog_base, content, index_buffer=self.light_ibo, index_element_size=4, skip_errors=True
            )
        self.vao = ctx.vertex_array(
            prog_occ, content, index_buffer=self.light_ibo, index_element_size=4, skip_errors=True
        )
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
        self.base_vao = ctx.vertex_array(
            prog_base, [(self.pos_vbo, "4f 3f", "in_pos", "in_albedo")], index_buffer=self.ibo, index_element_size=4
        )
        self.planar_vao = ctx.vertex_array(
            prog_pos, [(self.pos_vbo, "4f 12x", "in_pos")], index_buffer=self.ibo, index_element_size=4
        )
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
        self.sub_vao = ctx.vertex_array(
            prog_occ, content, index_buffer=self.sub_ibo, index_element_size=4, skip_errors=True
        )
        self.sub_ranges: dict[int, tuple[int, int]] = {}
        self.sub_key: tuple[bytes, ...] | None = None  # the lights sub_ibo holds subsets for
        self._planar_sub_vao: moderngl.VertexArray | None = None

    def set_object_ground(self, light: Callable[[np.ndarray], np.ndarray] | None) -> None:
        """Give the shading vertices the ground light their faces see (:func:`arshadow.shading.objground.vertex_ground`
        of ``light``, the photo's ground over the ring's value; None: the ring's everywhere) as a factor on their
        ground view; once per ``light`` (kept while the same object is handed in)."""
        if light is self.ground_of or self._shade is None or self.shade_vbo is None:
            return
        view = self._ground_view
        assert view is not None and self._corners is not None and self._caster is not None  # set with _shade
        if light is None:
            self._shade[:, 3] = view
        else:
            faces = face_ground(self._caster, light)
            self._shade[:, 3] = view * vertex_ground(self._caster, self._corners, len(view), faces)
        self.shade_vbo.write(self._shade.tobytes())
        self.ground_of = light

    def planar_sub_vao(self, ctx: moderngl.Context, prog: moderngl.Program) -> moderngl.VertexArray:
        """Positions of the light-facing subsets (``sub_ibo``) for the direct planar pass (made on first use)."""
        if self._planar_sub_vao is None:
            self._planar_sub_vao = ctx.vertex_array(
                prog, [(self.vbo, "4f 24x", "in_pos")], index_buffer=self.sub_ibo, index_element_size=4
            )
        return self._planar_sub_vao

    def upload_light_subsets(self, passes: Sequence[LightPass]) -> None:
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
        parts: list[np.ndarray] = []
        first = 0
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

    def release(self) -> None:
        for o in (
            self.shade_base_vao,
            self.shade_vbo,
            self.texture,
            self.vao,
            self.sub_vao,
            self._planar_sub_vao,
            self.base_vao,
            self.planar_vao,
            self.vbo,
            self.light_ibo,
            self.sub_ibo,
            self.pos_vbo,
            self.ibo,
        ):
            if o is not None:
                o.release()


def _object_sky(
    ctx: moderngl.Context, caster: ShadowCaster, points: np.ndarray, normals: np.ndarray, sky: str
) -> np.ndarray:
    """``(k, 2)``: sky visibility and ground view of the shading vertices, self-occlusion found with item
    buffers drawn on this context (:class:`arshadow.gl.sky.GLItemBuffer`, 512 px, 64 directions)."""
    from .sky import GLItemBuffer

    # one per context, kept like the programs (releasing a framebuffer moderngl may still think bound
    # left GL_INVALID_OPERATION when the next one was made)
    extra = _program_cache(ctx)

    def draw(xy: np.ndarray, depth: np.ndarray, faces: np.ndarray, res: int) -> np.ndarray:
        # made on first use: a convex mesh needs none
        ib: GLItemBuffer | None = extra.get("item_buffer_512")
        if ib is None:
            ib = extra["item_buffer_512"] = GLItemBuffer(ctx, 512)
        return ib(xy, depth, faces, res)

    s, g = object_sky_visibility(caster, points, normals, sky=sky, item_buffer=draw, res=512)
    return np.stack([s, g], axis=1)


def _texture(ctx: moderngl.Context, image: np.ndarray) -> moderngl.Texture:
    """``(h, w, 3)`` linear RGB (row 0 = the image's top) as a mipmapped half-float texture, rows flipped
    to GL order (texel row 0 = the image's bottom, so ``v`` counts from the bottom as the UVs do)."""
    img = np.ascontiguousarray(np.asarray(image, np.float32)[::-1, :, :3].astype(np.float16))
    tex = ctx.texture((img.shape[1], img.shape[0]), 3, img.tobytes(), dtype="f2")
    tex.repeat_x = tex.repeat_y = True  # glTF's default sampler wraps
    tex.build_mipmaps()
    tex.filter = (ctx.LINEAR_MIPMAP_LINEAR, ctx.LINEAR)
    return tex


def ground_vertices(ground_size: float | None = None, origin: npt.ArrayLike | None = None) -> np.ndarray:
    """The ground plane z = 0 as 12 homogeneous vertices ``(12, 4) float32`` (4 triangles, CCW seen from
    +z): unlimited (``None``: triangles fanning out to points at infinity, w = 0) or a square of side
    ``ground_size`` centred on the world origin (2 triangles padded with degenerate ones).

    ``origin (3,)``: the vertices relative to this point (:func:`local_origin`; points at infinity
    unchanged); the unlimited fan's centre is then the ground point under it (small local coordinates)."""
    o3 = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
    tris: list[tuple[float, float, float, float]]
    if ground_size is None:
        o, px, py, nx, ny = (0, 0, 0, 1), (1, 0, 0, 0), (0, 1, 0, 0), (-1, 0, 0, 0), (0, -1, 0, 0)
        tris = [o, px, py, o, py, nx, o, nx, ny, o, ny, px]
    else:
        key = float(ground_size)
        if not (math.isfinite(key) and key > 0):
            raise UsageError(f"ground_size must be a positive length, got {ground_size}")
        h = key / 2
        a, b, c, d = (-h, -h, 0, 1), (h, -h, 0, 1), (h, h, 0, 1), (-h, h, 0, 1)
        tris = [a, b, c, a, c, d] + [(0.0, 0.0, 0.0, 1.0)] * 6
    t = np.asarray(tris, dtype=np.float64)
    if ground_size is None:
        t[t[:, 3] == 1.0, :2] = o3[:2]  # fan centre under the origin (the plane itself stays z = 0)
    t[:, :3] -= o3 * t[:, 3:4]
    return t.astype(np.float32)


def local_origin(vertices: npt.ArrayLike) -> np.ndarray:
    """(3,) float64: the centre of the bounding box of ``vertices (n, 3)``, the origin of the frame the GPU
    works in. Every position is converted to float32 relative to it (and the matrices absorb the
    translation in float64): a millimetre object 1 km from the marker keeps float32's relative precision
    of its own size instead of losing ~0.06 mm (float32 at 1000) to the distance."""
    v = np.asarray(vertices, np.float64)
    centre: np.ndarray = 0.5 * (v.min(axis=0) + v.max(axis=0)) if len(v) else np.zeros(3)
    return centre


def translation(o: npt.ArrayLike) -> np.ndarray:
    """(4, 4) float64: the translation by ``o (3,)``."""
    t = np.eye(4)
    t[:3, 3] = o
    return t


class CasterCache:
    """:class:`CasterBuffers` of the last few casters, keyed by the caster object (held by weak reference:
    a caster that is garbage collected loses its buffers) and its colour override.

    Parameters
    ----------
    ctx : moderngl.Context
    programs : (prog_base, prog_occ, prog_pos)
        As :class:`CasterBuffers`.
    max_cached : int
        Least recently *made* entries are released beyond this many.
    """

    def __init__(
        self,
        ctx: moderngl.Context,
        programs: tuple[moderngl.Program, moderngl.Program, moderngl.Program],
        max_cached: int,
        rich_programs: tuple[moderngl.Program, moderngl.Program] | None = None,
    ) -> None:
        self.ctx = ctx
        self.programs = tuple(programs)
        #: (base, light) programs with textures, sky shading and the albedo gain (None: never used)
        self.rich_programs = rich_programs
        self.max_cached = int(max_cached)
        self._entries: dict[int, tuple[Callable[[], object], tuple, CasterBuffers]] = {}

    def get(
        self,
        caster: ShadowCaster,
        occluder_color: npt.ArrayLike | None,
        crease_deg: float,
        sky: str | None = None,
        rich: bool = False,
    ) -> CasterBuffers:
        """The buffers of ``caster`` with ``occluder_color`` ((3,) sRGB or None), made on first use; ``sky``
        (a sky model of :mod:`arshadow.shading.sky`, or None): with the object's sky visibility per vertex;
        ``rich``: drawn by the rich programs (also when the caster has a texture and no colour overrides it)."""
        material = getattr(caster, "material", None)
        rich = bool(self.rich_programs) and (
            rich or sky is not None or (occluder_color is None and material is not None and material.textured)
        )
        entries = self._entries
        # purge dead casters
        for key in [k for k, (ref, _, _) in entries.items() if ref() is None]:
            entries.pop(key)[2].release()
        ckey = None if occluder_color is None else tuple(float(c) for c in np.ravel(occluder_color)[:3])
        entry = entries.get(id(caster))
        if entry is not None and entry[0]() is caster and entry[1] == (ckey, crease_deg, sky, rich):
            return entry[2]
        if entry is not None:
            entries.pop(id(caster))[2].release()
        while len(entries) >= self.max_cached:
            entries.pop(next(iter(entries)))[2].release()
        prog_base, prog_occ, prog_pos = self.programs
        bufs = CasterBuffers(
            self.ctx,
            prog_base,
            prog_occ,
            prog_pos,
            caster,
            ckey,
            crease_deg,
            sky=sky,
            rich=self.rich_programs if rich else None,
        )
        ref: Callable[[], object]
        try:
            ref = weakref.ref(caster)
        except TypeError:  # objects without weakref support: keep a strong reference

            def strong(obj: object = caster) -> object:
                return obj

            ref = strong

        entries[id(caster)] = (ref, (ckey, crease_deg, sky, rich), bufs)
        return bufs

    def __len__(self) -> int:
        return len(self._entries)

    def release(self) -> None:
        for _, _, bufs in self._entries.values():
            bufs.release()
        self._entries.clear()


class VolumeBuffers:
    """One vertex + index buffer holding every light's shadow volume of a frame (grown, never shrunk).

    Parameters
    ----------
    ctx : moderngl.Context
    prog_volume : moderngl.Program
        The program the vertex array is made for (``in_pos``: vec4).
    """

    def __init__(self, ctx: moderngl.Context, prog_volume: moderngl.Program) -> None:
        self.ctx = ctx
        self.prog = prog_volume
        self.vbo: moderngl.Buffer | None = None
        self.ibo: moderngl.Buffer | None = None
        self.vao: moderngl.VertexArray | None = None
        self._cap = (0, 0)
        # (volumes, ranges, origin) of the last upload, kept when their arrays are read-only
        self._last: tuple[tuple[ShadowVolume | None, ...], tuple[tuple[int, int] | None, ...], np.ndarray] | None = None

    @property
    def array(self) -> moderngl.VertexArray:
        """The vertex array of the uploaded volumes (made by the first :meth:`upload` with a volume)."""
        assert self.vao is not None, "upload() first"
        return self.vao

    def upload(self, passes: Sequence[LightPass], origin: npt.ArrayLike | None = None) -> list[tuple[int, int] | None]:
        """Write every light's volume into the reused vertex/index buffers; returns per-pass
        ``(first_index, n_indices)`` (None where a pass has no volume).

        The pipeline hands the same (frozen, read-only) volume objects every frame while the lights stay
        put: when the passes' volumes are exactly those of the previous upload, the buffers already hold
        them and nothing is converted or uploaded. ``origin (3,)``: vertices are written relative to it
        (:func:`local_origin`; points at infinity unchanged)."""
        # LightPass.volume: a ShadowVolume (or None)
        vols = tuple(None if p.mode == "planar" else cast("ShadowVolume | None", p.volume) for p in passes)
        o3 = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
        last = self._last
        if (
            last is not None
            and len(last[0]) == len(vols)
            and all(a is b for a, b in zip(last[0], vols, strict=True))
            and np.array_equal(last[2], o3)
        ):
            return list(last[1])
        self._last = None
        ranges: list[tuple[int, int] | None] = []
        parts: list[tuple[np.ndarray, np.ndarray, int, int]] = []
        nv = ni = 0
        frozen = True
        for vol in vols:
            if vol is None:
                ranges.append(None)
                continue
            v = np.asarray(vol.vertices)
            t = np.asarray(vol.triangles)
            if v.ndim != 2 or v.shape[1] != 4 or t.ndim != 2 or t.shape[1] != 3:
                raise ShapeError(
                    "shadow volume must have vertices (p, 4) and triangles (q, 3)",
                    actual_shape=(v.shape, t.shape),
                    expected_shape="((p, 4), (q, 3))",
                )
            frozen = frozen and not (v.flags.writeable or t.flags.writeable)
            if len(t) == 0:
                ranges.append(None)
                continue
            parts.append((v, t, nv, ni))
            ranges.append((ni, 3 * len(t)))
            nv += len(v)
            ni += 3 * len(t)
        if ni:
            self._reserve(16 * nv, 4 * ni)
            vbo, ibo = self.vbo, self.ibo
            assert vbo is not None and ibo is not None  # made by _reserve
            # each volume straight into its slice of the buffers (no concatenated copy)
            for v, t, v_first, i_first in parts:
                idx = t.astype(np.uint32)
                if v_first:
                    idx += np.uint32(v_first)
                loc = v.astype(np.float64)  # relative to origin: X - origin * w (points at infinity unchanged)
                loc[:, :3] -= o3 * loc[:, 3:4]
                vbo.write(loc.astype(np.float32), offset=16 * v_first)
                ibo.write(idx, offset=4 * i_first)
        if frozen:  # read-only arrays cannot change behind our back: safe to reuse next frame
            self._last = (vols, tuple(ranges), o3)
        return ranges

    def _reserve(self, vbytes: int, ibytes: int) -> None:
        if self.vbo is not None and vbytes <= self._cap[0] and ibytes <= self._cap[1]:
            return
        vcap = max(vbytes, 2 * self._cap[0], 1 << 16)
        icap = max(ibytes, 2 * self._cap[1], 1 << 16)
        self.release()
        self.vbo = self.ctx.buffer(reserve=vcap, dynamic=True)
        self.ibo = self.ctx.buffer(reserve=icap, dynamic=True)
        self.vao = self.ctx.vertex_array(
            self.prog, [(self.vbo, "4f", "in_pos")], index_buffer=self.ibo, index_element_size=4
        )
        self._cap = (vcap, icap)

    def release(self) -> None:
        for o in (self.vao, self.vbo, self.ibo):
            if o is not None:
                o.release()
        self.vbo = self.ibo = self.vao = None


class GroundBuffer:
    """The ground plane's vertex buffer and array (:func:`ground_vertices`: 12 homogeneous vertices),
    rewritten only when the ground size or the local origin changes.

    Parameters
    ----------
    ctx : moderngl.Context
    prog : moderngl.Program
        The program the vertex array is made for (``in_pos``: vec4).
    """

    def __init__(self, ctx: moderngl.Context, prog: moderngl.Program) -> None:
        self.vbo = ctx.buffer(reserve=12 * 4 * 4)
        self.vao = ctx.vertex_array(prog, [(self.vbo, "4f", "in_pos")])
        self._key: tuple[str | float, tuple[float, ...]] | None = None

    def set(self, ground_size: float | None, origin: npt.ArrayLike | None = None) -> None:
        """The ground z = 0 (unlimited, or a ``ground_size`` square) relative to ``origin (3,)``."""
        o3 = np.zeros(3) if origin is None else np.asarray(origin, np.float64)
        key = ("inf" if ground_size is None else float(ground_size), tuple(o3.tolist()))
        if key == self._key:
            return
        self.vbo.write(ground_vertices(ground_size, o3).tobytes())
        self._key = key

    def render(self, ctx: moderngl.Context) -> None:
        self.vao.render(ctx.TRIANGLES, vertices=12)

    def release(self) -> None:
        self.vao.release()
        self.vbo.release()


def screen_box(mvp: np.ndarray, corners: np.ndarray, width: int, height: int) -> tuple[int, int, int, int]:
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
