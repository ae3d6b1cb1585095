"""``arshadow render``: composite a virtual object and its shadow into photos of a marker or board."""

from __future__ import annotations

import argparse
import logging
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import UsageError
from ..scene.options import DEFAULT_AA
from ..scene.spec import parse_triple, scene_from_args
from . import EXIT_OK, EXIT_SOME_FAILED, error_line, quiet_opencv
from .light import add_probe_options, probe_estimate

if TYPE_CHECKING:
    from tqdm import tqdm

    from ..frame.report import ReportItem
    from ..frame.result import FrameResult
    from ..photos import PhotoJob

log = logging.getLogger(__name__)

EPILOG = """\
examples:
  arshadow render photo.jpg --calib calib/cam.yml --marker-length 0.05 --model box:0.04,0.04,0.06 \\
      --light point:0.1,0.1,0.4 -o out/
  arshadow render 'shots/*.jpg' --calib cam.yml --board board.yml --model samples/meshes/knot.ply \\
      --place 0.1,0,0 --light sun:52.2,0.1,2024-06-21T15:00+01:00 --light point:0,0,1@0.3 -o out --save-mask \\
      --report out/report.json

outputs: DIR/<stem>.png (or the input's format with --keep-format), DIR/<stem>.shadow.png with --save-mask
(8-bit: round(255 x blocked light weight / total weight) where the ground is seen and the object is not).
exit status: 0 all done, 1 some inputs failed (the others were processed), 2 bad usage / configuration.
"""


def _triple(what: str) -> Callable[[str], tuple[float, float, float]]:
    """An argparse type over :func:`arshadow.scene.parse_triple` (a bad value: a usage error, exit 2)."""

    def parse(text: str) -> tuple[float, float, float]:
        try:
            return parse_triple(text, what)
        except UsageError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse


def _positive(what: str, integer: bool = False) -> Callable[[str], float]:
    """An argparse type: a positive finite number (an int with ``integer``)."""

    def parse(text: str) -> float:
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not (v > 0 and v != float("inf")):
            raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
        return v

    return parse


def add_scene_options(p: argparse.ArgumentParser, *, require: bool = True) -> None:
    """Options shared by ``render`` (and usable by the video command): calibration, marker, model, lights."""
    from .map import add_map_option

    g = p.add_argument_group("camera and marker")
    g.add_argument(
        "--calib", required=require, metavar="C", help="calibration file (OpenCV YAML/XML/JSON or ROS camera_info YAML)"
    )
    m = g.add_mutually_exclusive_group()
    m.add_argument(
        "--marker-length",
        type=_positive("--marker-length"),
        metavar="M",
        help="side of the printed marker in metres (single-marker mode)",
    )
    m.add_argument("--board", metavar="B", help="board file (GridBoard or ChArUco) instead of one marker")
    add_map_option(g)  # --map auto|FILE: loose markers learned into a map (cli/map.py)
    g.add_argument(
        "--dictionary",
        metavar="D",
        help="ArUco dictionary name or custom dictionary file (default DICT_6X6_250; a --board file names its own)",
    )
    g.add_argument(
        "--marker-id",
        type=int,
        metavar="N",
        help="use only this marker id as the reference (default: the lowest id found)",
    )
    g.add_argument(
        "--refine",
        choices=("edge", "ecc", "subpix", "apriltag", "contour", "none"),
        help="corner refinement (default ecc: the marker's border edges fitted and intersected (edge), then "
        "the marker's bitmap aligned to the photo, the edge corners kept where that fails; docs/tracking.md)",
    )
    g.add_argument(
        "--inverted",
        action="store_true",
        default=None,
        help="the markers are printed white on black (a board file may say 'inverted: 1')",
    )
    o = p.add_argument_group("virtual object")
    o.add_argument(
        "--model",
        required=require,
        metavar="M",
        help="mesh file (OBJ/PLY/STL/GLB/OFF, metres) or primitive box:WX,WY,HZ | cylinder:R,H | sphere:R | torus:R,r",
    )
    o.add_argument("--scale", type=_positive("--scale"), default=1.0, metavar="S", help="uniform scale (first)")
    o.add_argument(
        "--rotate",
        type=_triple("--rotate"),
        default=(0.0, 0.0, 0.0),
        metavar="RX,RY,RZ",
        help="rotation in degrees, XYZ order (after scale); a negative first number is fine: --rotate -90,0,0",
    )
    o.add_argument(
        "--place",
        type=_triple("--place"),
        default=(0.0, 0.0, 0.0),
        metavar="X,Y,Z",
        help="translation in metres, world (marker) frame (last); a negative first number is fine: --place -0.05,0,0",
    )
    o.add_argument(
        "--up",
        choices=("y", "z"),
        metavar="y|z",
        help="the mesh file's up axis, turned to the world's +z first (default: y for glTF "
        ".glb/.gltf, which is Y-up by specification; z for OBJ/PLY/STL/OFF). Blender's OBJ "
        "export is Y-up: --up y",
    )
    o.add_argument(
        "--drop-to-ground",
        action="store_true",
        help="stand the model on the ground: after scale and rotate, move it along z so that its "
        "lowest point is at z = 0 (for meshes centred on their origin); --place then adds",
    )
    o.add_argument(
        "--color",
        metavar="R,G,B",
        help="object colour relative to the marker paper's white, 8-bit sRGB 0..255 or #rrggbb (default: the mesh's own, read as reflectances)",
    )
    s = p.add_argument_group("lights and shadows")
    s.add_argument(
        "--light-from",
        metavar="FILE",
        help="a measured light (arshadow light ... -o FILE, docs/light.md): its light (unless --light "
        "is given), its shadow colour (instead of --opacity/--shadow-color) and the marker's exposure",
    )
    s.add_argument(
        "--ambient-occlusion",
        choices=("auto", "on", "off"),
        help="sky occlusion (docs/shading.md): the contact shadow on the ground, the object's own sky "
        "visibility and the light bounced from the ground. auto (default): on with a measured light "
        "(--light-from / --probe) whose sky share is not negligible",
    )
    s.add_argument(
        "--camera-effects",
        choices=("on", "off"),
        help="blur the inserted object and shadow by the photo's point-spread width (measured on the "
        "marker's edges) and add noise matched to the photo's (docs/shading.md); default off",
    )
    s.add_argument(
        "--motion-blur",
        choices=("on", "off"),
        help="with --camera-effects on, in a video: blur the inserted object and shadow along the image "
        "motion of the camera's pose change during the exposure (docs/shading.md); default on (photos: never)",
    )
    s.add_argument(
        "--shutter",
        type=float,
        metavar="FRACTION",
        help="exposure time / frame interval for --motion-blur, in (0, 1]; default 0.5 (a 180-degree shutter)",
    )
    s.add_argument(
        "--paper-albedo",
        type=float,
        metavar="R",
        help="the marker paper's reflectance, in (0, 1]; default 0.8 (printer paper: 0.8-0.9): a mesh's own "
        "colours and the light the object and the ground reflect are scaled to it (docs/shading.md)",
    )
    s.add_argument(
        "--no-exposure",
        action="store_true",
        help="keep the object's colour as given: no exposure / white balance match to the marker paper "
        "(on by default, every photo and video frame; docs/light.md)",
    )
    s.add_argument(
        "--light",
        action="append",
        metavar="L",
        help="point:X,Y,Z | directional:X,Y,Z | sun:LAT,LON,TIME[,NORTH], optional @W weight; "
        "repeat for several lights",
    )
    s.add_argument(
        "--soft-samples",
        type=_positive("--soft-samples", integer=True),
        default=1,
        metavar="N",
        help="samples per area light (lights with radius=...; sun: its 0.266 deg disc); 1 = hard",
    )
    s.add_argument(
        "--silhouette",
        default="adjacency",
        metavar="NAME",
        help="silhouette detector: adjacency (default), triangular, vnv, hsd, delta_plus",
    )
    s.add_argument(
        "--shadow-method",
        choices=("volume", "planar", "shadowmap"),
        default="volume",
        help="stencil shadow volumes (default, exact), planar projection shadows, or a shadow map "
        "(the baseline of three.js / pyrender: approximate; see docs/benchmarks.md)",
    )
    s.add_argument(
        "--shadowmap-size",
        type=_positive("--shadowmap-size", integer=True),
        default=2048,
        metavar="N",
        help="shadow map side in texels with --shadow-method shadowmap (default 2048)",
    )
    s.add_argument(
        "--opacity", type=float, default=0.7, metavar="O", help="darkness of a full shadow, 0..1 (default 0.7)"
    )
    s.add_argument(
        "--shadow-color", metavar="R,G,B", help="tint of a full shadow, 8-bit sRGB R,G,B or #rrggbb (default black)"
    )
    s.add_argument(
        "--aa",
        type=int,
        default=DEFAULT_AA,
        metavar="N",
        help=f"multisample anti-aliasing samples, {DEFAULT_AA} (default, as arshadow demo: pixel-centre "
        "sampling, the fastest), "
        "2 or 4 (smoother edges; ~5x the render time on a CPU renderer, see "
        "docs/compositing.md)",
    )
    s.add_argument(
        "--outline-aa",
        choices=("auto", "on", "off"),
        help="with --aa 0, the object's outline gets each pixel's coverage of its silhouette (exact for a "
        "straight edge, 1-2 ms; docs/compositing.md): auto (default) in photos, and in videos with sky "
        "occlusion on; on: always; off: pixel-centre samples only",
    )
    s.add_argument(
        "--ground-size",
        type=_positive("--ground-size"),
        metavar="S",
        help="side of the square shadow-catching ground plane in metres (default unlimited)",
    )
    s.add_argument(
        "--ground",
        metavar="SPEC",
        help="where the ground is, relative to the marker: marker (default: the marker plane), wall:H "
        "(marker upright on a wall, floor H m below its centre) or plane:PX,PY,PZ,NX,NY,NZ "
        "(point and up normal in the marker frame); the model and lights are placed in the "
        "ground's frame (docs/geometry.md)",
    )
    s.add_argument("--no-object", action="store_true", help="composite only the shadow, not the object")
    add_probe_options(p, run=True)
    s.add_argument(
        "--plan",
        choices=("auto", "general", "zpass", "zfail", "planar"),
        default="auto",
        help="frame planner: auto (default: the cheapest exact path per frame and light, decisions "
        "in the report's plan field), general (reference: z-fail, infinite volumes, whole "
        "photo, no reuse or culling), or force zpass / zfail / planar (docs/planner.md)",
    )
    s.add_argument(
        "--compose",
        choices=("auto", "cpu", "gpu"),
        default="auto",
        help="lens warp + composite in numpy (cpu) or in a shader (gpu); auto (default) times both "
        "on the first photo of each size and keeps numpy unless the shader is > 15 %% faster",
    )


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "render",
        help="composite a virtual object and its shadow into photos",
        description="Detect the marker or board in each photo, place the object in its frame, and composite "
        "the object and its exact shadow (stencil shadow volumes) into the photo.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("images", nargs="+", metavar="IMAGE", help="photos, folders of photos, or glob patterns")
    add_scene_options(p)
    out = p.add_argument_group("output")
    out.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created if missing)")
    out.add_argument("--save-mask", action="store_true", help="also write <stem>.shadow.png")
    out.add_argument("--report", metavar="R.json", help="write the JSON report of every input")
    out.add_argument("--keep-format", action="store_true", help="write the input's format instead of PNG")
    out.add_argument(
        "--layers",
        action="store_true",
        help="also write the compositing layers: <stem>.object, <stem>.shadow.mult (multiply pass), "
        "<stem>.shadow.only (black with alpha); plate x shadow.mult + object = the composite "
        "in linear light (docs/export.md)",
    )
    out.add_argument(
        "--layers-format",
        choices=("png", "exr"),
        default="png",
        help="16-bit PNG (default) or half-float linear OpenEXR (needs arshadow[exr])",
    )
    (
        out.add_argument(
            "--layers-undistorted",
            action="store_true",
            help="with --layers: also the layers in the undistorted (pinhole) camera, "
            "<stem>.undistorted.*, and the ST-map that distorts them onto the photo, <stem>.stmap.*",
        ),
    )
    out.add_argument("--quiet", "-q", action="store_true", help="no per-image progress lines or progress bar")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks and debug logging")
    p.set_defaults(func=run)


# --------------------------------------------------------------------------------------------------
def run(args: argparse.Namespace) -> int:
    # deferred: the engine (OpenCV, meshes) loads when a command runs, not at start-up (cli/__init__.py)
    from ..export.layerfiles import refuse_overwrite
    from ..frame.report import make_report
    from ..frame.session import Session
    from ..io import check_output_file, check_output_folder, write_json
    from ..photos import expand_inputs, photo_jobs, render_photos
    from ..scene.sanity import FlagTally

    debug = bool(getattr(args, "debug", False))
    quiet_opencv(debug)
    own: list[str] = []
    inputs = expand_inputs(args.images, skipped=own)
    if own:  # an earlier run's outputs in a folder given: not photos
        names = ", ".join(Path(f).name for f in own[:4]) + (", ..." if len(own) > 4 else "")
        print(
            f"arshadow render: skipped {len(own)} of arshadow's own outputs in the folder(s) given ({names}); "
            "give a file by name to render it anyway",
            file=sys.stderr,
        )
    # output paths first: a bad -o / --report / layer writer is one usage error before any work
    outdir = check_output_folder(args.output, "-o")
    if args.report:
        check_output_file(args.report, "--report")
    undistorted = bool(getattr(args, "layers_undistorted", False))
    layers = args.layers_format if getattr(args, "layers", False) or undistorted else None
    jobs = photo_jobs(
        inputs,
        outdir,
        save_mask=args.save_mask,
        keep_format=args.keep_format,
        layers_format=layers,
        layers_undistorted=undistorted,
    )
    if layers is not None:  # a layer file that would replace an input: a usage error, before any work
        refuse_overwrite([p for j in jobs for p in (j.layers or {}).values()], inputs)  # every job has layers
    est = probe_estimate(
        args,
        inputs,
        calib=args.calib,
        marker_length=args.marker_length,
        dictionary=args.dictionary,
        marker_id=args.marker_id,
    )  # --probe: docs/light.md
    use_map(args, inputs)  # --map: the markers' map learned (or read) first
    bar = None
    spec = scene_from_args(args) if est is None else scene_from_args(args, light_from=est)
    with Session(spec) as session:  # loads the scene: a bad one is exit 2
        try:  # made now (with the GL context): a bad --aa is a usage error (exit 2), not a per-photo one
            session.renderer  # noqa: B018
        except UsageError as exc:
            raise UsageError(f"--aa {args.aa} / --shadowmap-size: {exc}") from None
        if not args.quiet and len(jobs) > 1 and sys.stderr.isatty():
            from tqdm import tqdm  # deferred: only for a terminal

            bar = tqdm(total=len(jobs), unit="photo", desc="render", file=sys.stderr, dynamic_ncols=True)
        try:
            items = render_photos(session, jobs, debug=debug, on_done=lambda *a: _print_done(args, bar, *a))
        finally:
            if bar is not None:
                bar.close()
    if args.report:
        rep = make_report(items)
        if getattr(args, "map_info", None):  # --map: the map's file and residuals
            rep["map"] = args.map_info
        write_json(args.report, rep)
    if (away := out_of_view_warning(items, getattr(args, "place", None))) is not None:
        print(f"arshadow render: warning: {away}", file=sys.stderr)
    flags = FlagTally()
    for it in items:
        flags.add(it.input, it.flag_reasons)
    if flags.summary(len(items)):
        print(f"arshadow render: warning: {flags.summary(len(items))}", file=sys.stderr)
    failed = sum(i.status != "ok" for i in items)
    if not args.quiet and len(jobs) > 1:
        flagged = sum(1 for it in items if it.pose_flagged)
        print(
            f"{len(jobs) - failed} of {len(jobs)} photos rendered into {outdir}: "
            f"{len(jobs) - failed} done, {failed} failed, {flagged} flagged (ambiguous pose)",
            file=sys.stdout,
        )
    return EXIT_SOME_FAILED if failed else EXIT_OK


def use_map(args: argparse.Namespace, inputs: Sequence[str]) -> None:
    """``--map auto|FILE``: track against the map (learned from ``inputs`` into ``OUT/map.yml``, or read):
    ``args.board`` becomes the map file (cli/map.py)."""
    from .map import map_info, resolve_map

    board = resolve_map(
        args,
        inputs,
        args.output,
        calib=args.calib,
        marker_length=args.marker_length,
        dictionary=args.dictionary,
        marker_id=args.marker_id,
        inverted=args.inverted,
        board=args.board,
    )
    if board is not None:
        args.board, args.marker_length = board, None
        args.map_info = map_info(board)


def out_of_view_warning(items: Sequence[ReportItem], place: Sequence[float] | None = None) -> str | None:
    """The warning when the object and its shadows are outside the view (the planner's empty region,
    ``roi`` ``[0, 0, 0, 0]``) in every photo rendered, or in some of them; None when it is in view.

    >>> from types import SimpleNamespace as N
    >>> out_of_view_warning([N(status="ok", roi=[0, 0, 0, 0], input="a.jpg")], (3, 0, 0))[:60]
    'the object and its shadow are outside the view in every phot'
    """
    ok = [it for it in items if it.status == "ok"]
    away = [it for it in ok if it.roi is not None and not any(it.roi)]
    if not away:
        return None
    where = ""
    if place is not None and math.hypot(*map(float, place)) > 1.0:  # metres: a cm/m slip
        where = (
            f" (--place {','.join(f'{float(v):g}' for v in place)} is in metres, "
            f"{math.hypot(*map(float, place)):.3g} m from the marker: a cm/m slip?)"
        )
    if len(away) == len(ok):
        return f"the object and its shadow are outside the view in every photo: nothing was drawn{where}"
    return (
        f"the object and its shadow are outside the view in {len(away)} of {len(ok)} photos "
        f"({', '.join(it.input for it in away[:3])}{', ...' if len(away) > 3 else ''}){where}"
    )


def _print_done(
    args: argparse.Namespace,
    bar: tqdm | None,
    job: PhotoJob,
    item: ReportItem,
    res: FrameResult | None,
    err: BaseException | None,
) -> None:
    """One line per photo: the output (stdout, unless ``--quiet``) or the problem (stderr), above the
    progress bar when there is one."""
    say = bar.write if bar is not None else print
    if err is not None:
        say(_error_line(job.input, err), file=sys.stderr)
    elif not args.quiet:
        t = item.timings_ms.get("total", 0.0)
        say(f"{job.input} -> {job.output}  ({item.mode or 'no light casts a shadow'}, {t:.1f} ms)", file=sys.stdout)
    if bar is not None:
        bar.update(1)


def _error_line(inp: str | Path, exc: BaseException) -> str:
    """One line naming the input (once) and the problem."""
    msg = str(exc) or type(exc).__name__
    if str(inp) in msg:
        return f"arshadow render: error: {msg}"
    return error_line("render", str(inp), msg)
