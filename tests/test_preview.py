"""``arshadow preview`` without a browser (the preview work): the server's token, its errors, latest-wins, the
ground point under a pixel, Session.set_model, and Ctrl-C. The browser test is test_preview_browser.py."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest

from arshadow.preview.edit import ControlError, apply_controls, command_line, ground_point
from arshadow.preview.worker import LatestWins, Superseded

ROOT = Path(__file__).resolve().parents[1]
PHOTO = ROOT / "samples" / "knot_point.jpg"
CALIB = ROOT / "calib" / "synth_1280x720.yml"
BASE = {
    "calib": str(CALIB),
    "marker_length": 0.05,
    "model": str(ROOT / "samples" / "meshes" / "knot.ply"),
    "place": [0.1, 0.05, 0.0],
    "rotate": [0.0, 0.0, 15.0],
    "lights": ["point:-0.12,0.2,0.42"],
}
CONTROLS = {"place": [0.1, 0.05, 0.0], "rotate": [0.0, 0.0, 15.0], "scale": 1.0}


# -- pure parts (no GL) ----------------------------------------------------------------------------------
def test_ground_point_matches_opencv_back_projection():
    """The pixel's ray meets z = 0 where OpenCV's undistortPoints + the plane intersection put it, and the
    point projects back onto the pixel (distortion included)."""
    from arshadow.camera.model import Intrinsics
    from arshadow.synth.markers import look_at_pose

    cam = Intrinsics.from_file(CALIB)
    cfw = look_at_pose([0.1, -0.3, 0.4], [0.0, 0.0, 0.0])
    for uv in ([640.0, 400.0], [100.3, 650.7], [1200.0, 500.0]):
        g = ground_point(cam, cfw, uv)
        xy = cv2.undistortPoints(np.array([[uv]], np.float64), cam.K, cam.dist).reshape(2)
        R, t = cfw[:3, :3], cfw[:3, 3]
        c, d = -R.T @ t, R.T @ np.array([xy[0], xy[1], 1.0])
        want = c + d * (-c[2] / d[2])
        assert np.linalg.norm(g - want) < 1e-6
        assert np.allclose(cam.project(g[None], cfw)[0], uv, atol=1e-4)
    level = look_at_pose([0.0, -0.5, 0.05], [0.0, 0.0, 0.05])  # looking level: the top half is the sky
    assert ground_point(cam, level, [640.0, 100.0]) is None and ground_point(cam, level, [640.0, 600.0]) is not None


def test_controls_are_checked_with_one_clear_error():
    for bad, words in [
        ("x", "JSON object"),
        ({**CONTROLS, "colour": 1}, "unknown control"),
        ({"rotate": [0, 0, 0], "scale": 1}, "'place' is missing"),
        ({**CONTROLS, "place": [0, "a", 0]}, "three finite numbers"),
        ({**CONTROLS, "scale": -1}, "scale"),
        ({**CONTROLS, "opacity": 2}, "opacity"),
        ({**CONTROLS, "soft_samples": 1000}, "soft_samples"),
        ({**CONTROLS, "light": "measured"}, "no measured light"),
        ({**CONTROLS, "light": {"azimuth": 1}}, "azimuth"),
        ({**CONTROLS, "object": "yes"}, "object"),
    ]:
        with pytest.raises(ControlError, match=words):
            apply_controls(BASE, bad)


def test_light_sliders_move_the_first_light():
    d = apply_controls(BASE, {**CONTROLS, "light": {"azimuth": 0.0, "elevation": 90.0}})
    r = float(np.linalg.norm([-0.12, 0.2, 0.42]))
    assert d["lights"] == [f"point:0,0,{r:.6g}"]
    d = apply_controls(
        {**BASE, "lights": ["sun:48.85,2.35,2026-06-21T18:30+02:00"]},
        {**CONTROLS, "light": {"azimuth": 90.0, "elevation": 45.0}},
    )
    v = [float(x) for x in d["lights"][0].split(":")[1].split(",")[:3]]
    assert d["lights"][0].startswith("directional:") and ",radius=0.26" in d["lights"][0]  # the sun's disc kept
    assert np.allclose(v, [0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-6)


def test_command_line_reads_back_to_the_same_scene():
    """The command line the page shows parses (render's own parser) to the scene it describes."""
    from arshadow.cli import build_parser, join_negative_values
    from arshadow.scene.spec import scene_from_args, scene_from_dict

    d = {**BASE, "place": [-0.0123456789012345, 0.1, 0.0], "no_object": True, "opacity": 0.35}
    import shlex

    argv = shlex.split(command_line(d, str(PHOTO)))[1:]
    args = build_parser().parse_args(join_negative_values(argv))
    assert scene_from_args(args) == scene_from_dict(d)


def test_latest_wins_drops_waiting_requests():
    """While one job runs, of three requests that come, the two older ones are dropped unrun."""
    started, release, ran = threading.Event(), threading.Event(), []

    def job(x):
        ran.append(x)
        started.set()
        release.wait(10)
        return x

    w = LatestWins(job)
    try:
        first = w.submit(1)
        assert started.wait(10)
        older = [w.submit(2), w.submit(3)]
        newest = w.submit(4)
        release.set()
        assert first.result(10) == 1 and newest.result(10) == 4
        for f in older:
            with pytest.raises(Superseded):
                f.result(10)
        assert ran == [1, 4] and w.dropped == 2
    finally:
        release.set()
        w.close()


# -- the server (GL: renders through a Session) ------------------------------------------------------------
@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from arshadow.preview.engine import Media, PreviewEngine
    from arshadow.preview.server import PreviewServer

    out = tmp_path_factory.mktemp("preview") / "scene.yml"
    engine = PreviewEngine(Media(PHOTO), BASE, out)
    srv = PreviewServer(engine, 0, {"name": PHOTO.name})
    t = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    t.start()
    yield srv
    srv.shutdown()
    srv.server_close()
    engine.close()


def _call(srv, path, body=None, token=True, headers=None):
    url = f"http://127.0.0.1:{srv.port}{path}"
    if token:
        url += ("&" if "?" in url else "?") + f"token={srv.token}"
    data = None if body is None else (body if isinstance(body, bytes) else json.dumps(body).encode())
    req = urllib.request.Request(url, data=data, headers=headers or {}, method="POST" if data is not None else "GET")
    try:
        with urllib.request.urlopen(req, timeout=120) as r:
            return r.status, json.loads(r.read()) if "json" in r.headers["Content-Type"] else r.read()
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


@pytest.mark.gl
def test_server_needs_the_token_on_every_request(server):
    assert server.server_address[0] == "127.0.0.1"
    for path in ("/", "/api/info", "/api/render", "/api/save", "/api/image/1/composite", "/nope"):
        status, body = _call(server, path, token=False)
        assert status == 403 and "token" in body["error"]
        status, body = _call(server, path + "?token=wrong" + server.token[5:], token=False)
        assert status == 403
    status, body = _call(server, "/api/render", {"controls": CONTROLS}, token=False)
    assert status == 403
    status, page = _call(server, "/")
    assert status == 200 and b"<script>" in page and b"http" not in page.replace(b"http-equiv", b"")
    status, body = _call(server, "/api/info", headers={"Host": "evil.example:80"})
    assert status == 403 and "Host" in body["error"]


@pytest.mark.gl
def test_bad_requests_get_400_with_the_reason(server):
    cases = [
        (b"{not json", "not JSON"),
        ([1, 2], "not a JSON object"),
        ({"controls": CONTROLS, "path": "/etc/passwd"}, "unknown request key"),
        ({"controls": {**CONTROLS, "place": [0, 0]}}, "three finite numbers"),
        ({"controls": CONTROLS, "frame": 3}, "frame 3"),
        ({"controls": CONTROLS, "drag_to": [1e9, 0]}, "outside the 1280x720 image"),
        ({"controls": CONTROLS, "mask": "yes"}, "mask"),
    ]
    for body, words in cases:
        status, reply = _call(server, "/api/render", body)
        assert status == 400, (body, reply)
        assert words in reply["error"], (body, reply)
    status, reply = _call(server, "/api/render", b"x" * (70 * 1024))
    assert status == 413
    assert _call(server, "/nope")[0] == 404
    for path in ("/api/image/999999/composite", "/api/image/1/../../etc/passwd", "/api/image/1/photo"):
        status, reply = _call(server, path)
        assert status == 404 and "error" in reply
    assert _call(server, "/api/render")[0] == 405


@pytest.mark.gl
def test_a_scene_arshadow_refuses_is_a_400_and_the_server_goes_on(tmp_path):
    """A light inside the (scaled-up) model: 400 naming it, whether the mesh moved or a new session loads
    the scene; the next good requests render."""
    from arshadow.preview.engine import Media, PreviewEngine
    from arshadow.preview.server import PreviewServer

    box = {**BASE, "model": "box:0.04,0.04,0.06", "lights": ["point:0.1,0.1,0.4"]}
    engine = PreviewEngine(Media(PHOTO), box, tmp_path / "s.yml")
    srv = PreviewServer(engine, 0, {})
    threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()
    try:
        assert _call(srv, "/api/render", {"controls": CONTROLS})[0] == 200
        huge = {**CONTROLS, "scale": 20.0}  # 0.8 x 0.8 x 1.2 m: the light at 0.4 m is inside
        for controls in (huge, {**huge, "opacity": 0.5}):  # the mesh moved; a new session
            status, reply = _call(srv, "/api/render", {"controls": controls})
            assert status == 400 and "inside the closed mesh" in reply["error"], reply
        for controls in (CONTROLS, {**CONTROLS, "opacity": 0.5}):
            status, reply = _call(srv, "/api/render", {"controls": controls})
            assert status == 200 and reply["scene"]["scale"] == 1.0
    finally:
        srv.shutdown()
        srv.server_close()
        engine.close()


@pytest.mark.gl
def test_render_then_save_reproduces_through_batch(server, tmp_path):
    """The page's image (lossless) equals `arshadow batch --config` of the saved scene, pixel for pixel."""
    status, r = _call(server, "/api/render", {"controls": {**CONTROLS, "rotate": [0, 0, 40.0]}, "drag_to": [800, 480]})
    assert status == 200, r
    status, data = _call(server, r["image"])
    assert status == 200 and data[:2] == b"BM"  # lossless: BMP
    shown = _img(data)
    status, saved = _call(server, "/api/save", {})
    assert status == 200, saved
    out = tmp_path / "out"
    p = subprocess.run(
        [sys.executable, "-m", "arshadow", "batch", str(PHOTO), "--config", saved["path"], "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    assert np.array_equal(cv2.imread(str(out / "knot_point.png")), shown)


@pytest.mark.gl
def test_set_model_renders_as_a_fresh_session():
    """Session.set_model (the preview's drag) gives the pixels of a new session of the moved scene."""
    from arshadow.frame.session import Session
    from arshadow.io import read_image
    from arshadow.scene.spec import scene_from_dict

    img = read_image(PHOTO)
    moved = {**BASE, "place": [0.02, -0.03, 0.01], "rotate": [0, 0, 70], "scale": 0.8}
    with Session(scene_from_dict(BASE)) as s:
        pose = s.track(img)
        s.render(img, pose)
        s.set_model(scene_from_dict(moved).model)
        got = s.render(img, pose)
        assert s.spec == scene_from_dict(moved)
    with Session(scene_from_dict(moved)) as fresh:
        want = fresh.process(img)
    assert np.array_equal(got.composite, want.composite) and np.array_equal(got.mask, want.mask)


def _img(data: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)


def _shown(engine, reply, kind="composite"):
    """The image the page would load for ``reply`` (engine side)."""
    return _img(engine.image(reply["image_id"], kind))


@pytest.mark.gl
@pytest.mark.parametrize("light", ["directional:-0.3,0.5,0.8", "point:-0.12,0.2,0.42"])
def test_draft_frames_match_the_exact_render(light, tmp_path, tol):
    """A draft (drag or turn: the equivalent camera and lights) shows the exact render's shadow to rounding;
    under a directional light its composite too (a point light: the held exposure differs a few levels)."""
    from arshadow.preview.engine import Media, PreviewEngine

    engine = PreviewEngine(Media(PHOTO), {**BASE, "lights": [light]}, tmp_path / "s.yml")
    try:
        engine.render(engine.request({"controls": CONTROLS}))
        for body in ({"drag_to": [850.0, 470.0]}, {"controls": {**CONTROLS, "rotate": [0, 0, 75.0]}}):
            b = {"controls": CONTROLS, "mask": True, **body}
            draft = engine.render(engine.request({**b, "draft": True}))
            exact = engine.render(engine.request({**b, "draft": False}))
            assert draft["draft"] and not exact["draft"] and draft["scene"] == exact["scene"]
            masks = [_shown(engine, r, "mask") for r in (draft, exact)]
            assert int((masks[0] != masks[1]).sum()) <= tol.preview_draft_mask_px
            assert (masks[1] > 0).sum() > 10000  # a real shadow was compared
            diff = np.abs(_shown(engine, draft).astype(int) - _shown(engine, exact).astype(int)).max()
            if light.startswith("directional"):
                assert diff <= tol.preview_draft_levels
        raised = {**CONTROLS, "place": [0.1, 0.05, 0.02]}  # not a motion on the ground: rendered exactly
        assert not engine.render(engine.request({"controls": raised, "draft": True}))["draft"]
    finally:
        engine.close()


@pytest.mark.gl
def test_server_drops_superseded_renders(server):
    """Many renders at once: the ones that waited behind a newer one are answered 409, the newest 200."""
    results: list = [None] * 6

    def go(i):
        results[i] = _call(server, "/api/render", {"controls": {**CONTROLS, "rotate": [0, 0, 10.0 * i]}, "seq": i})

    threads = [threading.Thread(target=go, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
        time.sleep(0.01)
    for t in threads:
        t.join(300)
    codes = [r[0] for r in results]
    assert set(codes) <= {200, 409} and 409 in codes, codes
    assert results[-1][0] == 200 and results[-1][1]["seq"] == 5
    for status, body in results:
        if status == 409:
            assert "superseded" in body["error"]


@pytest.mark.gl
def test_cli_prints_the_address_and_stops_cleanly_on_ctrl_c(tmp_path):
    cmd = [sys.executable, "-m", "arshadow", "preview", str(PHOTO), "--calib", str(CALIB), "--marker-length", "0.05",
           "--model", "box:0.04,0.04,0.06", "--light", "point:0.1,0.1,0.4", "--no-browser",
           "--scene-out", str(tmp_path / "s.yml")]  # fmt: skip
    p = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path, preexec_fn=_ctrl_c_reaches_it
    )
    try:
        line = p.stdout.readline()
        assert "http://127.0.0.1:" in line and "token=" in line, (line, p.stderr.read() if p.poll() else "")
        url = line.split(" at ", 1)[1].strip()
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(url.split("?")[0] + "api/info", timeout=30)
        assert e.value.code == 403
        with urllib.request.urlopen(url, timeout=30) as r:
            assert r.status == 200
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0, err
    assert "Traceback" not in err and "stopped" in err


def test_no_browser_opened_without_a_display(monkeypatch):
    import webbrowser

    from arshadow.cli.preview import open_browser

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(webbrowser, "open", lambda *a, **k: pytest.fail("opened a browser"))
    if sys.platform.startswith("linux"):
        assert open_browser("http://127.0.0.1:1/") is False
    monkeypatch.setenv("DISPLAY", ":99")

    def broken(*a, **k):
        raise webbrowser.Error("no runnable browser")

    monkeypatch.setattr(webbrowser, "open", broken)
    assert open_browser("http://127.0.0.1:1/") is False
    assert os.environ["DISPLAY"] == ":99"


def _ctrl_c_reaches_it():
    """In the child before ``exec``: SIGINT's default disposition, as a process run from a terminal has it. A
    test run started in the background by a non-interactive shell (``.ci/run &``) ignores SIGINT, the
    children inherit that, and Python then installs no KeyboardInterrupt: the server would never stop."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start_cli(args, cwd):
    """``arshadow preview ARGS --no-browser`` in a subprocess: (process, address)."""
    cmd = [sys.executable, "-m", "arshadow", "preview", *map(str, args), "--no-browser"]
    p = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd, preexec_fn=_ctrl_c_reaches_it
    )
    line = p.stdout.readline()
    if "token=" not in line:
        p.kill()
        raise AssertionError(f"no address printed: {line!r} {p.stderr.read()}")
    return p, line.split(" at ", 1)[1].strip()


def _post(url, route, body):
    base, query = url.split("?", 1)
    req = urllib.request.Request(f"{base.rstrip('/')}{route}?{query}", data=json.dumps(body).encode(), method="POST")
    try:
        with urllib.request.urlopen(req, timeout=300) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


@pytest.mark.gl
def test_probe_measured_light_switch_and_save(tmp_path):
    """--probe: the measured light by default, a manual light and back; the saved scene names the measured
    light's file and batch reproduces the page's pixels."""
    probe = ROOT / "samples" / "probe_shadow.jpg"
    p, url = _start_cli(
        [
            probe,
            "--calib",
            CALIB,
            "--marker-length",
            "0.05",
            "--model",
            ROOT / "samples/meshes/knot.ply",
            "--place",
            "-0.02,0.1,0",
            "--probe",
            "box:0.05,0.05,0.1",
            "--probe-place",
            "0.1,0.02,0",
            "--scene-out",
            tmp_path / "job.yml",
        ],  # fmt: skip
        tmp_path,
    )
    try:
        controls = {"place": [-0.02, 0.1, 0.0], "rotate": [0.0, 0.0, 0.0], "scale": 1.0}
        status, manual = _post(
            url, "/api/render", {"controls": {**controls, "light": {"azimuth": 30, "elevation": 40}}}
        )
        assert status == 200 and manual["scene"]["lights"][0].startswith("directional:")
        assert "light_from" not in manual["scene"]
        status, measured = _post(url, "/api/render", {"controls": {**controls, "light": "measured"}})
        assert status == 200 and "lights" not in measured["scene"] and measured["controls"]["light"] == "measured"
        shown = [_get_bytes(url, r["image"]) for r in (manual, measured)]
        assert not np.array_equal(_img(shown[0]), _img(shown[1]))
        status, saved = _post(url, "/api/save", {})
        assert status == 200
    finally:
        p.send_signal(signal.SIGINT)
        p.communicate(timeout=60)
    assert p.returncode == 0
    assert (tmp_path / "job.light.json").is_file() and "light_from: job.light.json" in saved["scene"]
    run = subprocess.run(
        [sys.executable, "-m", "arshadow", "batch", str(probe), "--config", saved["path"], "-o", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert np.array_equal(cv2.imread(str(tmp_path / "o" / "probe_shadow.png")), _img(shown[1]))


@pytest.mark.gl
@pytest.mark.video
def test_video_frames_are_the_pipeline_s(tmp_path):
    """A video's frames by index (the page's slider), each composited as Session.process composites it."""
    from arshadow.frame.session import Session
    from arshadow.preview.engine import Media, PreviewEngine
    from arshadow.scene.spec import scene_from_dict

    video = ROOT / "samples" / "video" / "orbit.mp4"
    base = {**BASE, "calib": str(ROOT / "calib" / "synth_640x360.yml"), "model": "box:0.04,0.04,0.06"}
    media = Media(video)
    assert media.is_video and media.count > 20 and (media.width, media.height) == (640, 360)
    engine = PreviewEngine(media, base, tmp_path / "s.yml")
    try:
        replies = [engine.render(engine.request({"controls": CONTROLS, "frame": i})) for i in (0, 20)]
        shown = [_shown(engine, r) for r in replies]
        with pytest.raises(ControlError, match="frame"):
            engine.request({"controls": CONTROLS, "frame": media.count})
    finally:
        engine.close()
    cap = cv2.VideoCapture(str(video))
    frames = [cap.read()[1] for _ in range(21)]
    cap.release()
    with Session(scene_from_dict(base)) as s:
        assert np.array_equal(shown[0], s.process(frames[0]).composite)
    with Session(scene_from_dict(base)) as s:
        assert np.array_equal(shown[1], s.process(frames[20]).composite)
    assert not np.array_equal(shown[0], shown[1])


def _get_bytes(url, route):
    base, query = url.split("?", 1)
    with urllib.request.urlopen(f"{base.rstrip('/')}{route}?{query}", timeout=60) as r:
        return r.read()


def _get(url, route):
    base, query = url.split("?", 1)
    with urllib.request.urlopen(f"{base.rstrip('/')}{route}?{query}", timeout=60) as r:
        return json.loads(r.read())


@pytest.mark.gl
def test_config_reopens_a_saved_scene(tmp_path):
    """--config starts from a job file (its relative paths its own folder's): the page's controls are the
    file's, its image is batch's of that file; Save never replaces the file unless told to."""
    job = tmp_path / "jobs" / "knot_point.scene.yml"
    job.parent.mkdir()
    rel = lambda p: os.path.relpath(p, job.parent)  # noqa: E731
    job.write_text(
        f"calib: {rel(CALIB)}\nmarker_length: 0.05\nmodel: {rel(BASE['model'])}\nscale: 0.9\n"
        "rotate: [0, 0, 60]\nplace: [0.03, -0.04, 0.0]\nlights: ['directional:0.3,-0.4,0.8']\nopacity: 0.5\n"
    )
    refused = subprocess.run(
        [sys.executable, "-m", "arshadow", "preview", str(PHOTO), "--config", str(job), "--no-browser"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=job.parent,
    )
    assert refused.returncode == 2 and "--scene-out" in refused.stderr
    p, url = _start_cli([PHOTO, "--config", job, "--scene-out", tmp_path / "again.yml"], tmp_path)
    try:
        info = _get(url, "/api/info")
        c = info["controls"]
        assert (c["place"], c["rotate"], c["scale"], c["opacity"]) == ([0.03, -0.04, 0.0], [0, 0, 60], 0.9, 0.5)
        status, reply = _post(url, "/api/render", {"controls": c})
        assert status == 200
        shown = _img(_get_bytes(url, reply["image"]))
    finally:
        p.send_signal(signal.SIGINT)
        p.communicate(timeout=60)
    run = subprocess.run(
        [sys.executable, "-m", "arshadow", "batch", str(PHOTO), "--config", str(job), "-o", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert np.array_equal(cv2.imread(str(tmp_path / "o" / "knot_point.png")), shown)
