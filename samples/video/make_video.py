"""Generate the sample AR clip samples/video/orbit.mp4 and its truth orbit.json (deterministic).

    python samples/video/make_video.py            # writes samples/video/orbit.mp4 and orbit.json

Made by arshadow's own generator: every frame is :func:`arshadow.synth.render_marker_photo` (textured floor,
printed 5 cm DICT_6X6_250 marker id 0 on white paper) seen by the 640x360 camera of
``calib/synth_640x360.yml`` from a pose of :func:`arshadow.synth.camera_path` (a smooth hand-held orbit),
with mild blur and sensor noise; then encoded at 25 fps as MPEG-4 part 2 (OpenCV's FFmpeg ``mp4v``), like
a phone clip. ``orbit.json`` keeps the true pose of every frame (never used by ``arshadow video``, which
estimates the pose from the pixels like for any user video).

Try it::

    arshadow video samples/video/orbit.mp4 --calib calib/synth_640x360.yml --marker-length 0.05 \\
        --model samples/meshes/house.obj --place 0.07,0.03,0 --rotate 0,0,20 \\
        --light sun:48.8566,2.3522 --time-lapse 2024-06-21T06:00+02:00,3600 -o video_out --save-mask
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

FPS = 25.0
N_FRAMES = 60  # 2.4 s
MARKER_LENGTH = 0.05
PATH = dict(radius=0.5, height=(0.3, 0.42), sweep_deg=70.0, start_deg=-110.0, target_wobble=0.015)


def main(out_dir=HERE) -> int:
    sys.path.insert(0, str(ROOT))
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import camera_path, render_marker_photo
    from arshadow.video.avio import AvWriter

    intr = Intrinsics.from_file(ROOT / "calib" / "synth_640x360.yml")
    poses = camera_path(N_FRAMES, **PATH)
    out_dir = Path(out_dir)
    with AvWriter(out_dir / "orbit.mp4", FPS, (intr.width, intr.height)) as w:
        for i, pose in enumerate(poses):
            ph = render_marker_photo(
                intr, pose, marker_length=MARKER_LENGTH, noise_sigma=1.0, blur_sigma=0.6, seed=100 + i
            )
            w.write(ph.image)
    truth = {
        "video": "orbit.mp4",
        "calib": "calib/synth_640x360.yml",
        "fps": FPS,
        "marker_length": MARKER_LENGTH,
        "dictionary": "DICT_6X6_250",
        "marker_id": 0,
        "camera_path": PATH,
        "cam_from_world": np.round(poses, 9).tolist(),
    }
    from arshadow.io import write_json

    write_json(out_dir / "orbit.json", truth)
    print(f"wrote {out_dir / 'orbit.mp4'} ({(out_dir / 'orbit.mp4').stat().st_size // 1024} KB), {N_FRAMES} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
