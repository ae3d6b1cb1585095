"""The object's material as read from its mesh file: base colour, base-colour texture and its UVs.

What is read (see ``docs/shading.md`` for what is not modelled):

- glTF 2.0 (``.glb`` / ``.gltf``): ``pbrMetallicRoughness.baseColorFactor`` (linear RGBA),
  ``baseColorTexture`` (sRGB-encoded, decoded to linear here) with ``TEXCOORD_0``, ``metallicFactor``,
  ``roughnessFactor``;
- OBJ + MTL: ``Kd`` (taken as sRGB, like vertex colours) and ``map_Kd`` with the ``vt`` coordinates;
- PLY / OBJ vertex colours stay on the :class:`~arshadow.geometry.caster.ShadowCaster`
  (``vertex_colors``), as before.

Texture coordinates follow trimesh's (and OpenGL's) convention whatever the file: ``(u, v)`` with ``v``
from the image's *bottom* edge, so the texel of ``(u, v)`` is at column ``u * w``, row ``(1 - v) * h`` of
the image array (row 0 = top). trimesh converts glTF's top-left origin on reading. Coordinates outside
0..1 repeat (glTF's default sampler wrap).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..compose.composite import srgb_to_linear

if TYPE_CHECKING:  # annotations only: trimesh and Pillow are imported where a mesh file is read
    import trimesh
    from PIL import Image

__all__ = ["Material", "material_from_trimesh"]


@functools.lru_cache(maxsize=8)
def _barycentric_samples(level: int) -> np.ndarray:
    """``(level^2, 3)`` barycentric centroids of a triangle split into ``level^2`` equal triangles."""
    pts = []
    for i in range(level):
        for j in range(level - i):
            pts.append(((i + 1 / 3) / level, (j + 1 / 3) / level))  # upright sub-triangle
            if i + j < level - 1:
                pts.append(((i + 2 / 3) / level, (j + 2 / 3) / level))  # inverted one
    a = np.array(pts, np.float64)
    out: np.ndarray = np.c_[1.0 - a.sum(axis=1), a]
    return out


#: texture samples for :attr:`ShadowCaster.mean_albedo`: about this many in all, each face split into
#: ``L x L`` triangles sampled at their centroids, ``L`` from 8 (64 per face) to 32 (1024 per face)
ALBEDO_SAMPLES = 1 << 20


@dataclasses.dataclass(frozen=True, eq=False)
class Material:
    """A mesh's base-colour material (GL-free value).

    Attributes
    ----------
    base_color : (4,) float64
        Linear RGBA factor multiplied with the texture (1 when the file gives none).
    texture : (h, w, 3) float32 or None
        Base-colour texture in linear light, row 0 = the image's top.
    uv : (m, 3, 2) float32 or None
        Texture coordinates per face corner, aligned with the faces they were read with (see
        :meth:`select_faces`); ``v`` from the image's bottom.
    metallic, roughness : float
        glTF factors (1, 1 when absent; OBJ: 0, 1).
    source : str
        Where it came from (``"gltf"``, ``"obj"``), for messages and the report.
    """

    base_color: np.ndarray
    texture: np.ndarray | None = None
    uv: np.ndarray | None = None
    metallic: float = 0.0
    roughness: float = 1.0
    source: str = ""

    @property
    def textured(self) -> bool:
        return self.texture is not None and self.uv is not None

    def texture_mean(self, areas: np.ndarray) -> np.ndarray:
        """``(3,) float64`` linear RGB: the base colour times the texture's mean over the faces, weighted by
        their ``areas (m,)`` (the faces it was selected for): each face sampled at the centroids of its split
        into ``L x L`` triangles (nearest texel, wrapped), about :data:`ALBEDO_SAMPLES` samples in all."""
        w = np.asarray(areas, np.float64)
        if self.texture is None or self.uv is None or w.sum() <= 0:
            return np.asarray(self.base_color, np.float64)[:3].copy()
        tex = np.asarray(self.texture, np.float64)
        th, tw = tex.shape[:2]
        level = int(np.clip(np.sqrt(ALBEDO_SAMPLES / max(len(w), 1)), 8, 32))
        uv = np.einsum("sk,mkd->msd", _barycentric_samples(level), np.asarray(self.uv, np.float64))  # (m, s, 2)
        col = np.floor(np.mod(uv[..., 0], 1.0) * tw).astype(np.int64).clip(0, tw - 1)
        row = np.floor((1.0 - np.mod(uv[..., 1], 1.0)) * th).astype(np.int64).clip(0, th - 1)
        per_face = tex[row, col].mean(axis=1)  # (m, 3)
        out: np.ndarray = np.asarray(self.base_color, np.float64)[:3] * (w @ per_face) / w.sum()
        return out

    def select_faces(self, index: np.ndarray, flip_winding: bool = False) -> Material:
        """This material for the faces ``index (m',) int`` of the ones it was read with (the caster's
        surviving faces), corners reversed when ``flip_winding`` (a mirroring scale)."""
        if self.uv is None:
            return self
        uv = self.uv[np.asarray(index, np.intp)]
        if flip_winding:
            uv = uv[:, ::-1]
        return dataclasses.replace(self, uv=np.ascontiguousarray(uv))

    def sample(self, uv: np.ndarray) -> np.ndarray:
        """``(k, 3) float64`` linear base colour at texture coordinates ``uv (k, 2)`` (bilinear, repeat),
        times :attr:`base_color`; the factor alone when untextured.

        >>> m = Material(np.array([0.5, 1, 1, 1]), np.ones((2, 2, 3), np.float32), None)
        >>> m.sample(np.array([[0.3, 0.7]])).tolist()
        [[0.5, 1.0, 1.0]]
        """
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        if self.texture is None:
            return np.broadcast_to(self.base_color[:3], (len(uv), 3)).copy()
        tex = self.texture
        h, w = tex.shape[:2]
        x = np.mod(uv[:, 0], 1.0) * w - 0.5
        y = (1.0 - np.mod(uv[:, 1], 1.0)) * h - 0.5
        x0, y0 = np.floor(x).astype(np.intp), np.floor(y).astype(np.intp)
        tx, ty = (x - x0)[:, None], (y - y0)[:, None]
        xa, xb, ya, yb = x0 % w, (x0 + 1) % w, y0 % h, (y0 + 1) % h
        c = (
            tex[ya, xa] * (1 - tx) * (1 - ty)
            + tex[ya, xb] * tx * (1 - ty)
            + tex[yb, xa] * (1 - tx) * ty
            + tex[yb, xb] * tx * ty
        )
        out: np.ndarray = c * self.base_color[:3]
        return out


def _rgba01(c: npt.ArrayLike | None, default: tuple[float, float, float, float]) -> np.ndarray:
    if c is None:
        return np.asarray(default, np.float64)
    a = np.asarray(c, np.float64).ravel()
    if a.size == 3:
        a = np.r_[a, 255.0 if a.max() > 1 else 1.0]
    return a / 255.0 if np.asarray(c).dtype.kind in "ui" or a.max() > 1.0 else a


def _image(img: Image.Image | np.ndarray | None) -> np.ndarray | None:
    """A PIL image (or array) -> ``(h, w, 3) float32`` linear RGB, or None."""
    if img is None:
        return None
    a = np.asarray(img.convert("RGB") if hasattr(img, "convert") else img)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    a = a[:, :, :3]
    scale = 65535.0 if a.dtype == np.uint16 else 255.0 if a.dtype.kind in "ui" else 1.0
    return srgb_to_linear(a.astype(np.float64) / scale).astype(np.float32)


def material_from_trimesh(mesh: trimesh.Trimesh) -> Material | None:
    """The :class:`Material` of a ``trimesh.Trimesh`` as loaded (``process=False``), its UVs per corner of
    ``mesh.faces``; None when the mesh has no material (vertex / face colours, or nothing).

    glTF ``baseColorFactor`` is linear; OBJ ``Kd`` is taken as sRGB (as arshadow treats vertex colours).
    A texture that trimesh could not decode (no Pillow) leaves the base colour alone.
    """
    visual = getattr(mesh, "visual", None)
    mat = getattr(visual, "material", None)
    if mat is None or getattr(visual, "kind", None) not in ("texture", None):
        return None
    uv = getattr(visual, "uv", None)
    faces = np.asarray(mesh.faces, np.intp)
    corner_uv = None
    if uv is not None and len(uv) == len(mesh.vertices):
        corner_uv = np.asarray(uv, np.float32)[faces]
    if hasattr(mat, "baseColorFactor") or hasattr(mat, "baseColorTexture"):  # trimesh PBRMaterial (glTF)
        base = _rgba01(getattr(mat, "baseColorFactor", None), (1.0, 1.0, 1.0, 1.0))
        tex = _image(getattr(mat, "baseColorTexture", None))
        metallic = getattr(mat, "metallicFactor", None)
        rough = getattr(mat, "roughnessFactor", None)
        return Material(
            base_color=base,
            texture=tex,
            uv=corner_uv if tex is not None else None,
            metallic=1.0 if metallic is None else float(metallic),
            roughness=1.0 if rough is None else float(rough),
            source="gltf",
        )
    # trimesh SimpleMaterial (OBJ / MTL): Kd as sRGB
    kd = _rgba01(getattr(mat, "diffuse", None), (1.0, 1.0, 1.0, 1.0))
    base = np.r_[srgb_to_linear(kd[:3]), kd[3]]
    tex = _image(getattr(mat, "image", None))
    return Material(base_color=base, texture=tex, uv=corner_uv if tex is not None else None, source="obj")
