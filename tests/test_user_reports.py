"""Problems a new user met (issue 12, "Also found when tried as a new user would"), each pinned by a test.
The others of that list are in tests/test_hostile_inputs.py (Latin-1 OBJ, output paths checked first,
wrong-units / camera-inside / sun-below-horizon warnings, --board with --dictionary, --aa 3, empty folder,
--calib DIR) and tests/test_stress_render.py (the light seam where the object meets its shadow)."""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_1280x720.yml"


def _with_exif_orientation(jpeg: bytes, orientation: int, big_endian: bool = False) -> bytes:
    """Insert an APP1 Exif segment with IFD0 tag 0x0112 = orientation right after SOI."""
    e = ">" if big_endian else "<"
    tiff = (b"MM" if big_endian else b"II") + struct.pack(e + "HI", 42, 8)
    tiff += struct.pack(e + "H", 1) + struct.pack(e + "HHIHH", 0x0112, 3, 1, orientation, 0) + struct.pack(e + "I", 0)
    seg = b"Exif\0\0" + tiff
    return jpeg[:2] + b"\xff\xe1" + struct.pack(">H", len(seg) + 2) + seg + jpeg[2:]


@pytest.mark.parametrize("orientation", range(1, 9))
@pytest.mark.parametrize("big_endian", [False, True])
def test_exif_orientation_matches_opencv(tmp_path, orientation, big_endian):
    """io.exif_orientation + io.apply_orientation turn a photo upright exactly as OpenCV's own EXIF-aware
    decoder (IMREAD_COLOR) does: the independent reference."""
    from arshadow.io import apply_orientation, exif_orientation, read_image

    rng = np.random.default_rng(orientation)
    img = (rng.random((24, 40, 3)) * 255).astype(np.uint8)
    img = cv2.resize(img, (80, 48), interpolation=cv2.INTER_NEAREST)  # smooth enough for JPEG
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 100])
    p = tmp_path / "o.jpg"
    p.write_bytes(_with_exif_orientation(buf.tobytes(), orientation, big_endian))
    assert exif_orientation(p) == orientation
    stored = read_image(p)  # as stored: the calibration's frame
    assert stored.shape == (48, 80, 3)
    ref = cv2.imdecode(np.fromfile(str(p), np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(np.ascontiguousarray(apply_orientation(stored, orientation)), ref)


def test_exif_orientation_absent_or_garbage(tmp_path):
    from arshadow.io import exif_orientation

    p = tmp_path / "a.png"
    cv2.imwrite(str(p), np.zeros((4, 4, 3), np.uint8))
    assert exif_orientation(p) == 1
    q = tmp_path / "b.jpg"
    q.write_bytes(b"\xff\xd8\xff\xe1\x00\x10Exif\0\0II*\0\xff\xff\xff\xff" + b"\0" * 40)
    assert exif_orientation(q) == 1
    assert exif_orientation(tmp_path / "missing.jpg") == 1


@pytest.mark.gl
def test_render_honours_exif_orientation(tmp_path, capsys, gl_ctx):
    """A landscape sensor photo tagged 'rotate 90 CW' (a phone held upright): rendered in the stored
    orientation (where the calibration applies), written upright: the output is the untagged photo's
    output turned the same way."""
    from arshadow.camera import Intrinsics
    from arshadow.cli import main
    from arshadow.synth import look_at_pose, render_marker_photo

    intr = Intrinsics.from_file(CALIB)
    img = render_marker_photo(intr, look_at_pose([0.15, -0.3, 0.3], [0.0, 0.0, 0.0]), marker_length=0.05,
                              seed=3).image
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])
    d = tmp_path / "in"
    d.mkdir()
    (d / "plain.jpg").write_bytes(buf.tobytes())
    (d / "portrait.jpg").write_bytes(_with_exif_orientation(buf.tobytes(), 6))
    args = ["render", str(d), "--calib", str(CALIB), "--marker-length", "0.05", "--model", "box:0.04,0.03,0.05",
            "--light", "point:-0.1,0.1,0.4", "-o", str(tmp_path / "o"), "--save-mask", "-q"]
    assert main(args) == 0, capsys.readouterr().err
    plain = cv2.imread(str(tmp_path / "o" / "plain.png"), cv2.IMREAD_UNCHANGED)
    portrait = cv2.imread(str(tmp_path / "o" / "portrait.png"), cv2.IMREAD_UNCHANGED)
    assert portrait.shape == (1280, 720, 3)
    assert np.array_equal(portrait, cv2.rotate(plain, cv2.ROTATE_90_CLOCKWISE))
    pm = cv2.imread(str(tmp_path / "o" / "portrait.shadow.png"), 0)
    assert np.array_equal(pm, cv2.rotate(cv2.imread(str(tmp_path / "o" / "plain.shadow.png"), 0),
                                         cv2.ROTATE_90_CLOCKWISE))


def test_marker_id_help_is_the_same_in_render_and_pose():
    """`render` said "the first found", `pose` "the lowest id found" (the tracker takes the lowest)."""
    from arshadow.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    helps = {name: next(a.help for a in sub[name]._actions if "--marker-id" in a.option_strings)
             for name in ("render", "pose")}
    assert helps["render"] == helps["pose"] and "lowest id" in helps["render"]
    dicts = {name: next(a.help for a in sub[name]._actions if "--dictionary" in a.option_strings)
             for name in ("render", "pose")}
    assert dicts["render"] == dicts["pose"]


def test_board_with_conflicting_dictionary_is_refused():
    from arshadow.camera import Intrinsics
    from arshadow.errors import UsageError
    from arshadow.tracking.tracker import MarkerTracker

    intr = Intrinsics.from_file(CALIB)
    board = ROOT / "calib" / "gridboard_5x7.yml"
    with pytest.raises(UsageError, match="conflicts with the board"):
        MarkerTracker(intr, dictionary="DICT_4X4_50", board=board)
    assert MarkerTracker(intr, dictionary="DICT_6X6_250", board=board).board is not None  # agreeing: fine
    assert MarkerTracker(intr, board=board).board is not None


def test_aa_only_documented_values():
    from arshadow.errors import UsageError
    from arshadow.scene import RenderOptions

    for ok in (0, 2, 4):
        RenderOptions(aa=ok).check()
    for bad in (1, 3, 8, -2):
        with pytest.raises(UsageError, match=f"--aa {bad}"):
            RenderOptions(aa=bad).check()
