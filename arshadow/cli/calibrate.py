"""``arshadow calibrate``: camera calibration from photos of a chessboard or ChArUco board."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

DESCRIPTION = """\
Calibrate a camera from photos of a printed pattern and write an OpenCV calibration file (camera_matrix,
distortion_coefficients, image_width, image_height, plus avg_reprojection_error, per-view errors, the
views used and the ones rejected with the reason).
PATTERN: chessboard:COLS,ROWS,SQUARE (COLS x ROWS *inner* corners) or
charuco:COLS,ROWS,SQUARE,MARKER,DICT (squares); lengths in metres.
IMAGES may include folders (their images are used, sorted by name).
Exit status: 0 every view used, 1 calibration written but some views rejected, 2 bad usage or too few
usable views (nothing written).
"""


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "calibrate",
        help="calibrate a camera from chessboard / ChArUco photos",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("images", nargs="+", metavar="IMAGE", help="photos of the pattern, or folders of them")
    p.add_argument(
        "--pattern", required=True, help="chessboard:COLS,ROWS,SQUARE or charuco:COLS,ROWS,SQUARE,MARKER,DICT"
    )
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="calibration file to write (.yml/.xml/.json)")
    p.add_argument("--fix-aspect", action="store_true", help="fx = fy (cv2.CALIB_FIX_ASPECT_RATIO)")
    p.add_argument("--zero-tangent", action="store_true", help="p1 = p2 = 0 (cv2.CALIB_ZERO_TANGENT_DIST)")
    p.add_argument("--fix-k3", action="store_true", help="k3 = 0 (cv2.CALIB_FIX_K3)")
    p.add_argument("--rational", action="store_true", help="8-coefficient rational model (cv2.CALIB_RATIONAL_MODEL)")
    p.add_argument("--min-views", type=int, default=None, metavar="N", help="fewest usable views (default 5)")
    p.add_argument(
        "--max-view-error",
        type=float,
        default=None,
        metavar="PX",
        help="reject views whose RMS error exceeds PX and calibrate again (default: keep all)",
    )
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import cv2

    from ..errors import UsageError
    from ..photos import expand_inputs  # folders by arshadow.io.IMAGE_EXTENSIONS, globs
    from ..tracking.calibration import MIN_VIEWS, calibrate, find_view, parse_pattern

    pattern = parse_pattern(args.pattern)
    out = Path(args.output)
    if out.suffix.lower() not in (".yml", ".yaml", ".xml", ".json"):
        raise UsageError(f"{out}: the output must end in .yml, .yaml, .xml or .json")
    min_views = MIN_VIEWS if args.min_views is None else args.min_views
    if min_views < 1:
        raise UsageError("--min-views must be at least 1")
    flags = 0
    if args.fix_aspect:
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
    if args.zero_tangent:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    if args.fix_k3:
        flags |= cv2.CALIB_FIX_K3
    if args.rational:
        flags |= cv2.CALIB_RATIONAL_MODEL
    files = expand_inputs(args.images)
    if not files:
        raise UsageError("no images given (the folders hold no image files)")
    views = []
    for f in files:
        v = find_view(f, pattern)
        views.append(v)
        if not args.json:
            print(
                f"{f}: "
                + (
                    f"{0 if v.object_points is None else len(v.object_points)} corners"
                    if v.ok
                    else f"rejected: {v.reason}"
                ),
                file=sys.stdout if v.ok else sys.stderr,
            )
    res = calibrate(views, flags=flags, min_views=min_views, max_view_error=args.max_view_error, pattern=pattern)
    res.to_file(out)
    k = res.intrinsics
    summary = {
        "output": str(out),
        "pattern": pattern.spec,
        "flags": flags,
        "views_used": len(res.views),
        "views_rejected": [{"input": v.path, "reason": v.reason} for v in res.rejected],
        "rms_px": res.rms,
        "fx": k.fx,
        "fy": k.fy,
        "cx": k.cx,
        "cy": k.cy,
        "dist": k.dist.tolist(),
        "width": k.width,
        "height": k.height,
        "per_view_errors_px": {v.path: float(e) for v, e in zip(res.views, res.per_view_errors, strict=True)},
    }
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        for v in res.rejected:
            if v.reason and v.reason.startswith("reprojection error"):
                print(f"{v.path}: rejected: {v.reason}", file=sys.stderr)
        print(
            f"calibrated from {len(res.views)} of {len(views)} views ({pattern.describe()}), "
            f"{k.width}x{k.height}: RMS {res.rms:.4f} px"
        )
        print(f"  fx {k.fx:.3f}  fy {k.fy:.3f}  cx {k.cx:.3f}  cy {k.cy:.3f}")
        print(f"  distortion {', '.join(f'{d:.6g}' for d in k.dist)}")
        worst = max(zip(res.per_view_errors, res.views, strict=True), key=lambda t: t[0])
        print(f"  per-view RMS {min(res.per_view_errors):.3f}..{worst[0]:.3f} px (worst {Path(worst[1].path).name})")
        print(f"wrote {out}")
    return 1 if res.rejected else 0
