"""``arshadow render`` on good and hostile inputs: exit codes, one-line errors, outputs, report, mask."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from cli_run import run_cli

pytestmark = pytest.mark.gl

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_1280x720.yml"


def _digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def photos(tmp_path_factory, gl_ctx):
    """A folder of inputs: two good photos (one at half size: same aspect), and bad ones."""
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    d = tmp_path_factory.mktemp("inputs")
    intr = Intrinsics.from_file(CALIB)
    pose = look_at_pose([0.15, -0.3, 0.3], [0.0, 0.0, 0.0])
    good = render_marker_photo(intr, pose, marker_length=0.05, seed=3).image
    cv2.imwrite(str(d / "good.jpg"), good, [cv2.IMWRITE_JPEG_QUALITY, 95])
    half = render_marker_photo(intr.scaled(640, 360), pose, marker_length=0.05, seed=4).image
    cv2.imwrite(str(d / "half.png"), half)
    cv2.imwrite(str(d / "nomarker.png"), np.full((720, 1280, 3), 128, np.uint8))
    cv2.imwrite(str(d / "square.png"), np.full((500, 500, 3), 128, np.uint8))  # wrong aspect ratio
    (d / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n this is not really a png")
    return d


SCENE = [
    "--calib",
    CALIB,
    "--marker-length",
    "0.05",
    "--model",
    "box:0.04,0.03,0.05",
    "--place",
    "0.05,0,0",
    "--light",
    "point:-0.1,0.1,0.4",
]


def test_good_and_bad_inputs_in_one_run(photos, tmp_path, capsys):
    before = _digest(photos)
    out = tmp_path / "out"
    report = tmp_path / "report.json"
    names = ["good.jpg", "corrupt.png", "missing.png", "square.png", "nomarker.png", "half.png"]
    code, so, se = run_cli(
        capsys, "render", *[photos / n for n in names], *SCENE, "-o", out, "--save-mask", "--report", report
    )
    assert code == 1
    lines = [ln for ln in se.splitlines() if ln.strip()]
    assert len(lines) == 4, se
    assert "Traceback" not in se
    for ln, name in zip(lines, ["corrupt.png", "missing.png", "square.png", "nomarker.png"], strict=True):
        assert ln.startswith("arshadow render: error:") and name in ln, ln
    assert "does not match the calibration" in lines[2]
    # good inputs processed, bad ones left no file; no temporary files left behind
    assert sorted(p.name for p in out.iterdir()) == ["good.png", "good.shadow.png", "half.png", "half.shadow.png"]
    assert _digest(photos) == before  # inputs untouched
    rep = json.loads(report.read_text())
    st = {Path(i["input"]).name: i for i in rep["images"]}
    assert [st[n]["status"] for n in names] == ["ok", "error", "error", "error", "no_marker", "ok"]
    ok = st["good.jpg"]
    for key in (
        "input",
        "output",
        "mask",
        "status",
        "error",
        "marker_ids",
        "rvec",
        "tvec",
        "reprojection_error_px",
        "pose_ambiguity",
        "mode",
        "silhouette_edges",
        "timings_ms",
    ):
        assert key in ok
    # the scene's box is convex: the planner draws its shadow as a projection (no silhouette needed)
    assert ok["marker_ids"] == [0] and ok["mode"] == "planar" and ok["silhouette_edges"] == 0
    assert ok["plan"]["plan"] == "auto" and "convex" in ok["plan"]["lights"][0]["why"]["planar"]
    from arshadow.tracking.quality import AMBIGUITY_FLAG

    assert ok["pose_flagged"] is (ok["pose_ambiguity"] >= AMBIGUITY_FLAG)  # the flag is in every report
    assert set(ok["timings_ms"]) >= {
        "detect",
        "pose",
        "silhouette",
        "volume",
        "render",
        "readback",
        "warp",
        "composite",
        "total",
    }
    assert ok["timings_ms"]["detect"] > 0 and ok["timings_ms"]["pose"] > 0  # the tracker's time, split
    assert st["half.png"]["calibration_scaled"] == {"from": [1280, 720], "to": [640, 360]}
    assert st["nomarker.png"]["error"] and st["nomarker.png"]["output"] is None
    # the mask: 8-bit, one channel, photo size; 255 in the shadow, 0 where the object covers the ground
    mask = cv2.imread(str(out / "good.shadow.png"), cv2.IMREAD_UNCHANGED)
    photo = cv2.imread(str(out / "good.png"))
    assert mask.dtype == np.uint8 and mask.shape == (720, 1280)
    assert (mask == 255).sum() > 1000 and set(np.unique(mask)) <= set(range(256))
    small = cv2.imread(str(out / "half.shadow.png"), cv2.IMREAD_UNCHANGED)
    assert small.shape == (360, 640)
    # the composite differs from the input only where the object or its shadow is
    src = cv2.imread(str(photos / "good.jpg"))
    changed = np.any(photo != src, axis=2)
    assert changed.sum() > (mask > 0).sum()  # shadow plus object
    assert not np.any(changed & (mask == 0) & ~_near_object_box(photo.shape, ok))


def _near_object_box(shape, item):
    """Pixels of the compositor's ROI (the only place it may change anything)."""
    x0, y0, w, h = item["roi"]
    m = np.zeros(shape[:2], bool)
    m[y0 : y0 + h, x0 : x0 + w] = True
    return m


@pytest.mark.parametrize(
    "problem, argv, needle",
    [
        ("missing calib", ["--calib", "nope.yml"], "nope.yml"),
        ("bad light", ["--light", "point:1,2"], "point:1,2"),
        ("bad light kind", ["--light", "laser:1,2,3"], "laser"),
        ("missing mesh", ["--model", "nope.obj"], "nope.obj"),
        ("bad primitive", ["--model", "box:0,1,1"], "box"),
        ("bad opacity", ["--opacity", "1.5"], "opacity"),
        ("bad silhouette", ["--silhouette", "magic"], "magic"),
        ("bad shadow colour", ["--shadow-color", "1,2,900"], "shadow-color"),
        ("bad anti-aliasing", ["--aa", "64"], "--aa 64"),
        ("unknown dictionary", ["--dictionary", "DICT_FOO"], "DICT_FOO"),
    ],
)
def test_bad_configuration_exits_2_with_one_line(photos, tmp_path, capsys, problem, argv, needle):
    args = {
        "--calib": str(CALIB),
        "--marker-length": "0.05",
        "--model": "box:0.04,0.03,0.05",
        "--light": "point:-0.1,0.1,0.4",
    }
    args.update(dict(zip(argv[::2], argv[1::2], strict=True)))
    flat = [x for kv in args.items() for x in kv]
    code, so, se = run_cli(capsys, "render", photos / "good.jpg", *flat, "-o", tmp_path / "o")
    assert code == 2, (problem, se)
    lines = [ln for ln in se.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in se, se
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_bad_calibration_and_mesh_files(photos, tmp_path, capsys):
    nan = tmp_path / "nan.yml"
    nan.write_text(CALIB.read_text().replace("1000., 0., 641.29999999999995", ".nan, 0., 641.29999999999995"))
    code, _, se = run_cli(
        capsys,
        "render",
        photos / "good.jpg",
        *SCENE[:0],
        "--calib",
        nan,
        "--marker-length",
        "0.05",
        "--model",
        "box:0.04,0.03,0.05",
        "--light",
        "point:0,0,1",
        "-o",
        tmp_path / "o",
    )
    assert code == 2 and "nan.yml" in se and len(se.strip().splitlines()) == 1
    broken = tmp_path / "broken.yml"  # a YAML syntax error: OpenCV's parser message, not a Python wrapper's
    broken.write_text(CALIB.read_text().replace("data: [", "data: [ [", 1))
    code, _, se = run_cli(
        capsys,
        "render",
        photos / "good.jpg",
        "--calib",
        broken,
        "--marker-length",
        "0.05",
        "--model",
        "box:0.04,0.03,0.05",
        "--light",
        "point:0,0,1",
        "-o",
        tmp_path / "o",
    )
    assert code == 2 and "broken.yml" in se and "cannot parse" in se and "SystemError" not in se, se
    assert len(se.strip().splitlines()) == 1
    bad_mesh = tmp_path / "bad.obj"
    bad_mesh.write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    code, _, se = run_cli(
        capsys,
        "render",
        photos / "good.jpg",
        "--calib",
        CALIB,
        "--marker-length",
        "0.05",
        "--model",
        bad_mesh,
        "--light",
        "point:0,0,1",
        "-o",
        tmp_path / "o",
    )
    assert code == 2 and "bad.obj" in se and len(se.strip().splitlines()) == 1
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(b"\x00\x01 not a mesh at all" * 10)
    code, _, se = run_cli(
        capsys,
        "render",
        photos / "good.jpg",
        "--calib",
        CALIB,
        "--marker-length",
        "0.05",
        "--model",
        garbage,
        "--light",
        "point:0,0,1",
        "-o",
        tmp_path / "o",
    )
    assert code == 2 and "garbage.stl" in se and len(se.strip().splitlines()) == 1


def test_keep_format_glob_and_never_overwrite_inputs(photos, tmp_path, capsys):
    work = tmp_path / "w"
    work.mkdir()
    src = photos / "good.jpg"
    (work / "a.jpg").write_bytes(src.read_bytes())
    before = _digest(work)
    # output folder = input folder with --keep-format would overwrite a.jpg: refused, input untouched
    code, _, se = run_cli(capsys, "render", work / "*.jpg", *SCENE, "-o", work, "--keep-format")
    assert code == 1 and "overwrite" in se and _digest(work) == before
    code, so, se = run_cli(capsys, "render", work / "*.jpg", *SCENE, "-o", tmp_path / "o", "--keep-format")
    assert code == 0, se
    assert (tmp_path / "o" / "a.jpg").is_file() and cv2.imread(str(tmp_path / "o" / "a.jpg")).shape == (720, 1280, 3)


def test_real_process_exit_status(photos, tmp_path):
    """Through the installed entry point (a fresh process): exit code 1 and one line per failed input."""
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "arshadow",
            "render",
            str(photos / "good.jpg"),
            str(photos / "corrupt.png"),
            *map(str, SCENE),
            "-o",
            str(tmp_path / "o"),
            "-q",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 1, r.stderr
    assert r.stderr.strip().count("\n") == 0 and "corrupt.png" in r.stderr and "Traceback" not in r.stderr
    assert (tmp_path / "o" / "good.png").is_file()


def test_gray16_and_alpha_inputs(photos, tmp_path, capsys):
    """Grayscale 16-bit and BGRA photos are accepted (converted to 8-bit colour), outputs keep the size."""
    src = cv2.imread(str(photos / "good.jpg"))
    d = tmp_path / "in"
    d.mkdir()
    gray16 = cv2.cvtColor(src, cv2.COLOR_BGR2GRAY).astype(np.uint16) * 257
    cv2.imwrite(str(d / "g16.png"), gray16)
    cv2.imwrite(str(d / "rgba.png"), cv2.cvtColor(src, cv2.COLOR_BGR2BGRA))
    code, _, se = run_cli(capsys, "render", d, *SCENE, "-o", tmp_path / "o", "--save-mask")
    assert code == 0, se
    for stem in ("g16", "rgba"):
        out = cv2.imread(str(tmp_path / "o" / f"{stem}.png"), cv2.IMREAD_UNCHANGED)
        assert out.shape == (720, 1280, 3) and out.dtype == np.uint8
        assert (cv2.imread(str(tmp_path / "o" / f"{stem}.shadow.png"), cv2.IMREAD_UNCHANGED) == 255).sum() > 1000
