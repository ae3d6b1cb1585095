"""``arshadow preview``: place the object by hand in a browser page, then save the scene file."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from ..scene.spec import SCENE_KEYS
from . import EXIT_OK

EPILOG = """\
examples:
  arshadow preview samples/knot_point.jpg --calib calib/synth_1280x720.yml --marker-length 0.05 \\
      --model samples/meshes/knot.ply --light point:-0.12,0.2,0.42
  arshadow preview clip.mp4 --calib cam.yml --marker-length 0.05 --model box:0.04,0.04,0.06 \\
      --light-from light.json --scene-out job.yml --port 8765
  arshadow preview clip.mp4 --config job.yml --scene-out job2.yml        # reopen a saved scene

The page (served on 127.0.0.1 only, behind the random token in the printed address) shows the input
composited by the same pipeline as render / video. Drag on the photo to stand the object under the cursor;
turn, scale and raise it; move the light or switch to the measured one; Save writes the scene file (the
job-file format of batch --config) and shows the equivalent command lines. Ctrl-C stops the server.
"""

#: scene keys holding paths, made absolute at start (the saved file's are relative to its folder)
_PATHS = ("calib", "board", "dictionary", "model", "light_from")


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    from .render import add_scene_options

    p = subparsers.add_parser(
        "preview",
        help="place the object by hand in a browser page (live, the real pipeline) and save the scene",
        description="Serve a page on 127.0.0.1 that shows the photo (or a video frame) with the object and its "
        "shadow, rendered by the same session as render / video, and lets you drag, turn, scale and "
        "raise the object, move the light, and save the scene file.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", metavar="PHOTO|VIDEO", help="the photo or video to preview (the only file served)")
    add_scene_options(p, require=False)
    g = p.add_argument_group("preview")
    g.add_argument(
        "--config",
        "-c",
        metavar="JOB.yml",
        help="start from this scene file (e.g. one Save wrote: reopen it); scene options given as well "
        "replace its keys (without it, --calib and --model are required)",
    )
    g.add_argument("--port", type=int, default=0, metavar="N", help="port on 127.0.0.1 (default: any free port)")
    g.add_argument(
        "--scene-out",
        metavar="FILE.yml",
        help="where Save writes the scene file (default: <input stem>.scene.yml in the current folder)",
    )
    g.add_argument("--no-browser", action="store_true", help="print the address only; do not open a browser")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks and debug logging")
    p.set_defaults(func=run, preview_defaults={k: p.get_default(k) for k in SCENE_KEYS})


def base_scene(args: argparse.Namespace) -> dict:
    """The starting scene (job-file keys) from the parsed options: defaults left out, paths absolute; over
    ``--config``'s scene when given.

    Raises
    ------
    UsageError
        No ``--config`` and no ``--calib`` / ``--model``; a bad ``--config`` file.
    """
    from ..errors import UsageError
    from ..preview.edit import read_job

    defaults = getattr(args, "preview_defaults", {})
    config = getattr(args, "config", None)
    if config is None and not (args.calib and args.model):
        raise UsageError("give --calib and --model (or --config JOB.yml)")
    d = read_job(config) if config else {}
    for key in SCENE_KEYS:
        v = getattr(args, "light" if key == "lights" else key, None)
        if v is None or v is False or (key in defaults and v == defaults[key] and key not in ("calib", "model")):
            continue
        if key in _PATHS and isinstance(v, str) and (key not in ("model", "dictionary") or Path(v).is_file()):
            v = os.path.abspath(v)
        d[key] = list(v) if isinstance(v, tuple) else v
    if config and args.light_from and not args.light:
        d.pop("lights", None)  # --light-from over a file's lights: the measured light, as on render
    return d


def open_browser(url: str) -> bool:
    """Open ``url`` in the desktop's browser when there is a desktop (never a console browser, never an error)."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return False
    try:
        import webbrowser

        return bool(webbrowser.open(url, new=2))
    except Exception:  # noqa: BLE001 (no browser is not an error)
        return False


def run(args: argparse.Namespace) -> int:
    from ..errors import UsageError
    from ..estimate.record import load_estimate
    from ..io import check_output_file, write_json
    from ..preview.edit import controls_of, light_angles
    from ..preview.engine import Media, PreviewEngine
    from ..preview.server import PreviewServer
    from .light import probe_estimate

    if not 0 <= args.port <= 65535:
        raise UsageError(f"--port {args.port}: expected 0..65535")
    media = Media(args.input)
    scene_out = Path(args.scene_out or f"{Path(args.input).stem}.scene.yml")
    check_output_file(scene_out, "--scene-out")
    if scene_out.resolve() == Path(args.input).resolve():
        raise UsageError(f"--scene-out {scene_out}: that is the input")
    if args.config and not args.scene_out and scene_out.resolve() == Path(args.config).resolve():
        raise UsageError(f"Save would replace --config {args.config}: give --scene-out (that file, to do so)")
    base = base_scene(args)
    est = probe_estimate(
        args,
        [args.input],
        calib=base.get("calib"),
        marker_length=base.get("marker_length"),
        dictionary=base.get("dictionary"),
        marker_id=base.get("marker_id"),
    )
    if est is not None:  # the measured light, kept beside the scene file so that the saved scene names it
        light_file = scene_out.with_name(scene_out.stem + ".light.json")
        write_json(light_file, est.to_dict())
        base["light_from"] = str(light_file.resolve())
    own = list(base.get("lights") or ())
    if not own and base.get("light_from"):
        own = [load_estimate(base["light_from"]).light]
    engine = PreviewEngine(media, base, scene_out, own_lights=own or None)
    try:
        controls = controls_of(base)
        first = engine.render(engine.request({"controls": controls}))  # the session and its context, made now
        if first.get("error"):
            print(f"arshadow preview: warning: {first['error']}", file=sys.stderr, flush=True)
        info = {
            "name": media.name,
            "width": media.width,
            "height": media.height,
            "frames": media.count,
            "controls": controls,
            "measured_available": bool(base.get("light_from")),
            "light_angles": list(light_angles(str(own[0]))) if own else None,
        }
        try:
            server = PreviewServer(engine, args.port, info)
        except OSError as exc:
            raise UsageError(f"--port {args.port}: cannot listen on 127.0.0.1 ({exc.strerror or exc})") from None
        print(f"arshadow preview: {media.name} at {server.url}", flush=True)
        print(f"  Save writes {scene_out}; Ctrl-C stops the server.", flush=True)
        if not args.no_browser:
            open_browser(server.url)
        try:
            server.serve_forever(poll_interval=0.2)
        except KeyboardInterrupt:
            print("arshadow preview: stopped", file=sys.stderr, flush=True)
        finally:
            server.server_close()
    finally:
        engine.close()
    return EXIT_OK
