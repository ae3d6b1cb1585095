"""``arshadow video``: composite a virtual object and its shadow into every frame of AR videos."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from . import EXIT_OK, EXIT_SOME_FAILED, error_line

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
read gets one ITEM with status error and frame null; "videos" summarises each video.
exit status: 0 all videos done, 1 some video failed (unreadable, unwritable, or the marker in no frame; the
other videos were processed), 2 bad usage / configuration.
"""

FORMATS = ("mp4", "avi", "mkv")


def register(subparsers) -> None:
    from .render import add_scene_options

    p = subparsers.add_parser(
        "video", help="composite a virtual object and its shadow into AR videos",
        description="Decode each video (anything OpenCV's video I/O reads), track the marker or board in every "
                    "frame with temporally consistent poses, composite the object and its exact shadow, and "
                    "write the result video (atomically: never half-written).",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("videos", nargs="+", metavar="VIDEO",
                   help="video files (or OpenCV image-sequence patterns such as frames/%%04d.png)")
    add_scene_options(p)
    v = p.add_argument_group("video")
    v.add_argument("--time-lapse", metavar="START[,SPEED]",
                   help="sun lights follow the frame timestamps: the sun's time is START (ISO 8601 with UTC "
                        "offset; replaces the sun spec's TIME, which may then be left out) + SPEED x the frame "
                        "time (default SPEED 1)")
    v.add_argument("--recompute-deg", type=float, default=0.1, metavar="A",
                   help="with --time-lapse: recompute the silhouette only when the sun moved more than A "
                        "degrees since the last recompute (default 0.1; the shadow is at most A off)")
    v.add_argument("--max-frames", type=int, metavar="N", help="process only the first N frames of each video")
    v.add_argument("--pose-lag", type=int, default=16, metavar="K",
                   help="frames of look-ahead for the temporally consistent IPPE choice (default 16; 0 = the "
                        "solution consistent with the previous frame)")
    v.add_argument("--corner-refine", choices=("apriltag", "subpix", "contour", "none"), default="apriltag",
                   help="ArUco corner refinement (default apriltag: unbiased; subpix, the photo default, puts "
                        "small markers 1-4 %% too far at 640x360, see docs/video.md)")
    v.add_argument("--no-temporal", action="store_true",
                   help="choose each frame's pose by reprojection error alone (as for photos)")
    out = p.add_argument_group("output")
    out.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created if missing)")
    out.add_argument("--format", choices=FORMATS, default="mp4",
                     help="container of the output video: mp4 (MPEG-4 part 2, default), avi (MJPEG), "
                          "mkv (FFV1, lossless)")
    out.add_argument("--save-mask", action="store_true", help="also write DIR/<stem>.shadow.mkv (lossless)")
    out.add_argument("--report", metavar="R.json", help="write the JSON report (one item per frame)")
    out.add_argument("--quiet", "-q", action="store_true", help="no per-video progress lines")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                   help="show tracebacks and debug logging")
    p.set_defaults(func=run)


# --------------------------------------------------------------------------------------------------
def parse_time_lapse(text: str):
    """``START[,SPEED]`` -> (aware datetime, speed > 0). UsageError on bad input.

    Examples
    --------
    >>> parse_time_lapse("2024-06-21T06:00+02:00,600")[1]
    600.0
    """
    from ..errors import LightError, UsageError
    from ..lights import parse_time

    start_text, sep, speed_text = str(text).rpartition(",")
    if not sep:
        start_text, speed_text = text, "1"
    try:
        speed = float(speed_text)
    except ValueError:
        raise UsageError(f"--time-lapse {text!r}: SPEED {speed_text!r} is not a number") from None
    if not (math.isfinite(speed) and speed > 0):
        raise UsageError(f"--time-lapse {text!r}: SPEED must be a positive number")
    try:
        start = parse_time(start_text.strip(), what="--time-lapse START")
    except LightError as exc:
        raise UsageError(str(exc)) from None
    return start, speed


def build_lights(args):
    """``(static_lights, sun_tracks, time_lapse)`` from ``--light`` / ``--time-lapse`` / ``--recompute-deg``."""
    from ..errors import UsageError
    from ..lights import parse_light, parse_sun_track

    if not (math.isfinite(args.recompute_deg) and args.recompute_deg >= 0):
        raise UsageError(f"--recompute-deg {args.recompute_deg}: must be >= 0 degrees")
    if args.time_lapse is None:
        return [parse_light(s) for s in args.light], [], None
    tl = parse_time_lapse(args.time_lapse)
    static, tracks = [], []
    for spec in args.light:
        if spec.strip().lower().startswith("sun:"):
            tracks.append(parse_sun_track(spec, recompute_deg=args.recompute_deg))
        else:
            static.append(parse_light(spec))
    if not tracks:
        raise UsageError("--time-lapse needs a sun light (--light sun:LAT,LON[,TIME][,NORTH])")
    return static, tracks, tl


def output_paths(inputs, outdir: Path, fmt: str):
    """Map each video to ``(output, mask)``; stems that collide get ``_2``, ``_3``... ."""
    seen: dict[str, int] = {}
    res = []
    for inp in inputs:
        stem = Path(inp).stem.replace("%", "") or "video"
        n = seen.get(stem.lower(), 0) + 1
        seen[stem.lower()] = n
        if n > 1:
            stem = f"{stem}_{n}"
        res.append((outdir / f"{stem}.{fmt}", outdir / f"{stem}.shadow.mkv"))
    return res


def run(args) -> int:
    import dataclasses

    from ..errors import UsageError
    from ..gl.context import create_context
    from ..io import write_json
    from ..report import make_report
    from . import quiet_opencv
    from .render import build_scene

    debug = bool(getattr(args, "debug", False))
    quiet_opencv(debug)
    if args.max_frames is not None and args.max_frames < 1:
        raise UsageError(f"--max-frames {args.max_frames}: must be >= 1")
    if args.pose_lag < 0:
        raise UsageError(f"--pose-lag {args.pose_lag}: must be >= 0")
    static, tracks, tl = build_lights(args)
    # a sun track's lights are set per frame: the scene builder gets the static lights only
    intr, caster, _, opts, tracker = build_scene(args, lights=static)
    tracker["refine"] = args.corner_refine
    # video: search the marker near the last detection first (not with --plan general)
    opts = dataclasses.replace(opts, track_roi=True)
    outdir = Path(args.output)
    if outdir.exists() and not outdir.is_dir():
        raise UsageError(f"-o {outdir}: exists and is not a folder")
    ctx = create_context()
    try:
        items, summaries, failed = _process_all(args, ctx, intr, caster, static, tracks, tl, opts, tracker,
                                                outdir, debug)
    finally:
        ctx.release()
    if args.report:
        rep = make_report(items)
        from ..report import jsonable

        rep["videos"] = jsonable(summaries)
        write_json(args.report, rep)
    return EXIT_SOME_FAILED if failed else EXIT_OK


def _process_all(args, ctx, intr, caster, static, tracks, tl, opts, tracker, outdir, debug):
    from ..errors import ArshadowError
    from ..pipeline import Compositor
    from ..report import ReportItem
    from .render import _same_file

    first_lights = list(static)
    if tracks:
        for tr in tracks:
            tr.reset()
            first_lights.append(tr.light(tr.update(tl[0])))
            tr.reset()
    items, summaries, failed = [], [], 0
    paths = output_paths(args.videos, outdir, args.format)
    inputs = [Path(v) for v in args.videos]
    with Compositor(ctx, intr, caster, first_lights, opts, tracker=tracker) as comp:
        for inp, (out_path, mask_path) in zip(args.videos, paths):
            summary = {"input": str(inp), "output": None, "mask": None, "status": "ok", "error": None}
            try:
                if any(_same_file(out_path, i) or _same_file(mask_path, i) for i in inputs):
                    from ..errors import ImageError

                    raise ImageError(f"{out_path}: output would overwrite an input; choose another -o folder")
                frame_items = process_video(comp, inp, out_path, mask_path if args.save_mask else None,
                                            static=static, tracks=tracks, time_lapse=tl,
                                            max_frames=args.max_frames,
                                            pose_lag=None if args.no_temporal else args.pose_lag,
                                            summary=summary)
                items.extend(frame_items)
                if summary["frames_ok"] == 0:
                    failed += 1
                    summary["status"] = "no_marker"
                    summary["error"] = f"{inp}: the marker was found in none of the {summary['frames']} frames"
                    print(error_line("video", str(inp), "the marker was found in no frame (video written "
                                                        "unchanged)"), file=sys.stderr)
                elif not args.quiet:
                    print(f"{inp} -> {out_path}  ({summary['frames']} frames, {summary['frames_no_marker']} "
                          f"without marker, {summary['frame_ms_median']:.1f} ms/frame median)", file=sys.stdout)
            except (ArshadowError, OSError, MemoryError) as exc:
                if debug:
                    raise
                failed += 1
                msg = str(exc) if isinstance(exc, ArshadowError) else f"{type(exc).__name__}: {exc}"
                summary.update(status="error", error=msg, output=None, mask=None)
                print(_error_line(inp, msg), file=sys.stderr)
                it = ReportItem(input=str(inp), status="error", error=msg)
                it.extra["frame"] = None
                items.append(it)
            summaries.append(summary)
    return items, summaries, failed


def _error_line(inp, msg) -> str:
    return f"arshadow video: error: {msg}" if str(inp) in msg else error_line("video", str(inp), msg)


# --------------------------------------------------------------------------------------------------
def process_video(comp, path, out_path, mask_path=None, *, static=(), tracks=(), time_lapse=None,
                  max_frames=None, pose_lag=16, summary=None):
    """Composite every frame of one video; write the output (and mask) video atomically.

    Parameters
    ----------
    comp : arshadow.pipeline.Compositor
    path : str
        The input video.
    out_path, mask_path : Path
        Output video, and the lossless mask video (None: no mask).
    static : list of Light
        Lights fixed over the video (with ``tracks``; without tracks the compositor's own lights are used).
    tracks : list of arshadow.sun.SunTrack
        Sun lights following the frame times (``time_lapse = (start, speed)``).
    pose_lag : int or None
        Look-ahead of :class:`arshadow.video.TemporalPoseChooser`; None: pose by reprojection error only.
    summary : dict, optional
        Filled with the per-video summary.

    Returns
    -------
    list of ReportItem
        One per frame.

    Raises
    ------
    ImageError, CalibrationError
        Unreadable video, a frame size the calibration does not fit, an unwritable output.
    """
    import contextlib
    from datetime import timedelta

    import numpy as np

    from ..errors import MarkerNotFoundError
    from ..pipeline import STAGES
    from ..report import ReportItem
    from ..video import AtomicVideoWriter, TemporalPoseChooser, VideoReader

    summary = {} if summary is None else summary
    reader = VideoReader(path, max_frames=max_frames)
    try:
        W, H = reader.width, reader.height
        cal = comp.calib_for(W, H)  # CalibrationError: the size does not fit the calibration
        trackers = [t for t in (getattr(cal, "fast_tracker", None), cal.tracker) if t is not None]
        chooser = None if pose_lag is None else TemporalPoseChooser(lag=pose_lag, fps=reader.fps)
        for tr in tracks:
            tr.reset()
        items = []
        frame_ms = []
        stats = dict(frames=0, frames_ok=0, frames_no_marker=0, swapped=0, recomputes=0)

        def estimate(image, timings):
            t = time.perf_counter()
            err = None
            for k, trk in enumerate(trackers):
                try:
                    pose = trk.estimate(image)
                    break
                except MarkerNotFoundError as exc:
                    err = exc
            else:
                pose = None
            timings["detect"] += (time.perf_counter() - t) * 1e3
            return pose, err

        # each frame is encoded as soon as it is composited: one output (and mask) buffer per video
        out_buf = np.empty((H, W, 3), np.uint8)
        mask_buf = np.empty((H, W), np.uint8)
        no_mask = np.zeros((H, W), np.uint8)
        mask_ctx = (AtomicVideoWriter(mask_path, reader.fps, (W, H), color=False) if mask_path is not None
                    else contextlib.nullcontext())
        with AtomicVideoWriter(out_path, reader.fps, (W, H)) as vw, mask_ctx as mw:

            def finish(payload, pose, swapped):
                fr, timings, err = payload
                t0 = time.perf_counter()
                item = ReportItem(input=str(path), output=str(out_path),
                                  mask=None if mask_path is None else str(mask_path))
                item.extra.update(frame=fr.index, time_s=round(fr.time_s, 6))
                if cal.was_scaled:
                    item.extra["calibration_scaled"] = {"from": [comp.intrinsics.width, comp.intrinsics.height],
                                                        "to": [W, H]}
                if tracks:
                    when = time_lapse[0] + timedelta(seconds=fr.time_s * time_lapse[1])
                    sun_frames = [tr.update(when) for tr in tracks]
                    comp.set_lights(list(static) + [tr.light(f) for tr, f in zip(tracks, sun_frames)])
                    n_rec = sum(f.recompute for f in sun_frames)
                    stats["recomputes"] += n_rec
                    item.extra["sun"] = [
                        {"time": f.when.isoformat(), "zenith_deg": round(f.position.zenith_deg, 5),
                         "azimuth_deg": round(f.position.azimuth_deg, 5), "above_horizon": bool(f.above_horizon),
                         "recompute": bool(f.recompute), "stale_deg": round(f.stale_deg, 5)} for f in sun_frames]
                    if comp.notes:
                        item.extra["notes"] = list(comp.notes)
                if pose is None:
                    out = fr.image
                    mask = no_mask
                    item.status, item.error = "no_marker", str(err) if err else "no marker found"
                    stats["frames_no_marker"] += 1
                else:
                    item.set_pose(pose)
                    item.extra["pose_choice"] = "temporal (alternative IPPE solution)" if swapped else "error"
                    stats["swapped"] += int(swapped)
                    out, mask, info = comp.render_pose(fr.image, cal.intrinsics, np.asarray(pose.cam_from_world),
                                                       lens=cal.lens, timings=timings,
                                                       want_mask=mask_path is not None, out=out_buf,
                                                       mask_out=mask_buf)
                    item.mode = info["mode"]
                    item.silhouette_edges = info["silhouette_edges"]
                    item.extra.update({k: v for k, v in info.items() if k not in ("mode", "silhouette_edges")})
                    stats["frames_ok"] += 1
                timings["total"] += timings["detect"] + (time.perf_counter() - t0) * 1e3
                t1 = time.perf_counter()
                vw.write(out)
                if mask_path is not None:
                    mw.write(mask)
                item.extra["encode_ms"] = round((time.perf_counter() - t1) * 1e3, 3)
                item.timings_ms = {k: round(v, 3) for k, v in timings.items()}
                frame_ms.append(timings["total"])
                stats["frames"] += 1
                items.append(item)

            t_dec = time.perf_counter()
            for fr in reader:
                timings = dict.fromkeys(STAGES, 0.0)
                timings["decode"] = (time.perf_counter() - t_dec) * 1e3
                pose, err = estimate(fr.image, timings)
                if chooser is None:
                    finish((fr, timings, err), pose, False)
                else:
                    for ch in chooser.push((fr, timings, err), pose, fr.time_s):
                        finish(ch.payload, ch.pose, ch.swapped)
                t_dec = time.perf_counter()
            if chooser is not None:
                for ch in chooser.flush():
                    finish(ch.payload, ch.pose, ch.swapped)
        fm = np.asarray(frame_ms) if frame_ms else np.zeros(1)
        summary.update(stats, output=str(out_path), mask=None if mask_path is None else str(mask_path),
                       fps=reader.fps, fps_assumed=reader.fps_assumed, size=[W, H],
                       truncated=reader.truncated,
                       frame_ms_median=float(np.median(fm)),
                       frame_ms_iqr=[float(np.percentile(fm, 25)), float(np.percentile(fm, 75))],
                       frame_ms_minmax=[float(fm.min()), float(fm.max())])
        return items
    finally:
        reader.close()
