"""``arshadow marker`` and ``arshadow board``: printable markers and boards at their true size.

The PNG records its resolution in a ``pHYs`` chunk (pixels per metre), so printing it at "100 %" / "actual
size" gives the requested lengths; an SVG (millimetre units, exact vector cells) is written with
``--svg`` or when the output ends in ``.svg``.
"""

from __future__ import annotations

import argparse
import math
import struct
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..tracking.board import Board

MARKER_DESCRIPTION = """\
Write a printable ArUco marker: the black-bordered marker of side --length-mm with a white margin
(--margin-mm) and a small caption. The PNG's DPI is chosen near --dpi so that every marker cell is a
whole number of pixels, and recorded in the file: print at 100 % ("actual size") and measure the
black square's side -- that is the --marker-length to give `arshadow pose`.
"""

BOARD_DESCRIPTION = """\
Write a printable grid or ChArUco board from a board file (--board, schema in calib/README.md) or from
--type/--size/... options (then --save-board writes the matching board file). Print at 100 %.
"""


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "marker",
        help="printable ArUco marker (PNG with DPI, optional SVG)",
        description=MARKER_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--id", type=int, required=True, metavar="N", help="marker id")
    p.add_argument(
        "--dictionary", default="DICT_6X6_250", metavar="D", help="dictionary name or file (default DICT_6X6_250)"
    )
    p.add_argument("--length-mm", type=float, required=True, metavar="L", help="printed side of the black square, mm")
    p.add_argument(
        "--margin-mm", type=float, default=10.0, metavar="MM", help="white margin around it, mm (default 10)"
    )
    p.add_argument("--dpi", type=float, default=300.0, help="target resolution (default 300)")
    p.add_argument("--svg", action="store_true", help="also write an SVG beside the PNG")
    p.add_argument("--no-caption", action="store_true", help="no caption text in the margin")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="output .png (or .svg)")
    p.set_defaults(func=run_marker)

    b = subparsers.add_parser(
        "board",
        help="printable grid / ChArUco board (PNG with DPI, optional SVG)",
        description=BOARD_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    b.add_argument("--board", metavar="FILE", help="board file (YAML/JSON)")
    b.add_argument("--type", choices=("gridboard", "charuco"), help="board type (without --board)")
    b.add_argument("--size", metavar="COLS,ROWS", help="markers (gridboard) or squares (charuco)")
    b.add_argument("--marker-mm", type=float, help="marker side, mm")
    b.add_argument("--square-mm", type=float, help="ChArUco square side, mm")
    b.add_argument("--separation-mm", type=float, help="grid board gap between markers, mm")
    b.add_argument("--dictionary", default="DICT_6X6_250", metavar="D", help="dictionary (default DICT_6X6_250)")
    b.add_argument("--first-id", type=int, default=0, help="first marker id (default 0)")
    b.add_argument("--save-board", metavar="FILE", help="write the board file for these options")
    b.add_argument("--margin-mm", type=float, default=10.0, metavar="MM", help="white margin, mm (default 10)")
    b.add_argument("--dpi", type=float, default=300.0, help="resolution (default 300)")
    b.add_argument("--svg", action="store_true", help="also write an SVG beside the PNG")
    b.add_argument("-o", "--output", required=True, metavar="FILE", help="output .png (or .svg)")
    b.set_defaults(func=run_board)


# ---------------------------------------------------------------------------------------------------
# PNG with pHYs, SVG
# ---------------------------------------------------------------------------------------------------
def png_with_dpi(gray: np.ndarray, pixels_per_metre: float) -> bytes:
    """Encode an 8-bit image as PNG with a ``pHYs`` chunk (unit: metre) inserted after ``IHDR``."""
    import cv2

    ok, buf = cv2.imencode(".png", gray)
    if not ok:  # pragma: no cover
        raise RuntimeError("PNG encoding failed")
    data = buf.tobytes()
    ppm = int(round(pixels_per_metre))
    payload = struct.pack(">IIB", ppm, ppm, 1)
    chunk = struct.pack(">I", len(payload)) + b"pHYs" + payload + struct.pack(">I", zlib.crc32(b"pHYs" + payload))
    ihdr_end = 8 + 8 + 13 + 4  # signature, IHDR length+type, IHDR data, CRC
    if data[12:16] != b"IHDR":  # pragma: no cover - OpenCV always writes IHDR first
        raise RuntimeError("unexpected PNG layout from OpenCV: IHDR is not the first chunk")
    return data[:ihdr_end] + chunk + data[ihdr_end:]


def read_png_dpi(data: bytes) -> float | None:
    """DPI from a PNG's pHYs chunk (None if absent or not in metres)."""
    pos = 8
    while pos + 8 <= len(data):
        n, typ = struct.unpack(">I4s", data[pos : pos + 8])
        if typ == b"pHYs":
            x, y, unit = struct.unpack(">IIB", data[pos + 8 : pos + 17])
            return x * 0.0254 if unit == 1 else None
        if typ == b"IDAT":
            return None
        pos += 12 + n
    return None


def _svg(
    width_mm: float,
    height_mm: float,
    rects: list[tuple[float, float, float, float]],
    caption: str | None = None,
    caption_y: float | None = None,
) -> str:
    """rects: list of (x, y, w, h) black rectangles in mm (y down)."""
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width_mm:.4f}mm" height="{height_mm:.4f}mm" '
        f'viewBox="0 0 {width_mm:.4f} {height_mm:.4f}" shape-rendering="crispEdges">',
        f'<rect x="0" y="0" width="{width_mm:.4f}" height="{height_mm:.4f}" fill="#ffffff"/>',
    ]
    for x, y, w, h in rects:
        out.append(f'<rect x="{x:.4f}" y="{y:.4f}" width="{w:.4f}" height="{h:.4f}" fill="#000000"/>')
    if caption:
        out.append(
            f'<text x="{width_mm / 2:.4f}" y="{caption_y:.4f}" font-family="sans-serif" font-size="2.5" '
            f'text-anchor="middle" fill="#808080">{caption}</text>'
        )
    out.append("</svg>")
    return "\n".join(out) + "\n"


def _bits_rects(bits: np.ndarray, x0: float, y0: float, cell: float) -> list[tuple[float, float, float, float]]:
    """Black cells of a marker (bits True = white) as mm rectangles, merged along rows."""
    rects: list[tuple[float, float, float, float]] = []
    for r in range(bits.shape[0]):
        c = 0
        while c < bits.shape[1]:
            if not bits[r, c]:
                s = c
                while c < bits.shape[1] and not bits[r, c]:
                    c += 1
                rects.append((x0 + s * cell, y0 + r * cell, (c - s) * cell, cell))
            else:
                c += 1
    return rects


def _outputs(output: str, svg: bool) -> tuple[Path | None, Path | None]:
    p = Path(output)
    if p.suffix.lower() == ".svg":
        return None, p
    if p.suffix.lower() != ".png":
        from ..errors import UsageError

        raise UsageError(f"{p}: output must end in .png or .svg")
    return p, (p.with_suffix(".svg") if svg else None)


def _check_positive(name: str, v: float | None, allow_zero: bool = False) -> None:
    from ..errors import UsageError

    if v is None or not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise UsageError(f"{name} must be a positive number, got {v}")


# ---------------------------------------------------------------------------------------------------
# commands
# ---------------------------------------------------------------------------------------------------
def run_marker(args: argparse.Namespace) -> int:
    import cv2

    from ..io import write_bytes
    from ..tracking.dictionary import dictionary_label, get_dictionary, marker_bits

    _check_positive("--length-mm", args.length_mm)
    _check_positive("--margin-mm", args.margin_mm, allow_zero=True)
    _check_positive("--dpi", args.dpi)
    d = get_dictionary(args.dictionary)
    bits = marker_bits(d, args.id)
    cells = bits.shape[0]
    png, svg = _outputs(args.output, args.svg)
    label = dictionary_label(args.dictionary)
    caption = None if args.no_caption or args.margin_mm < 4 else f"{label} id {args.id}, {args.length_mm:g} mm"
    cell_mm = args.length_mm / cells
    if png is not None:
        px_cell = max(1, int(round(cell_mm / 25.4 * args.dpi)))
        ppmm = px_cell / cell_mm
        margin = int(round(args.margin_mm * ppmm))
        side = px_cell * cells
        img = np.full((side + 2 * margin, side + 2 * margin), 255, np.uint8)
        img[margin : margin + side, margin : margin + side] = np.kron(
            bits.astype(np.uint8) * 255, np.ones((px_cell, px_cell), np.uint8)
        )
        if caption:
            scale = max(0.3, 2.5 * ppmm / 22.0)
            (tw, th), _ = cv2.getTextSize(caption, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
            y = margin + side + min(margin - 2, int(margin * 0.6) + th // 2)
            if th < margin:
                cv2.putText(
                    img, caption, ((img.shape[1] - tw) // 2, y), cv2.FONT_HERSHEY_SIMPLEX, scale, 128, 1, cv2.LINE_AA
                )
        write_bytes(png, png_with_dpi(img, ppmm * 1000.0))
        print(
            f"wrote {png}: {img.shape[1]}x{img.shape[0]} px at {ppmm * 25.4:.2f} dpi; marker side "
            f"{side / ppmm:.3f} mm when printed at 100 %"
        )
    if svg is not None:
        m = args.margin_mm
        total = args.length_mm + 2 * m
        write_bytes(
            svg, _svg(total, total, _bits_rects(bits, m, m, cell_mm), caption, m + args.length_mm + 0.6 * m).encode()
        )
        print(f"wrote {svg}: {total:g} x {total:g} mm, marker side {args.length_mm:g} mm")
    return 0


def _board_from_args(args: argparse.Namespace) -> Board:
    from ..errors import UsageError
    from ..tracking.board import Board, load_board

    if args.board:
        return load_board(args.board)
    if not args.type or not args.size or args.marker_mm is None:
        raise UsageError(
            "give --board FILE, or --type, --size COLS,ROWS and --marker-mm (plus --square-mm or --separation-mm)"
        )
    try:
        cols, rows = (int(v) for v in args.size.split(","))
    except ValueError:
        raise UsageError(f"--size must be COLS,ROWS, got '{args.size}'") from None
    if args.type == "charuco":
        if args.square_mm is None:
            raise UsageError("a ChArUco board needs --square-mm")
        return Board(
            "charuco",
            (cols, rows),
            args.marker_mm / 1000,
            dictionary=args.dictionary,
            square_length=args.square_mm / 1000,
            first_id=args.first_id,
        )
    if args.separation_mm is None:
        raise UsageError("a grid board needs --separation-mm")
    return Board(
        "gridboard",
        (cols, rows),
        args.marker_mm / 1000,
        dictionary=args.dictionary,
        marker_separation=args.separation_mm / 1000,
        first_id=args.first_id,
    )


def run_board(args: argparse.Namespace) -> int:
    from ..io import write_bytes
    from ..synth.markers import INK_BLACK, PAPER_WHITE, board_markers, board_print

    _check_positive("--margin-mm", args.margin_mm, allow_zero=True)
    _check_positive("--dpi", args.dpi)
    board = _board_from_args(args)
    png, svg = _outputs(args.output, args.svg)
    if args.save_board:
        board.to_file(args.save_board)
        print(f"wrote {args.save_board}")
    m = args.margin_mm / 1000.0
    bw, bh = board.extent
    if png is not None:
        ppm = args.dpi / 0.0254
        tex, _, _ = board_print(board, m, ppm)
        v = tex[:, :, 0]
        img = np.clip((v - INK_BLACK) / (PAPER_WHITE - INK_BLACK) * 255.0 + 0.5, 0, 255).astype(np.uint8)
        write_bytes(png, png_with_dpi(img, ppm))
        print(
            f"wrote {png}: {img.shape[1]}x{img.shape[0]} px at {args.dpi:g} dpi; board "
            f"{1000 * bw:g} x {1000 * bh:g} mm when printed at 100 %"
        )
    if svg is not None:
        rects = []
        for sq in board.black_squares_world:
            (x0, y0), (x1, y1) = sq
            rects.append((1000 * (x0 + m), 1000 * (m - y1), 1000 * (x1 - x0), 1000 * (y1 - y0)))
        for (xl, yt), side, bits in board_markers(board):
            cell = 1000 * side / bits.shape[0]
            rects += _bits_rects(bits, 1000 * (xl + m), 1000 * (m - yt), cell)
        write_bytes(svg, _svg(1000 * (bw + 2 * m), 1000 * (bh + 2 * m), rects).encode())
        print(f"wrote {svg}: {1000 * (bw + 2 * m):g} x {1000 * (bh + 2 * m):g} mm")
    return 0
