"""What the preview page may change in a scene, checked: the page's controls -> job-file keys (no GL).

The page sends its whole control state with every request (never a difference: a dropped, superseded
request then loses nothing). :func:`apply_controls` checks it (every bad value a :class:`ControlError`
naming the key, answered 400) and returns the scene as a mapping of :data:`arshadow.scene.SCENE_KEYS`,
the job-file format that :func:`arshadow.scene.scene_from_dict` reads and ``arshadow preview`` saves.

Controls (all optional but ``place``, ``rotate``, ``scale``):

- ``place`` ``[x, y, z]`` metres, ground frame; ``rotate`` ``[rx, ry, rz]`` degrees (the page turns rz only);
  ``scale``: > 0;
- ``light``: ``null`` (the scene's own lights, as given), ``"measured"`` (``light_from``: the probe's
  estimate) or ``{"azimuth": A, "elevation": E}`` in degrees: the first light moved to that direction
  (azimuth from +x towards +y, elevation above the ground; a point light keeps its distance from the
  world origin, a directional light or the sun becomes ``directional:``);
- ``opacity`` 0..1, ``soft_samples`` 1..64, ``object`` (false: ``no_object``).

Examples
--------
>>> base = {"calib": "c.yml", "marker_length": 0.05, "model": "box:0.04,0.04,0.06", "lights": ["point:0,0.3,0.4"]}
>>> d = apply_controls(base, {"place": [0.1, 0, 0], "rotate": [0, 0, 30], "scale": 2,
...                           "light": {"azimuth": 90, "elevation": 90}})
>>> d["place"], d["rotate"], d["scale"], d["lights"]
([0.1, 0.0, 0.0], [0.0, 0.0, 30.0], 2.0, ['point:0,0,0.5'])
>>> apply_controls(base, {"place": [0, 0], "rotate": [0, 0, 0], "scale": 1})
Traceback (most recent call last):
...
arshadow.preview.edit.ControlError: place [0, 0]: expected three finite numbers
"""

from __future__ import annotations

import math
import os
import shlex
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import UsageError
from ..scene.spec import SCENE_KEYS

__all__ = [
    "ControlError",
    "CONTROL_KEYS",
    "apply_controls",
    "controls_of",
    "light_angles",
    "ground_point",
    "relative_paths",
    "read_job",
    "command_line",
    "PATH_KEYS",
]

#: the keys a control state may have
CONTROL_KEYS = ("place", "rotate", "scale", "light", "opacity", "soft_samples", "object")
#: scene keys holding file paths (made relative to a saved scene file's folder)
PATH_KEYS = ("calib", "board", "dictionary", "model", "light_from")
#: soft samples the page may ask for (each sample is a hard light rendered: keep a drag interactive)
MAX_SOFT_SAMPLES = 64


class ControlError(UsageError):
    """A control value the page sent is not usable (HTTP 400, the message names the key)."""


def _triple(v: Any, key: str) -> list[float]:
    ok = isinstance(v, (list, tuple)) and len(v) == 3 and all(_is_number(x) for x in v)
    if not ok or not all(math.isfinite(float(x)) for x in v):
        raise ControlError(f"{key} {v!r}: expected three finite numbers")
    return [float(x) for x in v]


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _number(v: Any, key: str, lo: float, hi: float) -> float:
    if not _is_number(v) or not math.isfinite(float(v)) or not lo <= float(v) <= hi:
        raise ControlError(f"{key} {v!r}: expected a number in [{lo:g}, {hi:g}]")
    return float(v)


def light_angles(spec: str) -> tuple[float, float]:
    """``(azimuth, elevation)`` degrees of a light spec's direction from the world origin (the page's
    sliders); a sun is given its direction at its time.

    >>> [round(a, 3) for a in light_angles("directional:0,1,1")]
    [90.0, 45.0]
    """
    from ..lights.spec import parse_light

    lt = parse_light(spec)
    v = np.asarray(lt.vector, np.float64)
    az = math.degrees(math.atan2(v[1], v[0]))
    el = math.degrees(math.atan2(v[2], math.hypot(v[0], v[1])))
    return az, el


def _moved_light(spec: str, azimuth: float, elevation: float) -> str:
    """The light ``spec`` turned to (azimuth, elevation): a point light at its distance from the origin, else
    ``directional:`` (its weight and radius kept)."""
    from ..lights.spec import parse_light

    lt = parse_light(spec)
    a, e = math.radians(azimuth), math.radians(elevation)
    u = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    extra = ""
    if lt.kind == "point":
        u = u * float(np.linalg.norm(lt.vector))
        extra = f",radius={lt.radius:g}" if lt.radius > 0 else ""
        kind = "point"
    else:
        extra = f",radius={math.degrees(lt.radius):g}" if lt.radius > 0 else ""
        kind = "directional"
    xyz = ",".join(f"{x:.6g}" if abs(x) > 1e-12 else "0" for x in u)
    weight = "" if lt.weight == 1.0 else f"@{lt.weight:g}"
    return f"{kind}:{xyz}{extra}{weight}"


def apply_controls(  # noqa: C901 -- one short branch per control of the page
    base: Mapping[str, Any], controls: Any, *, own_lights: Any = None
) -> dict[str, Any]:
    """The scene (job-file keys) of ``base`` with the page's ``controls`` applied.

    Parameters
    ----------
    base : mapping
        The scene the preview started with (its ``lights`` and ``light_from`` as given).
    controls : dict
        The page's control state (this module's docstring).
    own_lights : list of str, optional
        The lights the azimuth / elevation sliders move (default ``base["lights"]``; a scene lit by its
        measured light alone: the estimate's light).

    Raises
    ------
    ControlError
        Not a mapping, an unknown key, a missing or malformed value: naming it.
    """
    if not isinstance(controls, dict):
        raise ControlError("controls: expected a JSON object")
    unknown = sorted(set(controls) - set(CONTROL_KEYS))
    if unknown:
        raise ControlError(f"unknown control(s) {', '.join(map(repr, unknown))} (known: {', '.join(CONTROL_KEYS)})")
    for key in ("place", "rotate", "scale"):
        if key not in controls:
            raise ControlError(f"controls: {key!r} is missing")
    d = {k: v for k, v in base.items() if k in SCENE_KEYS}
    d["place"] = _triple(controls["place"], "place")
    if max(abs(x) for x in d["place"]) > 1e3:
        raise ControlError(f"place {d['place']!r}: more than 1 km from the marker")
    d["rotate"] = _triple(controls["rotate"], "rotate")
    d["scale"] = _number(controls["scale"], "scale", 1e-6, 1e6)
    if d["scale"] <= 0:
        raise ControlError("scale: must be positive")
    if "opacity" in controls:
        d["opacity"] = _number(controls["opacity"], "opacity", 0.0, 1.0)
    if "soft_samples" in controls:
        n = controls["soft_samples"]
        if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= MAX_SOFT_SAMPLES:
            raise ControlError(f"soft_samples {n!r}: expected a whole number in [1, {MAX_SOFT_SAMPLES}]")
        d["soft_samples"] = n
    if "object" in controls:
        if not isinstance(controls["object"], bool):
            raise ControlError(f"object {controls['object']!r}: expected true or false")
        d["no_object"] = not controls["object"]
    light = controls.get("light")
    own = list(own_lights if own_lights is not None else base.get("lights") or ())
    if light == "measured":
        if not base.get("light_from"):
            raise ControlError("light 'measured': no measured light (start the preview with --light-from or --probe)")
        d.pop("lights", None)  # scene_from_dict: the estimate's light when no light is given
    elif isinstance(light, dict):
        if set(light) != {"azimuth", "elevation"}:
            raise ControlError(f"light {light!r}: expected {{'azimuth': A, 'elevation': E}} in degrees")
        az = _number(light["azimuth"], "light azimuth", -360.0, 360.0)
        el = _number(light["elevation"], "light elevation", 0.5, 90.0)
        d["lights"] = [_moved_light(str(own[0]), az, el), *own[1:]]
        d.pop("light_from", None)  # a light of one's own: not the estimate's shadow colour either
    elif light is not None:
        raise ControlError(f"light {light!r}: expected null, 'measured' or {{'azimuth': A, 'elevation': E}}")
    return d


def controls_of(d: Mapping[str, Any]) -> dict[str, Any]:
    """The control state showing scene ``d`` (the page's starting values)."""
    opacity = d.get("opacity")
    return {
        "place": list(map(float, d.get("place") or (0.0, 0.0, 0.0))),
        "rotate": list(map(float, d.get("rotate") or (0.0, 0.0, 0.0))),
        "scale": float(d.get("scale") or 1.0),
        "light": "measured" if d.get("light_from") and not d.get("lights") else None,
        "opacity": float(opacity if opacity is not None else 0.7),
        "soft_samples": int(d.get("soft_samples") or 1),
        "object": not d.get("no_object"),
    }


def ground_point(intrinsics: Any, cam_from_world: np.ndarray, uv: Any) -> np.ndarray | None:
    """The point of the ground plane (world z = 0) seen at pixel ``uv`` (pixel-centre convention, the
    distorted photo's pixels), or None when that pixel's ray misses the ground (the sky, or behind).

    Parameters
    ----------
    intrinsics : arshadow.camera.Intrinsics
        For the photo's size (lens distortion undone exactly).
    cam_from_world : (4, 4) float64
        The ground frame's camera.
    uv : (2,) float

    Returns
    -------
    (3,) float64 or None
    """
    pin = intrinsics.undistort_pixels(np.asarray(uv, np.float64).reshape(1, 2))[0]
    if not np.all(np.isfinite(pin)):
        return None
    ray_cam = np.array([(pin[0] - intrinsics.cx) / intrinsics.fx, (pin[1] - intrinsics.cy) / intrinsics.fy, 1.0])
    m = np.asarray(cam_from_world, np.float64)
    rot, t = m[:3, :3], m[:3, 3]
    centre = -rot.T @ t
    ray = rot.T @ ray_cam
    if not ray[2] < -1e-12 or not centre[2] > 0:
        return None
    p: np.ndarray = centre + ray * (-centre[2] / ray[2])
    p[2] = 0.0
    return p


def read_job(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A job file's scene keys as a mapping, its file paths made absolute (relative ones are the file's
    folder's, as :func:`arshadow.scene.load_scene` reads them); checked by loading it.

    Raises
    ------
    UsageError
        Unreadable or malformed file, or a bad scene.
    """
    import json

    from ..scene.spec import load_scene

    p = Path(path)
    load_scene(p)  # every problem of the file, named as batch --config names it
    text = p.read_text(encoding="utf-8")
    if p.suffix.lower() in (".yml", ".yaml"):
        import yaml

        data = yaml.safe_load(text)
    else:
        data = json.loads(text)
    if isinstance(data.get("scene"), dict):
        data = data["scene"]
    d = dict(data)
    if "light" in d:
        d["lights"] = d.pop("light")
    if isinstance(d.get("lights"), str):
        d["lights"] = [d["lights"]]
    for key in PATH_KEYS:
        v = d.get(key)
        if not isinstance(v, str) or Path(v).is_absolute():
            continue
        if key == "dictionary" and v.upper().startswith("DICT_"):
            continue
        if key == "model" and ":" in v and not (p.parent / v).exists():
            continue  # a primitive
        d[key] = str((p.parent / v).resolve())
    return d


def relative_paths(d: Mapping[str, Any], folder: str | os.PathLike[str]) -> dict[str, Any]:
    """``d`` with its file paths made relative to ``folder`` (a job file's paths are relative to its own
    folder: :func:`arshadow.scene.load_scene`); primitives and dictionary names are kept."""
    out = dict(d)
    for key in PATH_KEYS:
        v = out.get(key)
        if isinstance(v, str) and Path(v).is_absolute() and Path(v).exists():
            out[key] = os.path.relpath(v, folder)
    return out


def _num(x: Any) -> str:
    """A number as the shortest text that reads back to the same float (``1.0`` -> ``1``)."""
    t = repr(float(x))
    return t[:-2] if t.endswith(".0") else t


def command_line(d: Mapping[str, Any], media: str, video: bool = False) -> str:
    """The ``arshadow render`` (or ``video``) command that renders scene ``d`` (paths as they are in ``d``).

    >>> command_line({"calib": "c.yml", "marker_length": 0.05, "model": "box:1,1,1", "place": [-0.1, 0, 0],
    ...               "lights": ["point:0,0,1"], "no_object": True}, "p.jpg")
    'arshadow render p.jpg --calib c.yml --marker-length 0.05 --model box:1,1,1 --place=-0.1,0,0 --light point:0,0,1 --no-object -o out/'
    """
    parts = ["arshadow", "video" if video else "render", shlex.quote(media)]
    for key in SCENE_KEYS:
        v = d.get(key)
        if v is None or v is False:
            continue
        opt = "--" + key.replace("_", "-")
        if key == "lights":
            for s in v:
                parts += ["--light", shlex.quote(str(s))]
        elif v is True:
            parts.append(opt)
        elif isinstance(v, (list, tuple)):
            text = ",".join(_num(x) for x in v)
            parts += [f"{opt}={text}"] if text.startswith("-") else [opt, text]
        else:
            text = _num(v) if isinstance(v, float) else str(v)
            parts += [opt, shlex.quote(text)]
    return " ".join([*parts, "-o", "out/"])
