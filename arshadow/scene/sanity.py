"""Sanity gates: plausible mistakes found before (or while) rendering, each named with its probable cause.

Everything here is plain functions over already loaded data (an occluder's bounds, parsed lights, a pose);
no GL, no files. Scene-level checks run once per scene (:func:`check_scene`, called by
:meth:`arshadow.scene.SceneSpec.build`, so every path -- photo, video, batch, API -- gets them); the
per-frame check (:class:`FrameChecks`) is O(1) per frame and says each problem once per run.

What is checked (the sanity gates):

* units: a marker length in millimetres or centimetres (``--marker-length 50`` or ``14.5``), an object
  much smaller than the marker, a camera tens of metres from the marker (:func:`scale_warnings`,
  :meth:`FrameChecks.check`);
* the model reaching below the ground (:func:`ground_warnings`; ``--drop-to-ground`` fixes it);
* lights: a point light inside a closed model (a scene error, :func:`check_lights_inside`), soft samples
  asked for lights without a size, a light so close to the model that each photo takes seconds
  (:func:`light_warnings`);
* a time-lapse sun that sets during the video (:func:`sun_set_warning`);
* why a pose was flagged (:func:`pose_flag_reasons`, the report's ``flag_reasons``).

Messages are plain text (the command line prints them as ``arshadow: WARNING: ...``).
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Iterable, Sequence
from datetime import datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from ..errors import LightError, UsageError

if TYPE_CHECKING:  # annotations only (sanity is imported on every path and stays light)
    from ..camera.model import Intrinsics
    from ..geometry.caster import ShadowCaster
    from ..lights.spec import Light
    from ..lights.suntrack import SunTrack
    from ..tracking.pose import MarkerPose

log = logging.getLogger(__name__)

__all__ = [
    "MAX_CAMERA_DISTANCE_M",
    "MAX_MARKER_LENGTH_M",
    "MAX_SIZE_RATIO",
    "MIN_MARKER_LENGTH_M",
    "MIN_OBJECT_RATIO",
    "SLOW_LIGHT_RATIO",
    "FlagTally",
    "flag_kind",
    "FrameChecks",
    "calibration_scaled_note",
    "quiet_notes",
    "say_note",
    "check_lights_inside",
    "check_scene",
    "check_shadowmap_lights",
    "ground_warnings",
    "looks_y_up",
    "light_warnings",
    "paper_warnings",
    "pose_flag_reasons",
    "scale_warnings",
    "sun_set_warning",
    "unit_guess",
]

#: the marker paper's reflectance (``--paper-albedo``) outside this range is warned of: printer and photo
#: papers reflect 0.75-0.95
PAPER_ALBEDO_RANGE = (0.6, 0.97)
#: a printed marker (or board square) longer than this (metres) is taken for a unit mistake
MAX_MARKER_LENGTH_M = 1.0
#: ... and shorter than this (metres): no printer makes a usable marker under 3 mm
MIN_MARKER_LENGTH_M = 0.003
#: a camera further than this from the marker (metres) cannot see a printed marker: wrong units
MAX_CAMERA_DISTANCE_M = 20.0
#: an object more than this many times the marker's side is taken for a unit mistake (a mesh in millimetres)
MAX_SIZE_RATIO = 100.0
#: an object smaller than this share of the marker's side is taken for a unit mistake
MIN_OBJECT_RATIO = 1.0 / 50.0
#: a point light nearer to the object's bounding box than this share of the object's size fans its shadow
#: volumes over most of the photo: each photo may take seconds (the sanity gates: 2 cm under the knot, 6.7 s)
SLOW_LIGHT_RATIO = 0.25
#: a typical printed marker side (metres), the centre of :func:`unit_guess`'s choice
TYPICAL_MARKER_M = 0.08
#: how far (metres) the model may reach below the ground before it warns (float noise of a placement)
GROUND_TOLERANCE_M = 1e-6


def unit_guess(value: float, what: str = "--marker-length") -> str:
    """The probable unit mistake behind a length given in metres that is implausible for a printed marker.

    The candidates are millimetres and centimetres read as metres; the one whose metres are nearer (in
    ratio) to a typical 8 cm marker comes first.

    >>> unit_guess(50)
    'millimetres (then give --marker-length 0.05; if centimetres, 0.5)'
    >>> unit_guess(14.5)
    'centimetres (then give --marker-length 0.145; if millimetres, 0.0145)'
    """
    cands = sorted(
        (abs(math.log(value / f / TYPICAL_MARKER_M)), unit, value / f)
        for unit, f in (("millimetres", 1000.0), ("centimetres", 100.0))
    )
    (_, u1, m1), (_, u2, m2) = cands
    return f"{u1} (then give {what} {m1:.4g}; if {u2}, {m2:.4g})"


def scale_warnings(
    caster: ShadowCaster | None, marker_length: float | None = None, square_length: float | None = None
) -> list[str]:
    """Lengths that are probably in the wrong units; one message per problem.

    Parameters
    ----------
    caster : arshadow.geometry.caster.ShadowCaster or None
        The placed object (its ``bounds`` ``(2, 3)``, metres).
    marker_length : float, optional
        Single-marker mode: the marker's side as given (metres).
    square_length : float, optional
        Board mode: the side of a board marker (metres), as the board file gives it.

    Returns
    -------
    list of str

    Examples
    --------
    >>> scale_warnings(None, marker_length=50)[0][:70]
    '--marker-length 50: a printed marker 50 m across? The length is metres'
    >>> scale_warnings(None, marker_length=0.05)
    []
    """
    out: list[str] = []
    what, length = (
        ("--marker-length", marker_length)
        if marker_length is not None
        else ("the board's marker length", square_length)
    )
    if length is None:
        return out
    length = float(length)
    if length > MAX_MARKER_LENGTH_M:
        out.append(
            f"{what} {length:g}: a printed marker {length:g} m across? The length is metres: "
            f"probably {unit_guess(length, what)}"
        )
    elif length < MIN_MARKER_LENGTH_M:
        out.append(
            f"{what} {length:g}: a printed marker {length * 1000:.3g} mm across? The length is metres "
            f"(a 5 cm marker is 0.05)"
        )
    if caster is not None:
        size = float(np.max(caster.bounds[1] - caster.bounds[0]))
        if marker_length is not None and size > MAX_SIZE_RATIO * length:
            out.append(
                f"{caster.name or 'the object'} is {size:.4g} m across, {size / length:.0f} x the "
                f"{length:.4g} m marker: wrong units? (mesh coordinates are metres; see --scale)"
            )
        if 0 < size < MIN_OBJECT_RATIO * length:
            out.append(
                f"{caster.name or 'the object'} is {size:.4g} m across, 1/{length / size:.0f} of the "
                f"{length:.4g} m marker: it will be a few pixels or vanish. Wrong units? (the marker "
                "length and the mesh are metres; see --scale)"
            )
    return out


def looks_y_up(caster: ShadowCaster) -> bool:
    """Whether a mesh read Z-up looks like a Y-up file (Blender's OBJ export): its extent along y more
    than 1.5 x its height and its z range straddling the ground (a model standing on y = 0 lies on its
    back, half under the ground).

    >>> from arshadow.geometry.mesh import load_occluder
    >>> looks_y_up(load_occluder("box:0.02,0.1,0.02", place=(0, 0, -0.01))), looks_y_up(load_occluder("box:0.02,0.02,0.1"))
    (True, False)
    """
    lo, hi = (np.asarray(b, np.float64) for b in caster.bounds)
    size = hi - lo
    return bool(size[1] > 1.5 * size[2] and lo[2] < 0.0 < hi[2])


def ground_warnings(caster: ShadowCaster, maybe_y_up: bool = False) -> list[str]:
    """The model reaching below the ground (z = 0 of the world frame): that part is hidden under the
    ground and casts no shadow on it. ``--drop-to-ground`` stands it on the ground.

    >>> from arshadow.geometry.mesh import load_occluder
    >>> ground_warnings(load_occluder("sphere:0.02", place=(0, 0, -0.02)))[0][:56]
    'sphere:0.02 reaches 0.02 m below the ground (lowest z = '
    >>> ground_warnings(load_occluder("sphere:0.02"))
    []
    """
    low, high = float(caster.bounds[0][2]), float(caster.bounds[1][2])
    if low >= -GROUND_TOLERANCE_M:
        return []
    name = caster.name or "the model"
    share = min(1.0, -low / (high - low)) if high > low else 1.0
    if maybe_y_up and looks_y_up(caster):  # a Y-up file read Z-up: lying on its back, half underground
        return [
            f"{name} reaches {-low:.4g} m below the ground and is {float(caster.bounds[1][1] - caster.bounds[0][1]):.4g} m "
            f"long along y but {high - low:.4g} m high: a Y-up mesh file (Blender's OBJ export) read Z-up? "
            "Give --up y"
        ]
    msg = (
        f"{name} reaches {-low:.4g} m below the ground (lowest z = {low:.4g} m; {share:.0%} of its height): "
        "that part is hidden under the ground and casts no shadow (a mesh centred on its origin? use "
        "--drop-to-ground to stand it on the ground, or raise --place's Z)"
    )
    return [msg]


def check_lights_inside(caster: ShadowCaster, lights: Iterable[Light]) -> None:
    """LightError when a point light is inside a closed model: it lights nothing outside the model, so no
    photo can be rendered (a scene error: found once, before any work, exit 2)."""
    if caster.two_sided:
        return
    lo, hi = caster.bounds
    for light in lights:
        if getattr(light, "kind", None) != "point":
            continue
        p = np.asarray(light.vector, np.float64)[:3]
        if np.any(p < lo) or np.any(p > hi):
            continue
        if abs(caster.winding_number(p)) > 0.5:
            raise LightError(
                f"light {light.label or 'point'}: the point light at {p.round(4).tolist()} is inside "
                f"the closed mesh {caster.name!r}: it lights nothing outside the mesh (move the "
                "light outside)"
            )


def _box_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    return float(np.linalg.norm(np.maximum(0.0, np.maximum(lo - p, p - hi))))


def light_warnings(caster: ShadowCaster | None, lights: Sequence[Light], soft_samples: int = 1) -> list[str]:
    """Lights that do not do what was probably meant, and lights that will make every photo slow.

    * ``soft_samples > 1`` with no light that has a size (``radius=``; the sun always has one): the
      shadows stay hard.
    * a point light within :data:`SLOW_LIGHT_RATIO` of the object's size from its bounding box: its shadow
      volumes fan out over most of the photo (seconds per photo on a CPU renderer).

    >>> from arshadow.geometry.mesh import load_occluder
    >>> from arshadow.lights.spec import parse_light
    >>> light_warnings(load_occluder("box:0.04,0.04,0.06"), [parse_light("point:0,0,0.5")], soft_samples=16)[0][:60]
    '--soft-samples 16: no light has a size, so the shadows stay '
    """
    out: list[str] = []
    if int(soft_samples) > 1 and not any(
        float(getattr(L, "radius", 0.0)) > 0 or getattr(L, "kind", "") == "sun" for L in lights
    ):
        points = [L.label or L.kind for L in lights if getattr(L, "kind", "") == "point"]
        hint = f" (e.g. {points[0]},radius=0.02)" if points else ""
        out.append(
            f"--soft-samples {int(soft_samples)}: no light has a size, so the shadows stay hard; give a "
            f"point light a sphere radius in metres{hint} or a directional one an angular radius in "
            "degrees"
        )
    if caster is None:
        return out
    lo, hi = (np.asarray(b, np.float64) for b in caster.bounds)
    size = float(np.max(hi - lo))
    for L in lights:
        if getattr(L, "kind", None) != "point":
            continue
        p = np.asarray(L.vector, np.float64)[:3]
        d = _box_distance(p, lo, hi)
        if d < SLOW_LIGHT_RATIO * size:
            out.append(
                f"light {L.label or 'point'} is {d:.3g} m from {caster.name or 'the object'} "
                f"({size:.3g} m across): its shadow volumes fan out over most of the photo, so each "
                "photo may take seconds; move the light further away for speed"
            )
    return out


def check_shadowmap_lights(caster: ShadowCaster, lights: Iterable[Light]) -> None:
    """UsageError when ``--shadow-method shadowmap`` meets a point light inside the model's bounding sphere
    (one shadow map cannot see the whole model: every photo would fail the same way)."""
    lo, hi = (np.asarray(b, np.float64) for b in caster.bounds)
    c, r = 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-9)
    for light in lights:
        if (
            getattr(light, "kind", None) == "point"
            and float(np.linalg.norm(np.asarray(light.vector, np.float64)[:3] - c)) <= r * 1.0001
        ):
            raise UsageError(
                f"--shadow-method shadowmap: the point light {light.label or ''} is inside the bounding "
                f"sphere of {caster.name or 'the model'} (radius {r:.3g} m): one shadow map cannot see "
                "the whole model; move the light away or use --shadow-method volume"
            )


def check_scene(
    caster: ShadowCaster,
    lights: Sequence[Light],
    *,
    soft_samples: int = 1,
    marker_length: float | None = None,
    square_length: float | None = None,
    shadow_method: str = "volume",
    maybe_y_up: bool = False,
) -> list[str]:
    """Every scene-level check, once per scene: raises for a scene that cannot render (LightError: a light
    inside the model; UsageError: a shadow map around a point light), returns the warnings (also logged by
    the caller). ``maybe_y_up``: the mesh file was read Z-up by default, unrotated (:func:`looks_y_up`)."""
    check_lights_inside(caster, lights)
    if shadow_method == "shadowmap":
        check_shadowmap_lights(caster, lights)
    return (
        scale_warnings(caster, marker_length, square_length)
        + ground_warnings(caster, maybe_y_up)
        + light_warnings(caster, lights, soft_samples)
    )


#: set in a worker process whose parent says the run's notes (local chunk workers): it says none
QUIET_NOTES = False


def say_note(logger: logging.Logger, msg: str) -> bool:
    """Log ``msg`` as a warning unless this process is a quiet worker (:func:`quiet_notes`: its parent
    says the run's notes, once); returns whether it was said. (A session says each note once itself.)"""
    if QUIET_NOTES:
        return False
    logger.warning(msg)
    return True


def quiet_notes() -> None:
    """Say no note in this process (the initializer of local chunk workers: the parent says them)."""
    global QUIET_NOTES
    QUIET_NOTES = True


def calibration_scaled_note(intrinsics: Intrinsics, width: int, height: int, kind: str = "photo") -> str:
    """The stderr line for a ``kind`` (``photo`` / ``video``) of another size than the calibration's (same
    aspect ratio: K scaled)."""
    return (
        f"the calibration is for {intrinsics.width}x{intrinsics.height}, the {kind} is {width}x{height}: "
        f"focal lengths and centre scaled by {width / intrinsics.width:.4g} (same aspect ratio); calibrate "
        "at this size for the best accuracy"
    )


def sun_set_warning(
    tracks: Sequence[SunTrack], start: datetime, speed: float, fps: float, n_frames: int, label: str = ""
) -> str | None:
    """The frames of a time-lapse during which a sun is below the horizon (no shadow), or None.

    Parameters
    ----------
    tracks : list of arshadow.lights.suntrack.SunTrack
    start : datetime
        Time of frame 0 (aware).
    speed : float
        Sun seconds per video second.
    fps : float
    n_frames : int
    label : str
        The video's name, for the message.

    The sun's elevation is sampled at most 2000 times over the video and each horizon crossing refined to
    its frame by bisection (positions are vectorised SPA; a few milliseconds in all).
    """
    # deferred: the SPA tables load only for a time-lapse (sanity is imported on every path)
    from ..lights.sun import sun_positions

    n = int(n_frames)
    if n <= 0 or not tracks:
        return None
    step = max(1, -(-n // 2000))
    frames = list(range(0, n, step)) + ([n - 1] if (n - 1) % step else [])

    def below(tr: SunTrack, idx: Iterable[int]) -> list[bool]:
        times = [start + timedelta(seconds=i * speed / fps) for i in idx]
        return [not p.above_horizon for p in sun_positions(times, tr.lat, tr.lon, tr.elevation, tr.model, **tr.kwargs)]

    ranges: list[tuple[int, int]] = []
    samples = frames
    for tr in tracks:
        flags = below(tr, samples)
        if not any(flags):
            continue
        frames = list(samples)  # refined in place below, per track
        for k in range(len(frames)):  # refine each change of state between samples to its first frame
            if k and flags[k] != flags[k - 1]:
                a, b = frames[k - 1], frames[k]
                while b - a > 1:
                    m = (a + b) // 2
                    if below(tr, [m])[0] == flags[k]:
                        b = m
                    else:
                        a = m
                frames[k] = b
        run_start: int | None = None
        for k, f in enumerate(frames):
            if flags[k] and run_start is None:
                run_start = f
            if not flags[k] and run_start is not None:
                ranges.append((run_start, f - 1))
                run_start = None
        if run_start is not None:
            ranges.append((run_start, n - 1))
    if not ranges:
        return None
    where = ", ".join(f"{a}-{b}" if b > a else f"{a}" for a, b in sorted(set(ranges)))
    t_end = start + timedelta(seconds=(n - 1) * speed / fps)
    return (
        f"{label + ': ' if label else ''}the sun is below the horizon in frames {where} of {n} (time-lapse "
        f"{start.isoformat()} .. {t_end.isoformat()}): those frames get no sun shadow"
    )


def pose_flag_reasons(pose: MarkerPose, flagged: bool | None = None) -> list[str]:
    """Why a pose is flagged (empty when it is not): the tracker's own reasons when it gives them
    (``pose.flag_reasons``), else read from the pose's measurements (:class:`MarkerPose.ambiguous`'s tests).

    A clearly separate stand-in for the tracking package's reasons (the sanity gates): when ``MarkerPose`` carries
    ``flag_reasons`` this function only passes them on.
    """
    own = getattr(pose, "flag_reasons", None)
    if own is not None:
        return [str(r) for r in own]
    if not (getattr(pose, "ambiguous", False) if flagged is None else flagged):  # ``flagged``: already known
        return []
    # deferred: the thresholds live with the tracker (OpenCV); sanity itself stays light
    from ..tracking.quality import (
        MAX_BORDER_OCCLUSION,
        MAX_CORNER_INSTABILITY,
        MIN_CONFIDENT_SIDE_PX,
    )

    out: list[str] = []
    ratio, thr = pose.pose_ambiguity, getattr(pose, "ambiguity_threshold", None)
    if ratio is not None and thr is not None and ratio >= thr:
        out.append(
            f"ambiguous: the two planar solutions explain the corners almost equally (ratio {ratio:.3g} >= {thr:g})"
        )
    ci = getattr(pose, "corner_instability", None)
    if ci is not None and ci > MAX_CORNER_INSTABILITY:
        out.append(
            f"blurred corners: they move by {ci:.3g} of the marker's side between refinement windows "
            f"(> {MAX_CORNER_INSTABILITY:g})"
        )
    bo = getattr(pose, "border_occlusion", None)
    if bo is not None and bo > MAX_BORDER_OCCLUSION:
        out.append(
            f"marker partly covered: a border cell reads {bo:.2f} of the way to white (> {MAX_BORDER_OCCLUSION:g})"
        )
    if getattr(pose, "kind", "marker") == "marker" and len(getattr(pose, "corners", ())) >= 4:
        q = np.asarray(pose.corners, np.float64)[:4]
        side = float(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).min())
        if side < MIN_CONFIDENT_SIDE_PX:
            out.append(
                f"small marker: {side:.1f} px across, under the {MIN_CONFIDENT_SIDE_PX:g} px a pose can be trusted at"
            )
    return out or ["flagged by the tracker"]


class FrameChecks:
    """Per-frame checks, O(1) each, each problem said once per run (a video says it once, not per frame).

    Parameters
    ----------
    caster : ShadowCaster
    marker_length : float, optional
        For the message of a far camera (the unit mistake it probably comes from).
    """

    def __init__(self, caster: ShadowCaster, marker_length: float | None = None):
        self.caster, self.marker_length = caster, marker_length
        lo, hi = caster.bounds
        self._lo, self._hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.said: set[str] = set()

    def check(self, cam_from_world: npt.ArrayLike, cam_from_marker: npt.ArrayLike | None = None) -> list[str]:
        """Messages for this frame's pose ``(4, 4)`` (world -> camera) not said before in this run.
        ``cam_from_marker`` ``(4, 4)``: the marker's pose when the world (the ground frame) is elsewhere
        (``--ground``): the camera's distance, a check of the marker length, is from the marker."""
        if len(self.said) == 2:
            return []
        m = np.asarray(cam_from_world, np.float64)
        eye = -m[:3, :3].T @ m[:3, 3]  # the camera centre, world frame
        out: list[str] = []
        mm = m if cam_from_marker is None else np.asarray(cam_from_marker, np.float64)
        dist = float(np.linalg.norm(mm[:3, :3].T @ mm[:3, 3]))  # the camera's distance from the marker
        if dist > MAX_CAMERA_DISTANCE_M and "far" not in self.said:
            self.said.add("far")
            ml = self.marker_length
            why = (
                f"--marker-length {ml:g} is probably in {unit_guess(ml)}"
                if ml is not None and ml > MAX_MARKER_LENGTH_M
                else "the marker or board length is probably in the wrong units (metres)"
            )
            out.append(f"the camera is {dist:.4g} m from the marker: {why}")
        if np.all(eye > self._lo) and np.all(eye < self._hi) and "inside" not in self.said:
            self.said.add("inside")
            out.append(
                f"the camera is inside the bounding box of {self.caster.name or 'the object'} "
                f"({self._lo.round(4).tolist()} .. {self._hi.round(4).tolist()} m): the object may cover "
                "the whole photo"
            )
        return out


def _ranges(keys: Iterable[int | str]) -> str:
    """``[1, 2, 3, 7]`` -> ``"1-3, 7"`` (ints), names joined as they are."""
    listed = list(keys)
    ks = [k for k in listed if isinstance(k, int)]
    if not listed or len(ks) < len(listed):
        return ", ".join(map(str, listed))
    ks.sort()
    runs = [[ks[0], ks[0]]]
    for k in ks[1:]:
        if k == runs[-1][1] + 1:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    return ", ".join(f"{a}-{b}" if b > a else f"{a}" for a, b in runs)


def flag_kind(reason: str) -> str:
    """The kind of a flag reason, its words before the first ``:`` or number (so that reasons that differ
    only by their measurements group into one).

    >>> flag_kind("small marker: 20.1 px across"), flag_kind("reprojection error 35.2 px, far above ...")
    ('small marker', 'reprojection error')
    """
    head = re.split(r"[:\d]", str(reason), maxsplit=1)[0].strip(" ,;(")
    return head or str(reason)


class FlagTally:
    """Flagged poses of a run, for one summary line on stderr (``render``: per photo, ``video``: per frame).

    >>> t = FlagTally()
    >>> t.add(3, ["small marker: 20.1 px across"]); t.add(4, ["small marker: 19.8 px across"]); t.add(5, [])
    >>> print(t.summary(6, "frames"))
    2 of 6 frames have a flagged pose (3-4): small marker (2); the report's flag_reasons say why for each
    """

    def __init__(self) -> None:
        self.keys: list[int | str] = []
        self.kinds: dict[str, int] = {}

    def add(self, key: int | str, reasons: Iterable[str] | None) -> None:
        """Record the reasons (:func:`pose_flag_reasons`) of the pose of ``key`` (a frame index or a name)."""
        if not reasons:
            return
        self.keys.append(key)
        for r in reasons:
            kind = flag_kind(r)
            self.kinds[kind] = self.kinds.get(kind, 0) + 1

    def summary(self, total: int, what: str = "photos", where: str | Path | None = None) -> str | None:
        """One line, or None when nothing was flagged; ``where``: the file whose records carry
        ``flag_reasons`` (a video's ``.frames.jsonl``), else "the report's"."""
        if not self.keys:
            return None
        kinds = ", ".join(f"{k} ({n})" for k, n in sorted(self.kinds.items(), key=lambda kv: -kv[1]))
        src = "the report's flag_reasons" if where is None else f"flag_reasons in {where}"
        return f"{len(self.keys)} of {total} {what} have a flagged pose ({_ranges(self.keys)}): {kinds}; {src} say why for each"


def paper_warnings(paper_albedo: float) -> list[str]:
    """A marker paper's reflectance (``--paper-albedo``) no printer paper has; one message naming the probable
    mistake, or none.

    >>> paper_warnings(0.85)
    []
    >>> paper_warnings(0.3)[0][:60]
    '--paper-albedo 0.3: darker than any printer paper (0.75-0.95'
    """
    lo, hi = PAPER_ALBEDO_RANGE
    p = float(paper_albedo)
    if p < lo:
        return [
            f"--paper-albedo {p:g}: darker than any printer paper (0.75-0.95); it is the reflectance of the "
            "marker's white paper, not of the floor or the ink"
        ]
    if p > hi:
        return [
            f"--paper-albedo {p:g}: brighter than any printer paper (0.75-0.95; 1 is a perfect white): the "
            "object's own colours come out that much darker"
        ]
    return []
