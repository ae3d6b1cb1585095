"""``arshadow demo``: render the bundled sample photos and write a contact sheet (:mod:`arshadow.demo`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..scene.options import DEFAULT_AA
from . import EXIT_OK, EXIT_SOME_FAILED, quiet_opencv


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "demo",
        help="render the bundled sample photos and write a contact sheet",
        description="Composite the sample meshes (including the 8 536-face knot) with their shadows into the "
        "synthetic sample photos of samples/ (point, directional, two lights, a soft sun, strong "
        "lens distortion), write the results, their shadow masks, a JSON report and "
        "contact_sheet.png into DIR.",
    )
    p.add_argument("-o", "--output", default="demo_out", metavar="DIR", help="output folder (default demo_out)")
    p.add_argument("--samples", metavar="DIR", help="samples folder with scenes.json (default: the bundled samples)")
    p.add_argument(
        "--aa",
        type=int,
        default=DEFAULT_AA,
        metavar="N",
        help=f"multisample anti-aliasing samples, 0, 2 or 4 (default {DEFAULT_AA}, as arshadow render: "
        "pixel-centre sampling; --aa 4 for smoother edges, ~5x the render time on a CPU)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no per-image lines")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..demo.run import find_samples, run_demo  # deferred: the API loads when the command runs

    debug = bool(getattr(args, "debug", False))
    quiet_opencv(debug)

    def done(job: Any, item: Any, res: Any, err: BaseException | None) -> None:
        name = Path(job.input).name
        if err is not None:
            print(f"arshadow demo: error: {name}: {err}", file=sys.stderr)
        elif not args.quiet:
            print(f"{name} -> {job.output}  ({item.mode}, {item.timings_ms['total']:.1f} ms)")

    items, sheet, light = run_demo(find_samples(args.samples), Path(args.output), aa=args.aa, debug=debug, on_done=done)
    if isinstance(light, Exception):
        print(f"arshadow demo: error: measured light: {light}", file=sys.stderr)
    elif not args.quiet:
        for line in light:
            print(line)
    if sheet is not None and not args.quiet:
        print(f"contact sheet: {sheet}")
    failed = any(i.status != "ok" for i in items) or isinstance(light, Exception)
    return EXIT_SOME_FAILED if failed else EXIT_OK
