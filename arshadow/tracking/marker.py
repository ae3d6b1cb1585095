"""ArUco dictionaries, board files, marker / board detection and pose.

Frames (CONVENTIONS.md): for a single marker the world frame is the marker frame — origin at the marker
centre, x right, y up (towards the printed top edge), z out of the printed face; corners TL, TR, BR, BL =
``(-s/2, s/2, 0), (s/2, s/2, 0), (s/2, -s/2, 0), (-s/2, -s/2, 0)``. For a board, the world frame has
OpenCV's board origin (the top-left corner of the board's outer edge) but, like the marker frame,
y points towards the board's printed top edge and z out of the printed face, so the ground is z = 0 with
+z up everywhere in arshadow. That is OpenCV's board frame (x right, y *down*, z *into* the board)
turned 180 degrees about its x axis: ``X_world = diag(1, -1, -1) @ X_opencv_board``
(:data:`OPENCV_BOARD_TO_WORLD`).

Pose: ``(rvec, tvec)`` world -> OpenCV camera, as ``cv2.solvePnP`` gives them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np

from ..camera import Intrinsics, open_storage, write_storage
from ..errors import ImageError, MarkerNotFoundError, UsageError
from ..transforms import matrix_from_rvec_tvec, rotation_error_deg

__all__ = [
    "PREDEFINED_DICTIONARIES",
    "OPENCV_BOARD_TO_WORLD",
    "REFINE_METHODS",
    "refine_corners_edges",
    "DEFAULT_REFINE",
    "AMBIGUITY_FLAG",
    "get_dictionary",
    "dictionary_label",
    "marker_object_points",
    "Board",
    "load_board",
    "load_detector_params",
    "make_detector_params",
    "Detection",
    "detect_markers",
    "AltPose",
    "MarkerPose",
    "MarkerTracker",
]

#: names accepted by :func:`get_dictionary` (case-insensitive, the ``DICT_`` prefix optional)
PREDEFINED_DICTIONARIES = tuple(
    sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and not any(c.islower() for c in n))
)

#: OpenCV board frame (y down, z into the board) -> arshadow world frame (y up, z out of the board)
OPENCV_BOARD_TO_WORLD = np.diag([1.0, -1.0, -1.0])
OPENCV_BOARD_TO_WORLD.setflags(write=False)

#: corner refinement methods (``cv2.aruco.CORNER_REFINE_*``)
REFINE_METHODS = {
    "none": cv2.aruco.CORNER_REFINE_NONE,
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
    "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
    # arshadow's own: OpenCV detects without refinement, then :func:`refine_corners_edges` fits the four
    # border edges at full resolution and intersects them (unbiased at any marker size; docs/tracking.md)
    "edge": cv2.aruco.CORNER_REFINE_NONE,
}

#: the default refinement, chosen by tests/benchmarks/bench_tracking.py (see docs/tracking.md)
DEFAULT_REFINE = "subpix"

#: ``DetectorParameters.minMarkerDistanceRate`` used unless a parameter file is given (OpenCV 4.x's value)
MIN_MARKER_DISTANCE_RATE = 0.05

#: OpenCV's AprilTag corner refinement returns corners in AprilTag's pixel convention (pixel *corner* at
#: 0, centre at 0.5): subtracted to get CONVENTIONS.md's pixel-centre coordinates (measured +0.42 px
#: mean offset on synthetic photos before the correction; see docs/tracking.md)
APRILTAG_OFFSET_PX = 0.5

#: pose_ambiguity (err_best / err_second of the two IPPE solutions) at or above which a single-marker
#: pose is flagged as ambiguous (see docs/tracking.md for how it was chosen)
AMBIGUITY_FLAG = 0.3
#: a single marker with a side shorter than this (pixels) is always flagged ambiguous (see MarkerPose)
MIN_CONFIDENT_SIDE_PX = 32.0
#: a single marker whose corners move by more than this share of its side between refinement windows is
#: flagged ambiguous: blurred corners (issue 12: heavy blur gave confident poses 2-4 deg off; their
#: corners moved by 0.010-0.068 of the side, sharp ones by < 0.006)
MAX_CORNER_INSTABILITY = 0.008
#: a single marker whose black border ring has a cell lighter than this share of the way from the marker's
#: black to its white (:func:`border_occlusion`) is flagged ambiguous: something covers the marker (issue
#: 12: a grey patch over one corner gave a pose 3.7 deg off with ratio 0.25 and stable corners; its ring
#: cells read 0.45, sharp unoccluded markers <= 0.15 in the stress suite)
MAX_BORDER_OCCLUSION = 0.3


def border_occlusion(gray, quad, bits) -> float:
    """How light the lightest cell of a marker's black border ring is, as a share of the way from the
    marker's black (0) to its white (1).

    The marker ``quad (4, 2)`` (OpenCV's corner order: the marker's own top-left first) is rectified onto
    its cell grid; each cell's central quarter is averaged; black and white are the medians of the cells
    the dictionary says are black / white. Shadows and light gradients leave the ring near 0 (they darken
    the white cells, not lighten the black ring); something lighter than black lying over the marker (a
    hand, a sticker, glare) lifts its ring cells. Cells outside the image are ignored.

    Parameters
    ----------
    gray : (H, W) uint8
    quad : (4, 2) float
    bits : (n, n) uint8
        The marker's inner bits (1 = white), ``Dictionary.getBitsFromByteList``.
    """
    n, c = int(bits.shape[0]) + 2, 8
    dst = np.array([[0, 0], [n * c, 0], [n * c, n * c], [0, n * c]], np.float32)
    H = cv2.getPerspectiveTransform(np.asarray(quad, np.float32).reshape(4, 2), dst)
    can = cv2.warpPerspective(gray, H, (n * c, n * c), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=0).astype(np.float32)
    cells = can.reshape(n, c, n, c)[:, 2:6, :, 2:6].mean(axis=(1, 3))
    h, w = gray.shape[:2]
    q = np.asarray(quad, np.float64).reshape(4, 2)
    inside = np.ones((n, n), bool)
    if q.min() < 0 or q[:, 0].max() > w - 1 or q[:, 1].max() > h - 1:
        # part of the marker is off the image: a cell counts when the corners of its sampled centre are in it
        g = np.arange(n, dtype=np.float32) * c
        corners = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 1, 2)[:, :, ::-1]  # (x, y)
        for dx, dy in ((2, 2), (6, 2), (2, 6), (6, 6)):
            p = cv2.perspectiveTransform(corners + np.float32([dx, dy]), np.linalg.inv(H)).reshape(n, n, 2)
            inside &= (p[..., 0] >= 0) & (p[..., 1] >= 0) & (p[..., 0] <= w - 1) & (p[..., 1] <= h - 1)
    white = np.zeros((n, n), bool)
    white[1:-1, 1:-1] = np.asarray(bits) > 0
    ring = np.ones((n, n), bool)
    ring[1:-1, 1:-1] = False
    if not (inside & white).any() or not (inside & ~white).any() or not (inside & ring).any():
        return 0.0
    black_level, white_level = np.median(cells[inside & ~white]), np.median(cells[inside & white])
    if white_level - black_level < 1.0:
        return 0.0
    return float(((cells[inside & ring] - black_level) / (white_level - black_level)).max())


def corner_instability(gray, quad) -> float:
    """How far the 4 corners ``quad (4, 2)`` of a marker move between ``cv2.cornerSubPix`` windows of 5 and
    13 px, as a share of the quad's shortest side: ~0 for a sharp corner (any window finds the same
    point), large for a blurred or disturbed one."""
    q = np.ascontiguousarray(np.asarray(quad, np.float32).reshape(-1, 1, 2)[:4])
    side = float(np.linalg.norm(q[:, 0] - np.roll(q[:, 0], 1, axis=0), axis=1).min())
    h, w = gray.shape[:2]
    inside = (q[:, 0, 0] >= 7) & (q[:, 0, 1] >= 7) & (q[:, 0, 0] < w - 7) & (q[:, 0, 1] < h - 7)
    if side <= 0 or not np.all(inside):
        return 0.0  # too close to the border for the large window
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 0.001)
    a = cv2.cornerSubPix(gray, q.copy(), (2, 2), (-1, -1), crit)
    b = cv2.cornerSubPix(gray, q.copy(), (6, 6), (-1, -1), crit)
    return float(np.linalg.norm((a - b)[:, 0], axis=1).max() / side)


# ---------------------------------------------------------------------------------------------------
# dictionaries
# ---------------------------------------------------------------------------------------------------
def _dict_constant(name: str):
    n = name.strip().upper()
    if not n.startswith("DICT_"):
        n = "DICT_" + n
    return n, getattr(cv2.aruco, n, None) if n in PREDEFINED_DICTIONARIES else None


#: the dictionary of single-marker mode when none is given
DEFAULT_DICTIONARY = "DICT_6X6_250"


def get_dictionary(spec, base_dir=None) -> cv2.aruco.Dictionary:
    """An ArUco dictionary from a predefined name or a custom dictionary file.

    Parameters
    ----------
    spec : str, Path or cv2.aruco.Dictionary
        ``"DICT_6X6_250"`` (case-insensitive, ``DICT_`` optional), or the path of a dictionary file
        in OpenCV's format (``nmarkers``, ``markersize``, ``marker_0`` ... as written by
        ``Dictionary.writeDictionary``; YAML/XML/JSON).
    base_dir : Path, optional
        Relative dictionary paths are resolved against it (board files use their own folder).

    Raises
    ------
    UsageError
        Unknown name, or a dictionary file that is missing or unreadable.

    Examples
    --------
    >>> get_dictionary("6x6_250").markerSize
    6
    """
    if isinstance(spec, cv2.aruco.Dictionary):
        return spec
    s = str(spec)
    looks_like_file = any(s.lower().endswith(e) for e in (".yml", ".yaml", ".xml", ".json")) or "/" in s
    if not looks_like_file:
        n, const = _dict_constant(s)
        if const is None:
            raise UsageError(
                f"unknown dictionary '{s}' (use a name such as DICT_6X6_250, one of "
                f"{', '.join(PREDEFINED_DICTIONARIES)}, or a dictionary file)")
        return cv2.aruco.getPredefinedDictionary(const)
    p = Path(s)
    if base_dir is not None and not p.is_absolute():
        p = Path(base_dir) / p
    with open_storage(p, "dictionary file", UsageError) as fs:
        if fs.getNode("nmarkers").empty() or fs.getNode("markersize").empty():
            raise UsageError(f"{p}: not a dictionary file (needs 'nmarkers', 'markersize', 'marker_0'...)")
        d = cv2.aruco.Dictionary()
        try:
            ok = d.readDictionary(fs.root())
        except cv2.error as exc:
            raise UsageError(f"{p}: invalid dictionary file ({str(exc).strip().splitlines()[-1][:100]})") from None
        if not ok or d.bytesList is None or len(d.bytesList) == 0:
            raise UsageError(f"{p}: invalid dictionary file")
    return d


def dictionary_label(spec) -> str:
    """A short human name for a dictionary spec (the predefined name, or the file name)."""
    if isinstance(spec, cv2.aruco.Dictionary):
        return f"custom {spec.markerSize}x{spec.markerSize} dictionary ({len(spec.bytesList)} markers)"
    s = str(spec)
    n, const = _dict_constant(s)
    return n if const is not None else Path(s).name


def marker_object_points(length: float) -> np.ndarray:
    """(4, 3) float64 marker corners TL, TR, BR, BL in the marker (world) frame, side ``length`` m.

    Examples
    --------
    >>> marker_object_points(2.0)[0].tolist()
    [-1.0, 1.0, 0.0]
    """
    h = float(length) / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def marker_bits(dictionary, marker_id: int, border_bits: int = 1) -> np.ndarray:
    """(c, c) bool, True = white cell, for ``marker_id`` including its black border (c = size + 2 border)."""
    d = get_dictionary(dictionary)
    if not 0 <= int(marker_id) < len(d.bytesList):
        raise UsageError(f"marker id {marker_id} is not in the dictionary (ids 0..{len(d.bytesList) - 1})")
    c = d.markerSize + 2 * border_bits
    return cv2.aruco.generateImageMarker(d, int(marker_id), c, borderBits=border_bits) > 127


# ---------------------------------------------------------------------------------------------------
# boards
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Board:
    """A GridBoard or ChArUco board described by a board file.

    Parameters
    ----------
    kind : str
        ``"gridboard"`` or ``"charuco"``.
    size : (int, int)
        (columns, rows): markers for a grid board, chessboard squares for ChArUco.
    marker_length : float
        Marker side, metres.
    marker_separation : float
        Grid board: gap between markers, metres.
    square_length : float
        ChArUco: chessboard square side, metres.
    dictionary : str
        Predefined name or custom dictionary file (relative paths resolve against ``base_dir``).
    ids : tuple of int, optional
        Marker ids in OpenCV's order; default ``first_id, first_id + 1, ...``.
    legacy_pattern : bool
        ChArUco boards made by OpenCV < 4.6 with an even number of rows.
    base_dir : Path, optional
        Folder of the board file.
    """

    kind: str
    size: tuple
    marker_length: float
    dictionary: str = "DICT_6X6_250"
    marker_separation: float = 0.0
    square_length: float = 0.0
    ids: tuple | None = None
    first_id: int = 0
    legacy_pattern: bool = False
    base_dir: Path | None = None
    source: str = ""

    def __post_init__(self):
        kind = str(self.kind).lower()
        if kind not in ("gridboard", "charuco"):
            raise UsageError(f"{self._where()}board type must be 'gridboard' or 'charuco', got '{self.kind}'")
        object.__setattr__(self, "kind", kind)
        try:
            cols, rows = (int(v) for v in self.size)
        except (TypeError, ValueError):
            raise UsageError(f"{self._where()}board size must be two integers [columns, rows]") from None
        if cols < 1 or rows < 1 or (kind == "charuco" and (cols < 2 or rows < 2)):
            raise UsageError(f"{self._where()}board size {cols}x{rows} is too small")
        object.__setattr__(self, "size", (cols, rows))
        ml = float(self.marker_length)
        if not (math.isfinite(ml) and ml > 0):
            raise UsageError(f"{self._where()}marker_length must be a positive length in metres, got {ml}")
        object.__setattr__(self, "marker_length", ml)
        if kind == "gridboard":
            sep = float(self.marker_separation)
            if not (math.isfinite(sep) and sep >= 0):
                raise UsageError(f"{self._where()}marker_separation must be >= 0, got {sep}")
            object.__setattr__(self, "marker_separation", sep)
        else:
            sq = float(self.square_length)
            if not (math.isfinite(sq) and sq > ml):
                raise UsageError(
                    f"{self._where()}square_length ({sq}) must be larger than marker_length ({ml})")
            object.__setattr__(self, "square_length", sq)
        if self.ids is not None:
            object.__setattr__(self, "ids", tuple(int(i) for i in self.ids))
        n = self.n_markers
        ids = self.marker_ids
        if len(ids) != n:
            raise UsageError(f"{self._where()}board needs {n} ids, got {len(ids)}")
        nd = len(self.cv_dictionary.bytesList)
        if min(ids) < 0 or max(ids) >= nd:
            raise UsageError(f"{self._where()}marker ids {min(ids)}..{max(ids)} exceed the dictionary "
                             f"({nd} markers)")

    def _where(self):
        return f"{self.source}: " if self.source else ""

    @property
    def n_markers(self) -> int:
        cols, rows = self.size
        return cols * rows if self.kind == "gridboard" else (cols * rows) // 2

    @property
    def marker_ids(self) -> tuple:
        return self.ids if self.ids is not None else tuple(range(self.first_id, self.first_id + self.n_markers))

    @property
    def extent(self) -> tuple[float, float]:
        """(width, height) of the board's outer edge, metres."""
        cols, rows = self.size
        if self.kind == "charuco":
            return cols * self.square_length, rows * self.square_length
        s, ml = self.marker_separation, self.marker_length
        return cols * ml + (cols - 1) * s, rows * ml + (rows - 1) * s

    @cached_property
    def cv_dictionary(self) -> cv2.aruco.Dictionary:
        return get_dictionary(self.dictionary, self.base_dir)

    @cached_property
    def cv_board(self):
        """The ``cv2.aruco.GridBoard`` / ``CharucoBoard``."""
        ids = np.asarray(self.marker_ids, dtype=np.int32)
        if self.kind == "gridboard":
            return cv2.aruco.GridBoard(self.size, self.marker_length, self.marker_separation,
                                       self.cv_dictionary, ids)
        b = cv2.aruco.CharucoBoard(self.size, self.square_length, self.marker_length, self.cv_dictionary, ids)
        if self.legacy_pattern:
            b.setLegacyPattern(True)
        return b

    @cached_property
    def marker_corners_world(self) -> dict:
        """marker id -> (4, 3) float64 corners TL, TR, BR, BL in the arshadow world frame (exact, float64).

        Recomputed from the float64 lengths (OpenCV stores float32), with OpenCV's layout.
        """
        cv_obj = [np.asarray(o, dtype=np.float64).reshape(4, 3) for o in self.cv_board.getObjPoints()]
        out = {}
        ml = self.marker_length
        for mid, o in zip(self.marker_ids, cv_obj):
            if self.kind == "gridboard":
                step = ml + self.marker_separation
                col, row = round(o[0, 0] / step), round(o[0, 1] / step)
                x0, y0 = col * step, row * step
            else:
                sq = self.square_length
                col, row = math.floor(o[0, 0] / sq), math.floor(o[0, 1] / sq)
                x0, y0 = col * sq + (sq - ml) / 2.0, row * sq + (sq - ml) / 2.0
            cv = np.array([[x0, y0, 0.0], [x0 + ml, y0, 0.0], [x0 + ml, y0 + ml, 0.0], [x0, y0 + ml, 0.0]])
            if np.max(np.abs(cv - o)) > 1e-5:  # pragma: no cover - OpenCV layout changed
                raise RuntimeError("board layout differs from OpenCV's object points")
            out[int(mid)] = cv @ OPENCV_BOARD_TO_WORLD.T
        return out

    @cached_property
    def charuco_corners_world(self) -> np.ndarray:
        """ChArUco: (n, 3) float64 inner chessboard corners in the world frame, OpenCV's id order."""
        if self.kind != "charuco":
            return np.zeros((0, 3))
        cols, rows = self.size
        sq = self.square_length
        j, i = np.mgrid[1:rows, 1:cols]
        cv = np.stack([i.ravel() * sq, j.ravel() * sq, np.zeros(i.size)], axis=1)
        return cv @ OPENCV_BOARD_TO_WORLD.T

    @cached_property
    def black_squares_world(self) -> np.ndarray:
        """ChArUco: (k, 2, 2) float64 [[xmin, ymin], [xmax, ymax]] of the black squares, world frame."""
        if self.kind != "charuco":
            return np.zeros((0, 2, 2))
        cols, rows = self.size
        sq = self.square_length
        with_marker = set()
        for c in self.marker_corners_world.values():
            cx, cy = c[:, 0].mean(), -c[:, 1].mean()  # OpenCV frame centre
            with_marker.add((math.floor(cx / sq), math.floor(cy / sq)))
        out = []
        for r in range(rows):
            for c in range(cols):
                if (c, r) not in with_marker:
                    out.append([[c * sq, -(r + 1) * sq], [(c + 1) * sq, -r * sq]])
        return np.asarray(out, dtype=np.float64).reshape(-1, 2, 2)

    def to_file(self, path) -> Path:
        """Write this board as a board file (YAML/JSON by extension), atomically."""
        p = Path(path)
        with write_storage(p, "board file", UsageError) as fs:
            fs.write("type", self.kind)
            fs.startWriteStruct("size", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
            for v in self.size:
                fs.write("", int(v))
            fs.endWriteStruct()
            if self.kind == "charuco":
                fs.write("square_length", float(self.square_length))
            fs.write("marker_length", float(self.marker_length))
            if self.kind == "gridboard":
                fs.write("marker_separation", float(self.marker_separation))
            fs.write("dictionary", str(self.dictionary))
            if self.ids is not None:
                fs.startWriteStruct("ids", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
                for v in self.ids:
                    fs.write("", int(v))
                fs.endWriteStruct()
            else:
                fs.write("first_id", int(self.first_id))
            if self.kind == "charuco":
                fs.write("legacy_pattern", int(bool(self.legacy_pattern)))
        return p


def _fs_number(fs, key, path, default=None):
    node = fs.getNode(key)
    if node.empty():
        if default is None:
            raise UsageError(f"{path}: board file is missing '{key}'")
        return default
    if not (node.isReal() or node.isInt()):
        raise UsageError(f"{path}: '{key}' must be a number")
    return node.real()


def _fs_int_list(node, key, path):
    if not node.isSeq():
        raise UsageError(f"{path}: '{key}' must be a list of integers")
    vals = [node.at(i).real() for i in range(node.size())]
    if any(v != int(v) for v in vals):
        raise UsageError(f"{path}: '{key}' must be a list of integers")
    return [int(v) for v in vals]


def load_board(path) -> Board:
    """Read a board file (YAML or JSON; schema in calib/README.md).

    Raises
    ------
    UsageError
        Missing/unreadable file, missing or invalid key, unknown dictionary.
    """
    p = Path(path)
    with open_storage(p, "board file", UsageError) as fs:
        t = fs.getNode("type")
        if t.empty() or not t.isString():
            raise UsageError(f"{p}: board file needs 'type: gridboard' or 'type: charuco'")
        kind = t.string().split(" #")[0].strip().lower()
        size_node = fs.getNode("size")
        if size_node.empty():
            raise UsageError(f"{p}: board file is missing 'size' ([columns, rows])")
        size = _fs_int_list(size_node, "size", p)
        if len(size) != 2:
            raise UsageError(f"{p}: 'size' must be [columns, rows]")
        ml = _fs_number(fs, "marker_length", p)
        sep = _fs_number(fs, "marker_separation", p, default=None if kind == "gridboard" else 0.0)
        sq = _fs_number(fs, "square_length", p, default=None if kind == "charuco" else 0.0)
        dnode = fs.getNode("dictionary")
        dictionary = dnode.string() if (not dnode.empty() and dnode.isString()) else "DICT_6X6_250"
        dictionary = dictionary.split(" #")[0].strip()  # OpenCV keeps a same-line YAML comment in a string
        ids_node = fs.getNode("ids")
        ids = None if ids_node.empty() else tuple(_fs_int_list(ids_node, "ids", p))
        first_id = int(_fs_number(fs, "first_id", p, default=0))
        legacy = bool(_fs_number(fs, "legacy_pattern", p, default=0))
    b = Board(kind=kind, size=tuple(size), marker_length=ml, dictionary=dictionary, marker_separation=sep,
              square_length=sq, ids=ids, first_id=first_id, legacy_pattern=legacy, base_dir=p.parent,
              source=str(p))
    b.cv_board  # noqa: B018 - build it now so that errors name the file
    return b


# ---------------------------------------------------------------------------------------------------
# detector parameters
# ---------------------------------------------------------------------------------------------------
def load_detector_params(path) -> cv2.aruco.DetectorParameters:
    """Read ``cv2.aruco.DetectorParameters`` from a YAML/XML/JSON file (OpenCV's key names).

    Raises
    ------
    UsageError
        Missing or unreadable file.
    """
    p = Path(path)
    with open_storage(p, "detector parameter file", UsageError) as fs:
        params = cv2.aruco.DetectorParameters()
        try:
            ok = params.readDetectorParameters(fs.root())
        except cv2.error as exc:
            raise UsageError(f"{p}: invalid detector parameters ({str(exc).strip().splitlines()[-1][:100]})") from None
        if not ok:
            raise UsageError(f"{p}: no detector parameters in this file")
    return params


def make_detector_params(refine=DEFAULT_REFINE, base=None) -> cv2.aruco.DetectorParameters:
    """Detector parameters with the corner refinement ``refine`` (None keeps ``base``'s own).

    ``base`` may be a ``DetectorParameters``, a parameter file path, or None (OpenCV's defaults).
    Sub-pixel refinement stops at 0.01 px instead of OpenCV's 0.1 px (measured: see docs/tracking.md).
    """
    if base is None:
        params = cv2.aruco.DetectorParameters()
        # OpenCV 5 raised the default from 0.05 to 0.125 (x perimeter). A marker printed with a white margin
        # under ~0.5 x its side then lies "too close" to the paper's own outline (also a quad) and is
        # dropped: 4 of 60 synthetic photos at 1280x720 missed the marker; 0.05 finds all 60 and adds no
        # false detection (tests/benchmarks, docs/tracking.md)
        params.minMarkerDistanceRate = MIN_MARKER_DISTANCE_RATE
    elif isinstance(base, cv2.aruco.DetectorParameters):
        params = _copy_params(base)
    else:
        params = load_detector_params(base)
    if refine is not None:
        key = str(refine).lower()
        if key not in REFINE_METHODS:
            raise UsageError(f"unknown corner refinement '{refine}' (use one of {', '.join(REFINE_METHODS)})")
        params.cornerRefinementMethod = REFINE_METHODS[key]
        if key == "subpix":
            params.cornerRefinementMinAccuracy = 0.01
            params.cornerRefinementMaxIterations = 50
    return params


def _copy_params(p: cv2.aruco.DetectorParameters) -> cv2.aruco.DetectorParameters:
    q = cv2.aruco.DetectorParameters()
    for name in dir(p):
        if name.startswith("_"):
            continue
        try:
            v = getattr(p, name)
        except Exception:  # pragma: no cover
            continue
        if callable(v):
            continue
        try:
            setattr(q, name, v)
        except (AttributeError, TypeError):  # read-only
            pass
    return q


# ---------------------------------------------------------------------------------------------------
# detection
# ---------------------------------------------------------------------------------------------------
@dataclass
class Detection:
    """Markers found in one image.

    Attributes
    ----------
    ids : (n,) int
        Marker ids, in detection order (an id may repeat).
    corners : (n, 4, 2) float64
        Corner pixels TL, TR, BR, BL per marker.
    n_rejected : int
        Candidates that were not markers.
    """

    ids: np.ndarray
    corners: np.ndarray
    n_rejected: int = 0

    def __len__(self):
        return int(self.ids.size)

    @property
    def by_id(self) -> dict:
        """id -> (4, 2) corners (the first detection of a repeated id)."""
        out = {}
        for i, c in zip(self.ids.tolist(), self.corners):
            out.setdefault(int(i), c)
        return out


def _gray(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 2 and img.dtype == np.uint8:
        return img
    if img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8:
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    from ..io import to_bgr8

    return cv2.cvtColor(to_bgr8(img), cv2.COLOR_BGR2GRAY)


def _detection(corners, ids, rejected, params=None) -> Detection:
    if ids is None or len(ids) == 0:
        return Detection(np.zeros(0, dtype=int), np.zeros((0, 4, 2)), len(rejected) if rejected is not None else 0)
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
    if params is not None and params.cornerRefinementMethod == cv2.aruco.CORNER_REFINE_APRILTAG:
        c = c - APRILTAG_OFFSET_PX
    return Detection(np.asarray(ids).ravel().astype(int), c, len(rejected) if rejected is not None else 0)


def detect_markers(image, dictionary="DICT_6X6_250", params=None, refine=DEFAULT_REFINE) -> Detection:
    """Detect every marker of ``dictionary`` in ``image``.

    Parameters
    ----------
    image : (H, W, 3) uint8 BGR or (H, W) uint8
    dictionary : str, Path or cv2.aruco.Dictionary
    params : DetectorParameters or path, optional
        Base detector parameters (OpenCV's defaults when None).
    refine : str or None
        Corner refinement (``none``, ``subpix``, ``contour``, ``apriltag``); None keeps ``params``'.

    Returns
    -------
    Detection
    """
    p = make_detector_params(refine, params)
    det = cv2.aruco.ArucoDetector(get_dictionary(dictionary), p)
    corners, ids, rejected = det.detectMarkers(_gray(image))
    return _detection(corners, ids, rejected, p)


def refine_corners_edges(gray, corners, intrinsics=None, *, bits: int = 8, iterations: int = 3,
                         n_samples: int = 24, reach_in: float = 0.45, reach_out: float = 0.45,
                         tol_px: float = 0.01) -> np.ndarray:
    """Refine marker corners by fitting the four border edges and intersecting them.

    Why: ``cv2.cornerSubPix`` (ArUco's ``subpix``) puts a corner where the image gradients around it are
    orthogonal to the corner direction. At an *outer* corner of a dark square the blur of the optics
    (and the demosaicing / JPEG) rounds the corner off, and the gradient-orthogonality point moves
    *into* the square by a fraction of the blur radius. The shift is a fixed number of pixels, so the
    smaller the marker, the larger the relative error: every corner moves inwards, the marker looks
    smaller and the pose comes out too far (1-4 % at 640x360 with a 45-px marker, docs/video.md).
    A straight edge blurred by a symmetric point-spread function keeps its 50 % level exactly at the
    edge, so the lines through the edges' mid-level crossings, away from the corners, are unbiased;
    their intersections are the corners.

    Per edge: ``n_samples`` intensity profiles across the edge (bilinear, 0.25-px steps, from the
    inner black border (``reach_in`` of a cell: the data cells beyond it may be white) to the paper
    (``reach_out`` of a cell); the two reaches must be equal: with a blur comparable to the window the
    profile's ends do not reach the plateaus, and only a window centred on the edge truncates them
    equally (measured: 0.45 / 0.6 of a cell puts the corners 0.11 px outwards at blur 0.8, 0.45 / 0.45
    0.002 px)) between 15 % and 85 % of
    its length; the 50 % crossing between the profile's dark and light ends, linearly interpolated; the
    crossings are undistorted to pinhole pixels (``intrinsics``), a total-least-squares line is fitted
    (with one outlier rejection pass), adjacent lines are intersected and the corners distorted back.
    Repeated around the new corners (the profiles re-centred) until no corner moves more than ``tol_px``
    (at most ``iterations`` times).

    Parameters
    ----------
    gray : (H, W) uint8
    corners : (n, 4, 2) float64
        Initial corners TL, TR, BR, BL (distorted pixels), within about a pixel.
    intrinsics : Intrinsics, optional
        The camera (its lens distortion makes the edges curved in the image; None: straight).
    bits : int
        Marker cells across, border included (ArUco 6x6: 8).

    Returns
    -------
    (n, 4, 2) float64
        Refined corners (a marker whose edges cannot be measured keeps its input corners).
    """
    img = np.asarray(gray)
    c_all = np.asarray(corners, np.float64).reshape(-1, 4, 2).copy()
    H, W = img.shape[:2]
    dist = intrinsics is not None and intrinsics.has_distortion
    t = np.linspace(0.15, 0.85, n_samples)
    for m in range(len(c_all)):
        c = c_all[m]
        for _ in range(iterations):
            side = float(np.mean(np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)))
            bit = side / bits
            offs = np.arange(-float(np.clip(reach_in * bit, 1.0, 6.0)), float(np.clip(reach_out * bit, 1.0, 8.0)) + 1e-9,
                             0.25)
            centre = c.mean(axis=0)
            a, b = c, np.roll(c, -1, axis=0)  # edge k: corner k -> corner k + 1
            d = b - a
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            nrm = np.stack([d[:, 1], -d[:, 0]], axis=1)
            mid = 0.5 * (a + b)
            flip = np.sum((mid - centre) * nrm, axis=1) < 0
            nrm[flip] *= -1.0  # outward: from the black border to the paper
            base = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]  # (4, S, 2)
            pts = base[:, :, None, :] + offs[None, None, :, None] * nrm[:, None, None, :]  # (4, S, P, 2)
            if pts[..., 0].min() < 0 or pts[..., 1].min() < 0 or pts[..., 0].max() > W - 1 or pts[..., 1].max() > H - 1:
                break  # too close to the image border to measure: keep the corners
            mx = np.ascontiguousarray(pts[..., 0].reshape(-1, len(offs)), np.float32)
            my = np.ascontiguousarray(pts[..., 1].reshape(-1, len(offs)), np.float32)
            prof = cv2.remap(img, mx, my, cv2.INTER_LINEAR).astype(np.float64)  # (4S, P)
            lo, hi = prof[:, :2].mean(axis=1), prof[:, -2:].mean(axis=1)
            ok = hi - lo > 20.0  # a real dark-to-light edge
            level = 0.5 * (lo + hi)
            above = prof > level[:, None]
            # the crossing: the last sample below the level before the profile stays above it
            idx = len(offs) - 1 - np.argmin(above[:, ::-1], axis=1)  # last index that is below
            idx = np.clip(idx, 0, len(offs) - 2)
            ok &= ~above[np.arange(len(prof)), idx] & above[np.arange(len(prof)), idx + 1]
            p0, p1 = prof[np.arange(len(prof)), idx], prof[np.arange(len(prof)), idx + 1]
            frac = (level - p0) / np.where(p1 - p0 == 0, 1.0, p1 - p0)
            o = offs[idx] + frac * (offs[1] - offs[0])
            edge_pts = (base.reshape(-1, 2) + o[:, None] * np.repeat(nrm, n_samples, axis=0))
            ok = ok.reshape(4, n_samples)
            if np.any(ok.sum(axis=1) < 4):
                break
            if dist:
                edge_pts = intrinsics.undistort_pixels(edge_pts)
            q = edge_pts.reshape(4, n_samples, 2)
            w = ok.astype(np.float64)
            for _rej in range(2):  # total-least-squares line per edge (closed form), one rejection pass
                sw = w.sum(axis=1)
                mu = np.einsum("es,esk->ek", w, q) / sw[:, None]
                dq = q - mu[:, None, :]
                sxx = np.einsum("es,es->e", w, dq[..., 0] ** 2)
                syy = np.einsum("es,es->e", w, dq[..., 1] ** 2)
                sxy = np.einsum("es,es->e", w, dq[..., 0] * dq[..., 1])
                th = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # direction of the line
                nl = np.stack([-np.sin(th), np.cos(th)], axis=1)  # its unit normal
                r = np.einsum("esk,ek->es", dq, nl)
                sd = np.sqrt(np.einsum("es,es->e", w, r * r) / sw)
                keep = (np.abs(r) <= np.maximum(3.0 * sd, 0.05)[:, None]) & ok
                if _rej or np.array_equal(keep, ok) or np.any(keep.sum(axis=1) < 4):
                    break
                w = keep.astype(np.float64)
            lines = np.column_stack([nl, -np.einsum("ek,ek->e", nl, mu)])  # (4, 3): a x + b y + c = 0
            prev = np.roll(lines, 1, axis=0)  # corner k = edge k-1 x edge k
            x = np.stack([prev[:, 1] * lines[:, 2] - prev[:, 2] * lines[:, 1],
                          prev[:, 2] * lines[:, 0] - prev[:, 0] * lines[:, 2],
                          prev[:, 0] * lines[:, 1] - prev[:, 1] * lines[:, 0]], axis=1)
            if np.any(np.abs(x[:, 2]) < 1e-12):
                break
            new = x[:, :2] / x[:, 2:3]
            if dist:
                new = intrinsics.distort_pixels(new)
            move = np.max(np.linalg.norm(new - c, axis=1)) if np.all(np.isfinite(new)) else np.inf
            if not move < 0.25 * side:
                break
            c = new
            if move <= tol_px:
                break
        c_all[m] = c
    return c_all


# ---------------------------------------------------------------------------------------------------
# pose
# ---------------------------------------------------------------------------------------------------
@dataclass
class AltPose:
    """The other IPPE solution (kept for sequences: the video layer may prefer it)."""

    rvec: np.ndarray
    tvec: np.ndarray
    cam_from_world: np.ndarray
    reprojection_error_px: float


@dataclass
class MarkerPose:
    """Pose of the marker (or board) in one image.

    Attributes
    ----------
    rvec, tvec : (3,) float64
        World -> OpenCV camera (as ``cv2.solvePnP`` gives them).
    cam_from_world : (4, 4) float64
    marker_ids : list[int]
        The reference marker first, then every other detected id (single marker), or the board's
        detected ids.
    reprojection_error_px : float
        RMS distance between the detected and re-projected points, pixels.
    pose_ambiguity : float or None
        ``err_best / err_second`` of the two planar (IPPE) solutions, in (0, 1]; high = ambiguous
        (flagged when >= :data:`AMBIGUITY_FLAG`). None when there is no second solution.
    corners : (n, 2) float64
        The detected image points used for the pose.
    object_points : (n, 3) float64
        Their world coordinates.
    n_points : int
    alternative : AltPose or None
        The other IPPE solution.
    chosen_by : str
        ``"error"`` (lower reprojection error) or ``"previous"`` (closer to the previous frame's pose).
    intrinsics : Intrinsics
        The intrinsics used (scaled to the image when ``scaled``).
    scaled : bool
        The calibration was scaled to this image's size (same aspect ratio).
    all_corners : dict[int, (4, 2)]
        Every detected marker's corners.
    kind : str
        ``"marker"``, ``"gridboard"`` or ``"charuco"``.
    timings_ms : dict
        ``{"detect": ms, "pose": ms}`` spent in :meth:`MarkerTracker.estimate`.
    """

    rvec: np.ndarray
    tvec: np.ndarray
    cam_from_world: np.ndarray
    marker_ids: list
    reprojection_error_px: float
    pose_ambiguity: float | None
    corners: np.ndarray
    object_points: np.ndarray
    n_points: int
    alternative: AltPose | None = None
    chosen_by: str = "error"
    intrinsics: Intrinsics | None = None
    scaled: bool = False
    all_corners: dict = field(default_factory=dict)
    ambiguity_threshold: float = AMBIGUITY_FLAG
    kind: str = "marker"
    timings_ms: dict = field(default_factory=dict)
    #: single marker: how far its corners move between sub-pixel refinement windows of 5 and 13 px, as a
    #: share of its shortest side (:func:`corner_instability`); None for boards
    corner_instability: float | None = None
    #: single marker: how light the lightest cell of its black border ring is, between its black (0) and
    #: white (1) (:func:`border_occlusion`); None for boards
    border_occlusion: float | None = None

    @property
    def ambiguous(self) -> bool:
        """True when the two IPPE solutions explain the corners almost equally well, or (single marker)
        when the marker is under :data:`MIN_CONFIDENT_SIDE_PX` across: its corners cannot tell the two
        solutions apart reliably (issue 12's stress suite: a 20-px marker gave a pose 69 deg off with
        ratio 0.20), its corners are blurred (:data:`MAX_CORNER_INSTABILITY`) or something lies over it
        (:data:`MAX_BORDER_OCCLUSION`)."""
        if self.pose_ambiguity is not None and self.pose_ambiguity >= self.ambiguity_threshold:
            return True
        if self.corner_instability is not None and self.corner_instability > MAX_CORNER_INSTABILITY:
            return True
        if self.border_occlusion is not None and self.border_occlusion > MAX_BORDER_OCCLUSION:
            return True
        if self.kind == "marker" and self.pose_ambiguity is not None and len(self.corners) >= 4:
            q = np.asarray(self.corners, np.float64)[:4]
            return bool(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1).min() < MIN_CONFIDENT_SIDE_PX)
        return False

    def swapped(self) -> MarkerPose:
        """This pose with the alternative IPPE solution chosen instead (for sequences)."""
        if self.alternative is None:
            raise UsageError("this pose has no alternative solution")
        a = self.alternative
        alt = AltPose(self.rvec, self.tvec, self.cam_from_world, self.reprojection_error_px)
        return replace(self, rvec=a.rvec, tvec=a.tvec, cam_from_world=a.cam_from_world,
                       reprojection_error_px=a.reprojection_error_px, alternative=alt, chosen_by="previous",
                       timings_ms=dict(self.timings_ms))


def _rms(intr: Intrinsics, obj, img, rvec, tvec) -> float:
    proj = cv2.projectPoints(obj, rvec, tvec, intr.K, intr.dist_cv)[0].reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=1))))


def _solve_planar(intr: Intrinsics, obj, img, square: bool, lm: bool = True):
    """Both planar (IPPE) solutions, sorted by RMS reprojection error, and their ambiguity ratio.

    The ratio ``err_best / err_second`` is taken from the two IPPE solutions as IPPE returns them
    (each is the exact pose of one of the two homography-consistent interpretations). Then each
    solution is polished by Levenberg-Marquardt on the reprojection error (``lm``); a second solution
    that LM drags onto the first is kept unrefined, so the alternative stays a distinct pose.

    Returns
    -------
    sols : list of (rvec (3,), tvec (3,), rms_px)
    ratio : float or None
    """
    flags = cv2.SOLVEPNP_IPPE_SQUARE if square else cv2.SOLVEPNP_IPPE
    K, dist = intr.K, intr.dist_cv
    obj = np.ascontiguousarray(obj, dtype=np.float64).reshape(-1, 3)
    img = np.ascontiguousarray(img, dtype=np.float64).reshape(-1, 2)
    try:
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, K, dist, flags=flags)
    except cv2.error as exc:
        raise MarkerNotFoundError(f"pose estimation failed ({str(exc).strip().splitlines()[-1][:80]})") from None
    raw = []
    for r, t in zip(rvecs[:n], tvecs[:n]):
        r = np.asarray(r, np.float64).reshape(3, 1).copy()
        t = np.asarray(t, np.float64).reshape(3, 1).copy()
        raw.append((r, t, _rms(intr, obj, img, r, t)))
    if not raw:
        raise MarkerNotFoundError("pose estimation found no solution")
    raw.sort(key=lambda s: s[2])
    ratio = None
    if len(raw) > 1:
        e0, e1 = raw[0][2], raw[1][2]
        ratio = 1.0 if e1 <= 0 else float(min(1.0, e0 / e1))
    sols = []
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12)
    for k, (r, t, e) in enumerate(raw[:2]):
        if lm:
            r2, t2 = cv2.solvePnPRefineLM(obj, img, K, dist, r.copy(), t.copy(), criteria=crit)
            e2 = _rms(intr, obj, img, r2, t2)
            collapsed = k > 0 and np.linalg.norm(r2.ravel() - sols[0][0]) < 1e-5
            if e2 <= e and not collapsed:
                r, t, e = r2, t2, e2
        sols.append((r.ravel(), t.ravel(), e))
    return sols, ratio


class MarkerTracker:
    """Detect a marker or board and estimate its pose.

    Parameters
    ----------
    intrinsics : Intrinsics
        The calibration (scaled automatically to a same-aspect image size).
    dictionary : str, Path or cv2.aruco.Dictionary, optional
        Marker dictionary (single-marker mode, default :data:`DEFAULT_DICTIONARY`). A board brings its own:
        a different one given here is a :class:`~arshadow.errors.UsageError`.
    marker_length : float
        Marker side in metres (single-marker mode).
    marker_id : int, optional
        The reference marker; default: the lowest id found.
    board : Board or path, optional
        A grid or ChArUco board (board file path accepted).
    refine : str or None
        Corner refinement (default :data:`DEFAULT_REFINE`, chosen by the benchmark); None keeps the
        detector parameters' own setting.
    detector_params : DetectorParameters or path, optional
        Base detector parameters.
    detector : str or object
        ``"full"`` (default): ``cv2.aruco.ArucoDetector`` with ``detector_params``; ``"fast"``: the fast
        first pass of :mod:`arshadow.tracking.fastdetect` (one 7-px threshold window unless ``detector_params`` are
        given, half-resolution detection for a single marker); or any object with OpenCV's
        ``detectMarkers(gray)`` (and ``refineDetectedMarkers`` for grid boards).
    ambiguity_threshold : float
        ``pose_ambiguity`` at or above which a pose is flagged.
    pnp_refine : bool
        Polish the IPPE pose with Levenberg-Marquardt (``cv2.solvePnPRefineLM``) on the reprojection
        error (default; measured in docs/tracking.md).
    track_roi : bool
        Video: search a window around the last detection first, the whole frame when it holds no marker
        (:class:`arshadow.tracking.roi_track.TrackingDetector`; single markers and ChArUco, not grid boards).

    Examples
    --------
    >>> from arshadow.synth import look_at_pose, render_marker_photo
    >>> cam = Intrinsics(1000.0, 1000.0, 639.5, 359.5, 1280, 720)
    >>> photo = render_marker_photo(cam, look_at_pose([0.1, -0.2, 0.4], [0, 0, 0]), marker_length=0.05)
    >>> pose = MarkerTracker(cam, marker_length=0.05).estimate(photo.image)
    >>> pose.marker_ids, bool(np.allclose(pose.tvec, photo.cam_from_world[:3, 3], atol=2e-3))
    ([0], True)
    """

    def __init__(self, intrinsics: Intrinsics, dictionary=None, marker_length=None, marker_id=None,
                 board=None, refine=DEFAULT_REFINE, detector_params=None, ambiguity_threshold=AMBIGUITY_FLAG,
                 pnp_refine=True, detector="full", track_roi=False):
        if not isinstance(intrinsics, Intrinsics):
            raise UsageError("intrinsics must be an arshadow.camera.Intrinsics")
        self.intrinsics = intrinsics
        if board is not None and not isinstance(board, Board):
            board = load_board(board)
        self.board = board
        if board is None:
            if marker_length is None:
                raise UsageError("give the marker side length (marker_length, metres) or a board")
            ml = float(marker_length)
            if not (math.isfinite(ml) and ml > 0):
                raise UsageError(f"marker length must be a positive number of metres, got {marker_length}")
            self.marker_length = ml
            dictionary = DEFAULT_DICTIONARY if dictionary is None else dictionary
            self.dictionary = get_dictionary(dictionary)
            self.dictionary_name = dictionary_label(dictionary)
        else:
            if dictionary is not None and dictionary_label(dictionary) != dictionary_label(board.dictionary):
                raise UsageError(f"dictionary {dictionary_label(dictionary)} conflicts with the board file's "
                                 f"dictionary {dictionary_label(board.dictionary)} (a board names its own: leave "
                                 "the dictionary out or make them agree)")
            if marker_length is not None and abs(float(marker_length) - board.marker_length) > 1e-9:
                raise UsageError("marker_length conflicts with the board file's marker_length")
            self.marker_length = board.marker_length
            self.dictionary = board.cv_dictionary
            self.dictionary_name = f"the board's dictionary ({dictionary_label(board.dictionary)})"
        if marker_id is not None:
            marker_id = int(marker_id)
            if not 0 <= marker_id < len(self.dictionary.bytesList):
                raise UsageError(f"marker id {marker_id} is not in {self.dictionary_name} "
                                 f"(ids 0..{len(self.dictionary.bytesList) - 1})")
        self.marker_id = marker_id
        self.refine = refine
        self.pnp_refine = bool(pnp_refine)
        fast = isinstance(detector, str) and detector == "fast"
        if isinstance(detector, str) and detector not in ("full", "fast"):
            raise UsageError(f"detector {detector!r}: choose 'full', 'fast' or a detector object")
        if fast and detector_params is None:
            from .fastdetect import fast_detector_params

            detector_params = fast_detector_params()
        self.params = make_detector_params(refine, detector_params)
        self.ambiguity_threshold = float(ambiguity_threshold)
        self.detector_kind = detector if isinstance(detector, str) else "custom"
        self._detector = cv2.aruco.ArucoDetector(self.dictionary, self.params)
        if fast:
            from .fastdetect import wrap_fast_detector

            self._detector = wrap_fast_detector(self._detector, board)
        elif not isinstance(detector, str):
            self._detector = detector
        if track_roi:
            from .roi_track import TrackingDetector

            self._detector = TrackingDetector(self._detector, marker_id)
        self._charuco = None
        if board is not None and board.kind == "charuco":
            cp = cv2.aruco.CharucoParameters()
            cp.minMarkers = 1
            self._charuco_params = cp
        self._charuco_for = None

    # -- helpers ---------------------------------------------------------------------------------------
    def _intrinsics_for(self, image) -> tuple[Intrinsics, bool]:
        h, w = np.asarray(image).shape[:2]
        return self.intrinsics.for_image(w, h)

    @property
    def last_search(self) -> str | None:
        """With ``track_roi``: where the last detection searched, ``"window"`` (around the previous marker)
        or ``"full"`` (the whole frame); None without ``track_roi``."""
        return getattr(self._detector, "last", None)

    def _charuco_detector(self, intr: Intrinsics):
        if self._charuco_for != intr:
            cp = self._charuco_params
            cp.cameraMatrix = intr.K
            cp.distCoeffs = intr.dist_cv
            self._charuco = cv2.aruco.CharucoDetector(self.board.cv_board, cp, self.params)
            self._charuco_for = intr
        return self._charuco

    def detect(self, image) -> Detection:
        """Detect the markers of this tracker's dictionary (no pose)."""
        gray = _gray(image)
        corners, ids, rejected = self._detector.detectMarkers(gray)
        det = _detection(corners, ids, rejected, self.params)
        if self.refine == "edge" and len(det):
            det.corners = refine_corners_edges(gray, det.corners, self._intrinsics_for(gray)[0])
        return det

    # -- pose ------------------------------------------------------------------------------------------
    def estimate(self, image_bgr, previous=None) -> MarkerPose:
        """Detect and estimate the pose in one image.

        Parameters
        ----------
        image_bgr : (H, W, 3) uint8
            The photo (its size must match the calibration or have the same aspect ratio).
        previous : MarkerPose or (4, 4) float64, optional
            The previous frame's pose. When this frame's pose is ambiguous, the IPPE solution whose
            rotation is closer to ``previous`` is chosen (``chosen_by = "previous"``).

        Raises
        ------
        MarkerNotFoundError
            No marker (or not the requested id, or too few board points).
        CalibrationError
            The image size does not fit the calibration.
        """
        img = np.asarray(image_bgr)
        if img.ndim not in (2, 3) or img.size == 0:
            raise ImageError(f"not an image (shape {img.shape})")
        intr, scaled = self._intrinsics_for(img)
        gray = _gray(img)
        self._t_detect = None
        t0 = time.perf_counter()
        if self.board is None:
            pose = self._estimate_marker(gray, intr)
        elif self.board.kind == "charuco":
            pose = self._estimate_charuco(gray, intr)
        else:
            pose = self._estimate_gridboard(gray, intr)
        total = 1e3 * (time.perf_counter() - t0)
        det_ms = total if self._t_detect is None else 1e3 * (self._t_detect - t0)
        pose.timings_ms = {"detect": det_ms, "pose": total - det_ms}
        pose.intrinsics, pose.scaled = intr, scaled
        pose.ambiguity_threshold = self.ambiguity_threshold
        if pose.kind == "marker":
            pose.corner_instability = corner_instability(gray, pose.corners[:4])
            ref = pose.marker_ids[0]
            bits = self.dictionary.getBitsFromByteList(self.dictionary.bytesList[ref : ref + 1],
                                                       self.dictionary.markerSize)
            pose.border_occlusion = border_occlusion(gray, pose.corners[:4], bits)
        if previous is not None and pose.alternative is not None and pose.ambiguous:
            prev = previous.cam_from_world if isinstance(previous, MarkerPose) else np.asarray(previous, float)
            if rotation_error_deg(pose.alternative.cam_from_world[:3, :3], prev[:3, :3]) < \
                    rotation_error_deg(pose.cam_from_world[:3, :3], prev[:3, :3]):
                pose = pose.swapped()
        return pose

    def _make_pose(self, solved, obj, img, ids, all_corners, kind):
        sols, ratio = solved
        r, t, e = sols[0]
        alt = None
        if len(sols) > 1:
            r2, t2, e2 = sols[1]
            alt = AltPose(r2, t2, matrix_from_rvec_tvec(r2, t2), e2)
        return MarkerPose(r, t, matrix_from_rvec_tvec(r, t), [int(i) for i in ids], e, ratio,
                          np.asarray(img, np.float64).reshape(-1, 2), np.asarray(obj, np.float64).reshape(-1, 3),
                          int(len(obj)), alt, "error", None, False, all_corners, self.ambiguity_threshold, kind)

    def _estimate_marker(self, gray, intr) -> MarkerPose:
        corners, ids, rejected = self._detector.detectMarkers(gray)
        self._t_detect = time.perf_counter()
        det = _detection(corners, ids, rejected, self.params)
        if len(det) == 0:
            raise MarkerNotFoundError(f"no marker of {self.dictionary_name} found")
        if self.refine == "edge":
            det.corners = refine_corners_edges(gray, det.corners, intr)
        found = sorted(set(det.ids.tolist()))
        if self.marker_id is not None:
            if self.marker_id not in found:
                raise MarkerNotFoundError(
                    f"marker id {self.marker_id} not found (found {', '.join(map(str, found))})")
            ref = self.marker_id
        else:
            ref = found[0]
        by_id = det.by_id
        img = by_id[ref]
        obj = marker_object_points(self.marker_length)
        sols = _solve_planar(intr, obj, img, square=True, lm=self.pnp_refine)
        ids = [ref] + [i for i in found if i != ref]
        return self._make_pose(sols, obj, img, ids, by_id, "marker")

    def _estimate_gridboard(self, gray, intr) -> MarkerPose:
        corners, ids, rejected = self._detector.detectMarkers(gray)
        if ids is None or len(ids) == 0:
            raise MarkerNotFoundError(f"no marker of {self.dictionary_name} found")
        corners, ids, rejected, _ = self._detector.refineDetectedMarkers(
            gray, self.board.cv_board, corners, ids, rejected, intr.K, intr.dist_cv)
        det = _detection(corners, ids, rejected, self.params)
        self._t_detect = time.perf_counter()
        obj, img = self.board.cv_board.matchImagePoints(tuple(c.reshape(1, 4, 2).astype(np.float32) for c in det.corners),
                                                        det.ids.reshape(-1, 1).astype(np.int32))
        if obj is None or len(obj) < 4:
            raise MarkerNotFoundError(
                f"none of the board's markers found (found ids {', '.join(map(str, sorted(set(det.ids.tolist()))))})")
        obj = np.asarray(obj, np.float64).reshape(-1, 3) @ OPENCV_BOARD_TO_WORLD.T
        img = np.asarray(img, np.float64).reshape(-1, 2)
        sols = _solve_planar(intr, obj, img, square=False, lm=self.pnp_refine)
        board_ids = set(self.board.marker_ids)
        used = [i for i in sorted(set(det.ids.tolist())) if i in board_ids]
        return self._make_pose(sols, obj, img, used, det.by_id, "gridboard")

    def _estimate_charuco(self, gray, intr) -> MarkerPose:
        det = self._charuco_detector(intr)
        ch_corners, ch_ids, m_corners, m_ids = det.detectBoard(gray)
        self._t_detect = time.perf_counter()
        if m_ids is None or len(m_ids) == 0:
            raise MarkerNotFoundError(f"no marker of {self.dictionary_name} found")
        n = 0 if ch_ids is None else len(ch_ids)
        if n < 4:
            raise MarkerNotFoundError(f"ChArUco board: only {n} chessboard corners found (need at least 4)")
        if self.board.cv_board.checkCharucoCornersCollinear(ch_ids):
            raise MarkerNotFoundError("ChArUco board: the detected corners are collinear (no pose)")
        obj, img = self.board.cv_board.matchImagePoints(ch_corners, ch_ids)
        obj = np.asarray(obj, np.float64).reshape(-1, 3) @ OPENCV_BOARD_TO_WORLD.T
        img = np.asarray(img, np.float64).reshape(-1, 2)
        sols = _solve_planar(intr, obj, img, square=False, lm=self.pnp_refine)
        mdet = _detection(m_corners, m_ids, None, self.params)
        return self._make_pose(sols, obj, img, sorted(set(mdet.ids.tolist())), mdet.by_id, "charuco")
