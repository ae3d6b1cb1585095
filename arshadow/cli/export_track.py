"""``arshadow export-track``: a video's or a photo set's camera track as glTF 2.0, JSON or CSV."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from . import EXIT_OK

EPILOG = """\
examples:
  arshadow video clip.mp4 --calib cam.yml --marker-length 0.05 --model box:0.04,0.04,0.06 --light point:0,0,1 -o out
  arshadow export-track out/clip.frames.jsonl --calib cam.yml --model box:0.04,0.04,0.06 -o clip.glb -o clip.csv
  arshadow render shots/*.jpg ... -o out --report out/report.json
  arshadow export-track out/report.json --config job.yml -o shots.glb --lost absent

SOURCE: a video's <stem>.frames.jsonl (the pose each frame was rendered with), or a render --report JSON (a
photo set: photo i at i / --fps seconds). Formats by extension: .glb, .gltf, .json, .csv (docs/export.md).
"""


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "export-track",
        help="write the camera track (glTF 2.0 / JSON / CSV) of a video or a photo set",
        description="The intrinsics and the per-frame camera in the marker frame, for Blender, three.js and "
        "compositors (docs/export.md).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("source", metavar="SOURCE", help="<stem>.frames.jsonl of arshadow video, or a render report")
    p.add_argument(
        "-o",
        "--output",
        action="append",
        required=True,
        metavar="OUT",
        help="output file: .glb, .gltf, .json or .csv (repeat for several)",
    )
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--config", metavar="JOB", help="the job file of the run (calibration and model)")
    g.add_argument("--calib", metavar="C", help="calibration file of the run")
    p.add_argument("--model", metavar="M", help="the occluder (mesh file or primitive) for the glTF")
    p.add_argument("--scale", type=float, default=1.0, metavar="S")
    p.add_argument("--rotate", default="0,0,0", metavar="RX,RY,RZ")
    p.add_argument("--place", default="0,0,0", metavar="X,Y,Z", help="as render's; the occluder's pivot in the glTF")
    p.add_argument(
        "--up", choices=("y", "z"), metavar="y|z", help="the mesh file's up axis, as render's (default: y for glTF)"
    )
    p.add_argument("--drop-to-ground", action="store_true", help="stand the model on the ground, as render's")
    p.add_argument(
        "--ground-size",
        type=float,
        default=None,
        metavar="S",
        help="side of the proxy ground square in metres (default: the job's, else 1)",
    )
    p.add_argument(
        "--size",
        metavar="W,H",
        help="the frames' size, when it differs from the calibration's (same aspect ratio: K is scaled)",
    )
    p.add_argument(
        "--lost",
        choices=("held", "absent"),
        default="held",
        help="marker-lost frames: keyed with the last pose (held, default) or without a key",
    )
    p.add_argument("--fps", type=float, default=1.0, metavar="F", help="photo sets: photos per second (default 1)")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..camera.model import Intrinsics
    from ..errors import UsageError
    from ..export.track import track_from_frames_jsonl, track_from_items, write_track
    from ..geometry.mesh import load_occluder
    from ..io import InputGuard, check_output_file
    from ..scene.spec import load_scene, parse_triple

    outs = [check_output_file(o, "-o") for o in args.output]
    for o in outs:
        if o.suffix.lower() not in (".glb", ".gltf", ".json", ".csv"):
            raise UsageError(f"-o {o}: unknown track format (expected .glb, .gltf, .json or .csv)")
        if InputGuard([args.source]).clash([o]):
            raise UsageError(f"-o {o}: would overwrite the input")
    caster, ground, pivot = None, args.ground_size, None
    intr: Any
    if args.config:
        spec = load_scene(args.config)
        scene = spec.build()
        intr, caster, pivot = scene.intrinsics, scene.caster, spec.model.place
        ground = ground or scene.options.ground_size
    else:
        intr = Intrinsics.from_file(args.calib)
        if args.model:
            pivot = parse_triple(args.place, "--place")
            caster = load_occluder(
                args.model,
                args.scale,
                parse_triple(args.rotate, "--rotate"),
                pivot,
                up=args.up,
                drop_to_ground=bool(args.drop_to_ground),
            )
    if args.size:
        w, h = parse_triple(args.size + ",0", "--size")[:2]
        intr = intr.scaled(int(w), int(h))
    src = Path(args.source)
    if src.name.endswith(".jsonl"):
        track = track_from_frames_jsonl(src, intr)
        interp = "LINEAR"
    else:
        try:
            report = json.loads(src.read_text(encoding="utf-8"))
            items = report["images"]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise UsageError(f"{src}: not a frames report (.jsonl) or a render report ({exc})") from None
        track = track_from_items(items, intr, name=src.stem, fps=args.fps)
        interp = "STEP"
    for o in outs:
        write_track(
            o, track, caster=caster, ground_size=ground or 1.0, lost=args.lost, interpolation=interp, pivot=pivot
        )
        print(f"{src} -> {o}  ({sum(1 for _ in track.keyed(args.lost))} of {len(track.frames)} frames keyed)")
    return EXIT_OK
