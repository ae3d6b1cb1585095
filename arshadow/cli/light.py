"""``arshadow light``: measure the light (direction / position / the world's bearing under the sun), the
shadow's colour and the exposure from photos of the marker and a reference object's real shadow."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..estimate.record import LightEstimate

DESCRIPTION = """\
Measure the real light from PHOTO or VIDEO files of the marker with a reference object (the probe) of known
shape and place standing on the ground, its real shadow in view (docs/light.md). The probe is placed like
--model: --probe MODEL (a mesh file in metres or box:WX,WY,HZ / cylinder:R,H / sphere:R), --probe-scale,
--probe-rotate RX,RY,RZ (degrees), --probe-place X,Y,Z (metres, marker frame).
--kind directional (2 DOF), point (3 DOF) or sun:LAT,LON,TIME (the world's bearing NORTH, 1 DOF).
All inputs see one light fixed in the world; a video gives up to 30 evenly spaced frames.

Prints the light (a spec --light accepts), the shadow ratio (linear RGB, shadow / lit), the uncertainty and
the marker paper's exposure / white balance; --json prints one JSON object, which render, video and batch
take with --light-from FILE.
exit status: 0 measured, 1 no marker / unreadable input / no usable shadow (one line names why), 2 bad usage.
"""


def _floats(n: int) -> Callable[[str], tuple[float, ...]]:
    def parse(text: str) -> tuple[float, ...]:
        try:
            vals = tuple(float(v) for v in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {n} comma-separated numbers, got {text!r}") from None
        if len(vals) != n or not all(math.isfinite(v) for v in vals):
            raise argparse.ArgumentTypeError(f"expected {n} finite comma-separated numbers, got {text!r}")
        return vals

    return parse


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return v


def add_probe_options(p: argparse.ArgumentParser, run: bool = False) -> None:
    """The probe's options (``--probe``, ``--probe-place``, ``--probe-rotate``, ``--probe-scale``, ``--kind``);
    ``run``: of render / video / batch (the light measured first, from the run's inputs)."""
    g = p.add_argument_group(
        "the probe (reference object casting the real shadow)"
        + (
            ": measure the light first, from the inputs (at most 30 frames), and use its light, shadow colour and "
            "exposure as --light-from does (docs/light.md)"
            if run
            else ""
        )
    )
    g.add_argument("--probe", metavar="MODEL", help="mesh file (metres) or box:WX,WY,HZ / cylinder:R,H / sphere:R")
    g.add_argument(
        "--probe-place",
        type=_floats(3),
        default=(0.0, 0.0, 0.0),
        metavar="X,Y,Z",
        help="translation, metres, marker frame (applied last)",
    )
    g.add_argument(
        "--probe-rotate",
        type=_floats(3),
        default=(0.0, 0.0, 0.0),
        metavar="RX,RY,RZ",
        help="degrees about x, then y, then z",
    )
    g.add_argument("--probe-scale", type=_positive, default=1.0, metavar="S", help="uniform scale (first)")
    g.add_argument(
        "--kind",
        default="directional",
        metavar="K",
        help="directional (default), point, or sun:LAT,LON,TIME (fits the world's bearing NORTH)",
    )


#: frames a render / video / batch run's --probe estimate uses at most (photos evenly spaced; video frames)
PROBE_FRAMES = 30


def probe_estimate(
    args: argparse.Namespace,
    inputs: Iterable[Any],
    *,
    calib: Any,
    marker_length: Any,
    dictionary: Any = None,
    marker_id: int | None = None,
) -> LightEstimate | None:
    """``render`` / ``video`` / ``batch`` with ``--probe``: the light estimated once from the run's inputs (at
    most :data:`PROBE_FRAMES` frames in all), one line on stderr; None without ``--probe``.

    Raises
    ------
    UsageError
        ``--probe`` with ``--light-from`` (one measured light at a time).
    """
    from ..errors import UsageError
    from ..estimate import estimate_light
    from ..estimate.api import VIDEO_EXTENSIONS

    if not getattr(args, "probe", None):
        return None
    if getattr(args, "light_from", None):
        raise UsageError("give either --probe (measure the light now) or --light-from FILE, not both")
    items = [str(x) for x in inputs]
    videos = [x for x in items if x.lower().endswith(tuple(VIDEO_EXTENSIONS))]
    photos = [x for x in items if x not in videos]
    if videos:  # the first videos, their frames shared out
        use, per = videos[:PROBE_FRAMES], max(1, PROBE_FRAMES // min(len(videos), PROBE_FRAMES))
    else:
        k = min(len(photos), PROBE_FRAMES)
        use, per = [photos[round(i * (len(photos) - 1) / max(k - 1, 1))] for i in range(k)], 1
    est = estimate_light(
        use,
        calib=calib,
        marker_length=marker_length,
        probe=args.probe,
        probe_place=args.probe_place,
        probe_rotate=args.probe_rotate,
        probe_scale=args.probe_scale,
        dictionary=dictionary,
        marker_id=marker_id,
        kind=args.kind,
        max_frames=per,
    )
    print(
        f"light: {est.light} (+-{est.uncertainty_deg:.2f} deg, {est.frames} frame(s)), shadow ratio "
        + " ".join(f"{v:.3f}" for v in est.shadow_ratio),
        file=sys.stderr,
    )
    for w in est.warnings:
        print(f"warning: {w}", file=sys.stderr)
    return type(est).from_dict(est.to_dict())  # the numbers its JSON holds: the same run as --light-from


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "light",
        help="measure the light, shadow colour and exposure from a probe's real shadow",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("inputs", nargs="+", metavar="PHOTO|VIDEO")
    p.add_argument("--calib", required=True, metavar="C", help="camera calibration (OpenCV YAML/XML/JSON, ROS)")
    p.add_argument("--marker-length", required=True, type=_positive, metavar="M", help="printed marker side, metres")
    p.add_argument("--dictionary", metavar="D", help="ArUco dictionary (default DICT_6X6_250)")
    p.add_argument("--marker-id", type=int, metavar="N", help="the reference marker (default: the lowest id found)")
    add_probe_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("-o", "--output", metavar="FILE", help="also write the JSON to FILE (for --light-from)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import UsageError
    from ..estimate import estimate_light
    from ..io import write_json

    if not args.probe:
        raise UsageError("give --probe MODEL: the reference object whose real shadow is measured")
    est = estimate_light(
        args.inputs,
        calib=args.calib,
        marker_length=args.marker_length,
        probe=args.probe,
        probe_place=args.probe_place,
        probe_rotate=args.probe_rotate,
        probe_scale=args.probe_scale,
        dictionary=args.dictionary,
        marker_id=args.marker_id,
        kind=args.kind,
    )
    if args.output:
        write_json(args.output, est.to_dict())
    if args.json:
        print(est.to_json())
        return 0
    print(f"light           {est.light}")
    print(
        f"uncertainty     {est.uncertainty_deg:.2f} deg (1 sigma)"
        + (f", position {1000 * est.position_uncertainty:.0f} mm" if est.position_uncertainty is not None else "")
    )
    print("shadow ratio    R {:.3f}  G {:.3f}  B {:.3f}  (linear, shadow / lit)".format(*est.shadow_ratio))
    if est.exposure is not None:
        e = est.exposure
        print(
            "paper (linear)  R {:.3f}  G {:.3f}  B {:.3f}  white balance {:.3f} {:.3f} {:.3f}".format(
                *e.paper_rgb, *e.white_balance
            )
        )
    for w in est.warnings:
        print(f"warning: {w}", file=sys.stderr)
    return 0
