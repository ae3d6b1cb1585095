"""GPU-resident compositing: lens warp + linear-light composite in a shader, one 8-bit readback.

The numpy path reads the renderer's float layers back (``RGBA16F`` colour, ``RG16F`` mask; with sky occlusion
``RGBA16F``, its b channel the sky occlusion read back as ``GL_RGB``), warps them
to the distorted photo with :meth:`arshadow.compose.lens.LensWarp.warp` (``cv2.remap``) and composites them with
:func:`arshadow.compose.composite.composite`. This module does the same work on the GPU:

1. ``ShadowRenderer.render_gpu(...)`` leaves the (MSAA-resolved, by ``glBlitFramebuffer``)
   layers in two textures (:class:`arshadow.gl.layers.GpuLayers`);
2. the photo's region of interest is uploaded into an ``RGB8UI`` texture (allocated once per photo size);
3. ``compose.frag`` runs once per ROI pixel: the undistortion map (``RG32F`` texture, uploaded once per
   calibration, tile by tile as :class:`LensWarp` computes it) gives the pinhole point, the layers are
   sampled bilinearly exactly as ``cv2.remap`` does (coordinates rounded to 1/32 px, border 0), and the
   composite is the numpy path's arithmetic with its own tables (``SRGB_TO_LINEAR`` as a 256-texel float
   texture, ``LINEAR_TO_SRGB16`` as a 256 x 256 ``R8UI`` texture), the sky-occlusion term included when the
   layers carry it (``GpuLayers.sky``: the warped sky clipped to [-1, 1], the ground keeping
   ``max(keep - opacity * mask * (1 - tint) - sky * (1 - opacity * (1 - tint)), 0)`` as
   :func:`arshadow.compose.composite.composite` does; the plan's ROI holds the sky's reach, the map's outline);
   with camera effects (``look.camera``) the warped layers are first written into float textures over the ROI
   grown by the blur's reach and blurred there, and the sensor noise is added (:mod:`arshadow.gl.gpu_effects`);
4. one ``glReadPixels`` of the 8-bit ROI straight into the output photo (``GL_PACK_ROW_LENGTH`` = photo
   width, no intermediate copy), and one of the 8-bit mask when asked.

Rows: the photo, the lens map and the output are stored with texel row = photo memory row (row 0 = top),
so neither upload nor readback flips anything; only the renderer's layers are bottom-up (OpenGL).

Parity with the numpy path: the same float32 operations in the same order on the same table values;
left-over differences come from the order of the bilinear (and the blur's) sums and fused multiply-adds, so a
pixel may differ by one 8-bit level where a value lies within ~1e-7 of a rounding tie (tests/test_gpu_compose.py).
The sensor noise is the exception: the same distribution, not the same random numbers.

Which path is faster depends on the backend (llvmpipe runs the shader on the same CPU cores; a GPU runs
it in microseconds and saves the float readback): :class:`PathChooser` times both on first use per key
(photo size, anti-aliasing, lens, sky occlusion, camera effects, backend) and keeps numpy unless the shader is
clearly (> 15 %) faster.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Hashable, Mapping, Sequence
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from ..compose.composite import LINEAR_TO_SRGB16, SRGB_TO_LINEAR, clip_roi
from ..compose.look import Look
from ..errors import ShapeError, UsageError
from . import glraw as G
from .context import current
from .gpu_effects import LayerBlur, NoiseTexture
from .layers import GpuLayers
from .resources import program, uniform

if TYPE_CHECKING:  # annotations only: the context is handed in (arshadow.gl.context makes it)
    import moderngl

    from ..compose.lens import LensWarp
    from ..plan.planner import FramePlan

_T = TypeVar("_T")

__all__ = ["GpuCompositor", "PathChooser", "SHARED_DECISIONS"]

#: the compose choices made in this process, shared by every :class:`PathChooser` made without its own
#: ``decisions`` (keys name the GL renderer, so one backend's measurement never decides for another)
SHARED_DECISIONS: dict = {}


class _LensTexture:
    """The undistortion map of one :class:`LensWarp` as an ``RG32F`` texture, filled tile by tile as the
    warp computes its map (never recomputed, each tile uploaded once)."""

    def __init__(self, ctx: moderngl.Context, lens: LensWarp) -> None:
        self.lens = lens
        self.tex = ctx.texture((lens.width, lens.height), 2, dtype="f4", alignment=4)
        self.tex.filter = (ctx.NEAREST, ctx.NEAREST)
        self.uploaded = np.zeros_like(lens.tiles_done)

    def update(self, roi: Sequence[int]) -> None:
        lens = self.lens
        lens.ensure(roi)
        done = lens.tiles_done
        todo = done & ~self.uploaded
        if not todo.any():
            return
        T = lens.TILE
        mx, my = lens.maps_partial()
        for row in np.flatnonzero(todo.any(axis=1)):
            r = int(row)
            cols = np.flatnonzero(todo[r])
            a, b = int(cols[0]), int(cols[-1]) + 1
            y0, y1 = r * T, min(lens.height, (r + 1) * T)
            x0, x1 = a * T, min(lens.width, b * T)
            data = np.empty((y1 - y0, x1 - x0, 2), np.float32)
            data[:, :, 0] = mx[y0:y1, x0:x1]
            data[:, :, 1] = my[y0:y1, x0:x1]
            self.tex.write(data.tobytes(), viewport=(x0, y0, x1 - x0, y1 - y0))
            self.uploaded[r, a:b] |= done[r, a:b]

    def release(self) -> None:
        self.tex.release()


def _grown(roi: tuple[int, int, int, int], pad: int, width: int, height: int) -> tuple[int, int, int, int]:
    """``roi (x0, y0, w, h)`` grown by ``pad`` px on each side, within a ``width`` x ``height`` photo."""
    x0, y0, w, h = roi
    return clip_roi((x0 - pad, y0 - pad, w + 2 * pad, h + 2 * pad), width, height)


class GpuCompositor:
    """Composites :class:`~arshadow.gl.layers.GpuLayers` into a photo on the GPU (one per context).

    Parameters
    ----------
    ctx : moderngl.Context
        The renderer's context.
    """

    @current
    def __init__(self, ctx: moderngl.Context) -> None:
        self.ctx = ctx
        self.gl = G.load()
        self.prog = program(ctx, "fullscreen.vert", "compose.frag")
        self.vao = ctx.vertex_array(self.prog, [])
        dec = ctx.texture((256, 1), 1, data=np.ascontiguousarray(SRGB_TO_LINEAR, np.float32).tobytes(), dtype="f4")
        enc = ctx.texture((256, 256), 1, data=np.ascontiguousarray(LINEAR_TO_SRGB16).tobytes(), dtype="u1", alignment=1)
        for t in (dec, enc):
            t.filter = (ctx.NEAREST, ctx.NEAREST)
        self._dec, self._enc = dec, enc
        self._size: tuple[int, int] | None = None
        # the photo-size textures and framebuffer (_ensure_size)
        self._photo: moderngl.Texture | None = None
        self._out: moderngl.Texture | None = None
        self._mask: moderngl.Texture | None = None
        self._fbo: moderngl.Framebuffer | None = None
        self._lens: dict[int, _LensTexture] = {}
        self._blur: LayerBlur | None = None  # the camera effects' (made on first use)
        self._noise: NoiseTexture | None = None
        self._released = False

    @current
    def release(self) -> None:
        if self._released:
            return
        self._free_size()
        for lt in self._lens.values():
            lt.release()
        self._lens.clear()
        for fx in (self._blur, self._noise):
            if fx is not None:
                fx.release()
        self._blur = self._noise = None
        for o in (self.vao, self._dec, self._enc):
            o.release()
        self._released = True

    def _free_size(self) -> None:
        for o in (self._fbo, self._photo, self._out, self._mask):
            if o is not None:
                o.release()
        self._photo = self._out = self._mask = self._fbo = None

    def _ensure_size(self, width: int, height: int) -> None:
        """Photo, output colour and output mask textures of the photo size (allocated once per size)."""
        if self._size == (width, height):
            return
        self._free_size()
        ctx = self.ctx
        self._photo = ctx.texture((width, height), 3, dtype="u1", alignment=1)
        self._out = ctx.texture((width, height), 4, dtype="f1")
        self._mask = ctx.texture((width, height), 1, dtype="f1")
        for t in (self._photo, self._out, self._mask):
            t.filter = (ctx.NEAREST, ctx.NEAREST)
        ctx.detect_framebuffer(0).use()  # moderngl rebinds "its" current framebuffer, maybe one released since
        self._fbo = ctx.framebuffer(color_attachments=[self._out, self._mask])
        self._size = (width, height)

    def _lens_texture(self, lens: LensWarp) -> _LensTexture:
        lt = self._lens.get(id(lens))
        if lt is None or lt.lens is not lens:
            if lt is not None:
                lt.release()
            lt = self._lens[id(lens)] = _LensTexture(self.ctx, lens)
        return lt

    @current
    def compose(
        self,
        image: np.ndarray,
        layers: GpuLayers,
        plan: FramePlan,
        look: Look,
        *,
        lens: LensWarp | None = None,
        out: np.ndarray | None = None,
        mask_out: np.ndarray | None = None,
        timings: dict[str, float] | None = None,
    ) -> np.ndarray:
        """Composite the layers into ``out`` over ``plan.roi`` (the numpy path's result within one level).

        Parameters
        ----------
        image : (H, W, 3) uint8
            BGR photo (not modified).
        layers : arshadow.gl.layers.GpuLayers
            From ``ShadowRenderer.render_gpu(...)`` of ``plan.canvas`` (with its sky occlusion when
            ``layers.sky``: composited too, with the look's opacity and shadow colour).
        plan : arshadow.plan.FramePlan
            Its ``roi`` ``(x0, y0, w, h)`` int: the photo pixels to composite (inside the photo; the others are
            left as they are in ``out``), and its ``canvas`` ``(u0, v0, w, h)`` int: the pinhole canvas the
            layers hold (``w, h`` = ``layers.width, layers.height``).
        look : arshadow.compose.look.Look
            Opacity, shadow colour (linear RGB), whether the object is drawn, the exposure gain, as the numpy
            :func:`arshadow.compose.composite.composite` takes them, and the camera effects (``look.camera``,
            :mod:`arshadow.gl.gpu_effects`): with a blur the region composited (and read back) is the ROI grown
            by the blur's reach (``look.camera.pad``), within the photo.
        lens : arshadow.compose.lens.LensWarp, optional
            With a distorted calibration: the photo pixel's pinhole point comes from its map.
            Without: the canvas is the photo's own pixel grid.
        out : (H, W, 3) uint8, optional
            Receives the result over ``roi`` (C-contiguous); a copy of ``image`` if None.
        mask_out : (H, W) uint8, optional
            Receives ``round(255 * mask)`` over ``roi`` (C-contiguous); not read back if None.
        timings : dict, optional
            ``upload``, ``draw``, ``readback`` (ms) are added to it.

        Returns
        -------
        out : (H, W, 3) uint8
        """
        roi, canvas = plan.roi, plan.canvas
        if self._released:
            raise UsageError("this GpuCompositor has been released")
        H, W = image.shape[:2]
        x0, y0, w, h = (int(v) for v in roi)
        out = self._checked_out(image, layers, roi, canvas, out, mask_out)
        if w == 0 or h == 0:
            return out
        t0 = time.perf_counter()
        ctx = self.ctx
        self._ensure_size(W, H)
        photo, fbo = self._photo, self._fbo
        assert photo is not None and fbo is not None  # made by _ensure_size
        cam = look.camera
        kernel = None if cam is None else cam.blur_kernel
        # the region composited: the ROI, grown by the blur's reach (the numpy path's _blurred)
        region = (x0, y0, w, h) if kernel is None or cam is None else _grown((x0, y0, w, h), cam.pad, W, H)
        rx, ry, rw, rh = region
        photo.write(np.ascontiguousarray(image[ry : ry + rh, rx : rx + rw]).data, viewport=region)
        if lens is not None:
            lt = self._lens_texture(lens)
            lt.update((x0, y0, w, h))
            lt.tex.use(5)
        self._set_uniforms(canvas, (x0, y0, w, h), lens is not None, look)
        self._set_sky(look, layers.sky, layers.bleed)
        self._set_noise(image, look)
        ctx.enable_only(ctx.NOTHING)
        self._bind(layers)
        t1 = time.perf_counter()
        if kernel is not None:
            self._blur_layers(region, kernel)
            self._bind(layers)  # the blur's passes used units 0-2
        fbo.use()
        fbo.viewport = region
        self.vao.render(ctx.TRIANGLES, vertices=3)
        t2 = time.perf_counter()
        self._readback(fbo, region, W, out, mask_out)
        t3 = time.perf_counter()
        if timings is not None:
            for k, v in (("upload", t1 - t0), ("draw", t2 - t1), ("readback", t3 - t2)):
                timings[k] = timings.get(k, 0.0) + v * 1e3
        return out

    def _bind(self, layers: GpuLayers) -> None:
        """The compose shader's textures on their units (the lens map, unit 5, is bound by :meth:`compose`)."""
        assert self._photo is not None  # made by _ensure_size
        for unit, tex in enumerate((self._photo, self._dec, self._enc, layers.color_tex, layers.mask_tex)):
            tex.use(unit)

    def _blur_layers(self, region: tuple[int, int, int, int], kernel: np.ndarray) -> None:
        """The warped layers over ``region`` (stage 1: zeros outside the ROI) into the blur's textures,
        blurred there (:class:`arshadow.gl.gpu_effects.LayerBlur`); the shader set to composite them
        (stage 2) over the whole region."""
        prog, (rx, ry, rw, rh) = self.prog, region
        if self._blur is None:
            self._blur = LayerBlur(self.ctx)
        target = self._blur.target(rw, rh)
        uniform(prog, "u_stage").value = 1
        uniform(prog, "u_origin").value = (rx, ry)
        target.use()
        target.viewport = (0, 0, rw, rh)
        self.vao.render(self.ctx.TRIANGLES, vertices=3)
        color, mask = self._blur.run(kernel, rw, rh)
        color.use(6)
        mask.use(7)
        uniform(prog, "u_stage").value = 2
        uniform(prog, "u_origin").value = (0, 0)
        uniform(prog, "u_blurred_origin").value = (rx, ry)
        uniform(prog, "u_roi").value = region

    @staticmethod
    def _checked_out(
        image: np.ndarray,
        layers: GpuLayers,
        roi: Sequence[int],
        canvas: Sequence[int],
        out: np.ndarray | None,
        mask_out: np.ndarray | None,
    ) -> np.ndarray:
        """Check the arguments of :meth:`compose`; returns ``out`` (a copy of ``image`` if None)."""
        H, W = image.shape[:2]
        x0, y0, w, h = (int(v) for v in roi)
        if x0 < 0 or y0 < 0 or w < 0 or h < 0 or x0 + w > W or y0 + h > H:
            raise ShapeError(f"roi {tuple(roi)} is not inside the {W}x{H} photo")
        if (int(canvas[2]), int(canvas[3])) != (int(layers.width), int(layers.height)):
            raise ShapeError(
                "the layers do not hold the canvas",
                actual_shape=(layers.width, layers.height),
                expected_shape=tuple(canvas[2:]),
            )
        if out is None:
            out = image.copy()
        for name, arr, shape in (("out", out, (H, W, 3)), ("mask_out", mask_out, (H, W))):
            if arr is not None and (arr.shape != shape or arr.dtype != np.uint8 or not arr.flags.c_contiguous):
                raise ShapeError(
                    f"{name} must be a C-contiguous uint8 array", actual_shape=arr.shape, expected_shape=shape
                )
        return out

    def _set_uniforms(self, canvas: Sequence[int], roi: tuple[int, int, int, int], use_lens: bool, look: Look) -> None:
        """The compose shader's texture units, geometry and darkening constants."""
        prog, opacity, shadow_color, draw_occluder = self.prog, look.opacity, look.shadow_color, look.draw_occluder
        sc = np.asarray(shadow_color, np.float64).reshape(3)
        gray = bool(sc[0] == sc[1] == sc[2])
        uniform(prog, "u_photo").value = 0
        uniform(prog, "u_decode").value = 1
        uniform(prog, "u_encode").value = 2
        uniform(prog, "u_color").value = 3
        uniform(prog, "u_mask").value = 4
        uniform(prog, "u_lens").value = 5
        uniform(prog, "u_use_lens").value = use_lens
        uniform(prog, "u_canvas").value = tuple(int(v) for v in canvas)
        uniform(prog, "u_roi").value = tuple(roi)
        uniform(prog, "u_occluder").value = bool(draw_occluder)
        uniform(prog, "u_gray").value = gray
        uniform(prog, "u_gray_k").value = float(np.float32(-float(opacity) * (1.0 - sc[0])))
        uniform(prog, "u_dark").value = tuple(
            float(v) for v in (np.float32(opacity) * (1.0 - sc[::-1])).astype(np.float32)
        )
        uniform(prog, "u_darken").value = float(opacity) > 0.0
        gain = (1.0, 1.0, 1.0) if look.color_gain is None else tuple(float(v) for v in look.color_gain)
        uniform(prog, "u_gain").value = tuple(float(v) for v in np.asarray(gain, np.float32).reshape(3)[::-1])

    def _set_noise(self, image: np.ndarray, look: Look) -> None:
        """The stage (0: warp and composite), the blur's and the noise's texture units, and the noise of
        ``look.camera`` (with a table and the object drawn, as the numpy path; seeded by the photo)."""
        prog = self.prog
        uniform(prog, "u_stage").value = 0
        uniform(prog, "u_origin").value = (0, 0)
        uniform(prog, "u_blurred_origin").value = (0, 0)
        for name, unit in (("u_bl_color", 6), ("u_bl_mask", 7), ("u_noise_tab", 8)):
            uniform(prog, name).value = unit
        cam = look.camera
        table = None if cam is None or not look.draw_occluder else cam.noise_table
        uniform(prog, "u_noise").value = table is not None
        if cam is not None and table is not None:
            uniform(prog, "u_seed").value = cam.noise_seed(image) & 0xFFFFFFFF
            if self._noise is None:
                self._noise = NoiseTexture(self.ctx)
            self._noise.use(table, 8)

    def _set_sky(self, look: Look, sky: bool, bleed: tuple | None = None) -> None:
        """The sky-occlusion term's switch and weights (BGR, float32 as ``composite._darken_sky`` makes them:
        the mask's ``-opacity * (1 - tint)``, the sky's ``opacity * (1 - tint) - 1``)."""
        prog = self.prog
        uniform(prog, "u_sky").value = bool(sky)
        dark = float(look.opacity) * (1.0 - np.asarray(look.shadow_color, np.float64).reshape(3)[::-1])
        uniform(prog, "u_sky_wm").value = tuple(float(v) for v in (-dark).astype(np.float32))
        uniform(prog, "u_sky_ws").value = tuple(float(v) for v in (dark - 1.0).astype(np.float32))
        b = np.zeros(3, np.float32) if bleed is None else np.asarray(bleed, np.float32).reshape(3)[::-1]
        uniform(prog, "u_bleed").value = tuple(float(v) for v in b)  # BGR

    def _readback(
        self,
        fbo: moderngl.Framebuffer,
        roi: tuple[int, int, int, int],
        W: int,
        out: np.ndarray,
        mask_out: np.ndarray | None,
    ) -> None:
        """One readback of the 8-bit ROI of ``fbo`` (the photo-size framebuffer) straight into the output
        photo (and the mask)."""
        ctx, gl = self.ctx, self.gl
        x0, y0, w, h = roi
        gl.glBindBuffer(G.GL_PIXEL_PACK_BUFFER, 0)
        gl.glBindFramebuffer(G.GL_READ_FRAMEBUFFER, fbo.glo)
        gl.glPixelStorei(G.GL_PACK_ALIGNMENT, 1)
        gl.glPixelStorei(G.GL_PACK_ROW_LENGTH, W)
        gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0)
        gl.glReadPixels(x0, y0, w, h, G.GL_RGB, G.GL_UNSIGNED_BYTE, out[y0:, x0:].ctypes.data)
        if mask_out is not None:
            gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0 + 1)
            gl.glReadPixels(x0, y0, w, h, G.GL_RED, G.GL_UNSIGNED_BYTE, mask_out[y0:, x0:].ctypes.data)
        gl.glPixelStorei(G.GL_PACK_ROW_LENGTH, 0)
        gl.glPixelStorei(G.GL_PACK_ALIGNMENT, 4)
        gl.glReadBuffer(G.GL_COLOR_ATTACHMENT0)
        gl.glBindFramebuffer(G.GL_FRAMEBUFFER, 0)
        if ctx.screen is not None:
            ctx.screen.use()


class PathChooser:
    """Picks the faster of several interchangeable code paths by timing them on first use, per key.

    On the first call for a key every path runs ``trials`` times, interleaved (the first round is a warm-up
    that allocates buffers and fills caches and is not counted). The first path given is the default: another
    is kept for that key only when its median time beats the default's by more than ``margin`` (a share), so
    that two paths within the timing noise do not swap from run to run. Later calls run only the chosen
    path.

    Parameters
    ----------
    trials : int
        Timed runs per path after the warm-up round (>= 1).
    force : str, optional
        Always take this path (no timing).
    margin : float
        How much faster (a share of the default's median time) another path must be to be chosen (default
        0.15: on llvmpipe the numpy and shader paths measure within about 15 % of each other, with the
        load; on a GPU the shader path should win by far more, as it saves the float readback and the CPU
        warp -- not measured: no GPU was available, docs/planner.md).
    decisions : dict, optional
        Where the measured choices are kept (default :data:`SHARED_DECISIONS`: shared by every chooser of the
        process, so each key is timed once; a forced chooser records nothing).
    time_software : bool
        Also time the paths on a software rasteriser (llvmpipe). Off by default: there the shader path runs
        on the same cores as the rest of the pipeline, the timings of a path's wall time on the calling
        thread say little about its CPU cost, and the default (numpy) path is taken untimed
        (:meth:`arshadow.frame.session.Session.render`).

    Attributes
    ----------
    decisions : dict
        key -> ``{"choice": name, "ms": {name: median ms}}``.
    """

    def __init__(
        self,
        trials: int = 3,
        force: str | None = None,
        decisions: dict | None = None,
        margin: float = 0.15,
        clock: Callable[[], float] = time.perf_counter,
        time_software: bool = False,
    ) -> None:
        if int(trials) < 1:
            raise UsageError(f"trials must be >= 1, got {trials}")
        if not 0.0 <= float(margin) < 1.0:
            raise UsageError(f"margin must be in [0, 1), got {margin}")
        self.trials = int(trials)
        self.margin = float(margin)
        self.force = force
        self.clock = clock  # seconds; a test hands in a deterministic clock
        self.time_software = bool(time_software)
        if decisions is None:
            decisions = SHARED_DECISIONS  # one measurement per key and process, whichever session asks first
        self.decisions: dict = decisions

    def run(self, key: Hashable, paths: Mapping[str, Callable[[], _T]]) -> tuple[str, _T]:
        """Run the chosen path for ``key`` (timing all ``paths`` on first use); returns ``(name, result)``.

        ``paths`` maps a name to a no-argument callable; each must have the same effect (the caller's
        output buffers are simply written again by each).
        """
        if self.force is not None:
            if self.force not in paths:
                raise UsageError(f"path {self.force!r} is not one of {', '.join(paths)}")
            return self.force, paths[self.force]()
        d = self.decisions.get(key)
        if d is not None:
            return d["choice"], paths[d["choice"]]()
        times: dict[str, list[float]] = {name: [] for name in paths}
        result: dict[str, _T] = {}
        for rnd in range(self.trials + 1):
            for name, fn in paths.items():
                t = self.clock()
                result[name] = fn()
                if rnd:
                    times[name].append((self.clock() - t) * 1e3)
        med = {name: statistics.median(v) for name, v in times.items()}
        default = next(iter(paths))
        fastest = min(med, key=med.__getitem__)
        choice = fastest if med[fastest] < (1.0 - self.margin) * med[default] else default
        self.decisions[key] = {"choice": choice, "ms": {k: round(v, 3) for k, v in med.items()}}
        # the chosen path runs last so that the caller's buffers hold its result
        return choice, paths[choice]()
