"""Path-traced reference scenes (Mitsuba 3): a floor, the printed marker, a probe box, an object, a light.

The truth for the realism work (the realism work): each scene is rendered once without the object (the PLATE, what
a user photographs and gives arshadow), once with it (the TRUTH), and once more with it and another seed
(a second truth: the path tracer's noise floor). Nothing here comes from arshadow's renderer: the images
are Mitsuba's, the masks come from the geometry (ray casts by Mitsuba, distances to the object's surface).

Scene (world frame = marker frame, z up, metres, CONVENTIONS.md):

- floor: z = 0, diffuse, a procedural texture (``noise`` or ``tiles``), linear reflectance;
- paper: the printed marker (its bitmap from :func:`arshadow.tracking.dictionary.marker_bits`, paper
  reflectance sRGB 235, ink sRGB 22 as :mod:`arshadow.synth` prints it) with a margin of 0.3 marker side,
  coplanar with the floor (the floor has a hole where the paper lies);
- probe: a box (``arshadow light --probe``), grey diffuse;
- object: a primitive (``box:``, ``cylinder:``, ``sphere:``, ``torus:``), diffuse, its colour;
- light: ``sun`` (a directional light, hard: ``sun_radius_deg`` 0, or a disc: a far sphere emitter) plus a
  uniform sky (constant environment), or ``point`` (an isotropic point light) plus ambient (a dimmer
  uniform environment).

Camera: an OpenCV pinhole (no distortion) with arshadow's pixel-centre convention, reproduced by Mitsuba's
``perspective`` sensor (its field of view and principal point offset) and a box pixel filter (a sensor's
pixel integration). :func:`render_scene` returns linear radiance times ``exposure`` (camera-linear units,
what the 8-bit plate's sRGB codes decode to).

Mitsuba is imported inside the functions that need it (the ``reference`` extra); everything else works
without it (the committed renders are scored with numpy only: :mod:`arshadow.bench.reference_score`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..camera.model import Intrinsics
from ..compose.composite import SRGB_TO_LINEAR
from ..errors import UsageError
from ..geometry.mesh import load_occluder
from ..synth.poses import look_at_pose
from ..tracking.dictionary import get_dictionary, marker_bits

__all__ = ["ReferenceScene", "intrinsics_of", "pose_of", "render_scene", "scene_masks", "light_spec"]

#: the Mitsuba variant: CPU, scalar (``llvm_ad_rgb`` aborts in LLVM on this machine)
VARIANT = "scalar_rgb"
#: paper and ink reflectance, sRGB codes (the values :mod:`arshadow.synth` prints with)
PAPER_CODE, INK_CODE = 235, 22
#: floor texture: texels and their period (metres)
FLOOR_TEXELS, FLOOR_PERIOD = 512, 0.512
#: contact band: ground within this distance (metres) of the object's surface
CONTACT_BAND_M = 0.015


@dataclass
class ReferenceScene:
    """One reference scene, all of it plain data (it is written to the committed JSON).

    Attributes
    ----------
    name : str
    width, height : int
        Image size, pixels.
    fov_x_deg : float
        Horizontal field of view of the pinhole (``fx = W / 2 / tan(fov / 2)``; ``fy = fx``; Mitsuba is given
        :func:`mitsuba_fov`).
    principal_offset : (2,) float
        ``(cx, cy)`` minus the image centre ``((W - 1) / 2, (H - 1) / 2)``, pixels.
    eye, target : (3,) float
        Camera centre and the point it looks at, world frame (``up`` = +z).
    marker_length : float
        The marker's printed side, metres (DICT_6X6_250, id ``marker_id``).
    probe, probe_place : str, (3,) float
        The probe (``box:WX,WY,HZ``) and where it stands.
    model, place, rotate : str, (3,) float, (3,) float
        The object, placed like ``--model`` (``--place``, ``--rotate`` degrees).
    color : (3,) float
        The object's linear RGB reflectance.
    light : str
        ``"sun"`` or ``"point"``.
    light_vec : (3,) float
        Towards the sun (need not be unit length) or the point light's position, world frame.
    direct : (3,) float
        Sun: linear RGB irradiance on a surface facing it; point: radiant intensity (per steradian).
    sky : (3,) float
        Linear RGB irradiance of the uniform environment on an open horizontal surface (``pi * L``).
    sun_radius_deg : float
        The sun's angular radius (0: a hard directional light).
    floor : str
        ``"noise"``, ``"tiles"`` or ``"plain"``; ``floor_seed`` its random seed; ``floor_tint`` (3,) linear
        multiplier.
    exposure : float
        Camera gain on radiance (camera-linear = exposure * radiance).
    spp, seed, seed2 : int
        Samples per pixel, the plate's and truth's seed, the second truth's seed.
    max_depth : int
        Path length (interreflections: the floor's bounce on the object, the object's on the floor).
    """

    name: str
    width: int = 400
    height: int = 300
    fov_x_deg: float = 55.0
    principal_offset: tuple = (3.0, -2.0)
    eye: tuple = (0.0, -0.34, 0.28)
    target: tuple = (0.0, 0.04, 0.0)
    marker_length: float = 0.08
    marker_id: int = 0
    probe: str = "box:0.04,0.04,0.08"
    probe_place: tuple = (-0.12, 0.06, 0.0)
    model: str = "box:0.045,0.065,0.07"
    place: tuple = (0.1, 0.09, 0.0)
    rotate: tuple = (0.0, 0.0, 0.0)
    color: tuple = (0.6, 0.6, 0.6)
    light: str = "sun"
    light_vec: tuple = (-0.6, -0.35, 0.65)
    direct: tuple = (3.0, 2.85, 2.6)
    sky: tuple = (1.2, 1.3, 1.5)
    sun_radius_deg: float = 0.0
    floor: str = "noise"
    floor_seed: int = 7
    floor_tint: tuple = (1.0, 1.0, 1.0)
    exposure: float = 0.0  # 0: chosen so that the lit paper records 0.75 (set_exposure)
    spp: int = 64
    seed: int = 1
    seed2: int = 2
    max_depth: int = 5
    notes: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """The scene as JSON-able plain data."""
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> ReferenceScene:
        """The inverse of :meth:`to_json` (lists become tuples)."""
        kw: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}
        return cls(**kw)


def intrinsics_of(sc: ReferenceScene) -> Intrinsics:
    """The scene's OpenCV pinhole (no distortion), arshadow's pixel-centre convention."""
    fx = sc.width / 2.0 / math.tan(math.radians(sc.fov_x_deg) / 2.0)
    cx = (sc.width - 1) / 2.0 + sc.principal_offset[0]
    cy = (sc.height - 1) / 2.0 + sc.principal_offset[1]
    return Intrinsics(fx, fx, cx, cy, sc.width, sc.height)


def mitsuba_fov(sc: ReferenceScene) -> float:
    """The ``fov`` (degrees, x axis) to give Mitsuba's ``perspective`` sensor for arshadow's ``fx``: the plain
    ``2 atan(W / 2 / fx)`` (Mitsuba spreads it over the W pixels' full width, as arshadow's pinhole does).

    Until 2026-11-28 this gave ``2 atan((W - 1) / 2 / fx)``, a "fix" for a 0.25 % scale that was an artefact of
    the camera check: its reference averaged each pixel's sub-samples in code values, not linear light, which
    shrinks the printed paper's bright area by about a quarter of a pixel. Against a linear-light reference
    (:func:`arshadow.bench.reference.plate_alignment`) the 12 plates rendered over W - 1 measured scale
    +0.0023..+0.0031 (W / (W - 1)); re-rendered with this plain fov, see docs/reference.md.
    """
    K = intrinsics_of(sc)
    return math.degrees(2.0 * math.atan(sc.width / 2.0 / K.fx))


def pose_of(sc: ReferenceScene) -> np.ndarray:
    """``cam_from_world`` (4, 4) float64 of the scene's camera (OpenCV frame)."""
    return look_at_pose(sc.eye, sc.target)


def light_spec(sc: ReferenceScene) -> str:
    """The true light as arshadow's ``--light`` takes it (``directional:X,Y,Z`` or ``point:X,Y,Z``)."""
    kind = "directional" if sc.light == "sun" else "point"
    return f"{kind}:" + ",".join(f"{v:.6g}" for v in sc.light_vec)


def paper_irradiance(sc: ReferenceScene) -> np.ndarray:
    """Direct + sky irradiance on the paper at the marker's centre, linear RGB (3,) (no occlusion)."""
    v = np.asarray(sc.light_vec, np.float64)
    if sc.light == "sun":
        cos = v[2] / np.linalg.norm(v)
        e = np.asarray(sc.direct) * max(cos, 0.0)
    else:
        d = np.linalg.norm(v)
        e = np.asarray(sc.direct) * max(v[2] / d, 0.0) / d**2
    out: np.ndarray = e + np.asarray(sc.sky)
    return out


def set_exposure(sc: ReferenceScene, paper_linear: float = 0.75) -> ReferenceScene:
    """The scene with ``exposure`` chosen so that the lit paper records ``paper_linear`` in its brightest
    channel (camera-linear), when it is 0."""
    if sc.exposure > 0:
        return sc
    rad = float(SRGB_TO_LINEAR[PAPER_CODE]) * paper_irradiance(sc).max() / math.pi
    sc.exposure = paper_linear / rad
    return sc


# ---------------------------------------------------------------------------------------------------
# textures
# ---------------------------------------------------------------------------------------------------
def floor_texture(kind: str, seed: int, tint: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> np.ndarray:
    """(FLOOR_TEXELS, FLOOR_TEXELS, 3) float32 linear RGB reflectance of the floor, periodic.

    ``noise``: a warm grey-brown with structure at every scale (like :mod:`arshadow.synth`'s floor);
    ``tiles``: 8 x 8 cm tiles with grout lines and per-tile variation; ``plain``: one neutral grey, sRGB code
    137 (reflectance 0.25).
    """
    n = FLOOR_TEXELS
    rng = np.random.default_rng(seed)
    f = np.fft.fftfreq(n)
    fr = np.sqrt(f[:, None] ** 2 + f[None, :] ** 2)
    fr[0, 0] = 1.0
    spectrum = 1.0 / fr**1.3
    spectrum[fr > 0.25] = 0.0
    common = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * spectrum))
    common = (common - common.mean()) / common.std()
    if kind == "noise":
        codes = np.array([150.0, 125.0, 95.0])[None, None, :] + 28.0 * common[:, :, None]
    elif kind == "tiles":
        t = n // 8  # 8 tiles per period: 6.4 cm each
        ii = np.arange(n)
        tile_val = rng.normal(0.0, 10.0, (8, 8))
        codes = np.array([170.0, 160.0, 145.0])[None, None, :] + tile_val[ii[:, None] // t, ii[None, :] // t, None]
        codes = codes + 8.0 * common[:, :, None]
        grout = ((ii % t) < 3)[:, None] | ((ii % t) < 3)[None, :]
        codes[grout] = (90.0, 88.0, 85.0)
    elif kind == "plain":
        codes = np.full((n, n, 3), 137.0)
    else:
        raise UsageError(f"floor must be 'noise', 'tiles' or 'plain', got {kind!r}")
    codes = np.clip(codes, 0, 255)
    lin = SRGB_TO_LINEAR[np.rint(codes).astype(np.uint8)].astype(np.float32)
    out: np.ndarray = lin * np.asarray(tint, np.float32)
    return out


def paper_texture(sc: ReferenceScene, texels_per_cell: int = 24) -> tuple[np.ndarray, float]:
    """The printed marker with its white margin: ((n, n, 3) float32 linear reflectance, half side metres).

    Row 0 is the paper's top edge (world +y), column 0 its left edge (world -x).
    """
    bits = marker_bits(get_dictionary("DICT_6X6_250"), sc.marker_id)  # (8, 8) with the black border
    c = bits.shape[0]
    img = np.where(bits, float(SRGB_TO_LINEAR[PAPER_CODE]), float(SRGB_TO_LINEAR[INK_CODE]))
    img = np.kron(img, np.ones((texels_per_cell, texels_per_cell)))
    margin_px = int(round(0.3 * c * texels_per_cell))
    img = np.pad(img, margin_px, constant_values=float(SRGB_TO_LINEAR[PAPER_CODE]))
    half = sc.marker_length / 2.0 * img.shape[0] / (c * texels_per_cell)
    return np.repeat(img[:, :, None], 3, axis=2).astype(np.float32), half


# ---------------------------------------------------------------------------------------------------
# the Mitsuba scene
# ---------------------------------------------------------------------------------------------------
def _mitsuba() -> Any:  # the mitsuba module
    """Mitsuba 3 with :data:`VARIANT` set (the ``reference`` extra)."""
    try:
        import mitsuba as mi
    except ImportError:  # pragma: no cover - the extra is missing
        raise UsageError("the path-traced reference needs Mitsuba 3: pip install -e '.[reference]'") from None
    mi.set_variant(VARIANT)
    return mi


def _mesh(
    mi: Any,
    name: str,
    verts: np.ndarray,
    faces: np.ndarray,
    uv: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    bsdf: Any = None,
    emitter: Any = None,
) -> Any:
    """A Mitsuba mesh from (n, 3) vertices, (m, 3) faces, optional (n, 2) texture coordinates."""
    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    m = mi.Mesh(
        name,
        vertex_count=len(verts),
        face_count=len(faces),
        has_vertex_normals=normals is not None,
        has_vertex_texcoords=uv is not None,
        props=props,
    )
    p = mi.traverse(m)
    p["vertex_positions"] = np.asarray(verts, np.float32).ravel()
    p["faces"] = np.asarray(faces, np.uint32).ravel()
    if uv is not None:
        p["vertex_texcoords"] = np.asarray(uv, np.float32).ravel()
    if normals is not None:
        p["vertex_normals"] = np.asarray(normals, np.float32).ravel()
    p.update()
    return m


def _quad(x0: float, y0: float, x1: float, y1: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (4, 3) and faces (2, 3) of the rectangle [x0, x1] x [y0, y1] on z = 0, facing +z."""
    v = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], np.float64)
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def _floor_parts(half_paper: float, extent: float = 3.0) -> tuple[Any, Any]:
    """The floor around the paper: four quads leaving the paper's square [-h, h]^2 open."""
    h, e = half_paper, extent
    quads = [_quad(-e, -e, e, -h), _quad(-e, h, e, e), _quad(-e, -h, -h, h), _quad(h, -h, e, h)]
    verts = np.concatenate([q[0] for q in quads])
    faces = np.concatenate([q[1] + 4 * k for k, q in enumerate(quads)])
    return verts, faces


def _object_mesh(
    spec: str, place: Sequence[float], rotate: Sequence[float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(verts (n, 3), faces (m, 3), normals (n, 3) or None): the placed primitive as arshadow loads it;
    smooth normals for the round ones (their facets stand for a smooth surface), flat for a box."""
    caster = load_occluder(spec, rotate=rotate, place=place)
    verts, faces = np.asarray(caster.vertices, np.float64), np.asarray(caster.faces)
    if spec.startswith("box:"):  # flat faces: no shared vertices, no vertex normals
        return verts[faces].reshape(-1, 3), np.arange(3 * len(faces)).reshape(-1, 3), None
    if spec.startswith("cylinder:"):
        return _cylinder_split(verts, faces)
    import trimesh

    tm = trimesh.Trimesh(verts, faces, process=False)
    return verts, faces, np.asarray(tm.vertex_normals)


def _cylinder_split(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A cylinder with its caps flat and its side smooth (the caps' faces get their own vertices)."""
    import trimesh

    tm = trimesh.Trimesh(verts, faces, process=False)
    fn = np.asarray(tm.face_normals)
    cap = np.abs(fn[:, 2]) > 0.99
    side = trimesh.Trimesh(verts, faces[~cap], process=False)
    sv, sf, sn = verts, faces[~cap], np.asarray(side.vertex_normals).copy()
    sn[:, 2] = 0.0
    sn /= np.maximum(np.linalg.norm(sn, axis=1, keepdims=True), 1e-12)
    cv = verts[faces[cap]].reshape(-1, 3)
    cn = np.repeat(fn[cap], 3, axis=0)
    cf = np.arange(len(cv)).reshape(-1, 3) + len(sv)
    return np.concatenate([sv, cv]), np.concatenate([sf, cf]), np.concatenate([sn, cn])


def _diffuse(mi: Any, rgb: Sequence[float]) -> Any:
    return mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": [float(v) for v in rgb]}})


def _textured(mi: Any, tex: np.ndarray) -> Any:
    return mi.load_dict(
        {
            "type": "diffuse",
            "reflectance": {
                "type": "bitmap",
                "bitmap": mi.Bitmap(np.ascontiguousarray(tex, np.float32)),
                "raw": True,
                "filter_type": "bilinear",
                "wrap_mode": "repeat",
            },
        }
    )


def build_scene(sc: ReferenceScene, *, with_object: bool, mode: str = "photo") -> Any:
    """The Mitsuba scene (loaded).

    ``mode``: ``"photo"`` the lit scene; ``"object"`` / ``"ground"`` a coverage scene where only the object
    / only the floor and paper emit (radiance 1) and nothing is lit: rendered with ``max_depth`` 1 it gives
    each pixel's covered fraction (the masks, from the geometry).
    """
    mi = _mitsuba()
    black = _diffuse(mi, (0.0, 0.0, 0.0))
    glow = {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    K = intrinsics_of(sc)
    pose = pose_of(sc)
    world_from_cv = np.linalg.inv(pose)
    to_world = world_from_cv @ np.diag([-1.0, -1.0, 1.0, 1.0])  # Mitsuba's camera: x left, y up, z forward
    # principal point: (cx + 0.5) in corner coordinates, as a fraction of the film from its centre
    # (Mitsuba's offsets move the principal point the other way: checked against the detected corners)
    off_x = -(K.cx + 0.5 - sc.width / 2.0) / sc.width
    off_y = -(K.cy + 0.5 - sc.height / 2.0) / sc.height
    d: dict = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": sc.max_depth if mode == "photo" else 1},
        "sensor": {
            "type": "perspective",
            "fov": mitsuba_fov(sc),
            "fov_axis": "x",
            "principal_point_offset_x": off_x,
            "principal_point_offset_y": off_y,
            "near_clip": 0.01,
            "far_clip": 1000.0,
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "film": {
                "type": "hdrfilm",
                "width": sc.width,
                "height": sc.height,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
            # multi-jittered: 9x less noise than independent samples at equal spp (measured at 16 spp)
            "sampler": {"type": "multijitter", "sample_count": sc.spp},
        },
    }
    paper, half = paper_texture(sc)
    pv, pf = _quad(-half, -half, half, half)
    puv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float64)  # checked: the marker is detected, id 0
    fv, ff = _floor_parts(half)
    fuv = fv[:, :2] / FLOOR_PERIOD
    ground_emit = mode == "ground"
    d["paper"] = _mesh(
        mi,
        "paper",
        pv,
        pf,
        puv,
        bsdf=black if mode != "photo" else _textured(mi, paper),
        emitter=mi.load_dict(glow) if ground_emit else None,
    )
    d["floor"] = _mesh(
        mi,
        "floor",
        fv,
        ff,
        fuv,
        bsdf=black if mode != "photo" else _textured(mi, floor_texture(sc.floor, sc.floor_seed, sc.floor_tint)),
        emitter=mi.load_dict(glow) if ground_emit else None,
    )
    caster = load_occluder(sc.probe, place=sc.probe_place)
    bv = np.asarray(caster.vertices)[np.asarray(caster.faces)].reshape(-1, 3)
    d["probe"] = _mesh(
        mi,
        "probe",
        bv,
        np.arange(len(bv)).reshape(-1, 3),
        bsdf=_diffuse(mi, (0.5, 0.5, 0.5)) if mode == "photo" else black,
    )
    if with_object:
        ov, of, on = _object_mesh(sc.model, sc.place, sc.rotate)
        d["object"] = _mesh(
            mi,
            "object",
            ov,
            of,
            normals=on,
            bsdf=_diffuse(mi, sc.color) if mode == "photo" else black,
            emitter=mi.load_dict(glow) if mode == "object" else None,
        )
    if mode == "photo":
        d.update(_lights(sc))
    return mi.load_dict(d)


def _lights(sc: ReferenceScene) -> dict:
    """Mitsuba emitters of the scene's light: the direct light and the uniform environment."""
    sky = [float(v) / math.pi for v in sc.sky]  # radiance: irradiance pi * L on an open horizontal surface
    out: dict = {"sky": {"type": "constant", "radiance": {"type": "rgb", "value": sky}}}
    v = np.asarray(sc.light_vec, np.float64)
    if sc.light == "point":
        out["lamp"] = {"type": "point", "position": v.tolist(), "intensity": {"type": "rgb", "value": list(sc.direct)}}
    elif sc.sun_radius_deg <= 0:
        out["sun"] = {
            "type": "directional",
            "direction": (-v / np.linalg.norm(v)).tolist(),
            "irradiance": {"type": "rgb", "value": list(sc.direct)},
        }
    else:  # a disc: a far sphere of angular radius a, radiance E / (pi sin^2 a) gives irradiance E facing it
        a = math.radians(sc.sun_radius_deg)
        dist = 50.0
        centre = v / np.linalg.norm(v) * dist
        rad = [float(e) / (math.pi * math.sin(a) ** 2) for e in sc.direct]
        out["sun"] = {
            "type": "sphere",
            "center": centre.tolist(),
            "radius": dist * math.sin(a),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": rad}},
        }
    return out


def _render(scene: Any, spp: int, seed: int) -> np.ndarray:
    mi = _mitsuba()
    img = mi.render(scene, spp=spp, seed=seed)
    return np.asarray(img, np.float64)[:, :, :3]


def render_scene(sc: ReferenceScene) -> dict:
    """Render the plate, the truth and the second truth, camera-linear RGB (H, W, 3) float64, and time them.

    Returns ``{"plate", "truth", "truth2", "seconds": {name: s}}``. The plate and the truth share the seed
    (their noise is correlated where the object changes nothing); ``truth2`` has ``seed2``.
    """
    set_exposure(sc)
    out: dict = {"seconds": {}}
    for name, with_obj, seed in (("plate", False, sc.seed), ("truth", True, sc.seed), ("truth2", True, sc.seed2)):
        t0 = time.perf_counter()
        out[name] = _render(build_scene(sc, with_object=with_obj), sc.spp, seed) * sc.exposure
        out["seconds"][name] = time.perf_counter() - t0
    return out


def coverage(sc: ReferenceScene, what: str, spp: int = 16) -> np.ndarray:
    """(H, W) float64: the fraction of each pixel that sees ``what`` (``"object"`` or ``"ground"``: the
    floor and the paper), from a ray-cast of the geometry (with the object in the scene)."""
    img = _render(build_scene(sc, with_object=True, mode=what), spp, 0)
    out: np.ndarray = img.mean(axis=2)
    return out


def contact_band(sc: ReferenceScene, ground: np.ndarray, dist_m: float = CONTACT_BAND_M) -> np.ndarray:
    """(H, W) bool: ground pixels whose ground point (at the pixel centre) lies within ``dist_m`` of the
    object's surface (3D distance), from the geometry: the pinhole ray's point on z = 0 against a dense
    sampling of the placed object's surface (spacing well under a millimetre)."""
    import trimesh
    from scipy.spatial import cKDTree

    K = intrinsics_of(sc)
    pose = pose_of(sc)
    caster = load_occluder(sc.model, rotate=sc.rotate, place=sc.place)
    tm = trimesh.Trimesh(np.asarray(caster.vertices), np.asarray(caster.faces), process=False)
    n = int(min(4e5, max(2e4, tm.area / (0.4e-3) ** 2)))
    pts, _ = trimesh.sample.sample_surface(tm, n, seed=0)
    pts = np.concatenate([pts, np.asarray(tm.vertices)])
    hinv = np.linalg.inv(K.K @ np.column_stack([pose[:3, 0], pose[:3, 1], pose[:3, 3]]))
    vv, uu = np.mgrid[0 : sc.height, 0 : sc.width]
    ph = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)]).astype(np.float64)
    g = hinv @ ph
    ok = g[2] > 1e-12
    xy = (g[:2] / np.where(ok, g[2], 1.0)).T
    lo, hi = pts.min(axis=0)[:2] - dist_m, pts.max(axis=0)[:2] + dist_m
    near = ok & np.all((xy >= lo) & (xy <= hi), axis=1) & ground.ravel()
    band = np.zeros(uu.size, bool)
    if near.any():
        dd, _ = cKDTree(pts).query(np.column_stack([xy[near], np.zeros(near.sum())]))
        band[np.flatnonzero(near)] = dd <= dist_m
    return band.reshape(sc.height, sc.width)


def scene_masks(sc: ReferenceScene) -> dict:
    """The scoring masks, from the geometry: ``object`` (H, W) bool (object coverage >= 0.5), ``ground``
    (floor or paper coverage >= 0.5, not object), ``contact`` (:func:`contact_band` within ``ground``)."""
    obj = coverage(sc, "object") >= 0.5
    ground = (coverage(sc, "ground") >= 0.5) & ~obj
    return {"object": obj, "ground": ground, "contact": contact_band(sc, ground)}
