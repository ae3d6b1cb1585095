"""Generate the light-estimate sample: samples/probe_shadow.jpg and samples/light_probe.json (deterministic).

    python samples/make_light_sample.py

A photo made by arshadow's own lit generator (:func:`arshadow.synth.lit.render_lit_photo`): the 5 cm marker
on the textured floor, a 5 x 5 x 10 cm grey box (the probe) beside it casting its real shadow under a sun-like
directional light and a bluish sky (ambient), exposed at 0.7 with a warm white balance, mild blur, noise and
JPEG. ``light_probe.json`` holds the probe's placement (what ``arshadow light`` is told), the virtual object
that ``arshadow demo`` puts into the photo with the measured look, and the generating truth (never used by
the demo). Kept apart from make_samples.py / scenes.json so that the other samples stay as they are.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

SAMPLE = {
    "photo": "probe_shadow.jpg",
    "title": "measured light: probe's real shadow -> light, shadow colour, exposure",
    "calib": "calib/synth_1280x720.yml",
    "marker_length": 0.05,
    "dictionary": "DICT_6X6_250",
    "marker_id": 0,
    "probe": "box:0.05,0.05,0.1",
    "probe_place": [0.1, 0.02, 0.0],
    "probe_rotate": [0, 0, 0],
    "kind": "directional",
    # the virtual object put in with the measured look
    "model": "samples/meshes/knot.ply",
    "place": [-0.02, 0.1, 0.0],
    "rotate": [0, 0, 15],
    "color": "230,230,230",
}
EYE, TARGET = [0.12, -0.38, 0.42], [0.04, 0.04, 0.0]
LIGHT = dict(
    azimuth=160.0,
    elevation=40.0,
    ambient=(0.32, 0.36, 0.46),
    direct=(1.0, 0.95, 0.85),
    exposure=0.7,
    white_balance=(1.08, 1.0, 0.9),
    blur_sigma=0.5,
    noise_sigma=1.5,
    jpeg_quality=92,
    seed=21,
)


def make(out_dir: Path = HERE) -> dict:
    sys.path.insert(0, str(ROOT))
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.lit import light_vector, render_lit_photo
    from arshadow.synth.markers import look_at_pose

    intr = Intrinsics.from_file(ROOT / SAMPLE["calib"])
    pose = look_at_pose(EYE, TARGET)
    lv = light_vector(LIGHT["azimuth"], LIGHT["elevation"])
    p = render_lit_photo(
        intr,
        pose,
        marker_length=SAMPLE["marker_length"],
        probe=SAMPLE["probe"],
        probe_place=SAMPLE["probe_place"],
        probe_rotate=SAMPLE["probe_rotate"],
        light=lv,
        ambient=LIGHT["ambient"],
        direct=LIGHT["direct"],
        exposure=LIGHT["exposure"],
        white_balance=LIGHT["white_balance"],
        blur_sigma=LIGHT["blur_sigma"],
        noise_sigma=LIGHT["noise_sigma"],
        seed=LIGHT["seed"],
        supersample=3,
    )
    if not cv2.imwrite(str(out_dir / SAMPLE["photo"]), p.image, [cv2.IMWRITE_JPEG_QUALITY, LIGHT["jpeg_quality"]]):
        raise SystemExit(f"cannot write {out_dir / SAMPLE['photo']}")
    entry = dict(SAMPLE)
    entry["truth"] = {
        "direction": np.round(lv, 9).tolist(),
        "shadow_ratio": np.round(p.shadow_ratio, 6).tolist(),
        "paper_linear": np.round(p.paper_linear, 6).tolist(),
        "true_cam_from_world": np.round(pose, 9).tolist(),
    }
    (out_dir / "light_probe.json").write_text(json.dumps(entry, indent=1) + "\n")
    print(f"{SAMPLE['photo']}: {p.image.shape[1]}x{p.image.shape[0]}")
    return entry


if __name__ == "__main__":
    make()
