"""``arshadow video``: composite a virtual object and its shadow into every frame of AR videos."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..tracking.detect import VIDEO_REFINE
from . import EXIT_OK, EXIT_SOME_FAILED

if TYPE_CHECKING:
    from tqdm import tqdm

    from ..video.api import VideoRun
    from ..video.encode import ProgressFactory
    from ..video.engine import EngineOptions

EPILOG = """\
examples:
  arshadow video clip.mp4 --calib calib/synth_640x360.yml --marker-length 0.05 --model box:0.04,0.04,0.06 \\
      --light point:0.1,0.1,0.4 -o out/ --report out/report.json
  arshadow video samples/video/orbit.mp4 --calib calib/synth_640x360.yml --marker-length 0.05 \\
      --model samples/meshes/house.obj --place 0.07,0.03,0 --light sun:48.86,2.35 \\
      --time-lapse 2024-06-21T06:00+02:00,3600 --recompute-deg 0.5 -o out --save-mask

outputs: DIR/<stem>.mp4 (or .avi / .mkv with --format), and with --save-mask DIR/<stem>.shadow.mkv, a
lossless (FFV1) 8-bit single-channel video of the shadow mask (CONVENTIONS.md mask values). Frames without
the marker are written unchanged (mask 0) and reported with status no_marker.
report: one ITEM per FRAME in "images" (input = the video, plus "frame" and "time_s"); a video that cannot be
read gets one ITEM with status error (no "frame"); "videos" summarises each video.
exit status: 0 all videos done, 1 some video failed (unreadable, unwritable, or the marker in no frame; the
other videos were processed), 2 bad usage / configuration.
"""

FORMATS = ("mp4", "mkv", "mov", "avi")
#: default codec per container
FORMAT_CODEC = {"mp4": "h264", "mov": "h264", "mkv": "ffv1", "avi": "mjpeg"}


def add_output_options(out: argparse._ArgumentGroup) -> None:
    """The video output options shared by ``arshadow video`` and ``arshadow batch``."""
    out.add_argument(
        "--format",
        choices=FORMATS,
        default="mp4",
        help="container of the output video: mp4 (H.264, default), mov, mkv (FFV1 lossless), avi (MJPEG)",
    )
    out.add_argument(
        "--codec",
        choices=("h264", "mpeg4", "mjpeg", "ffv1"),
        help="video codec (default: the container's, see --format)",
    )
    out.add_argument(
        "--crf",
        type=float,
        default=20.0,
        metavar="Q",
        help="H.264 quality, constant rate factor 0 (lossless) .. 51 (default 20)",
    )
    out.add_argument(
        "--preset", default="ultrafast", help="x264 speed preset (default ultrafast; slower presets give smaller files)"
    )
    out.add_argument(
        "--save-mask",
        nargs="?",
        const="mkv",
        choices=("mkv", "png"),
        metavar="mkv|png",
        help="also write the shadow mask: DIR/<stem>.shadow.mkv (lossless FFV1, default) or "
        "DIR/<stem>.shadow/NNNNNN.png",
    )
    out.add_argument(
        "--contact-sheet",
        type=int,
        default=12,
        metavar="N",
        help="frames on DIR/<stem>.sheet.jpg (default 12; 0 = none)",
    )
    out.add_argument("--no-audio", action="store_true", help="do not copy the input's audio")
    out.add_argument(
        "--jobs",
        "-j",
        type=int,
        default=1,
        metavar="N",
        help="worker processes per video: it is cut after keyframes into N chunks processed in parallel "
        "and joined (same output as one process; docs/video.md)",
    )
    out.add_argument(
        "--layers",
        action="store_true",
        help="also write the compositing layers (object with alpha, shadow multiply pass, shadow-only "
        "with alpha), lens distortion applied: plate x shadow.mult + object = the composite in "
        "linear light (docs/export.md)",
    )
    out.add_argument(
        "--layers-format",
        choices=("prores", "ffv1", "png", "exr"),
        default="prores",
        help="videos' layers: prores (ProRes 4444 .mov, default), ffv1 (lossless 16-bit .mkv), or "
        "png / exr sequences in DIR/<stem>.layers/; photos of a batch: 16-bit PNG, or EXR with exr",
    )
    out.add_argument(
        "--layers-undistorted",
        action="store_true",
        help="with --layers: also the layers in the undistorted (pinhole) camera and the ST-map "
        "DIR/<stem>.stmap.* that distorts them onto the frames",
    )


def engine_options(args: argparse.Namespace, collect_items: bool = False) -> EngineOptions:
    """:class:`arshadow.video.engine.EngineOptions` from the parsed options."""
    from ..video.engine import EngineOptions

    return EngineOptions(
        fmt=args.format,
        codec=args.codec or FORMAT_CODEC[args.format],
        crf=args.crf,
        preset=args.preset,
        mask=args.save_mask,
        pose_lag=None if getattr(args, "no_temporal", False) else getattr(args, "pose_lag", 16),
        smooth=getattr(args, "smooth", 10),
        hold=getattr(args, "hold", 12),
        max_frames=getattr(args, "max_frames", None),
        contact_sheet=args.contact_sheet,
        keep_audio=not args.no_audio,
        collect_items=collect_items,
        layers=args.layers_format
        if (getattr(args, "layers", False) or getattr(args, "layers_undistorted", False))
        else None,
        layers_undistorted=bool(getattr(args, "layers_undistorted", False)),
    ).check()


def progress_bar(quiet: bool) -> ProgressFactory | None:
    """A ``progress_factory`` for :func:`arshadow.video.runner.run_videos`: a tqdm bar per video (none with
    ``-q`` or when stderr is not a terminal: a log file gets the closing lines only)."""
    if quiet or not sys.stderr.isatty():
        return None

    def factory(name: str) -> tuple[Callable[[int, int | None], None], Callable[[], None]]:
        from tqdm import tqdm

        bars: list[tqdm] = []  # made on the first frame: a video that cannot be opened prints only its error line

        def update(done: int, total: int | None) -> None:
            if not bars:
                bars.append(
                    tqdm(
                        desc=Path(name).name, unit="frame", total=total, dynamic_ncols=True, file=sys.stderr, leave=True
                    )
                )
            bar = bars[0]
            if total and bar.total != total:
                bar.total = total
            bar.update(done - bar.n)

        def close() -> None:
            if bars:
                bars[0].close()

        return update, close

    return factory


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from .render import add_scene_options

    p = subparsers.add_parser(
        "video",
        help="composite a virtual object and its shadow into AR videos",
        description="Decode each video (anything OpenCV's video I/O reads), track the marker or board in every "
        "frame with temporally consistent poses, composite the object and its exact shadow, and "
        "write the result video (atomically: never half-written).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "videos",
        nargs="+",
        metavar="VIDEO",
        help="video files (or OpenCV image-sequence patterns such as frames/%%04d.png)",
    )
    add_scene_options(p)
    v = p.add_argument_group("video")
    v.add_argument(
        "--time-lapse",
        metavar="START[,SPEED]",
        help="sun lights follow the frame timestamps: the sun's time is START (ISO 8601 with UTC "
        "offset; replaces the sun spec's TIME, which may then be left out) + SPEED x the frame "
        "time (default SPEED 1)",
    )
    v.add_argument(
        "--recompute-deg",
        type=float,
        default=0.1,
        metavar="A",
        help="with --time-lapse: recompute the silhouette only when the sun moved more than A "
        "degrees since the last recompute (default 0.1; the shadow is at most A off)",
    )
    v.add_argument("--max-frames", type=int, metavar="N", help="process only the first N frames of each video")
    v.add_argument(
        "--pose-lag",
        type=int,
        default=16,
        metavar="K",
        help="frames of look-ahead for the temporally consistent IPPE choice (default 16; 0 = the "
        "solution consistent with the previous frame)",
    )
    v.add_argument(
        "--corner-refine",
        choices=("edge", "ecc", "apriltag", "subpix", "contour", "none"),
        default=VIDEO_REFINE,
        help="corner refinement (default edge: the four border edges fitted at full resolution and "
        "intersected, unbiased and fast; ecc: then the marker's bitmap aligned, +1.6 ms a frame, the "
        "photos' default; subpix puts small markers 1-4 %% too far; apriltag is unbiased but ~10x "
        "slower; see docs/video.md, docs/tracking.md)",
    )
    v.add_argument(
        "--smooth",
        type=int,
        default=10,
        metavar="K",
        help="pose smoothing: centred local-quadratic fit over 2K+1 frames (default 10; zero lag on "
        "steady motion; 0 = raw poses)",
    )
    v.add_argument(
        "--hold",
        type=int,
        default=12,
        metavar="N",
        help="frames a lost marker's last pose is held before frames pass through untouched (default 12)",
    )
    v.add_argument(
        "--no-temporal",
        action="store_true",
        help="choose each frame's pose by reprojection error alone (as for photos)",
    )
    out = p.add_argument_group("output")
    out.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created if missing)")
    add_output_options(out)
    out.add_argument("--report", metavar="R.json", help="write the JSON report (one item per frame)")
    out.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no per-video lines")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks and debug logging")
    p.set_defaults(func=run)


# --------------------------------------------------------------------------------------------------
def run(args: argparse.Namespace) -> int:
    """``arshadow video``: the scene from the options, :func:`arshadow.video.api.process_video`, the lines and
    the report."""
    from ..errors import UsageError
    from ..io import check_output_file, check_output_folder, write_json
    from ..scene.spec import scene_from_args
    from ..video.api import process_video
    from . import quiet_opencv
    from .light import probe_estimate
    from .render import use_map

    debug = bool(getattr(args, "debug", False))
    quiet_opencv(debug)
    opts = engine_options(args, collect_items=bool(args.report))
    # --time-lapse and --recompute-deg are scene keys (SceneSpec.time_lapse); process_video tracks near the
    # last detection first (track_roi), as set here for the probe's scene too
    est = probe_estimate(
        args,
        args.videos,
        calib=args.calib,
        marker_length=args.marker_length,
        dictionary=args.dictionary,
        marker_id=args.marker_id,
    )  # --probe: docs/light.md
    extra: dict[str, object] = {} if est is None else {"light_from": est}
    use_map(args, args.videos)  # --map: the markers' map learned (or read) first (cli/map.py)
    spec = scene_from_args(args, refine=args.corner_refine, track_roi=True, **extra)
    # output paths before any work: a bad -o / --report is one usage error, not one per video
    outdir = check_output_folder(args.output, "-o")
    if args.report:
        check_output_file(args.report, "--report")
    if args.jobs < 1:
        raise UsageError(f"--jobs {args.jobs}: must be >= 1")
    run = process_video(
        spec,
        args.videos,
        outdir,
        options=opts,
        jobs=args.jobs,
        progress=progress_bar(args.quiet),
        warn=lambda msg: print(f"arshadow video: warning: {msg}", file=sys.stderr),
        raise_errors=debug,
    )
    _print_summaries(run, outdir, args.quiet)
    if args.report:
        rep = run.report()
        if getattr(args, "map_info", None):  # --map: the map's file and residuals
            rep["map"] = args.map_info
        write_json(args.report, rep)
    return EXIT_SOME_FAILED if run.failed else EXIT_OK


def _print_summaries(run: VideoRun, outdir: Path, quiet: bool) -> None:
    """Each video's warnings, error or tracking line and output line; the closing line of several."""
    failed, summaries = 0, run.summaries
    for s in summaries:
        # the sun-set warning was printed before any frame (process_video's warn): its copy first in the
        # summary's warnings is not repeated
        for w in s.get("warnings", [])[1 if s.get("input") in run.warnings else 0 :]:
            print(f"arshadow video: warning: {w}", file=sys.stderr)
        if s["status"] == "error":
            print(f"arshadow video: error: {s['error']}", file=sys.stderr)
        if s["status"] != "ok":
            failed += 1
        if s["status"] != "error" and not quiet:
            print(tracking_summary(s), file=sys.stderr)
        if s["status"] == "ok" and not quiet:
            print(
                f"{s['input']} -> {s['output']}  ({s['frames']} frames: {s['frames_ok']} tracked, "
                f"{s['frames_held']} held, {s['frames_no_marker']} without marker; "
                f"{s['fps_processed']:.1f} fps)",
                file=sys.stdout,
            )
    if not quiet and len(summaries) > 1:
        flagged = sum(1 for s in summaries if s["status"] == "ok" and s.get("frames_no_marker"))
        print(
            f"{len(summaries) - failed} of {len(summaries)} videos rendered into {outdir}: "
            f"{len(summaries) - failed} done, {failed} failed, {flagged} flagged (frames without the marker)"
        )


def tracking_summary(s: dict[str, Any]) -> str:
    """The stderr line of one video's tracking: frames tracked / held / lost and the longest gap."""
    gap = s.get("longest_gap") or 0
    where = f" (frames {s['longest_gap_start']}-{s['longest_gap_start'] + gap - 1})" if gap else ""
    return (
        f"arshadow video: {s['input']}: tracked {s['frames_ok']}, held {s['frames_held']}, lost "
        f"{s['frames_no_marker']} of {s['frames']} frames; longest gap {gap} frames{where}"
    )
