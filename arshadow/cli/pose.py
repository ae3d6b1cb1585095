"""``arshadow pose``: detect the marker (or board) in photos and print its pose per image."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

DESCRIPTION = """\
Detect an ArUco marker (or a grid / ChArUco board) in each IMAGE and print the pose of the marker
(world) frame in the camera: ids, rvec, tvec (world -> camera, metres, as cv2.solvePnP gives them),
the RMS reprojection error and the IPPE ambiguity ratio err_best/err_second (in (0, 1]; at or above
the flag threshold the pose may be the mirrored solution: it is marked AMBIGUOUS). A pose is also
marked AMBIGUOUS when its marker is under 32 px across, its corners are blurred or its border covered, and
FLAGGED when its reprojection error is far above what the detected corners allow; the reasons follow,
with their numbers.
Exit status: 0 all images done, 1 some image failed (no marker, unreadable, wrong size; the others
are still processed), 2 bad usage or unreadable calibration / board / dictionary.
"""


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "pose",
        help="marker / board pose per photo (ids, rvec, tvec, error, ambiguity)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("images", nargs="+", metavar="IMAGE", help="photos (anything OpenCV reads)")
    p.add_argument(
        "--calib",
        required=True,
        metavar="FILE",
        help="camera calibration (OpenCV YAML/XML/JSON or ROS camera_info YAML)",
    )
    p.add_argument(
        "--dictionary",
        metavar="D",
        help="ArUco dictionary name or custom dictionary file (default DICT_6X6_250; a --board file names its own)",
    )
    g = p.add_mutually_exclusive_group()
    g.add_argument("--marker-length", type=float, metavar="M", help="printed marker side, metres")
    g.add_argument("--board", metavar="FILE", help="board file (gridboard or charuco; see calib/README.md)")
    p.add_argument(
        "--marker-id",
        type=int,
        metavar="N",
        help="use only this marker id as the reference (default: the lowest id found)",
    )
    p.add_argument(
        "--inverted",
        action="store_true",
        default=None,
        help="the markers are printed white on black (a board file may say 'inverted: 1')",
    )
    p.add_argument(
        "--refine",
        default=None,
        choices=("none", "subpix", "contour", "apriltag", "edge", "ecc"),
        help="corner refinement (default: ecc, the edge corners then the marker's bitmap aligned to the "
        "photo; or the --detector-params file's own)",
    )
    p.add_argument("--detector-params", metavar="FILE", help="cv2.aruco.DetectorParameters YAML file")
    p.add_argument("--json", action="store_true", help="print the JSON report (CONVENTIONS.md) on stdout")
    p.add_argument("--report", metavar="PATH", help="also write the JSON report to PATH")
    p.add_argument("--overlay", metavar="DIR", help="write <stem>.png with the markers and axes drawn into DIR")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..camera.model import Intrinsics
    from ..errors import UsageError
    from ..frame.report import make_report
    from ..io import write_json
    from ..photos import track_photos
    from ..tracking.detect import DEFAULT_REFINE
    from ..tracking.tracker import MarkerTracker
    from . import error_line

    if args.marker_length is None and args.board is None:
        raise UsageError("give --marker-length M (metres) or --board FILE")
    if args.marker_length is not None and not (args.marker_length > 0 and args.marker_length < float("inf")):
        raise UsageError(f"--marker-length must be a positive number of metres, got {args.marker_length}")
    intr = Intrinsics.from_file(args.calib)
    refine = args.refine if args.refine is not None else (None if args.detector_params else DEFAULT_REFINE)
    tracker = MarkerTracker(
        intr,
        dictionary=args.dictionary,
        marker_length=args.marker_length,
        marker_id=args.marker_id,
        board=args.board,
        refine=refine,
        inverted=args.inverted,
        detector_params=args.detector_params,
    )

    def done(name: Any, item: Any, pose: Any, image: Any, err: BaseException | None) -> None:
        if err is not None:
            msg = str(err)
            print(
                f"arshadow pose: error: {msg}" if msg.startswith(str(name)) else error_line("pose", str(name), err),
                file=sys.stderr,
            )
        elif not args.json:
            amb = "n/a" if pose.pose_ambiguity is None else f"{pose.pose_ambiguity:.3f}"
            print(
                f"{name}: ids {item.marker_ids} rvec [{', '.join(f'{v:.6f}' for v in pose.rvec)}] "
                f"tvec [{', '.join(f'{v:.6f}' for v in pose.tvec)}] m, reprojection "
                f"{pose.reprojection_error_px:.3f} px, ambiguity {amb}"
                + (" AMBIGUOUS" if pose.ambiguous else (" FLAGGED" if pose.flagged else ""))
                + (f" ({'; '.join(pose.flag_reasons)})" if pose.flagged else "")
                + (f" (calibration scaled to {image.shape[1]}x{image.shape[0]})" if pose.scaled else "")
            )

    items = track_photos(tracker, args.images, overlay_dir=args.overlay, on_done=done)
    failed = sum(i.status != "ok" for i in items)
    report = make_report(items)
    if args.json:
        print(json.dumps(report, indent=1))
    if args.report:
        write_json(args.report, report)
    return 1 if failed else 0
