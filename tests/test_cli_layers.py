"""``arshadow render --layers`` (the compositing-layers work): the files, their recombination, bad input, progress and summary.

Ground truth: the composite ``arshadow render`` wrote; the recombination is float64 from the sRGB formula
(tests/test_layers.py's helpers), not the module's tables.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from cli_run import run_cli
from layer_checks import linear, maxdiff, recombine

pytestmark = pytest.mark.gl

ROOT = Path(__file__).resolve().parents[1]
CALIB = ROOT / "calib" / "synth_1280x720_k1.yml"
SCENE = [
    "--calib",
    CALIB,
    "--marker-length",
    "0.05",
    "--model",
    "box:0.04,0.03,0.05",
    "--place",
    "0.03,0,0",
    "--rotate",
    "0,0,25",
    "--light",
    "point:-0.1,0.1,0.4",
]


@pytest.fixture(scope="module")
def photos(tmp_path_factory, gl_ctx):
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose, render_marker_photo

    d = tmp_path_factory.mktemp("inputs")
    intr = Intrinsics.from_file(CALIB)
    for k, eye in enumerate(([0.15, -0.3, 0.3], [-0.1, -0.25, 0.35])):
        img = render_marker_photo(intr, look_at_pose(eye, [0.0, 0.0, 0.0]), marker_length=0.05, seed=5 + k).image
        cv2.imwrite(str(d / f"p{k}.png"), img)
    return d


def test_render_layers_png_recombine_and_summary(photos, tmp_path, capsys):
    out = tmp_path / "out"
    code, so, se = run_cli(capsys, "render", photos / "p0.png", photos / "p1.png", *SCENE, "-o", out, "--layers")
    assert code == 0, se
    assert "render:" not in se  # no progress bar: stderr is not a terminal here
    assert "2 done, 0 failed, 0 flagged" in so
    for k in range(2):
        plate = cv2.imread(str(photos / f"p{k}.png"))
        comp = cv2.imread(str(out / f"p{k}.png"))
        o = cv2.imread(str(out / f"p{k}.object.png"), cv2.IMREAD_UNCHANGED)
        m = cv2.imread(str(out / f"p{k}.shadow.mult.png"), cv2.IMREAD_UNCHANGED)
        only = cv2.imread(str(out / f"p{k}.shadow.only.png"), cv2.IMREAD_UNCHANGED)
        a = o[..., 3] / 65535.0
        obj = np.dstack([linear(o[..., 2::-1] / 257.0) * a[..., None], a])
        assert np.count_nonzero(a > 0.5) > 300 and np.count_nonzero(m < 50000) > 300
        assert maxdiff(recombine(plate, obj, m / 65535.0), comp) <= 1
        assert maxdiff(recombine(plate, obj, only[..., 3] / 65535.0, over=True), comp) <= 1


def test_missing_exr_writer_is_exit_2_before_any_work(photos, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "OpenEXR", None)  # import OpenEXR -> ImportError
    out = tmp_path / "out"
    code, _so, se = run_cli(
        capsys, "render", photos / "p0.png", *SCENE, "-o", out, "--layers", "--layers-format", "exr"
    )
    assert code == 2
    lines = se.strip().splitlines()
    assert len(lines) == 1 and "OpenEXR" in lines[0] and "arshadow[exr]" in lines[0]
    assert not any(out.glob("*.png")) and not any(out.glob("*.exr"))


def test_layer_file_that_would_overwrite_an_input_is_exit_2(photos, tmp_path, capsys):
    d = tmp_path / "in"
    d.mkdir()
    (d / "a.png").write_bytes((photos / "p0.png").read_bytes())
    (d / "a.object.png").write_bytes((photos / "p1.png").read_bytes())
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    code, _so, se = run_cli(
        capsys, "render", d / "a.png", d / "a.object.png", *SCENE, "-o", tmp_path / "o2", "--layers"
    )
    assert code == 0, se  # another folder: fine
    # -o the inputs' folder: the layer file a.object.png of a.png would replace the input a.object.png
    code, _so, se = run_cli(capsys, "render", d / "a.png", d / "a.object.png", *SCENE, "-o", d, "--layers")
    assert code == 2
    lines = se.strip().splitlines()
    assert len(lines) == 1 and "would overwrite an input" in lines[0] and "a.object.png" in lines[0]
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before


def test_export_track_of_a_photo_set_from_the_render_report(photos, tmp_path, capsys):
    import json

    pygltflib = pytest.importorskip("pygltflib")
    out = tmp_path / "out"
    rep = tmp_path / "report.json"
    code, _so, se = run_cli(
        capsys, "render", photos / "p0.png", photos / "p1.png", *SCENE, "-o", out, "--report", rep, "-q"
    )
    assert code == 0, se
    code, _so, se = run_cli(
        capsys,
        "export-track",
        rep,
        "--calib",
        CALIB,
        "--model",
        "box:0.04,0.03,0.05",
        "--place",
        "0.03,0,0",
        "--rotate",
        "0,0,25",
        "-o",
        tmp_path / "t.glb",
        "-o",
        tmp_path / "t.json",
        "-o",
        tmp_path / "t.csv",
        "--fps",
        "4",
    )
    assert code == 0, se
    g = pygltflib.GLTF2().load(str(tmp_path / "t.glb"))
    assert g.cameras[0].type == "perspective" and len(g.meshes) == 2 and len(g.animations) == 1
    doc = json.loads((tmp_path / "t.json").read_text())
    assert [f["time_s"] for f in doc["frames"]] == [0.0, 0.25]
    items = json.loads(rep.read_text())["images"]
    assert doc["frames"][1]["opencv"]["tvec"] == pytest.approx(items[1]["tvec"])
    # bad input: one line, exit 2, nothing written
    code, _so, se = run_cli(capsys, "export-track", rep, "--calib", CALIB, "-o", tmp_path / "t.obj")
    assert code == 2 and len(se.strip().splitlines()) == 1 and "unknown track format" in se


def test_render_layers_undistorted_writes_the_pinhole_layers_and_the_stmap(photos, tmp_path, capsys):
    out = tmp_path / "out"
    code, _so, se = run_cli(capsys, "render", photos / "p0.png", *SCENE, "-o", out, "--layers-undistorted", "-q")
    assert code == 0, se
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        [
            "p0.png",
            "p0.object.png",
            "p0.shadow.mult.png",
            "p0.shadow.only.png",
            "p0.stmap.png",
            "p0.undistorted.object.png",
            "p0.undistorted.shadow.mult.png",
            "p0.undistorted.shadow.only.png",
        ]
    )
    st = cv2.imread(str(out / "p0.stmap.png"), cv2.IMREAD_UNCHANGED)
    assert st.dtype == np.uint16 and st.shape == (720, 1280, 3) and np.all(st[..., 0] == 0)  # B = 0
    # the principal point maps to itself (no distortion there): s = (cx + 0.5) / W
    from arshadow.camera.model import Intrinsics

    intr = Intrinsics.from_file(CALIB)
    u, v = round(intr.K[0, 2]), round(intr.K[1, 2])
    assert st[v, u, 2] / 65535 == pytest.approx((u + 0.5) / 1280, abs=5e-5)


def test_progress_bar_on_a_terminal_only_and_not_with_q(photos, tmp_path):
    """stderr a pseudo-terminal: the tqdm bar is drawn; with -q, or stderr a pipe (the tests above), it is not."""
    import fcntl
    import os
    import pty
    import struct
    import subprocess
    import termios

    def run(*extra):
        master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 120, 0, 0))  # a 120-column terminal
        p = subprocess.run(
            [
                sys.executable,
                "-m",
                "arshadow",
                "render",
                str(photos / "p0.png"),
                str(photos / "p1.png"),
                *map(str, SCENE),
                "-o",
                str(tmp_path / "o"),
                *extra,
            ],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=slave,
            timeout=300,
            check=False,
        )
        os.close(slave)
        chunks = []
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:
                break
            if not data:
                break
            chunks.append(data)
        os.close(master)
        return p.returncode, p.stdout.decode(), b"".join(chunks).decode(errors="replace")

    code, out, err = run()
    assert code == 0 and "render:" in err and "2/2" in err and "2 done, 0 failed" in out
    code, out, err = run("-q")
    assert code == 0 and "render:" not in err and out == ""
