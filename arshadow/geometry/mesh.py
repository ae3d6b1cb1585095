"""Loading the occluder: mesh files and primitives, their up axis, and their placement in the world frame.

:func:`load_occluder` reads a mesh file (anything trimesh reads) or builds a primitive, turns a Y-up file
Z-up (``up``: glTF is Y-up by specification, so ``.glb`` / ``.gltf`` default to ``"y"``), applies scale,
rotation and placement, optionally stands it on the ground (``drop_to_ground``), and returns the
:class:`~arshadow.geometry.caster.ShadowCaster` (re-exported here with :func:`plane_side` and
:func:`connected_labels`, where they were defined before the split).
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..errors import MeshError
from .caster import ShadowCaster, connected_labels, plane_side
from .material import Material, material_from_trimesh

if TYPE_CHECKING:  # annotations only: trimesh is imported where a mesh is built or read
    import trimesh

__all__ = [
    "PRIMITIVES",
    "UP_AXES",
    "ShadowCaster",
    "connected_labels",
    "default_up",
    "load_occluder",
    "plane_side",
    "primitive",
    "rotation_xyz_deg",
    "up_rotation",
]

#: primitive names and their parameter names (CONVENTIONS.md "Files / Meshes")
PRIMITIVES = {"box": ("WX", "WY", "HZ"), "cylinder": ("R", "H"), "sphere": ("R",), "torus": ("R", "r")}


def rotation_xyz_deg(angles: npt.ArrayLike) -> np.ndarray:
    """(3, 3) rotation for XYZ angles in degrees: about x first, then y, then z (fixed axes),
    i.e. ``Rz @ Ry @ Rx``."""
    rx, ry, rz = np.radians(np.asarray(angles, np.float64).reshape(3))
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    rot: np.ndarray = mz @ my @ mx
    return rot


_PRIM_RE = re.compile(r"^\s*(box|cylinder|sphere|torus)\s*:\s*(.*)$", re.IGNORECASE)


def primitive(spec: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(n, 3)`` and faces ``(m, 3)`` of a primitive spec standing on the ground (z = 0),
    centred on the origin: ``box:WX,WY,HZ``, ``cylinder:R,H`` (64 sides), ``sphere:R`` (icosphere,
    1280 faces), ``torus:R,r`` (lying flat, 64 x 32 sections).

    Raises
    ------
    MeshError
        Unknown primitive, wrong number of parameters, non-positive or non-finite sizes.
    """
    import trimesh

    m = _PRIM_RE.match(spec)
    if not m:
        raise MeshError(
            f"{spec!r} is not a primitive spec ({', '.join(k + ':' + ','.join(v) for k, v in PRIMITIVES.items())})"
        )
    kind = m.group(1).lower()
    names = PRIMITIVES[kind]
    try:
        vals = [float(x) for x in m.group(2).split(",")]
    except ValueError:
        raise MeshError(f"{spec!r}: parameters must be numbers ({kind}:{','.join(names)})") from None
    if len(vals) != len(names):
        raise MeshError(f"{spec!r}: {kind} takes {len(names)} parameter(s) {','.join(names)}, got {len(vals)}")
    if not all(np.isfinite(x) and x > 0 for x in vals):
        raise MeshError(f"{spec!r}: sizes must be positive finite numbers")
    if kind == "box":
        t = trimesh.creation.box(extents=vals)
        lift = vals[2] / 2
    elif kind == "cylinder":
        t = trimesh.creation.cylinder(radius=vals[0], height=vals[1], sections=64)
        lift = vals[1] / 2
    elif kind == "sphere":
        t = trimesh.creation.icosphere(subdivisions=3, radius=vals[0])
        lift = vals[0]
    else:
        if vals[1] >= vals[0]:
            raise MeshError(f"{spec!r}: torus tube radius r must be smaller than R")
        t = trimesh.creation.torus(major_radius=vals[0], minor_radius=vals[1], major_sections=64, minor_sections=32)
        lift = vals[1]
    v = np.asarray(t.vertices, np.float64).copy()
    v[:, 2] += lift
    v[:, 2] -= v[:, 2].min()  # exactly on the ground
    return v, np.asarray(t.faces, np.intp)


def _parse_color(color: str | npt.ArrayLike | None) -> np.ndarray | None:
    if color is None:
        return None
    if isinstance(color, str):
        s = color.strip().lstrip("#")
        if re.fullmatch(r"[0-9a-fA-F]{6}([0-9a-fA-F]{2})?", s):
            return np.array([int(s[i : i + 2], 16) for i in range(0, len(s), 2)], np.float64) / 255.0
        try:
            c = np.array([float(x) for x in s.split(",")])
        except ValueError:
            raise MeshError(f"color {color!r} is not '#rrggbb' or 'r,g,b[,a]' in 0..1") from None
    else:
        c = np.asarray(color, np.float64).ravel()
    if c.size not in (3, 4) or not np.all(np.isfinite(c)) or c.min() < 0 or c.max() > 1:
        raise MeshError(f"color {color!r} must be 3 or 4 numbers in 0..1")
    return c


#: text mesh formats that trimesh decodes itself (non-UTF-8 text needs its optional charset_normalizer)
_TEXT_FORMATS = (".obj", ".off")
#: largest coordinate accepted (metres): the GPU gets float32 vertices, and a mesh bigger than this is in
#: the wrong units anyway
MAX_COORDINATE = 1e6


def _load_mesh_file(p: Path) -> trimesh.Geometry:
    """``trimesh.load`` of a file; text formats that are not UTF-8 (a Latin-1 comment) are read as Latin-1
    (every byte is a valid Latin-1 character) instead of failing on trimesh's optional encoding detector."""
    import io

    import trimesh

    if p.suffix.lower() in _TEXT_FORMATS:
        data = p.read_bytes()
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("latin-1")
            resolver = trimesh.resolvers.FilePathResolver(str(p))
            return trimesh.load(
                io.BytesIO(text.encode("utf-8")),
                file_type=p.suffix.lower()[1:],
                force="mesh",
                process=False,
                resolver=resolver,
            )
    return trimesh.load(str(p), force="mesh", process=False)


#: up axes :func:`load_occluder` takes: the file's axis that points up (away from the ground)
UP_AXES = ("z", "y")
#: mesh formats whose specification says +Y is up (glTF 2.0, section 3.4: "+Y is up")
Y_UP_FORMATS = (".glb", ".gltf")


def default_up(spec_or_path: str | Path) -> str:
    """The up axis a mesh file is read with when none is given: ``"y"`` for glTF (``.glb`` / ``.gltf``: Y-up by
    specification), else ``"z"`` (arshadow's world frame; OBJ, PLY, STL and OFF say nothing).

    >>> default_up("chair.glb"), default_up("knot.ply"), default_up("box:1,1,1")
    ('y', 'z', 'z')
    """
    return "y" if Path(str(spec_or_path)).suffix.lower() in Y_UP_FORMATS else "z"


def up_rotation(up: str) -> np.ndarray:
    """(3, 3) rotation taking a file's up axis to world +z: identity for ``"z"``; for ``"y"`` +90 degrees
    about x, so file +y -> world +z and file +z (glTF's front) -> world -y (towards the camera of a marker
    seen from its bottom edge).

    >>> (up_rotation("y") @ [0, 1, 0]).round(12).tolist()
    [0.0, 0.0, 1.0]
    """
    if up not in UP_AXES:
        raise MeshError(f"--up {up!r}: choose {' or '.join(UP_AXES)} (the axis of the mesh file that points up)")
    return np.eye(3) if up == "z" else rotation_xyz_deg((90.0, 0.0, 0.0))


def load_occluder(
    spec_or_path: str | Path,
    scale: npt.ArrayLike = 1.0,
    rotate: npt.ArrayLike = (0.0, 0.0, 0.0),
    place: npt.ArrayLike = (0.0, 0.0, 0.0),
    color: str | npt.ArrayLike | None = None,
    *,
    up: str | None = None,
    drop_to_ground: bool = False,
) -> ShadowCaster:
    """Load a mesh file (anything trimesh reads) or build a primitive, and place it in the world frame.

    Parameters
    ----------
    spec_or_path : str or Path
        ``box:WX,WY,HZ``, ``cylinder:R,H``, ``sphere:R``, ``torus:R,r`` (standing on the ground, centred
        on the origin) or a mesh file whose coordinates are metres in the world frame.
    scale : float or (3,) float
        Applied first.
    rotate : (3,) float
        Degrees about x, then y, then z (fixed axes), applied second.
    place : (3,) float
        Translation, metres, applied last.
    color : str or (3|4,) float, optional
        One colour for the whole mesh (``'#rrggbb'`` or floats in 0..1); overrides the file's colours.
    up : {"z", "y"}, optional
        The file's up axis, turned to world +z before anything else (:func:`up_rotation`); default
        :func:`default_up` (``"y"`` for glTF). Primitives are built Z-up: ``"y"`` is refused for them.
    drop_to_ground : bool
        After scale and rotation, move the mesh along z so that its lowest point is on the ground (z = 0);
        ``place`` is added after that.

    Returns
    -------
    ShadowCaster

    Raises
    ------
    MeshError
        Missing / unreadable file, bad primitive spec, no triangles, NaN coordinates, bad transform.

    Examples
    --------
    >>> c = load_occluder("box:0.1,0.2,0.3", place=(1, 0, 0))
    >>> c.bounds.round(6).tolist()
    [[0.95, -0.1, 0.0], [1.05, 0.1, 0.3]]
    >>> load_occluder("box:0.1,0.2,0.3", rotate=(90, 0, 0), drop_to_ground=True).bounds.round(6).tolist()
    [[-0.05, -0.3, 0.0], [0.05, 0.0, 0.2]]
    """
    vertex_colors: np.ndarray | None = None
    face_colors: np.ndarray | None = None
    material: Material | None = None
    spec = str(spec_or_path)
    if up is not None:
        up = str(up).strip().lower()
        up_rotation(up)  # an unknown axis: MeshError before the file is read
    if _PRIM_RE.match(spec) and not Path(spec).exists():
        if up not in (None, "z"):
            raise MeshError(
                f"--up {up!r}: primitives ({spec.strip()}) are built standing on the ground, z up; "
                "--up is for mesh files"
            )
        v, f = primitive(spec)
        name = spec.strip()
    else:
        p = Path(spec)
        name = p.name
        if not p.is_file():
            raise MeshError(f"{p}: no such mesh file (and not a primitive spec box:/cylinder:/sphere:/torus:)")
        import trimesh

        try:
            mesh = _load_mesh_file(p)
        except Exception as exc:  # trimesh raises many types for corrupt files
            raise MeshError(f"{p}: cannot read mesh ({type(exc).__name__}: {exc})") from None
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            raise MeshError(f"{p}: no triangles in the file")
        v = np.asarray(mesh.vertices, np.float64)
        f = np.asarray(mesh.faces, np.intp)
        try:
            material = material_from_trimesh(mesh)
        except Exception as exc:  # a material is a nicety: a file with a broken one still casts its shadow
            warnings.warn(f"{p}: material not read ({type(exc).__name__}: {exc}); using its colours", stacklevel=2)
            material = None
        try:
            visual = mesh.visual  # ColorVisuals: kind "vertex", "face" or None; TextureVisuals: kind "texture"
            if isinstance(visual, trimesh.visual.ColorVisuals):
                kind = visual.kind
                if kind == "vertex":
                    vertex_colors = np.asarray(visual.vertex_colors)
                elif kind == "face":
                    face_colors = np.asarray(visual.face_colors)
            elif isinstance(visual, trimesh.visual.TextureVisuals):
                vertex_colors = np.asarray(visual.to_color().vertex_colors)
        except Exception:  # colours are a nicety: a file with broken colours still casts its shadow
            vertex_colors = face_colors = None
        if vertex_colors is not None and vertex_colors.shape[0] != len(v):
            vertex_colors = None
        if face_colors is not None and face_colors.shape[0] != len(f):
            face_colors = None
    try:
        s = np.broadcast_to(np.asarray(scale, np.float64), (3,))
        rot = rotation_xyz_deg(rotate)
        t = np.asarray(place, np.float64).reshape(3)
    except (ValueError, TypeError):
        raise MeshError(f"{name}: scale must be 1 or 3 numbers, rotate and place 3 numbers") from None
    if not (np.all(np.isfinite(s)) and np.all(s != 0) and np.all(np.isfinite(rot)) and np.all(np.isfinite(t))):
        raise MeshError(f"{name}: scale must be non-zero and finite, rotate and place finite")
    v = np.asarray(v, np.float64)
    axis = default_up(spec) if up is None else up
    if axis != "z":  # the file's up axis to world +z, before anything else
        v = v @ up_rotation(axis).T
    v = (v * s) @ rot.T
    if drop_to_ground and np.all(np.isfinite(v)):
        v[:, 2] -= v[:, 2].min()
    v = v + t
    big = float(np.max(np.abs(v))) if v.size and np.all(np.isfinite(v)) else 0.0
    if big > MAX_COORDINATE:
        raise MeshError(
            f"{name}: coordinates up to {big:.3g} m (more than {MAX_COORDINATE:.0e} m): wrong units? "
            "(mesh coordinates are metres; see --scale)"
        )
    mirrored = bool(np.prod(np.sign(s)) < 0)
    if mirrored:  # a mirroring scale flips the winding: keep normals outward
        f = f[:, ::-1]
    c = _parse_color(color)
    if c is not None:
        vertex_colors, face_colors, material = np.broadcast_to(c, (len(v), c.size)), None, None
    caster = ShadowCaster(v, f, vertex_colors=vertex_colors, face_colors=face_colors, name=name)
    if material is not None:
        caster.material = material.select_faces(caster.source_faces, flip_winding=mirrored)
    return caster
