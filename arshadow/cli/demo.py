"""``arshadow demo``: render the bundled sample photos and write a contact sheet."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..scene import DEFAULT_AA
from . import EXIT_OK, EXIT_SOME_FAILED

THUMB_W, THUMB_H, BAR = 640, 360, 30


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "demo", help="render the bundled sample photos and write a contact sheet",
        description="Composite the sample meshes (including the 8 536-face knot) with their shadows into the "
                    "synthetic sample photos of samples/ (point, directional, two lights, a soft sun, strong "
                    "lens distortion), write the results, their shadow masks, a JSON report and "
                    "contact_sheet.png into DIR.")
    p.add_argument("-o", "--output", default="demo_out", metavar="DIR", help="output folder (default demo_out)")
    p.add_argument("--samples", metavar="DIR",
                   help="samples folder with scenes.json (default: the bundled samples)")
    p.add_argument("--aa", type=int, default=DEFAULT_AA, metavar="N",
                   help=f"multisample anti-aliasing samples, 0, 2 or 4 (default {DEFAULT_AA}, as arshadow render: "
                        "pixel-centre sampling; --aa 4 for smoother edges, ~5x the render time on a CPU)")
    p.add_argument("--quiet", "-q", action="store_true", help="no per-image lines")
    p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks")
    p.set_defaults(func=run)


def find_samples(explicit=None) -> Path:
    """The samples folder: ``explicit``, else the bundled ``samples/`` (the repository's in a checkout, the
    installed copy otherwise: :func:`arshadow.resources.samples_dir`), else ``./samples``."""
    from ..errors import UsageError
    from ..resources import samples_dir

    cands = [Path(explicit)] if explicit else [samples_dir(), Path("samples")]
    for c in cands:
        if (c / "scenes.json").is_file():
            return c
    raise UsageError(f"no samples found ({', '.join(str(c / 'scenes.json') for c in cands)} missing); "
                     "run from the repository root or pass --samples DIR")


#: the keys of a samples/scenes.json entry that describe the scene (the rest: photo, title)
SCENE_JSON_KEYS = ("calib", "model", "scale", "rotate", "place", "color", "lights", "soft_samples", "marker_length",
                   "dictionary", "marker_id")


def scene_spec(sc: dict, root: Path, aa: int):
    """The :class:`arshadow.scene.SceneSpec` of one ``scenes.json`` entry (paths relative to ``root``)."""
    from ..scene import scene_from_dict

    d = {k: sc[k] for k in SCENE_JSON_KEYS if sc.get(k) is not None}
    d["soft_samples"] = int(sc.get("soft_samples", 1))
    d["aa"] = int(aa)
    return scene_from_dict(d, base_dir=root)


def run(args) -> int:
    from ..errors import ArshadowError
    from ..estimate.demo import light_demo
    from ..gl.context import create_context
    from ..gl.stencil import ShadowRenderer
    from ..io import read_image, write_image, write_json
    from ..report import make_report
    from ..session import Session
    from . import quiet_opencv

    debug = bool(getattr(args, "debug", False))
    quiet_opencv(debug)
    samples = find_samples(args.samples)
    root = samples.parent
    scenes = json.loads((samples / "scenes.json").read_text())["scenes"]
    outdir = Path(args.output)
    ctx = create_context()
    items, panels, failed = [], [], 0
    try:
        with ShadowRenderer(ctx, samples=int(args.aa)) as renderer:
            for sc in scenes:
                photo_path = samples / sc["photo"]
                stem = Path(sc["photo"]).stem
                try:
                    # one context and one renderer shared by the scenes' sessions
                    session = Session(scene_spec(sc, root, args.aa), context=ctx, renderer=renderer)
                    image = read_image(photo_path)
                    with session:
                        res = session.process(image, name=str(photo_path))
                    out, mask, item = res.composite, res.mask, res.item
                    item.output = str(write_image(outdir / f"{stem}.png", out))
                    item.mask = str(write_image(outdir / f"{stem}.shadow.png", mask))
                    item.title = sc.get("title", stem)
                    items.append(item)
                    caption = f"{sc.get('title', stem)}  |  {item.mode}, {item.silhouette_edges} silhouette edges"
                    panels.append(_panel(out, caption))
                    if not args.quiet:
                        print(f"{photo_path.name} -> {outdir / (stem + '.png')}  ({item.mode}, "
                              f"{item.timings_ms['total']:.1f} ms)")
                except ArshadowError as exc:
                    if debug:
                        raise
                    failed += 1
                    print(f"arshadow demo: error: {photo_path.name}: {exc}", file=sys.stderr)
                    from ..report import ReportItem

                    items.append(ReportItem(input=str(photo_path), status="error", error=str(exc)))
            if panels and scenes:
                first = samples / scenes[0]["photo"]
                if first.is_file():
                    panels.append(_panel(read_image(first), f"input photo: {first.name} (before)"))
            try:  # the measured-look item (issue 17): extra outputs, the rest is unchanged
                lines = light_demo(samples, outdir, context=ctx, renderer=renderer, aa=args.aa)
            except ArshadowError as exc:
                failed += 1
                lines = []
                print(f"arshadow demo: error: measured light: {exc}", file=sys.stderr)
            for line in [] if args.quiet else lines:
                print(line)
    finally:
        ctx.release()
    if panels:
        sheet = contact_sheet(panels, columns=2)
        write_image(outdir / "contact_sheet.png", sheet)
        if not args.quiet:
            print(f"contact sheet: {outdir / 'contact_sheet.png'}")
    write_json(outdir / "report.json", make_report(items))
    return EXIT_SOME_FAILED if failed else EXIT_OK


def _panel(image, caption: str):
    """A thumbnail (THUMB_W x THUMB_H) with a caption bar below it."""
    import cv2
    import numpy as np

    th = cv2.resize(image, (THUMB_W, THUMB_H), interpolation=cv2.INTER_AREA)
    bar = np.full((BAR, THUMB_W, 3), 32, np.uint8)
    cv2.putText(bar, caption, (8, BAR - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (235, 235, 235), 1, cv2.LINE_AA)
    return np.vstack([th, bar])


def contact_sheet(panels, columns: int = 2, gap: int = 6):
    """Tile equally sized panels row by row on a dark background; ``(H, W, 3) uint8``."""
    import numpy as np

    ph, pw = panels[0].shape[:2]
    rows = (len(panels) + columns - 1) // columns
    sheet = np.full((rows * ph + (rows + 1) * gap, columns * pw + (columns + 1) * gap, 3), 16, np.uint8)
    for i, p in enumerate(panels):
        r, c = divmod(i, columns)
        y, x = gap + r * (ph + gap), gap + c * (pw + gap)
        sheet[y : y + ph, x : x + pw] = p
    return sheet
