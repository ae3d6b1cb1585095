"""Board model and board files: grid and ChArUco boards, their world frame and their marker corners.

The board's world frame has OpenCV's board origin (the top-left corner of the board's outer edge) but,
like the marker frame, y points towards the board's printed top edge and z out of the printed face, so
the ground is z = 0 with +z up everywhere in arshadow. That is OpenCV's board frame (x right, y *down*,
z *into* the board) turned 180 degrees about its x axis: ``X_world = diag(1, -1, -1) @ X_opencv_board``
(:data:`OPENCV_BOARD_TO_WORLD`).

A **generic board** (``type: markers``) is any set of markers at known 3D corners (OpenCV's
``cv2.aruco.Board(objPoints, dictionary, ids)``): its corners are given directly in the arshadow world
frame (z out of the printed face, y towards its top; TL, TR, BR, BL of each marker as printed), so its
world frame is whatever frame the file's corners are in. The ArUco library's own layout files
(``aruco_bc_markers``, e.g. ``chessboardinfo_meters.yml``) are in OpenCV's board convention (y down,
z into the board) and are turned into the world frame with :data:`OPENCV_BOARD_TO_WORLD` when read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np

from ..camera.model import open_storage, write_storage
from ..errors import UsageError
from .dictionary import get_dictionary

__all__ = ["OPENCV_BOARD_TO_WORLD", "BOARD_KINDS", "Board", "load_board", "read_aruco_layout"]

#: a board whose marker side is longer than this (metres) is taken for a file in millimetres / centimetres
MAX_PLAUSIBLE_MARKER_M = 1.0

#: board types of a board file's ``type``
BOARD_KINDS = ("gridboard", "charuco", "markers")

#: OpenCV board frame (y down, z into the board) -> arshadow world frame (y up, z out of the board)
OPENCV_BOARD_TO_WORLD = np.diag([1.0, -1.0, -1.0])
OPENCV_BOARD_TO_WORLD.setflags(write=False)


@dataclass(frozen=True, eq=False)
class Board:
    """A GridBoard, ChArUco board or generic board (markers at known corners) described by a board file.

    Parameters
    ----------
    kind : str
        ``"gridboard"``, ``"charuco"`` or ``"markers"``.
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
    markers : dict, optional
        ``kind == "markers"``: id -> (4, 3) float64 corners TL, TR, BR, BL in the world frame, metres
        (``size`` and ``marker_length`` are then derived: ``(n, 1)`` and the mean marker side).
    inverted : bool
        The markers are printed white on black (detected as such; ``inverted: 1`` in a board file).
    """

    kind: str
    size: tuple[int, ...]
    marker_length: float
    dictionary: str = "DICT_6X6_250"
    marker_separation: float = 0.0
    square_length: float = 0.0
    ids: tuple[int, ...] | None = None
    first_id: int = 0
    legacy_pattern: bool = False
    base_dir: Path | None = None
    source: str = ""
    markers: dict[int, np.ndarray] | None = None
    inverted: bool = False

    def __post_init__(self) -> None:
        kind = str(self.kind).lower()
        if kind not in BOARD_KINDS:
            raise UsageError(f"{self._where()}board type must be one of {', '.join(BOARD_KINDS)}, got '{self.kind}'")
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "inverted", bool(self.inverted))
        if kind == "markers":
            self._init_markers()
            return
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
                raise UsageError(f"{self._where()}square_length ({sq}) must be larger than marker_length ({ml})")
            object.__setattr__(self, "square_length", sq)
        if self.ids is not None:
            object.__setattr__(self, "ids", tuple(int(i) for i in self.ids))
        self._check_ids()

    def _init_markers(self) -> None:
        """Validate a generic board's ``markers`` and derive ``size``, ``marker_length`` and ``ids``."""
        if not self.markers:
            raise UsageError(f"{self._where()}a 'markers' board needs a non-empty 'markers' list")
        out: dict[int, np.ndarray] = {}
        for mid, c in dict(self.markers).items():
            c = np.asarray(c, np.float64)
            if c.shape != (4, 3) or not np.all(np.isfinite(c)):
                raise UsageError(f"{self._where()}marker {mid}: corners must be 4 finite [x, y, z] points")
            side = np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1)
            if side.min() <= 0:
                raise UsageError(f"{self._where()}marker {mid}: two of its corners coincide")
            if int(mid) in out:
                raise UsageError(f"{self._where()}marker id {mid} is listed twice")
            c.setflags(write=False)
            out[int(mid)] = c
        sides = [np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1).mean() for c in out.values()]
        object.__setattr__(self, "markers", out)
        object.__setattr__(self, "size", (len(out), 1))
        object.__setattr__(self, "marker_length", float(np.mean(sides)))
        object.__setattr__(self, "ids", tuple(out))
        self._check_ids()

    def _check_ids(self) -> None:
        n = self.n_markers
        ids = self.marker_ids
        if len(ids) != n:
            raise UsageError(f"{self._where()}board needs {n} ids, got {len(ids)}")
        nd = len(self.cv_dictionary.bytesList)
        if min(ids) < 0 or max(ids) >= nd:
            raise UsageError(f"{self._where()}marker ids {min(ids)}..{max(ids)} exceed the dictionary ({nd} markers)")

    def _where(self) -> str:
        return f"{self.source}: " if self.source else ""

    @property
    def n_markers(self) -> int:
        cols, rows = self.size
        n: int = cols * rows if self.kind in ("gridboard", "markers") else (cols * rows) // 2
        return n

    def _generic_markers(self) -> dict[int, np.ndarray]:
        """A generic board's markers (``kind == "markers"``: ``__post_init__`` made them a dict)."""
        if self.markers is None:  # pragma: no cover - __post_init__ rejects a generic board without markers
            raise UsageError(f"{self._where()}a 'markers' board needs a non-empty 'markers' list")
        return self.markers

    def unit_warnings(self) -> list[str]:
        """Warnings for lengths that are plausible only in another unit (board files are in metres): a
        marker side over :data:`MAX_PLAUSIBLE_MARKER_M` is probably millimetres (or centimetres)."""
        ml = self.marker_length
        if ml <= MAX_PLAUSIBLE_MARKER_M:
            return []
        unit, f = ("millimetres", 1000.0) if ml >= 10.0 else ("centimetres", 100.0)
        return [
            f"{self._where()}marker side {ml:g} m: the board file is probably in {unit} (its lengths are "
            f"metres: a {ml / f:g} m marker would be written {ml / f:g})"
        ]

    @property
    def planar(self) -> bool:
        """All markers on the plane z = 0 of the world frame (grid and ChArUco boards always are)."""
        return self.kind != "markers" or all(abs(c[:, 2]).max() < 1e-9 for c in self._generic_markers().values())

    @property
    def marker_ids(self) -> tuple[int, ...]:
        return self.ids if self.ids is not None else tuple(range(self.first_id, self.first_id + self.n_markers))

    @property
    def extent(self) -> tuple[float, float]:
        """(width, height) of the board's outer edge, metres."""
        cols, rows = self.size
        if self.kind == "markers":
            pts = np.concatenate(list(self._generic_markers().values()))
            w, h = (float(v) for v in pts[:, :2].max(axis=0) - pts[:, :2].min(axis=0))
            return w, h
        if self.kind == "charuco":
            return cols * self.square_length, rows * self.square_length
        s, ml = self.marker_separation, self.marker_length
        return cols * ml + (cols - 1) * s, rows * ml + (rows - 1) * s

    @cached_property
    def cv_dictionary(self) -> cv2.aruco.Dictionary:
        return get_dictionary(self.dictionary, self.base_dir)

    @cached_property
    def cv_board(self) -> cv2.aruco.Board:
        """The ``cv2.aruco.GridBoard`` / ``CharucoBoard``."""
        ids = np.asarray(self.marker_ids, dtype=np.int32)
        if self.kind == "markers":
            # OpenCV's object points in its board convention: the inverse of OPENCV_BOARD_TO_WORLD is itself
            markers = self._generic_markers()
            obj = [np.ascontiguousarray(markers[i] @ OPENCV_BOARD_TO_WORLD.T, np.float32) for i in ids]
            return cv2.aruco.Board(obj, self.cv_dictionary, ids)
        if self.kind == "gridboard":
            return cv2.aruco.GridBoard(self.size, self.marker_length, self.marker_separation, self.cv_dictionary, ids)
        b = cv2.aruco.CharucoBoard(self.size, self.square_length, self.marker_length, self.cv_dictionary, ids)
        if self.legacy_pattern:
            b.setLegacyPattern(True)
        return b

    @property
    def cv_charuco(self) -> cv2.aruco.CharucoBoard:
        """A ChArUco board's :attr:`cv_board`, typed as OpenCV's ``CharucoBoard``."""
        b = self.cv_board
        if not isinstance(b, cv2.aruco.CharucoBoard):
            raise UsageError(f"{self._where()}a {self.kind} board is not a ChArUco board")
        return b

    @cached_property
    def marker_corners_world(self) -> dict[int, np.ndarray]:
        """marker id -> (4, 3) float64 corners TL, TR, BR, BL in the arshadow world frame (exact, float64).

        Recomputed from the float64 lengths (OpenCV stores float32), with OpenCV's layout.
        """
        if self.kind == "markers":
            return dict(self._generic_markers())
        cv_obj = [np.asarray(o, dtype=np.float64).reshape(4, 3) for o in self.cv_board.getObjPoints()]
        out: dict[int, np.ndarray] = {}
        ml = self.marker_length
        for mid, o in zip(self.marker_ids, cv_obj, strict=True):
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
        with_marker: set[tuple[int, int]] = set()
        for q in self.marker_corners_world.values():
            cx, cy = q[:, 0].mean(), -q[:, 1].mean()  # OpenCV frame centre
            with_marker.add((math.floor(cx / sq), math.floor(cy / sq)))
        out = []
        for r in range(rows):
            for c in range(cols):
                if (c, r) not in with_marker:
                    out.append([[c * sq, -(r + 1) * sq], [(c + 1) * sq, -r * sq]])
        return np.asarray(out, dtype=np.float64).reshape(-1, 2, 2)

    def to_file(self, path: str | Path) -> Path:
        """Write this board as a board file (YAML/JSON by extension), atomically."""
        p = Path(path)
        if self.kind == "markers":
            return self._markers_to_file(p)
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
            if self.inverted:
                fs.write("inverted", 1)
        return p

    def _markers_to_file(self, p: Path) -> Path:
        with write_storage(p, "board file", UsageError) as fs:
            fs.write("type", "markers")
            fs.write("dictionary", str(self.dictionary))
            if self.inverted:
                fs.write("inverted", 1)
            fs.startWriteStruct("markers", cv2.FileNode_SEQ)
            for mid, c in self._generic_markers().items():
                fs.startWriteStruct("", cv2.FileNode_MAP)
                fs.write("id", int(mid))
                fs.startWriteStruct("corners", cv2.FileNode_SEQ)
                for q in c:
                    fs.startWriteStruct("", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
                    for v in q:
                        fs.write("", float(v))
                    fs.endWriteStruct()
                fs.endWriteStruct()
                fs.endWriteStruct()
            fs.endWriteStruct()
        return p


def _fs_number(fs: cv2.FileStorage, key: str, path: Path, default: float | None = None) -> float:
    node = fs.getNode(key)
    if node.empty():
        if default is None:
            raise UsageError(f"{path}: board file is missing '{key}'")
        return default
    if not (node.isReal() or node.isInt()):
        raise UsageError(f"{path}: '{key}' must be a number")
    return node.real()


def _fs_int_list(node: cv2.FileNode, key: str, path: Path) -> list[int]:
    if not node.isSeq():
        raise UsageError(f"{path}: '{key}' must be a list of integers")
    vals = [node.at(i).real() for i in range(node.size())]
    if any(v != int(v) for v in vals):
        raise UsageError(f"{path}: '{key}' must be a list of integers")
    return [int(v) for v in vals]


def _fs_string(fs: cv2.FileStorage, key: str, default: str) -> str:
    node = fs.getNode(key)
    s = node.string() if (not node.empty() and node.isString()) else default
    return s.split(" #")[0].strip()  # OpenCV keeps a same-line YAML comment in a string


def _fs_corners(node: cv2.FileNode, where: str) -> np.ndarray:
    """(4, 3) float64 from a FileNode list of 4 [x, y, z] lists."""
    if not node.isSeq() or node.size() != 4:
        raise UsageError(f"{where}: 'corners' must be a list of 4 [x, y, z] points")
    out = []
    for k in range(4):
        q = node.at(k)
        if not q.isSeq() or q.size() != 3:
            raise UsageError(f"{where}: 'corners' must be a list of 4 [x, y, z] points")
        out.append([q.at(j).real() for j in range(3)])
    return np.asarray(out, np.float64)


def _fs_markers(node: cv2.FileNode, p: Path, to_world: np.ndarray | None = None) -> dict[int, np.ndarray]:
    """id -> (4, 3) corners from a board file's ``markers`` (or the ArUco library's ``aruco_bc_markers``)."""
    if not node.isSeq() or node.size() == 0:
        raise UsageError(f"{p}: 'markers' must be a non-empty list of {{id, corners}}")
    out: dict[int, np.ndarray] = {}
    for k in range(node.size()):
        m = node.at(k)
        idn = m.getNode("id") if m.isMap() else None
        if idn is None or idn.empty() or not (idn.isInt() or idn.isReal()):
            raise UsageError(f"{p}: markers[{k}] needs an integer 'id'")
        mid = int(idn.real())
        if mid in out:
            raise UsageError(f"{p}: marker id {mid} is listed twice")
        c = _fs_corners(m.getNode("corners"), f"{p}: marker {mid}")
        out[mid] = c if to_world is None else c @ to_world.T
    return out


def read_aruco_layout(path: str | Path, dictionary: str | None = None) -> Board:
    """A generic board from the ArUco library's layout file (``aruco_bc_nmarkers``, ``aruco_bc_markers``:
    each marker's ``id`` and four 3D ``corners`` in metres, OpenCV's board convention; e.g. the library's
    ``chessboardinfo_meters.yml``).

    Parameters
    ----------
    path : str or Path
    dictionary : str, optional
        The markers' dictionary: the file's ``aruco_bc_dict`` when it has one, else this, else
        ``DICT_ARUCO_ORIGINAL`` (the library's own).

    Raises
    ------
    UsageError
        Unreadable file, a marker without id or four corners, info type other than metres
        (``aruco_bc_mInfoType: 1``).
    """
    p = Path(path)
    with open_storage(p, "ArUco layout file", UsageError) as fs:
        info = _fs_number(fs, "aruco_bc_mInfoType", p, default=1.0)
        if int(info) != 1:
            raise UsageError(
                f"{p}: the layout is in pixels (aruco_bc_mInfoType {int(info)}); arshadow needs "
                "the metre layout (aruco_bc_mInfoType: 1, e.g. chessboardinfo_meters.yml)"
            )
        name = _fs_string(fs, "aruco_bc_dict", "") or dictionary or "DICT_ARUCO_ORIGINAL"
        markers = _fs_markers(fs.getNode("aruco_bc_markers"), p, OPENCV_BOARD_TO_WORLD)
    b = Board(
        kind="markers",
        size=(len(markers), 1),
        marker_length=1.0,
        dictionary=_aruco_dict_name(name),
        markers=markers,
        base_dir=p.parent,
        source=str(p),
    )
    b.cv_board  # noqa: B018 - build it now so that errors name the file
    return b


def _aruco_dict_name(name: str) -> str:
    """The ArUco library's dictionary names (``ARUCO``, ``ARUCO_MIP_36h12``...) as OpenCV's."""
    n = name.strip().upper()
    return {
        "ARUCO": "DICT_ARUCO_ORIGINAL",
        "ARUCO_MIP_36H12": "DICT_ARUCO_MIP_36h12",
        "TAG36H11": "DICT_APRILTAG_36h11",
    }.get(n, name)


def load_board(path: str | Path) -> Board:
    """Read a board file (YAML or JSON; schema in calib/README.md), or an ArUco library layout file
    (:func:`read_aruco_layout`).

    Raises
    ------
    UsageError
        Missing/unreadable file, missing or invalid key, unknown dictionary.
    """
    p = Path(path)
    with open_storage(p, "board file", UsageError) as fs:
        if not fs.getNode("aruco_bc_markers").empty():
            kind = "aruco_layout"
        else:
            t = fs.getNode("type")
            if t.empty() or not t.isString():
                raise UsageError(f"{p}: board file needs 'type: gridboard', 'type: charuco' or 'type: markers'")
            kind = t.string().split(" #")[0].strip().lower()
            b = _load_markers_board(fs, p) if kind == "markers" else _load_grid_board(fs, p, kind)
    if kind == "aruco_layout":
        return read_aruco_layout(p)
    b.cv_board  # noqa: B018 - build it now so that errors name the file
    return b


def _load_grid_board(fs: cv2.FileStorage, p: Path, kind: str) -> Board:
    """A ``type: gridboard`` / ``charuco`` board file."""
    size_node = fs.getNode("size")
    if size_node.empty():
        raise UsageError(f"{p}: board file is missing 'size' ([columns, rows])")
    size = _fs_int_list(size_node, "size", p)
    if len(size) != 2:
        raise UsageError(f"{p}: 'size' must be [columns, rows]")
    ml = _fs_number(fs, "marker_length", p)
    sep = _fs_number(fs, "marker_separation", p, default=None if kind == "gridboard" else 0.0)
    sq = _fs_number(fs, "square_length", p, default=None if kind == "charuco" else 0.0)
    ids_node = fs.getNode("ids")
    ids = None if ids_node.empty() else tuple(_fs_int_list(ids_node, "ids", p))
    return Board(
        kind=kind,
        size=tuple(size),
        marker_length=ml,
        dictionary=_fs_string(fs, "dictionary", "DICT_6X6_250"),
        marker_separation=sep,
        square_length=sq,
        ids=ids,
        first_id=int(_fs_number(fs, "first_id", p, default=0)),
        legacy_pattern=bool(_fs_number(fs, "legacy_pattern", p, default=0)),
        base_dir=p.parent,
        source=str(p),
        inverted=bool(_fs_number(fs, "inverted", p, default=0)),
    )


def _load_markers_board(fs: cv2.FileStorage, p: Path) -> Board:
    """A ``type: markers`` board file (its ``markers`` list of ``{id, corners}``, world frame)."""
    markers = _fs_markers(fs.getNode("markers"), p)
    b = Board(
        kind="markers",
        size=(len(markers), 1),
        marker_length=1.0,
        dictionary=_fs_string(fs, "dictionary", "DICT_6X6_250"),
        markers=markers,
        inverted=bool(_fs_number(fs, "inverted", p, default=0)),
        base_dir=p.parent,
        source=str(p),
    )
    return b
