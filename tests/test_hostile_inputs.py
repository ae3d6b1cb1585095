"""Hostile files and arguments (the stress suite): every kind gets one clear line on stderr naming the problem, the
right exit status (CONVENTIONS.md: 1 = some inputs failed, the rest processed; 2 = bad usage or
configuration), no traceback, no half-written output; merely unusual inputs are accepted.

The module prints how many kinds it tried and how many behaved (``-s`` shows it):
``python -m pytest -q -s tests/test_hostile_inputs.py``.
"""

from __future__ import annotations

import errno
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
BOARD = ROOT / "calib" / "gridboard_5x7.yml"
SCENE = {
    "--calib": str(CALIB),
    "--marker-length": "0.05",
    "--model": "box:0.04,0.03,0.05",
    "--light": "point:-0.1,0.1,0.4",
}
TALLY: dict[str, list] = {"config (exit 2)": [], "per input (exit 1)": [], "accepted": []}


@pytest.fixture(scope="module")
def good(tmp_path_factory, gl_ctx):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    d = tmp_path_factory.mktemp("good")
    intr = Intrinsics.from_file(CALIB)
    img = render_marker_photo(intr, look_at_pose([0.15, -0.3, 0.3], [0.0, 0.0, 0.0]), marker_length=0.05, seed=3).image
    cv2.imwrite(str(d / "good.png"), img)
    cv2.imwrite(str(d / "good.jpg"), img, [cv2.IMWRITE_JPEG_QUALITY, 95])
    return d


# ------------------------------------------------------------------------------------ configuration
def _calib_text(**repl):
    t = CALIB.read_text()
    for a, b in repl.items():
        t = t.replace(a.replace("_SP_", " "), b)
    return t


K_ROW = "1000., 0., 641.29999999999995"
CALIB_FILES = {  # name -> (file content (str or bytes), needle)
    "calib_empty": (b"", "empty file"),
    "calib_garbage": (bytes(range(256)) * 4, "calib_garbage.yml"),
    "calib_yaml_syntax": (_calib_text(**{"data: [": "data: [ ["}), "cannot parse"),
    "calib_no_K": (_calib_text(camera_matrix="camera_matrixx"), "missing key 'camera_matrix'"),
    "calib_nan_focal": (_calib_text(**{K_ROW: ".nan, 0., 641.29999999999995"}), "NaN"),
    "calib_zero_focal": (_calib_text(**{K_ROW: "0., 0., 641.29999999999995"}), "focal lengths must be positive"),
    "calib_negative_focal": (
        _calib_text(**{K_ROW: "-1000., 0., 641.29999999999995"}),
        "focal lengths must be positive",
    ),
    "calib_K_2x2": (
        _calib_text(
            **{
                "rows: 3\n   cols: 3\n   dt: d\n   data: [ 1000., 0., 641.29999999999995, 0., "
                "1000., 358.19999999999999,\n       0., 0., 1. ]": "rows: 2\n   cols: 2\n   dt: d\n   data: [ 1000., 0., 0., 1000. ]"
            }
        ),
        "3x3",
    ),
    "calib_no_width": (_calib_text(image_width="image_widthh"), "image_width"),
    "calib_20_dist": (
        _calib_text(
            **{"cols: 5": "cols: 20", "-0.0060000000000000001 ]": "-0.0060000000000000001" + ", 0." * 15 + " ]"}
        ),
        "distortion",
    ),
}

MESH_FILES = {  # name -> (content, needle)
    "empty.obj": (b"", "empty.obj"),
    "nan.obj": (b"v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n", "nan.obj"),
    "garbage.stl": (b"\x00\x01 not a mesh at all" * 10, "garbage.stl"),
    "novfaces.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles"),
    "enormous.obj": (b"v 0 0 0\nv 1e9 0 0\nv 0 1e9 1e9\nf 1 2 3\n", "wrong units"),
    "degenerate.obj": (b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "degenerate.obj"),
    "mesh.xyz": (b"0 0 0\n1 0 0\n", "mesh.xyz"),
}

# (kind, argv overrides or extra args, needle)
ARG_CASES = [
    ("calib_missing", {"--calib": "nope.yml"}, "no such calibration file"),
    ("calib_folder", {"--calib": "{tmp}"}, "is a folder"),
    *[(k, {"--calib": "{tmp}/" + k + ".yml"}, v[1]) for k, v in CALIB_FILES.items()],
    ("mesh_missing", {"--model": "nope.obj"}, "no such mesh file"),
    *[("mesh_" + k.replace(".", "_"), {"--model": "{tmp}/" + k}, v[1]) for k, v in MESH_FILES.items()],
    ("prim_zero_size", {"--model": "box:0,1,1"}, "positive"),
    ("prim_not_numbers", {"--model": "box:a,b,c"}, "numbers"),
    ("prim_negative", {"--model": "sphere:-1"}, "positive"),
    ("prim_unknown", {"--model": "cone:1,2"}, "cone:1,2"),
    ("prim_torus_fat", {"--model": "torus:0.1,0.2"}, "smaller than R"),
    ("prim_wrong_count", {"--model": "cylinder:1"}, "parameter"),
    ("light_short", {"--light": "point:1,2"}, "point:1,2"),
    ("light_kind", {"--light": "laser:1,2,3"}, "laser"),
    ("light_nan", {"--light": "point:nan,0,1"}, "point:nan,0,1"),
    ("light_zero_dir", {"--light": "directional:0,0,0"}, "directional:0,0,0"),
    ("light_neg_weight", {"--light": "point:0,0,1@-1"}, "@-1"),
    ("light_bad_weight", {"--light": "point:0,0,1@abc"}, "abc"),
    ("light_empty", {"--light": ""}, "light"),
    ("light_below_ground", {"--light": "point:0,0,-1"}, "point:0,0,-1"),
    ("light_dir_down", {"--light": "directional:1,0,-0.5"}, "must point up"),
    ("sun_bad_time", {"--light": "sun:52,0,yesterday"}, "yesterday"),
    ("sun_bad_lat", {"--light": "sun:100,0,2024-06-21T12:00+00:00"}, "100"),
    ("board_missing", {"--marker-length": None, "--board": "nope_board.yml"}, "nope_board.yml"),
    ("board_garbage", {"--marker-length": None, "--board": "{tmp}/calib_garbage.yml"}, "calib_garbage.yml"),
    (
        "board_dict_conflict",
        {"--marker-length": None, "--board": str(BOARD), "--dictionary": "DICT_4X4_50"},
        "conflicts with the board",
    ),
    ("dict_unknown", {"--dictionary": "DICT_FOO"}, "DICT_FOO"),
    ("dict_file_garbage", {"--dictionary": "{tmp}/calib_garbage.yml"}, "calib_garbage.yml"),
    ("marker_id_out_of_range", {"--marker-id": "99999"}, "99999"),
    ("marker_length_negative", {"--marker-length": "-1"}, "--marker-length"),
    ("marker_length_text", {"--marker-length": "abc"}, "--marker-length"),
    ("marker_and_board", {"--board": str(BOARD)}, "not allowed with"),
    ("no_marker_length_or_board", {"--marker-length": None}, "--marker-length"),
    ("scale_zero", {"--scale": "0"}, "--scale"),
    ("rotate_two_numbers", {"--rotate": "1,2"}, "--rotate"),
    ("place_nan", {"--place": "nan,0,0"}, "--place"),
    ("aa_3", {"--aa": "3"}, "--aa 3"),
    ("aa_64", {"--aa": "64"}, "--aa 64"),
    ("opacity_above_1", {"--opacity": "1.5"}, "opacity"),
    ("opacity_nan", {"--opacity": "nan"}, "opacity"),
    ("soft_samples_zero", {"--soft-samples": "0"}, "--soft-samples"),
    ("ground_size_negative", {"--ground-size": "-1"}, "--ground-size"),
    ("color_out_of_range", {"--color": "300,0,0"}, "--color"),
    ("shadow_color_text", {"--shadow-color": "a,b,c"}, "shadow-color"),
    ("silhouette_unknown", {"--silhouette": "magic"}, "magic"),
    ("shadow_method_unknown", {"--shadow-method": "foo"}, "--shadow-method"),
    ("unknown_option", {"--frobnicate": "1"}, "unrecognized arguments"),
    ("calib_not_given", {"--calib": None}, "--calib"),
    ("output_is_file", {"-o": "{tmp}/calib_empty.yml"}, "not a folder"),
    ("output_under_file", {"-o": "/dev/null/out"}, "-o /dev/null/out"),
    ("output_in_proc", {"-o": "/proc/arshadow_out"}, "/proc/arshadow_out"),
    ("report_is_folder", {"--report": "{tmp}"}, "is a folder"),
    ("report_under_file", {"--report": "/dev/null/r.json"}, "--report /dev/null/r.json"),
]


@pytest.fixture(scope="module")
def config_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cfg")
    for k, (content, _) in CALIB_FILES.items():
        p = d / f"{k}.yml"
        p.write_bytes(content if isinstance(content, bytes) else content.encode())
    for k, (content, _) in MESH_FILES.items():
        (d / k).write_bytes(content)
    return d


@pytest.mark.parametrize("kind, over, needle", ARG_CASES, ids=[c[0] for c in ARG_CASES])
def test_bad_configuration(good, config_dir, tmp_path, capsys, kind, over, needle):
    """Exit 2, one line naming the problem, before any photo is touched: nothing written."""
    args = dict(SCENE)
    args["-o"] = str(tmp_path / "out")
    for k, v in over.items():
        if v is None:
            args.pop(k, None)
        else:
            args[k] = v.replace("{tmp}", str(config_dir))
    flat = [x for kv in args.items() for x in kv]
    try:
        code, so, se = run_cli(capsys, "render", good / "good.png", *flat)
    except SystemExit as exc:  # argparse
        code = exc.code
        cap = capsys.readouterr()
        se = cap.err
    lines = [ln for ln in se.splitlines() if ln.strip()]
    print(f"\n{kind}: exit {code}: {se.strip()}")
    ok = code == 2 and len(lines) == 1 and needle in lines[0] and "Traceback" not in se
    TALLY["config (exit 2)"].append((kind, ok))
    assert ok, (kind, code, se)
    assert "error" in lines[0]
    out = tmp_path / "out"
    assert not out.exists() or not any(out.iterdir())


# ------------------------------------------------------------------------------------ per-input
def _pixel_bomb_png() -> bytes:
    """A valid PNG signature + IHDR announcing 60000 x 60000 pixels, no real data."""
    import struct
    import zlib

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    ihdr = struct.pack(">IIBBBBB", 60000, 60000, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\x00" * 100)) + chunk(b"IEND", b"")
    )


def _bad_inputs(d: Path, good: Path):
    """name -> needle of its error line; files made in ``d``."""
    jpg, png = (good / "good.jpg").read_bytes(), (good / "good.png").read_bytes()
    (d / "truncated.jpg").write_bytes(jpg[: len(jpg) // 3])
    (d / "truncated.png").write_bytes(png[: len(png) // 3])
    (d / "corrupt.jpg").write_bytes(jpg[:200] + bytes(range(256)) * 20)
    (d / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n this is not really a png")
    (d / "zero.png").write_bytes(b"")
    (d / "zero.jpg").write_bytes(b"")
    (d / "text.png").write_text("hello, I am a text file\n")
    (d / "page.jpg").write_text("<html><body>404 not found</body></html>\n")
    (d / "bmp_header.bmp").write_bytes(b"BM" + b"\x00" * 20)
    (d / "pixelbomb.png").write_bytes(_pixel_bomb_png())
    (d / "emptydir").mkdir()
    (d / "folder.png").mkdir()
    (d / "dangling.png").symlink_to(d / "does_not_exist.png")
    cv2.imwrite(str(d / "square.png"), np.full((500, 500, 3), 128, np.uint8))
    cv2.imwrite(str(d / "tiny.png"), np.full((1, 1, 3), 128, np.uint8))
    cv2.imwrite(str(d / "nomarker.png"), np.full((720, 1280, 3), 128, np.uint8))
    cv2.imwrite(str(d / "huge8k.png"), np.full((8192, 8192), 128, np.uint8))
    return {
        "truncated.jpg": "cannot decode",
        "truncated.png": "truncated or corrupt PNG",
        "corrupt.jpg": "cannot decode",
        "corrupt.png": "truncated or corrupt PNG",
        "zero.png": "empty file",
        "zero.jpg": "empty file",
        "text.png": "cannot decode",
        "page.jpg": "cannot decode",
        "bmp_header.bmp": "cannot decode",
        "pixelbomb.png": "cannot decode",
        "emptydir": "folder contains no image files",
        "folder.png": "folder contains no image files",
        "dangling.png": "no such image file",
        "missing.png": "no such image file",
        "nomatch*.png": "no file matches",
        "square.png": "does not match the calibration",
        "tiny.png": "no marker",
        "nomarker.png": "marker",
        "huge8k.png": "does not match the calibration",
    }


def test_bad_inputs_in_one_run(good, tmp_path, capsys):
    """Every bad input: one line naming it; the good photos around them are still rendered; the report
    has one item per input; exit 1; no temporary or partial files."""
    d = tmp_path / "in"
    d.mkdir()
    bad = _bad_inputs(d, good)
    names = ["good.png", *bad, "good.jpg"]
    paths = [good / n if n.startswith("good") else d / n for n in names]
    out, report = tmp_path / "out", tmp_path / "r.json"
    code, so, se = run_cli(
        capsys,
        "render",
        *paths,
        *[x for kv in SCENE.items() for x in kv],
        "-o",
        out,
        "--report",
        report,
        "-q",
        "--save-mask",
    )
    assert code == 1
    assert "Traceback" not in se
    lines = [ln for ln in se.splitlines() if ln.strip()]
    assert len(lines) == len(bad), se
    for ln, (name, needle) in zip(lines, bad.items(), strict=True):
        ok = ln.startswith("arshadow render: error:") and name in ln and needle in ln
        TALLY["per input (exit 1)"].append((name, ok))
        assert ok, (name, ln)
    assert sorted(p.name for p in out.iterdir()) == ["good.png", "good.shadow.png", "good_2.png", "good_2.shadow.png"]
    rep = json.loads(report.read_text())
    assert [i["status"] for i in rep["images"]] == ["ok"] + [
        "no_marker" if n in ("nomarker.png", "tiny.png") else "error" for n in bad
    ] + ["ok"]


def test_disk_full_while_writing(good, tmp_path, capsys, monkeypatch):
    """The disk fills while the first photo's output is written: that photo fails with one line, no partial
    or temporary file is left, the next photo is still written."""
    import arshadow.io as aio

    real = aio._write_file

    def full(path, data):
        if Path(path).name.startswith(".first."):
            with open(path, "wb") as fh:
                fh.write(bytes(memoryview(data).cast("B")[:1000]))
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, data)

    monkeypatch.setattr(aio, "_write_file", full)
    d = tmp_path / "in"
    d.mkdir()
    (d / "first.png").write_bytes((good / "good.png").read_bytes())
    (d / "second.png").write_bytes((good / "good.png").read_bytes())
    out = tmp_path / "out"
    code, so, se = run_cli(
        capsys, "render", d / "first.png", d / "second.png", *[x for kv in SCENE.items() for x in kv], "-o", out, "-q"
    )
    lines = [ln for ln in se.splitlines() if ln.strip()]
    ok = code == 1 and len(lines) == 1 and "No space left on device" in lines[0] and "first" in lines[0]
    TALLY["per input (exit 1)"].append(("disk_full", ok))
    assert ok, se
    assert sorted(p.name for p in out.iterdir()) == ["second.png"]


# ------------------------------------------------------------------------------------ accepted
def test_unusual_inputs_are_accepted(good, tmp_path, capsys):
    """Grayscale 8/16-bit, RGBA 8/16-bit, a PNG named .jpg, BGR float32 TIFF: converted and rendered."""
    src = cv2.imread(str(good / "good.png"))
    d = tmp_path / "in"
    d.mkdir()
    g = cv2.cvtColor(src, cv2.COLOR_BGR2GRAY)
    cv2.imwrite(str(d / "gray8.png"), g)
    cv2.imwrite(str(d / "gray16.png"), g.astype(np.uint16) * 257)
    cv2.imwrite(str(d / "rgba8.png"), cv2.cvtColor(src, cv2.COLOR_BGR2BGRA))
    cv2.imwrite(str(d / "rgba16.png"), cv2.cvtColor(src, cv2.COLOR_BGR2BGRA).astype(np.uint16) * 257)
    (d / "png_named.jpg").write_bytes((good / "good.png").read_bytes())
    cv2.imwrite(str(d / "float32.tiff"), src.astype(np.float32) / 255.0)
    code, _, se = run_cli(
        capsys, "render", d, *[x for kv in SCENE.items() for x in kv], "-o", tmp_path / "o", "--save-mask", "-q"
    )
    assert code == 0, se
    for f in sorted(d.iterdir()):
        out = cv2.imread(str(tmp_path / "o" / f"{f.stem}.png"), cv2.IMREAD_UNCHANGED)
        ok = out is not None and out.shape == (720, 1280, 3) and out.dtype == np.uint8
        ok = ok and (cv2.imread(str(tmp_path / "o" / f"{f.stem}.shadow.png"), 0) == 255).sum() > 1000
        TALLY["accepted"].append((f.name, ok))
        assert ok, f.name


@pytest.mark.parametrize("kind", ["single_open_triangle", "latin1_obj", "non_manifold", "self_intersecting"])
def test_unusual_meshes_are_accepted(good, tmp_path, capsys, kind):
    """Meshes that are odd but valid cast their shadows: a single open triangle, an OBJ with a Latin-1
    comment (read without trimesh's optional charset_normalizer), three triangles on one edge
    (non-manifold), two interpenetrating boxes (self-intersecting)."""
    import trimesh

    if kind == "single_open_triangle":
        m = tmp_path / "tri.obj"
        m.write_bytes(b"v -0.02 -0.02 0.0\nv 0.03 -0.02 0.0\nv 0.0 0.02 0.05\nf 1 2 3\n")
    elif kind == "latin1_obj":
        m = tmp_path / "latin1.obj"
        m.write_bytes(
            "# modèle créé à la main (Latin-1)\n".encode("latin-1")
            + b"v -0.02 -0.02 0.0\nv 0.03 -0.02 0.0\nv 0.0 0.02 0.05\nv 0 0 0.06\nf 1 2 4\nf 2 3 4\n"
            + b"f 3 1 4\nf 1 3 2\n"
        )
    elif kind == "non_manifold":
        m = tmp_path / "nonmanifold.obj"
        m.write_bytes(b"v 0 0 0\nv 0 0 0.05\nv 0.03 0 0.02\nv -0.03 0 0.02\nv 0 0.03 0.02\nf 1 2 3\nf 2 1 4\nf 1 2 5\n")
    else:
        a = trimesh.creation.box(extents=(0.04, 0.02, 0.05))
        b = trimesh.creation.box(extents=(0.02, 0.04, 0.03))
        both = trimesh.util.concatenate([a, b])
        both.vertices[:, 2] += 0.025
        m = tmp_path / "selfint.ply"
        both.export(m)
    args = dict(SCENE, **{"--model": str(m), "--light": "point:0.3,-0.15,0.25"})  # shadow to the side: visible
    code, _, se = run_cli(
        capsys,
        "render",
        good / "good.png",
        *[x for kv in args.items() for x in kv],
        "-o",
        tmp_path / "o",
        "--save-mask",
        "-q",
    )
    shadow = cv2.imread(str(tmp_path / "o" / "good.shadow.png"), 0)
    ok = code == 0 and "error" not in se and shadow is not None and (shadow == 255).sum() > 200
    TALLY["accepted"].append((kind, ok))
    assert ok, se


def test_warnings_wrong_units_camera_inside_sun_below_horizon(good, tmp_path):
    """Not errors, but said on stderr (exit 0): a model 1200x the marker (millimetres read as metres) with
    the camera inside it, and a sun below the horizon."""
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "arshadow",
            "render",
            str(good / "good.png"),
            "--calib",
            str(CALIB),
            "--marker-length",
            "0.05",
            "--model",
            "box:40,40,60",
            "--light",
            "point:0,0,100",
            "--light",
            "sun:52,0,2024-06-21T23:00+00:00",
            "-o",
            str(tmp_path / "o"),
            "-q",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    warn = [ln for ln in r.stderr.splitlines() if "WARNING" in ln]
    found = {
        "wrong_units": any("wrong units" in w for w in warn),
        "camera_inside": any("camera is inside" in w for w in warn),
        "sun_below_horizon": any("below the horizon" in w for w in warn),
    }
    for k, v in found.items():
        TALLY["accepted"].append((k + "_warned", v))
    assert all(found.values()), r.stderr
    assert "Traceback" not in r.stderr


def test_report_counts():
    """Print the tally (run last in this module)."""
    total = sum(len(v) for v in TALLY.values())
    print(f"\nhostile-input kinds tried: {total}")
    for k, v in TALLY.items():
        print(f"  {k}: {len(v)} tried, {sum(ok for _, ok in v)} behaved")
    if total:
        assert all(ok for v in TALLY.values() for _, ok in v)
