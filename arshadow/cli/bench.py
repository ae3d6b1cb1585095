"""``arshadow bench``: run time against error (see :mod:`arshadow.bench`)."""

from __future__ import annotations

import argparse
from typing import Any


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "bench",
        help="benchmark run time against error; writes CSV, PNG plots and a Markdown summary",
        description="Measure, for every setting that trades speed for accuracy (silhouette detectors, render "
        "options, the shadow-map baseline, tracking, the whole pipeline, the realism options against a path tracer), its run time (median and IQR of "
        "repeated runs) and its error against an independent exact reference; compare with the papers' claims. "
        "Writes <section>.csv, results.json, PNG plots (needs matplotlib: pip install arshadow[bench]) and "
        "summary.md into DIR. The full run takes about 10 minutes on 2 CPU cores; --quick under 3.",
    )
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created if needed)")
    p.add_argument("--quick", action="store_true", help="fewer sizes, repeats and photos (under 3 minutes)")
    p.add_argument(
        "--sections",
        default=None,
        metavar="LIST",
        help="comma-separated subset of: silhouettes, render, tracking, pipeline, realism (default all)",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..bench import SECTIONS
    from ..bench import run as bench_run

    sections = SECTIONS if not args.sections else tuple(s.strip() for s in args.sections.split(",") if s.strip())
    res = bench_run(args.output, quick=args.quick, sections=sections, plots=not args.no_plots)
    print(f"{len(res['files'])} files in {args.output} ({res['duration_s']:.0f} s)")
    return 0
