"""The declarative scene: what to put into the photos, as frozen, picklable data.

A :class:`SceneSpec` says *what* (camera, marker or board, model and its placement, lights, render
options) with paths and spec strings, not loaded objects, so it pickles to a worker process and compares
equal when two sources describe the same scene. :meth:`SceneSpec.build` loads it into a :class:`Scene`
(calibration, occluder, parsed lights, tracker arguments); a :class:`arshadow.frame.session.Session` does that
once and renders photos with it.

(About 640 lines, just over the project's ~600: the spec classes and their one builder, whose key table and
checks are read together; the render options are already apart, :mod:`arshadow.scene.options`.)

One function builds specs from every source, :func:`scene_from_dict`; the command line
(:func:`scene_from_args`), job files (:func:`load_scene`: YAML or JSON) and the demo's ``scenes.json``
map onto its keys, which are the ``arshadow render`` option names with ``_`` for ``-``::

    calib: calib/cam.yml             # or an Intrinsics (Python)
    marker_length: 0.05              # or  board: boards/grid.yml
    dictionary: DICT_6X6_250
    marker_id: 3
    model: box:0.04,0.04,0.06        # or a mesh file
    scale: 1.0
    rotate: [0, 0, 30]
    place: [0.1, 0, 0]
    up: z                            # the mesh file's up axis (default: y for glTF, z otherwise)
    drop_to_ground: false            # stand the model on the ground (after scale and rotate)
    color: 200,80,40                 # 8-bit sRGB or "#c85028"
    lights: [point:0.1,0.1,0.4, "sun:52.2,0.1,2024-06-21T15:00+01:00@0.5"]
    soft_samples: 1
    silhouette: adjacency
    shadow_method: volume
    opacity: 0.7
    shadow_color: 0,0,0
    aa: 0
    outline_aa: auto                 # the object's outline anti-aliased without MSAA (aa 0): photos, realistic videos
    ground_size: null
    no_object: false
    time_lapse: 2026-06-21T08:00+02:00,600   # video: the suns follow the frame times (START[,SPEED])
    recompute_deg: 0.1

Relative paths in a job file are relative to the file's folder (``base_dir``).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import UsageError
from ..geometry.ground import ground_warnings, parse_ground
from .options import RenderOptions
from .timelapse import TimeLapse, parse_time_lapse, time_lapse_spec

if TYPE_CHECKING:  # annotations only (the session imports this module; these load on build)
    from ..camera.model import Intrinsics
    from ..geometry.mesh import ShadowCaster
    from ..lights.spec import Light, SunLightTrack

log = logging.getLogger(__name__)

__all__ = [
    "RenderOptions",
    "TrackerSpec",
    "ModelSpec",
    "TimeLapse",
    "SceneSpec",
    "Scene",
    "scene_from_dict",
    "parse_time_lapse",
    "scene_from_args",
    "load_scene",
    "parse_triple",
    "SCENE_KEYS",
]


@dataclass(frozen=True)
class TrackerSpec:
    """The printed target: one marker (``marker_length``) or a board file.

    Attributes
    ----------
    dictionary : str or None
        ArUco dictionary name or custom dictionary file (single-marker mode; None:
        :data:`arshadow.tracking.dictionary.DEFAULT_DICTIONARY`). A board names its own: a different one is an error.
    marker_length : float or None
        Marker side, metres.
    marker_id : int or None
        The reference marker (default: the lowest id found).
    board : str or None
        Board file (GridBoard or ChArUco) instead of one marker.
    refine : str or None
        Corner refinement; ``"default"``: the tracker's own default (:data:`arshadow.tracking.detect.DEFAULT_REFINE`).
    """

    dictionary: str | None = None
    marker_length: float | None = None
    marker_id: int | None = None
    board: str | None = None
    refine: str | None = "default"
    #: detect markers printed white on black (None: the board file's ``inverted``, else no)
    inverted: bool | None = None

    def kwargs(self) -> dict:
        """Keyword arguments of :class:`arshadow.tracking.tracker.MarkerTracker` (the board file loaded).

        Raises
        ------
        UsageError
            Neither a marker length nor a board; an unknown dictionary.
        """
        from ..tracking.board import load_board
        from ..tracking.dictionary import DEFAULT_DICTIONARY, get_dictionary

        if self.board is None and self.marker_length is None:
            raise UsageError("give --marker-length M (metres) for a single marker, or --board B")
        kw: dict[str, Any] = {"dictionary": self.dictionary, "marker_id": self.marker_id}
        if self.board is None:
            get_dictionary(self.dictionary or DEFAULT_DICTIONARY)  # unknown: a usage error, not per photo
            kw["marker_length"] = self.marker_length
        else:
            kw["board"] = load_board(self.board)
        if self.refine != "default":
            kw["refine"] = self.refine
        if self.inverted is not None:
            kw["inverted"] = bool(self.inverted)
        return kw


@dataclass(frozen=True)
class ModelSpec:
    """The virtual object: a mesh file or a primitive, then scale, rotate (degrees, XYZ), place (metres).

    ``color`` is 8-bit sRGB ``"R,G,B"`` (None: the mesh's own colours). ``up``: the mesh file's up axis
    (None: :func:`arshadow.geometry.mesh.default_up`, Y for glTF); ``drop_to_ground``: stand the model on
    the ground after scale and rotate.
    """

    source: str
    scale: float = 1.0
    rotate: tuple = (0.0, 0.0, 0.0)
    place: tuple = (0.0, 0.0, 0.0)
    color: str | None = None
    up: str | None = None
    drop_to_ground: bool = False

    def maybe_y_up(self) -> bool:
        """A mesh file read Z-up because no ``up`` was given (not glTF, not a primitive), not rotated: it
        may be a Y-up file (the ground warning then suggests ``--up y``)."""
        from ..geometry.mesh import default_up

        primitive = ":" in self.source and not Path(self.source).exists()
        return self.up is None and not primitive and default_up(self.source) == "z" and not any(self.rotate)

    def build(self) -> ShadowCaster:
        """The :class:`arshadow.geometry.mesh.ShadowCaster` (MeshError / UsageError on a bad file or colour)."""
        from ..compose.composite import parse_rgb
        from ..geometry.mesh import load_occluder

        color = None
        if self.color:
            parse_rgb(self.color, "--color")  # validates: three numbers 0..255
            color = tuple(float(v) / 255.0 for v in self.color.split(","))  # sRGB 0..1, as the loader takes
        return load_occluder(
            self.source,
            scale=self.scale,
            rotate=self.rotate,
            place=self.place,
            color=color,
            up=self.up,
            drop_to_ground=self.drop_to_ground,
        )


@dataclass(frozen=True)
class SceneSpec:
    """Everything a session needs, as picklable data (paths and spec strings).

    Attributes
    ----------
    camera : str or arshadow.camera.Intrinsics
        Calibration file, or the intrinsics themselves.
    tracker : TrackerSpec
    model : ModelSpec
    lights : tuple of str or arshadow.lights.spec.Light
        Light specs (CONVENTIONS.md: ``point:X,Y,Z``, ``directional:X,Y,Z``, ``sun:LAT,LON,TIME[,NORTH]``,
        optional ``@W``) or parsed lights.
    options : RenderOptions
    time_lapse : TimeLapse or None
        Sun lights follow the frame times (video).
    """

    camera: str | Path | Intrinsics
    tracker: TrackerSpec
    model: ModelSpec
    lights: tuple
    options: RenderOptions = field(default_factory=RenderOptions)
    time_lapse: TimeLapse | None = None

    def build(self, lights: Iterable[Light] | None = None) -> Scene:
        """Load the files and parse the specs, in the order the command line reports problems.

        Parameters
        ----------
        lights : sequence of Light, optional
            Use these instead of ``self.lights`` (e.g. the static lights of a time-lapse).

        Raises
        ------
        ArshadowError
            CalibrationError, UsageError, MeshError, LightError: the first problem found.
        """
        from ..camera.model import Intrinsics
        from ..lights.spec import parse_light

        intr = self.camera if isinstance(self.camera, Intrinsics) else Intrinsics.from_file(self.camera)
        from ..tracking.tracker import MarkerTracker
        from .sanity import check_scene, paper_warnings

        tracker = self.tracker.kwargs()
        board = MarkerTracker(intr, **tracker).board  # a dictionary conflicting with the board: a usage error
        for msg in board.unit_warnings() if board is not None else []:  # a board file in millimetres
            log.warning(msg)
        caster = self.model.build()
        for msg in ground_warnings(self.options.ground):
            log.warning(msg)
        static: list[Light] | None = None
        tracks: list[SunLightTrack] = []
        time_lapse: tuple[datetime, float] | None = None
        if lights is None and self.time_lapse is not None:
            static, tracks, lights = self.time_lapse.lights(self.lights)
            time_lapse = self.time_lapse.when()
        elif lights is None:
            lights = [parse_light(s) if isinstance(s, str) else s for s in self.lights]
        opts = self.options.check()
        for msg in paper_warnings(opts.paper_albedo):
            log.warning(msg)
        light_list = list(lights)
        for msg in check_scene(
            caster,
            light_list,
            soft_samples=opts.soft_samples,  # LightError: exit 2, once
            marker_length=tracker.get("marker_length"),
            shadow_method=opts.shadow_method,
            maybe_y_up=self.model.maybe_y_up(),
        ):
            log.warning(msg)
        _check_silhouette_name(opts.silhouette)
        return Scene(intr, caster, light_list, opts, tracker, static, tracks, time_lapse)

    def replace(self, **changes: Any) -> SceneSpec:
        """A copy with some fields changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)


@dataclass
class Scene:
    """A loaded :class:`SceneSpec` (not meant to be pickled: it holds the mesh and the parsed lights).

    Attributes
    ----------
    intrinsics : arshadow.camera.Intrinsics
    caster : arshadow.geometry.mesh.ShadowCaster
    lights : list of arshadow.lights.spec.Light
    options : RenderOptions
    tracker : dict
        Keyword arguments of :class:`arshadow.tracking.tracker.MarkerTracker`.
    static_lights : list of Light or None
        With a time-lapse: the lights that do not move.
    sun_tracks : list of arshadow.lights.spec.SunLightTrack
        With a time-lapse: the suns following the frame times (``lights`` has them at the start).
    time_lapse : (datetime, float) or None
        ``(start, speed)`` of the time-lapse.
    """

    intrinsics: Intrinsics
    caster: ShadowCaster
    lights: list[Light]
    options: RenderOptions
    tracker: dict[str, Any]
    static_lights: list[Light] | None = None
    sun_tracks: list[SunLightTrack] = field(default_factory=list)
    time_lapse: tuple[datetime, float] | None = None


def _check_silhouette_name(name: str) -> None:
    from ..geometry.silhouette import METHODS

    if name not in METHODS:
        raise UsageError(f"--silhouette {name!r}: choose one of {', '.join(METHODS)}")


#: the keys :func:`scene_from_dict` takes (``light`` is accepted for ``lights``)
SCENE_KEYS = (
    "calib",
    "marker_length",
    "board",
    "dictionary",
    "marker_id",
    "refine",
    "inverted",
    "model",
    "scale",
    "rotate",
    "place",
    "color",
    "up",
    "drop_to_ground",
    "lights",
    "soft_samples",
    "silhouette",
    "shadow_method",
    "opacity",
    "shadow_color",
    "aa",
    "outline_aa",
    "ground_size",
    "no_object",
    "roi",
    "truncate",
    "fast_detect",
    "plan",
    "compose",
    "shadowmap_size",
    "track_roi",
    "ambient_occlusion",
    "camera_effects",
    "motion_blur",
    "shutter",
    "paper_albedo",
    "light_from",
    "no_exposure",
    "ground",
    "time_lapse",
    "recompute_deg",
)


def parse_triple(v: Any, key: str) -> tuple[float, float, float]:
    """Three finite numbers from ``"X,Y,Z"`` or a sequence: the one X,Y,Z parser (``--place``, ``--rotate``,
    job files).

    >>> parse_triple("0.1, 0, -2", "place")
    (0.1, 0.0, -2.0)

    Raises
    ------
    UsageError
        Naming ``key``: not three numbers, or one not finite.
    """
    if isinstance(v, str):
        v = v.split(",")
    try:
        t = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise UsageError(f"{key} {v!r}: expected three numbers") from None
    if len(t) != 3 or not all(math.isfinite(x) for x in t):
        raise UsageError(f"{key} {v!r}: expected three finite numbers")
    return t


def _value(d: Mapping[str, Any], key: str, conv: type, default: Any = None) -> Any:
    """``conv(d[key])`` (``default`` when absent or None); a value of the wrong type is a UsageError naming
    the key. ``bool`` takes only true/false (``bool("no")`` would be True), ``int`` only whole numbers."""
    v = d.get(key)
    if v is None:
        return default
    what = {bool: "true or false", int: "a whole number", float: "a number", str: "a text"}[conv]
    ok = (
        isinstance(v, bool)
        if conv is bool
        else isinstance(v, str)
        if conv is str
        else not isinstance(v, bool) and isinstance(v, (int, float, str))
    )
    try:
        out = conv(v) if ok else None
        if conv is int and (isinstance(v, float) and not float(v).is_integer()):
            out = None
    except (TypeError, ValueError, OverflowError):
        out = None
    if out is None:
        raise UsageError(f"{key} {v!r}: expected {what}")
    return out


def _rgb_text(v: Any, key: str = "color") -> str | None:
    """A colour as ``"R,G,B"`` text (0..255); ``"#rrggbb"`` converted, so equal colours give equal specs."""
    if v is None or (isinstance(v, str) and not v.strip()):
        return None
    if isinstance(v, str) and not v.strip().startswith("#"):
        return v  # checked when the scene is built
    from ..compose.composite import rgb8

    return ",".join(f"{x:g}" for x in rgb8(v, f"--{key}"))


def _path(v: Any, base_dir: str | Path | None) -> Any:
    if v is None or not isinstance(v, (str, Path)):
        return v
    p = Path(v)
    if base_dir is not None and not p.is_absolute():
        p = Path(base_dir) / p
    return str(p)


def _apply_estimate(d: dict, base_dir: str | Path | None) -> dict:
    """``light_from``: the estimate's light (unless ``lights`` are given), its shadow colour (opacity 1) and
    the marker paper's exposure on the object's colour (``occluder_color``)."""
    from ..estimate.record import LightEstimate, load_estimate, scene_overrides, shading_gain

    d = dict(d)
    est = d.pop("light_from")  # a file, or the estimate itself (render/video/batch --probe)
    est = est if isinstance(est, LightEstimate) else load_estimate(_path(est, base_dir))
    place = parse_triple(d.get("place", (0, 0, 0)), "place")  # a point light's shadow ratio is the one there
    o = scene_overrides(est, _rgb_text(d.get("color")), exposure=not d.get("no_exposure"), place=place)
    if not d.get("lights"):
        d["lights"] = list(o["lights"])
    d["opacity"] = o["opacity"]
    if d.get("shadow_color") is None:
        d["_shadow_color_linear"] = o["shadow_color"]
    if "occluder_color" in o:
        d["_occluder_color"] = o["occluder_color"]
        d["_exposure_gain"] = shading_gain(est, o["ambient"])  # the per-photo match is relative to it
    # RenderOptions fields (ratio_at: a point light's, where its shadow ratio holds)
    d["_shading"] = {k: o[k] for k in ("ambient", "specular", "ambient_tint", "direct_tint", "ratio_at") if k in o}
    d["_ambient_measured"] = True
    if d.get("color") is None and "occluder_color" in o:
        # a mesh with its own colours or texture keeps them, times the exposure (the grey default otherwise)
        d["_material_gain"] = shading_gain(est, o["ambient"])
    return d


def scene_from_dict(d: Mapping[str, Any], base_dir: str | Path | None = None) -> SceneSpec:
    """The one builder of :class:`SceneSpec`: from a mapping with the keys of :data:`SCENE_KEYS`.

    Command-line options (:func:`scene_from_args`), job files (:func:`load_scene`) and the demo's
    ``scenes.json`` all come through here. Values are normalised (numbers to floats, sequences to
    tuples, colours to ``"R,G,B"`` text) so that equal scenes give equal specs; files are not read here
    (:meth:`SceneSpec.build` does).

    Parameters
    ----------
    d : mapping
        At least ``calib``, ``model``, ``lights`` and ``marker_length`` or ``board``.
    base_dir : path, optional
        Folder that relative file paths (calibration, board, mesh, dictionary file) are relative to.

    Raises
    ------
    UsageError
        An unknown key, a missing required key, a malformed number.

    Examples
    --------
    >>> spec = scene_from_dict({"calib": "cam.yml", "marker_length": 0.05, "model": "box:0.04,0.04,0.06",
    ...                         "lights": ["point:0.1,0.1,0.4"]})
    >>> spec.tracker.marker_length, spec.model.source, spec.lights
    (0.05, 'box:0.04,0.04,0.06', ('point:0.1,0.1,0.4',))
    """
    d = dict(d)
    if "light" in d:
        if "lights" in d:
            raise UsageError("give either 'light' or 'lights', not both")
        d["lights"] = d.pop("light")
    unknown = sorted(
        set(d)
        - set(SCENE_KEYS)
        - {
            "_shadow_color_linear",
            "_occluder_color",
            "_shading",
            "_exposure_gain",
            "_ambient_measured",
            "_material_gain",
        }
    )
    if unknown:
        raise UsageError(f"unknown scene key(s) {', '.join(map(repr, unknown))} (known: {', '.join(SCENE_KEYS)})")
    if d.get("light_from") is not None:  # a measured light (arshadow light -o FILE): docs/light.md
        d = _apply_estimate(d, base_dir)
    for key in ("calib", "model", "lights"):
        if d.get(key) is None or (key == "lights" and d[key] in ((), [])):
            raise UsageError(
                f"the scene needs {key!r}" + (" (--light L or --light-from FILE)" if key == "lights" else "")
            )
    lights = d["lights"]
    if isinstance(lights, str) or not hasattr(lights, "__iter__"):
        lights = [lights]
    model = d["model"]
    if isinstance(model, (str, Path)) and ":" not in str(model):
        model = _path(model, base_dir)
    dictionary = d.get("dictionary")
    if (
        base_dir is not None
        and isinstance(dictionary, str)
        and not dictionary.upper().startswith("DICT_")
        and (Path(base_dir) / dictionary).exists()
    ):
        dictionary = _path(dictionary, base_dir)
    from ..lights.spec import Light

    bad = [s for s in lights if not isinstance(s, (str, Light))]
    if bad:
        raise UsageError(f"lights {bad[0]!r}: a light is a text spec such as point:X,Y,Z (in YAML, quote it)")
    if not isinstance(model, (str, Path)):
        raise UsageError(f"model {model!r}: expected a mesh file or a primitive such as box:WX,WY,HZ")
    ml = _value(d, "marker_length", float)
    mid = _value(d, "marker_id", int)
    tracker = TrackerSpec(
        dictionary=dictionary,
        marker_length=ml,
        marker_id=mid,
        board=_path(d.get("board"), base_dir),
        refine=d.get("refine", "default"),
        inverted=None if d.get("inverted") is None else bool(d.get("inverted")),
    )
    calib = d["calib"]
    if isinstance(calib, (str, Path)):
        calib = _path(calib, base_dir)
    model_spec = ModelSpec(
        str(model),
        scale=_value(d, "scale", float, 1.0),
        rotate=parse_triple(d.get("rotate", (0, 0, 0)), "rotate"),
        place=parse_triple(d.get("place", (0, 0, 0)), "place"),
        color=_rgb_text(d.get("color")),
        up=_value(d, "up", str),
        drop_to_ground=_value(d, "drop_to_ground", bool, False),
    )
    opts: dict[str, Any] = {}
    if d.get("shadow_color") is not None:
        from ..compose.composite import parse_rgb

        opts["shadow_color"] = parse_rgb(d["shadow_color"], "--shadow-color")
    for key, conv in (
        ("opacity", float),
        ("shadow_method", str),
        ("shadowmap_size", int),
        ("silhouette", str),
        ("soft_samples", int),
        ("aa", int),
        ("outline_aa", str),
        ("ground_size", float),
        ("roi", bool),
        ("truncate", bool),
        ("fast_detect", bool),
        ("plan", str),
        ("compose", str),
        ("track_roi", bool),
        ("ambient_occlusion", str),
        ("camera_effects", str),
        ("motion_blur", str),
        ("shutter", float),
        ("paper_albedo", float),
    ):
        if d.get(key) is not None:
            opts[key] = _value(d, key, conv)
    if d.get("ground") is not None:
        opts["ground"] = parse_ground(d["ground"]).text
    if d.get("no_object"):
        opts["draw_occluder"] = False
    if d.get("_shadow_color_linear") is not None:
        opts["shadow_color"] = d["_shadow_color_linear"]
    if d.get("_occluder_color") is not None:
        opts["occluder_color"] = d["_occluder_color"]
    if d.get("_shading") is not None:
        opts.update(d["_shading"])
    if d.get("no_exposure"):
        opts["exposure"] = False
    if d.get("_exposure_gain") is not None:
        opts["exposure_gain"] = tuple(float(v) for v in d["_exposure_gain"])
    if d.get("_ambient_measured"):
        opts["ambient_measured"] = True
    if d.get("_material_gain") is not None:
        opts["material_gain"] = tuple(float(v) for v in d["_material_gain"])
    return SceneSpec(
        camera=calib,
        tracker=tracker,
        model=model_spec,
        lights=tuple(s if not isinstance(s, str) else s.strip() for s in lights),
        options=RenderOptions(**opts),
        time_lapse=time_lapse_spec(d.get("time_lapse"), _value(d, "recompute_deg", float, 0.1), lights),
    )


def scene_from_args(args: Any, **overrides: Any) -> SceneSpec:
    """:func:`scene_from_dict` of parsed ``arshadow render`` options (``add_scene_options``)."""
    d = {k: getattr(args, k, None) for k in SCENE_KEYS if k != "lights"}
    d["lights"] = getattr(args, "light", None) or ()
    d["no_object"] = bool(getattr(args, "no_object", False))
    d.update(overrides)
    return scene_from_dict({k: v for k, v in d.items() if v is not None})


def load_scene(path: str | Path, **overrides: Any) -> SceneSpec:
    """A :class:`SceneSpec` from a job file: YAML (``.yml``/``.yaml``, needs PyYAML) or JSON; relative paths
    resolve against the file's folder. ``overrides``: scene keys replacing the file's (``arshadow batch
    --probe``: ``light_from`` and ``lights``).

    Raises
    ------
    UsageError
        Unreadable or malformed file, or a bad scene (:func:`scene_from_dict`).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"{p}: cannot read the scene file ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise UsageError(f"{p}: not a scene file (not UTF-8 text)") from None
    try:
        if p.suffix.lower() in (".yml", ".yaml"):
            import yaml

            data = yaml.safe_load(text)
        else:
            data = json.loads(text)
    except Exception as exc:  # noqa: BLE001 (yaml and json raise their own error types)
        mark = getattr(exc, "problem_mark", None)  # YAML: the message spans lines; say where, in one
        problem = getattr(exc, "problem", None)
        why = (
            f"line {mark.line + 1}, column {mark.column + 1}: {problem}"
            if mark is not None and problem
            else " ".join(str(exc).split())
        )
        raise UsageError(f"{p}: not a valid scene file ({type(exc).__name__}: {why})") from None
    if isinstance(data, dict) and isinstance(data.get("scene"), dict):
        data = data["scene"]
    if not isinstance(data, dict):
        raise UsageError(f"{p}: a scene file holds a mapping of scene keys")
    data = {**{k: v for k, v in data.items() if not (k == "light" and "lights" in overrides)}, **overrides}
    try:
        return scene_from_dict(data, base_dir=p.parent)
    except UsageError as exc:
        raise UsageError(f"{p}: {exc}") from None
