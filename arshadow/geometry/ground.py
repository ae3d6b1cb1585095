"""A ground plane that is not the marker plane: parse ``--ground``, build ``marker_from_ground``, check a pose.

Pure numpy, no GL. The renderer, the planner and the shadow geometry all work in a frame whose ground is
z = 0 with +z up (CONVENTIONS.md). By default that frame is the marker's. With a marker hung on a wall or
leaning on something, the ground is elsewhere: this module turns a ground spec into the rigid transform
``marker_from_ground`` (4, 4) float64, and the session renders with

    cam_from_ground = cam_from_marker @ marker_from_ground

so that everything downstream (model placement, lights, shadows, the planar fast path, culling, the
planner) sees a ground frame and is unchanged.

Ground specs (``--ground`` / the scene key ``ground``; lengths in metres, in the marker frame: x right,
y towards the marker's top edge, z out of its printed face):

``marker``
    The marker plane itself (the default): ``marker_from_ground`` is the identity.
``wall:H``
    The marker hangs upright on a vertical wall (its top edge up); the floor is ``H`` metres below the
    marker's centre. Same as ``plane:0,-H,0,0,1,0``.
``plane:PX,PY,PZ,NX,NY,NZ``
    Any plane, through the point ``P`` with the normal ``N`` (need not be unit length) pointing up, to
    the side the object stands on and the camera looks from.

The ground frame (docs/geometry.md, "The ground frame"): origin at ``P`` (for ``wall:H``: the floor point
straight below the marker's centre); +z = ``N`` normalised; +x = the marker's +x projected onto the plane
(or, when the marker's x is within ~6 degrees of the normal, +y = the marker's +y projected and +x =
y x z); +y = z x x. A plane parallel to the marker keeps the marker's axes; for ``wall:H``, +x runs along
the wall like the marker's x and +y points *into* the wall (an object in front of the wall has y < 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import UsageError

__all__ = [
    "GROUND_KINDS",
    "MIN_ELEVATION_DEG",
    "GroundSpec",
    "check_camera_above",
    "ground_frame",
    "ground_warnings",
    "parse_ground",
]

#: the kinds of ground spec :func:`parse_ground` accepts
GROUND_KINDS = ("marker", "wall", "plane")
#: a camera that sees the ground's origin under a smaller elevation than this sees the plane edge-on
MIN_ELEVATION_DEG = 1.0
#: a ground farther than this from the marker (metres) is probably given in millimetres or centimetres
FAR_GROUND_M = 10.0
#: below this angle (sine) between the marker's x and the plane, the marker's y gives the frame's axes
_AXIS_MIN_SIN = 0.1


@dataclass(frozen=True)
class GroundSpec:
    """A parsed ground spec: the plane through ``point`` with unit ``normal`` (both in the marker frame).

    Attributes
    ----------
    text : str
        The spec, normalised (``"marker"``, ``"wall:0.5"``, ``"plane:..."``).
    point : (3,) float64
        A point of the plane, the ground frame's origin (marker frame).
    normal : (3,) float64
        Unit normal, pointing up (marker frame).
    """

    text: str
    point: tuple
    normal: tuple

    @property
    def is_marker(self) -> bool:
        """True when the ground is the marker plane itself (the identity transform)."""
        return self.text == "marker"

    @property
    def marker_from_ground(self) -> np.ndarray:
        """(4, 4) float64: ground-frame points to marker-frame points (:func:`ground_frame`)."""
        return ground_frame(self.point, self.normal)


def _numbers(body: str, n: int, text: str) -> list[float]:
    parts = [p.strip() for p in body.split(",")]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise UsageError(f"--ground {text!r}: expected {n} comma-separated numbers after the colon") from None
    if len(vals) != n:
        raise UsageError(f"--ground {text!r}: expected {n} comma-separated numbers, got {len(vals)}")
    if not all(math.isfinite(v) for v in vals):
        raise UsageError(f"--ground {text!r}: numbers must be finite")
    return vals


def parse_ground(text: str | None) -> GroundSpec:
    """Parse a ground spec (module docstring); None or ``""`` means ``marker``.

    Raises
    ------
    UsageError
        An unknown kind, a malformed number, ``wall:H`` with ``H <= 0``, a zero normal.

    Examples
    --------
    >>> g = parse_ground("wall:0.5")
    >>> g.text, g.point, g.normal
    ('wall:0.5', (0.0, -0.5, 0.0), (0.0, 1.0, 0.0))
    >>> parse_ground(None).is_marker
    True
    >>> parse_ground("plane:0,0,-0.01,0,0,2").normal
    (0.0, 0.0, 1.0)
    """
    if isinstance(text, GroundSpec):
        return text
    t = "marker" if text is None else str(text).strip()
    if t in ("", "marker"):
        return GroundSpec("marker", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    kind, _, body = t.partition(":")
    kind = kind.strip().lower()
    if kind == "wall":
        (h,) = _numbers(body, 1, t)
        if h <= 0:
            raise UsageError(
                f"--ground {t!r}: H is the height of the marker's centre above the floor, in metres, and must be > 0"
            )
        return GroundSpec(f"wall:{h:g}", (0.0, -h, 0.0), (0.0, 1.0, 0.0))
    if kind == "plane":
        v = _numbers(body, 6, t)
        n = np.asarray(v[3:], np.float64)
        norm = float(np.linalg.norm(n))
        if not norm > 1e-12:
            raise UsageError(f"--ground {t!r}: the normal NX,NY,NZ must not be zero")
        n = n / norm
        return GroundSpec(
            "plane:" + ",".join(f"{x:g}" for x in v), tuple(float(x) for x in v[:3]), tuple(float(x) for x in n)
        )
    raise UsageError(f"--ground {t!r}: choose marker, wall:H or plane:PX,PY,PZ,NX,NY,NZ (metres, in the marker frame)")


def ground_warnings(spec: str | None) -> list[str]:
    """Plausible mistakes in a ground spec (each a message naming the probable cause); [] if none.

    Examples
    --------
    >>> ground_warnings("wall:0.45")
    []
    >>> ground_warnings("wall:450")[0]
    '--ground wall:450: the ground is 450 m from the marker; lengths are metres (450 mm would be wall:0.45)'
    """
    g = parse_ground(spec)
    p, n = np.asarray(g.point), np.asarray(g.normal)
    dist = abs(float(p @ n))  # the marker's centre to the plane
    if dist <= FAR_GROUND_M:
        return []
    kind = g.text.partition(":")[0]
    hint = f" ({dist:g} mm would be wall:{dist / 1000:g})" if kind == "wall" else ""
    return [f"--ground {g.text}: the ground is {dist:g} m from the marker; lengths are metres{hint}"]


def ground_frame(point: npt.ArrayLike, normal: npt.ArrayLike) -> np.ndarray:
    """``marker_from_ground`` (4, 4) float64 of the plane through ``point (3,)`` with ``normal (3,)`` (marker
    frame; the normal need not be unit length): the axes of the module docstring, origin at ``point``.

    Examples
    --------
    >>> ground_frame((0, 0, 0), (0, 0, 1)).tolist() == np.eye(4).tolist()
    True
    >>> m = ground_frame((0, -0.5, 0), (0, 1, 0))   # wall:0.5
    >>> m[:3, :3].round(12).tolist(), m[:3, 3].tolist()
    ([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]], [0.0, -0.5, 0.0])
    """
    z = np.asarray(normal, np.float64)
    z = z / np.linalg.norm(z)
    ex, ey = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    x = ex - (ex @ z) * z
    if np.linalg.norm(x) >= _AXIS_MIN_SIN:
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
    else:
        y = ey - (ey @ z) * z
        y /= np.linalg.norm(y)
        x = np.cross(y, z)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = x, y, z
    m[:3, 3] = np.asarray(point, np.float64)
    return m


def check_camera_above(
    cam_from_ground: npt.ArrayLike, spec: str = "", *, min_elevation_deg: float = MIN_ELEVATION_DEG
) -> None:
    """Refuse a pose that sees the ground plane from below, from within it, or edge-on.

    Parameters
    ----------
    cam_from_ground : (4, 4) float64
        The camera pose in the ground frame (``cam_from_marker @ marker_from_ground``).
    spec : str
        The ground spec, for the message.
    min_elevation_deg : float
        The least elevation of the camera above the plane, seen from the ground frame's origin.

    Raises
    ------
    UsageError
        The camera centre is not above the plane (the normal points away from the camera, or the plane
        passes through or in front of it), or it sees the plane at less than ``min_elevation_deg``.

    Examples
    --------
    >>> T = np.diag([1.0, -1.0, -1.0, 1.0]); T[2, 3] = 1.0   # camera 1 m above the marker, looking down
    >>> check_camera_above(T)           # marker plane: the camera is 1 m above it
    >>> check_camera_above(T @ ground_frame((0, 0, 1.5), (0, 0, 1)), "plane:0,0,1.5,0,0,1")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    arshadow.errors.UsageError: --ground plane:0,0,1.5,0,0,1: the camera is 0.5 m below that ground plane ...
    """
    m = np.asarray(cam_from_ground, np.float64)
    c = -m[:3, :3].T @ m[:3, 3]  # camera centre, ground frame
    h, dist = float(c[2]), float(np.linalg.norm(c))
    name = f"--ground {spec}" if spec else "the ground"
    if not h > 0:
        raise UsageError(
            f"{name}: the camera is {-h:.3g} m below that ground plane (or in it) in this photo; "
            "the plane's normal must point up, to the side the camera looks from (the marker "
            "frame: x right, y to the marker's top edge, z out of its face)"
        )
    elev = math.degrees(math.asin(min(1.0, h / dist))) if dist > 0 else 90.0
    if elev < min_elevation_deg:
        raise UsageError(
            f"{name}: the camera sees that ground plane edge-on ({elev:.2g} degrees above it, "
            f"{h:.3g} m over a distance of {dist:.3g} m); a shadow on it would be a line"
        )
