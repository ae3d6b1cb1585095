"""The demo's measured-look item: ``samples/light_probe.json`` (made by samples/make_light_sample.py).

Measures the light, shadow colour and exposure from the probe's real shadow in the sample photo, then puts
the sample's virtual object into the photo with that look (``light_from``). Kept apart from the demo's
scenes: its outputs are extra files (``probe_shadow.png``, ``probe_shadow.light.json``), the contact sheet
and the other outputs are unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..estimate.api import estimate_light
from ..frame.session import Session
from ..io import read_image, write_image, write_json
from ..scene.spec import scene_from_dict

__all__ = ["SAMPLE_FILE", "light_demo"]

SAMPLE_FILE = "light_probe.json"


def light_demo(samples: Path, outdir: Path, *, context: Any = None, renderer: Any = None, aa: int = 4) -> list[str]:
    """Run the measured-look item if ``samples/light_probe.json`` exists; returns lines to print.

    Writes ``outdir/<stem>.light.json`` (the estimate, as ``arshadow light --json``) and ``outdir/<stem>.png``
    (the sample's object composited with the measured light, shadow colour and exposure).
    """

    path = Path(samples) / SAMPLE_FILE
    if not path.is_file():
        return []
    sc = json.loads(path.read_text())
    root = Path(samples).parent
    photo = Path(samples) / sc["photo"]
    stem = photo.stem
    est = estimate_light(
        photo,
        calib=str(root / sc["calib"]),
        marker_length=sc["marker_length"],
        probe=sc["probe"],
        probe_place=sc["probe_place"],
        probe_rotate=sc["probe_rotate"],
        dictionary=sc.get("dictionary"),
        marker_id=sc.get("marker_id"),
        kind=sc.get("kind", "directional"),
    )
    est_path = write_json(Path(outdir) / f"{stem}.light.json", est.to_dict())
    spec = scene_from_dict(
        {
            "calib": sc["calib"],
            "marker_length": sc["marker_length"],
            "dictionary": sc.get("dictionary"),
            "marker_id": sc.get("marker_id"),
            "model": sc["model"],
            "place": sc["place"],
            "rotate": sc["rotate"],
            "color": sc.get("color"),
            # absolute: the scene resolves relative paths against the samples' folder (base_dir), and a
            # relative -o (the README's `-o demo_out`) lies under the working directory, not there
            "light_from": str(Path(est_path).resolve()),
            "aa": int(aa),
        },
        base_dir=root,
    )
    with Session(spec, context=context, renderer=renderer) as session:
        res = session.process(read_image(photo), name=str(photo))
    out = write_image(Path(outdir) / f"{stem}.png", res.composite)
    ratio = " ".join(f"{v:.2f}" for v in est.shadow_ratio)
    line = (
        f"{photo.name} -> {out}  (measured light {est.light}, +/- {est.uncertainty_deg:.1f} deg, shadow ratio "
        f"{ratio}; estimate in {est_path})"
    )
    return [line]
