"""``arshadow map``: learn the rigid layout of loose markers from photos or videos (a generic board file).

Also the ``--map auto|FILE`` option of ``render``, ``video`` and ``batch`` (:func:`add_map_option`,
:func:`resolve_map`): the map learned from the run's own inputs first (or read), then every frame posed
against all the markers in view (the generic-board pose path).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from . import EXIT_OK

if TYPE_CHECKING:
    from ..tracking.mapping import MarkerMap

EPILOG = """\
examples:
  arshadow map clip.mp4 --calib cam.yml --marker-length 0.05 -o map.yml
  arshadow map shots/*.jpg --calib cam.yml --marker-length 0.05 101=0.1 --dictionary DICT_ARUCO_ORIGINAL \\
      --marker-id 101 -o map.yml
  arshadow video clip.mp4 --calib cam.yml --board map.yml --model box:0.04,0.04,0.06 --light point:0,0,1 -o out/

The map is a generic board file (type: markers; calib/README.md) whose frame is the reference marker's
(the lowest id kept, or --marker-id): --place values mean what they mean with that marker alone. Beside
each marker: rms_px (corner reprojection error after the bundle adjustment) and frames_seen; the 'map'
block says what was rejected (a marker seen in one frame only, false ids, pairs that disagree).
exit status: 0 map written, 1 no map (no marker seen twice), 2 bad usage.
"""


def parse_lengths(items: Sequence[str]) -> dict | float:
    """``--marker-length`` values: ``L`` (every id) and ``ID=L`` (that id) -> a float or {id or None: L}.

    >>> parse_lengths(["0.05"]), parse_lengths(["0.05", "7=0.1"])
    (0.05, {None: 0.05, 7: 0.1})
    """
    from ..errors import UsageError

    out: dict = {}
    for s in items:
        key, _, val = str(s).rpartition("=")
        try:
            v = float(val)
            k = int(key) if key else None
        except ValueError:
            raise UsageError(f"--marker-length {s!r}: give L or ID=L (metres)") from None
        if not (v > 0 and v < float("inf")):
            raise UsageError(f"--marker-length {s!r}: a marker side must be a positive number of metres")
        out[k] = v
    return out[None] if list(out) == [None] else out


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "map",
        help="learn a rigid map of loose markers from photos or a video (a board file)",
        description="Detect every marker in each frame, join them through the frames that see them together "
        "(pose graph, then bundle adjustment of all marker and camera poses on the corners), and write the "
        "map as a generic board file with its residuals.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("inputs", nargs="+", metavar="VIDEO|PHOTO", help="videos (by extension) and photos")
    p.add_argument("--calib", required=True, metavar="C", help="calibration file")
    p.add_argument(
        "--marker-length", required=True, nargs="+", metavar="L|ID=L", help="marker side in metres: all, or per id"
    )
    p.add_argument("--dictionary", metavar="D", help="ArUco dictionary (default DICT_6X6_250)")
    p.add_argument("--marker-id", type=int, metavar="N", help="reference marker: the map's frame (default lowest id)")
    p.add_argument("--inverted", action="store_true", default=None, help="markers printed white on black")
    p.add_argument("--max-frames", type=int, default=None, metavar="N", help="frames read at most (default 600)")
    p.add_argument("-o", "--output", required=True, metavar="MAP.yml", help="the map file (YAML or JSON)")
    p.add_argument("--quiet", "-q", action="store_true", help="only errors")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks")
    p.set_defaults(func=run)


def learn(
    inputs: Any,
    *,
    calib: Any,
    marker_length: dict | float,
    dictionary: str | None = None,
    marker_id: int | None = None,
    inverted: bool | None = None,
    max_frames: int | None = None,
) -> tuple[MarkerMap, float]:
    """The map of ``inputs``: ``(MarkerMap, seconds)``."""
    from ..camera.model import Intrinsics
    from ..tracking.dictionary import DEFAULT_DICTIONARY, dictionary_label
    from ..tracking.mapio import MAX_MAP_FRAMES, observe_inputs
    from ..tracking.mapping import learn_map

    t0 = time.perf_counter()
    intr = calib if isinstance(calib, Intrinsics) else Intrinsics.from_file(calib)
    obs = observe_inputs(
        inputs, intr, dictionary=dictionary, inverted=inverted, max_frames=max_frames or MAX_MAP_FRAMES
    )
    name = dictionary_label(dictionary or DEFAULT_DICTIONARY)
    mmap = learn_map(obs, intr, marker_length, dictionary=name, reference_id=marker_id)
    return mmap, time.perf_counter() - t0


def _say(mmap: MarkerMap, seconds: float, prog: str, quiet: bool) -> None:
    if quiet:
        return
    print(f"arshadow {prog}: {mmap.summary()} ({seconds:.2f} s)", file=sys.stderr)
    for i in sorted(mmap.corners):
        print(
            f"  marker {i}: {mmap.frames_seen[i]} frames, corner RMS {mmap.rms_px[i]:.2f} px",
            file=sys.stderr,
        )
    if mmap.rejected:
        shown = "; ".join(mmap.rejected[:5]) + (
            f"; ... ({len(mmap.rejected)} in all)" if len(mmap.rejected) > 5 else ""
        )
        print(f"  rejected: {shown}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    from ..io import check_output_file
    from ..tracking.mapio import write_map
    from . import quiet_opencv

    quiet_opencv(bool(getattr(args, "debug", False)))
    out = check_output_file(args.output, "-o")
    mmap, secs = learn(
        args.inputs,
        calib=args.calib,
        marker_length=parse_lengths(args.marker_length),
        dictionary=args.dictionary,
        marker_id=args.marker_id,
        inverted=args.inverted,
        max_frames=args.max_frames,
    )
    write_map(mmap, out)
    _say(mmap, secs, "map", args.quiet)
    if not args.quiet:
        print(f"{out}", file=sys.stdout)
    return EXIT_OK


# -- --map for render / video / batch -------------------------------------------------------------------
def add_map_option(group: Any) -> None:  # an argparse group (a private class, hence Any)
    """``--map auto|FILE`` (an argparse group of render / video / batch)."""
    group.add_argument(
        "--map",
        metavar="auto|FILE",
        help="pose every frame against all the markers of a map: 'auto' learns it from this run's inputs "
        "first (needs --marker-length; written to OUT/map.yml), FILE is a map or generic board file "
        "(arshadow map ... -o FILE). The reference marker may then be hidden (docs/tracking.md)",
    )


def resolve_map(  # noqa: PLR0913 -- the tracker options of render/video/batch, one per flag (CLI glue)
    args: argparse.Namespace,
    inputs: Any,
    outdir: str | Path,
    *,
    calib: Any,
    marker_length: dict | float | None,
    dictionary: str | None = None,
    marker_id: int | None = None,
    inverted: bool | None = None,
    board: str | None = None,
) -> str | None:
    """The board file a ``--map`` run tracks against (None without ``--map``): ``auto`` learns the map from
    ``inputs`` and writes it to ``outdir/map.yml`` (one line on stderr with its residuals).

    Raises
    ------
    UsageError
        ``--map`` with ``--board``; ``--map auto`` without a marker length.
    """
    from ..errors import UsageError
    from ..io import check_output_folder
    from ..tracking.mapio import write_map

    choice = getattr(args, "map", None)
    if not choice:
        return None
    if board:
        raise UsageError("give either --map or --board, not both (a map file is a board file: --map FILE)")
    if choice != "auto":
        if not Path(choice).is_file():
            raise UsageError(f"--map {choice}: no such map file (or 'auto' to learn it from the inputs)")
        return str(choice)
    if marker_length is None:
        raise UsageError("--map auto needs --marker-length (the markers' side: the map's scale)")
    mmap, secs = learn(
        inputs,
        calib=calib,
        marker_length=marker_length,
        dictionary=dictionary,
        marker_id=marker_id,
        inverted=inverted,
    )
    path = write_map(mmap, check_output_folder(outdir, "-o") / "map.yml")
    _say(mmap, secs, "map", bool(getattr(args, "quiet", False)))
    return str(path)


def map_info(path: str | Path) -> dict:
    """The report's ``map``: the file, and (for a map written by ``arshadow map``) its reference marker, total
    and per-marker corner RMS (pixels) and frames seen, read back from the file."""
    import cv2

    out: dict = {"file": str(path)}
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        m = fs.getNode("map")
        if not m.empty():
            out["reference_id"] = int(m.getNode("reference_id").real())
            out["rms_px"] = float(m.getNode("rms_px").real())
            out["frames_used"] = int(m.getNode("frames_used").real())
        mk = fs.getNode("markers")
        per = {}
        for k in range(mk.size() if mk.isSeq() else 0):
            n = mk.at(k)
            if not n.getNode("rms_px").empty():
                per[str(int(n.getNode("id").real()))] = {
                    "rms_px": float(n.getNode("rms_px").real()),
                    "frames_seen": int(n.getNode("frames_seen").real()),
                }
        if per:
            out["markers"] = per
    finally:
        fs.release()
    return out
