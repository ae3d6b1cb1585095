"""``arshadow light`` and ``--light-from`` end to end: the measured look on a synthetic photo whose light,
reflectances and camera are known (truth from :mod:`arshadow.synth.lit`, never from the estimator)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from arshadow.camera.model import Intrinsics
from arshadow.cli import main
from arshadow.compose.composite import SRGB_TO_LINEAR
from arshadow.synth.lit import light_vector, render_lit_photo
from arshadow.synth.markers import look_at_pose

CALIB = "calib/synth_1280x720.yml"
PROBE = ["--probe", "box:0.05,0.05,0.1", "--probe-place", "0.1,0.02,0"]


@pytest.fixture(scope="module")
def lit(tmp_path_factory):
    cam = Intrinsics.from_file(CALIB)
    pose = look_at_pose([0.15, -0.35, 0.45], [0.05, 0.0, 0.0])
    p = render_lit_photo(
        cam,
        pose,
        light=light_vector(160, 40),
        probe="box:0.05,0.05,0.1",
        probe_place=(0.1, 0.02, 0),
        exposure=0.7,
        white_balance=(1.1, 1.0, 0.85),
        noise_sigma=1.0,
        seed=2,
        supersample=2,
    )
    d = tmp_path_factory.mktemp("lit")
    path = d / "lit.png"
    cv2.imwrite(str(path), p.image)
    return p, path, d


def test_light_json(lit, capsys):
    p, path, d = lit
    code = main(
        ["light", str(path), "--calib", CALIB, "--marker-length", "0.05", *PROBE, "--json", "-o", str(d / "est.json")]
    )
    out = capsys.readouterr().out
    assert code == 0
    est = json.loads(out)
    for key in ("light", "direction", "position", "north_deg", "shadow_ratio", "uncertainty_deg", "exposure"):
        assert key in est
    assert est["light"].startswith("directional:")
    d_est = np.array(est["direction"])
    assert np.degrees(np.arccos(np.clip(d_est @ p.light, -1, 1))) < 1.5
    assert json.loads((d / "est.json").read_text())["light"] == est["light"]


def test_light_needs_a_probe(lit, capsys):
    _, path, _ = lit
    code = main(["light", str(path), "--calib", CALIB, "--marker-length", "0.05"])
    assert code == 2 and "--probe" in capsys.readouterr().err


def test_light_no_marker_is_one_line(tmp_path, capsys):
    img = tmp_path / "grey.png"
    cv2.imwrite(str(img), np.full((720, 1280, 3), 128, np.uint8))
    code = main(["light", str(img), "--calib", CALIB, "--marker-length", "0.05", *PROBE])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1 and "no marker" in err[0]


def test_white_box_matches_the_paper(lit, gl_ctx, tmp_path, capsys):
    """A white (255) virtual box rendered with --light-from: its lit top face records the photographed
    paper's linear RGB (truth: the generating light, exposure and white balance) within 5 % per channel."""
    p, path, d = lit
    est = d / "est2.json"
    assert main(["light", str(path), "--calib", CALIB, "--marker-length", "0.05", *PROBE, "-o", str(est)]) == 0
    out = tmp_path / "out"
    code = main(
        [
            "render",
            str(path),
            "--calib",
            CALIB,
            "--marker-length",
            "0.05",
            "--model",
            "box:0.03,0.03,0.03",
            "--place=-0.02,0.08,0",
            "--color",
            "255,255,255",
            "--light-from",
            str(est),
            "-o",
            str(out),
        ]
    )
    capsys.readouterr()
    assert code == 0
    img = cv2.imread(str(out / "lit.png"))
    uv = p.intrinsics.project(np.array([[-0.02, 0.08, 0.03]]), p.cam_from_world)[0]
    u, v = np.rint(uv).astype(int)
    top = SRGB_TO_LINEAR[img[v - 2 : v + 3, u - 2 : u + 3]].reshape(-1, 3).mean(axis=0)[::-1]  # RGB
    assert np.allclose(top, p.paper_linear, rtol=0.05), (top, p.paper_linear)
    # and the shadow: its darkness is the measured ratio, not the default 0.7
    data = json.loads(est.read_text())
    assert all(0.2 < r < 0.8 for r in data["shadow_ratio"])


def test_light_from_in_a_scene(tmp_path):
    """``light_from`` in a scene (job file key / --light-from): the estimate's light, its shadow colour at
    opacity 1, a matte object with the measured ambient, and the exposure on the colour unless no_exposure."""
    from arshadow.errors import UsageError
    from arshadow.estimate import Exposure, LightEstimate
    from arshadow.scene.spec import scene_from_dict

    est = LightEstimate(
        "directional",
        "directional:0,0.6,0.8",
        direction=(0.0, 0.6, 0.8),
        shadow_ratio=(0.3, 0.4, 0.5),
        exposure=Exposure((0.5, 0.45, 0.4), (0.02, 0.02, 0.02), 20),
    )
    (tmp_path / "est.json").write_text(est.to_json())
    base = {"calib": "cam.yml", "marker_length": 0.05, "model": "box:0.04,0.04,0.06", "color": "255,255,255"}
    spec = scene_from_dict({**base, "light_from": "est.json"}, base_dir=tmp_path)
    o = spec.options
    assert spec.lights == ("directional:0,0.6,0.8",) and o.opacity == 1.0 and o.specular == 0.0
    assert np.allclose(o.shadow_color, (0.3, 0.4, 0.5))
    a = 0.4 * 0.8 / 0.6  # ambient giving a horizontal surface the mean ratio 0.4 under sin(e) = 0.8
    assert o.ambient == pytest.approx(a)
    # a white horizontal face shaded ambient + sin(e) records the paper: colour = paper / (a + 0.8), linear
    lin = np.where(
        np.array(o.occluder_color) <= 0.04045,
        np.array(o.occluder_color) / 12.92,
        ((np.array(o.occluder_color) + 0.055) / 1.055) ** 2.4,
    )
    assert np.allclose(lin * (a + 0.8), (0.5, 0.45, 0.4), rtol=1e-6)
    off = scene_from_dict({**base, "light_from": "est.json", "no_exposure": True}, base_dir=tmp_path).options
    assert off.occluder_color is None
    mine = scene_from_dict({**base, "light_from": "est.json", "lights": ["point:0,0,1"]}, base_dir=tmp_path)
    assert mine.lights == ("point:0,0,1",)
    with pytest.raises(UsageError, match="light-from"):
        scene_from_dict({**base, "light_from": "missing.json"}, base_dir=tmp_path)
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(UsageError, match="not a light estimate"):
        scene_from_dict({**base, "light_from": "bad.json"}, base_dir=tmp_path)


def test_render_with_probe_options(lit, gl_ctx, tmp_path, capsys):
    """``render --probe ...``: the light measured first from the inputs; the white box's top face records the
    photographed paper (truth: the generating exposure / white balance) within 5 % per channel."""
    p, path, d = lit
    out = tmp_path / "out"
    code = main(
        [
            "render",
            str(path),
            "--calib",
            CALIB,
            "--marker-length",
            "0.05",
            *PROBE,
            "--model",
            "box:0.03,0.03,0.03",
            "--place=-0.02,0.08,0",
            "--color",
            "255,255,255",
            "-o",
            str(out),
            "--report",
            str(tmp_path / "r.json"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 0 and "light: directional:" in err
    img = cv2.imread(str(out / "lit.png"))
    uv = p.intrinsics.project(np.array([[-0.02, 0.08, 0.03]]), p.cam_from_world)[0]
    u, v = np.rint(uv).astype(int)
    top = SRGB_TO_LINEAR[img[v - 2 : v + 3, u - 2 : u + 3]].reshape(-1, 3).mean(axis=0)[::-1]  # RGB
    assert np.allclose(top, p.paper_linear, rtol=0.05), (top, p.paper_linear)
    item = json.loads((tmp_path / "r.json").read_text())["images"][0]
    assert np.allclose(item["exposure"]["paper_rgb"], p.paper_linear, rtol=0.03)


def test_probe_equals_light_then_light_from_on_the_sample(gl_ctx, tmp_path, capsys):
    """On the sample photo: ``render --probe`` gives the same picture as ``light -o est.json`` then
    ``render --light-from est.json``; --probe with --light-from is a usage error."""
    s = json.loads(open("samples/light_probe.json").read())
    photo = "samples/" + s["photo"]
    cam = ["--calib", s["calib"], "--marker-length", str(s["marker_length"])]
    probe = ["--probe", s["probe"], "--probe-place", ",".join(map(str, s["probe_place"]))]
    model = ["--model", "box:0.03,0.03,0.03", "--place=-0.02,0.1,0"]
    est = tmp_path / "est.json"
    assert main(["light", photo, *cam, *probe, "-o", str(est)]) == 0
    assert main(["render", photo, *cam, *model, "--light-from", str(est), "-o", str(tmp_path / "a")]) == 0
    assert main(["render", photo, *cam, *model, *probe, "-o", str(tmp_path / "b")]) == 0
    a = cv2.imread(str(tmp_path / "a" / "probe_shadow.png"))
    b = cv2.imread(str(tmp_path / "b" / "probe_shadow.png"))
    assert a is not None and np.array_equal(a, b)
    capsys.readouterr()
    assert main(["render", photo, *cam, *model, *probe, "--light-from", str(est), "-o", str(tmp_path / "c")]) == 2
    assert "--probe" in capsys.readouterr().err


def test_video_with_probe_options(lit, gl_ctx, tmp_path, capsys):
    """``video --probe ...``: measured once from the video's frames; every frame record carries its exposure."""
    p, path, d = lit
    clip = tmp_path / "clip.avi"
    vw = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 10, (p.image.shape[1], p.image.shape[0]))
    for _ in range(3):
        vw.write(p.image)
    vw.release()
    code = main(
        [
            "video",
            str(clip),
            "--calib",
            CALIB,
            "--marker-length",
            "0.05",
            *PROBE,
            "--model",
            "box:0.03,0.03,0.03",
            "--place=-0.02,0.08,0",
            "--color",
            "255,255,255",
            "-o",
            str(tmp_path / "out"),
            "--report",
            str(tmp_path / "r.json"),
            "-q",
        ]
    )
    err = capsys.readouterr().err
    assert code == 0 and "light: directional:" in err and "3 frame(s)" in err
    frames = [i for i in json.loads((tmp_path / "r.json").read_text())["images"] if i.get("frame") is not None]
    assert len(frames) == 3
    for f in frames:
        assert np.allclose(f["exposure"]["smoothed_paper_rgb"], p.paper_linear, rtol=0.05)


def test_batch_with_probe_options(lit, gl_ctx, tmp_path, capsys):
    """``batch --probe ...``: the measured light replaces the job file's; the same picture as ``render --probe``."""
    p, path, d = lit
    job = tmp_path / "job.json"
    job.write_text(
        json.dumps(
            {
                "calib": str(Path(CALIB).resolve()),
                "marker_length": 0.05,
                "model": "box:0.03,0.03,0.03",
                "place": [-0.02, 0.08, 0],
                "color": "255,255,255",
                "light": "point:0,0,1",
            }
        )
    )
    assert main(["batch", str(path), "-c", str(job), "-o", str(tmp_path / "b"), *PROBE, "-q"]) == 0
    assert "light: directional:" in capsys.readouterr().err
    assert (
        main(
            [
                "render",
                str(path),
                "--calib",
                CALIB,
                "--marker-length",
                "0.05",
                *PROBE,
                "--model",
                "box:0.03,0.03,0.03",
                "--place=-0.02,0.08,0",
                "--color",
                "255,255,255",
                "-o",
                str(tmp_path / "r"),
            ]
        )
        == 0
    )
    assert np.array_equal(cv2.imread(str(tmp_path / "b" / "lit.png")), cv2.imread(str(tmp_path / "r" / "lit.png")))


def test_light_without_the_probe_is_one_line(capsys):
    """samples/knot_point.jpg has no box probe where it is given: exit 1, one line naming the cause (the trust fixes:
    it answered a confident light)."""
    code = main(["light", "samples/knot_point.jpg", "--calib", CALIB, "--marker-length", "0.05", *PROBE, "--json"])
    cap = capsys.readouterr()
    err = cap.err.strip().splitlines()
    assert code == 1 and cap.out == "" and len(err) == 1 and "probe is not in the photo" in err[0], cap
