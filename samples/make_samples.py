"""Generate the sample photos in samples/ and their scene list samples/scenes.json (deterministic).

    python samples/make_samples.py          # writes samples/*.jpg and samples/scenes.json

Every photo is made by arshadow's own generator (:func:`arshadow.synth.render_marker_photo`): a textured
floor with a printed 5 cm DICT_6X6_250 marker (id 0) on white paper, seen by the synthetic 1280x720 camera
of ``calib/synth_1280x720.yml`` (or its strongly distorted twin ``calib/synth_1280x720_k1.yml``), with mild
blur, sensor noise and JPEG compression like a phone photo. The true pose is stored in scenes.json (it is
never used by the demo, which estimates the pose from the photo like any user photo).

``scenes.json`` also says what ``arshadow demo`` puts into each photo: model (a sample mesh in
samples/meshes/ or a primitive), its placement, the lights (including a sun from date, time and place).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

#: the scenes: photo name -> camera, print, object and lights
SCENES = [
    {
        "photo": "knot_point.jpg",
        "title": "knot (8 536 faces), point light",
        "calib": "calib/synth_1280x720.yml",
        "eye": [0.28, -0.36, 0.34],
        "target": [0.06, 0.03, 0.02],
        "model": "samples/meshes/knot.ply",
        "place": [0.1, 0.05, 0.0],
        "rotate": [0, 0, 15],
        "lights": ["point:-0.12,0.2,0.42"],
        "seed": 11,
    },
    {
        "photo": "house_sun.jpg",
        "title": "house, sun (Paris, 21 June 18:30)",
        "calib": "calib/synth_1280x720.yml",
        "eye": [-0.2, -0.42, 0.3],
        "target": [0.04, 0.04, 0.0],
        "model": "samples/meshes/house.obj",
        "place": [0.075, 0.035, 0.0],
        "rotate": [0, 0, 20],
        # the world +y axis points to compass bearing 120 deg (east-south-east)
        "lights": ["sun:48.8566,2.3522,2024-06-21T18:30+02:00,120"],
        "seed": 12,
    },
    {
        "photo": "umbrella_two_lights.jpg",
        "title": "umbrella (open mesh), two lights",
        "calib": "calib/synth_1280x720.yml",
        "eye": [0.05, -0.45, 0.36],
        "target": [0.02, 0.05, 0.02],
        "model": "samples/meshes/umbrella.ply",
        "place": [0.0, 0.09, 0.0],
        "lights": ["point:0.22,0.15,0.35", "directional:-0.5,0.2,1@0.6"],
        "seed": 13,
    },
    {
        "photo": "torus_k1.jpg",
        "title": "torus, strong barrel distortion k1 = -0.25",
        "calib": "calib/synth_1280x720_k1.yml",
        "eye": [0.3, 0.2, 0.3],
        "target": [0.02, 0.06, 0.0],
        "model": "torus:0.045,0.015",
        "rotate": [60, 0, 30],
        "place": [0.09, 0.07, 0.05],
        "color": "70,130,200",
        "lights": ["directional:0.4,-0.5,1"],
        "seed": 14,
    },
    {
        "photo": "box_soft_sun.jpg",
        "title": "box, soft sun (16 samples), low sun",
        "calib": "calib/synth_1280x720.yml",
        "eye": [0.33, 0.2, 0.26],
        "target": [0.0, -0.05, 0.0],
        "model": "box:0.04,0.04,0.07",
        "place": [0.06, -0.06, 0.0],
        "rotate": [0, 0, 30],
        "color": "200,90,60",
        "lights": ["sun:35.68,139.69,2024-03-20T16:00+09:00"],
        "soft_samples": 16,
        "seed": 15,
    },
]

MARKER = {"marker_length": 0.05, "dictionary": "DICT_6X6_250", "marker_id": 0}


def make(out_dir: Path = HERE) -> list[dict]:
    sys.path.insert(0, str(ROOT))
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    scenes = []
    for sc in SCENES:
        intr = Intrinsics.from_file(ROOT / sc["calib"])
        pose = look_at_pose(sc["eye"], sc["target"])
        ph = render_marker_photo(
            intr,
            pose,
            marker_length=MARKER["marker_length"],
            dictionary=MARKER["dictionary"],
            marker_id=MARKER["marker_id"],
            noise_sigma=1.5,
            blur_sigma=0.5,
            exposure=1.0,
            seed=sc["seed"],
        )
        ok = cv2.imwrite(str(out_dir / sc["photo"]), ph.image, [cv2.IMWRITE_JPEG_QUALITY, 92])
        if not ok:
            raise SystemExit(f"cannot write {out_dir / sc['photo']}")
        entry = {k: v for k, v in sc.items() if k not in ("eye", "target", "seed")}
        entry.update(MARKER)
        entry["true_cam_from_world"] = np.round(pose, 9).tolist()
        scenes.append(entry)
        print(f"{sc['photo']}: {ph.image.shape[1]}x{ph.image.shape[0]}")
    (out_dir / "scenes.json").write_text(json.dumps({"scenes": scenes}, indent=1) + "\n")
    return scenes


if __name__ == "__main__":
    make()
