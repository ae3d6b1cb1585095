"""``arshadow preview`` in a real browser (the preview work): headless Chromium (Debian's ``chromium``) driven by
Playwright loads the page, drags the object to a pixel, saves; the saved place is the ground point under
that pixel (back-projected here with OpenCV) and ``arshadow render`` of the saved scene gives the page's
image pixel for pixel.

Needs ``/usr/bin/chromium`` (``apt-get install chromium``; or ``$ARSHADOW_CHROMIUM``) and the ``playwright``
package (the ``test`` extra); never ``playwright install``. Skips, saying which is missing, without them.
``ARSHADOW_PREVIEW_SCREENSHOT=docs/preview.png`` also writes the README's screenshot.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import threading
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

pytestmark = pytest.mark.gl

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
CHROMIUM = os.environ.get("ARSHADOW_CHROMIUM", "/usr/bin/chromium")
#: Chromium's flags: headless, no sandbox (root in CI containers), nothing fetched from the network
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
#: the pixel the object is dragged to (on the ground, right of the marker) and where the drag starts
TARGET_PX = (859.0, 445.0)
START_PX = (700.0, 420.0)


@pytest.fixture(scope="module")
def browser():
    if not (Path(CHROMIUM).is_file() and os.access(CHROMIUM, os.X_OK)):
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium, or set ARSHADOW_CHROMIUM)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("the playwright package is not installed (pip install -e '.[test]')")
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        yield b
        b.close()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from arshadow.cli.preview import base_scene  # noqa: F401 (the CLI's module loads)
    from arshadow.preview.edit import controls_of, light_angles
    from arshadow.preview.engine import Media, PreviewEngine
    from arshadow.preview.server import PreviewServer

    out = tmp_path_factory.mktemp("preview") / "knot.scene.yml"
    engine = PreviewEngine(Media(PHOTO), BASE, out)
    info = {
        "name": PHOTO.name,
        "width": 1280,
        "height": 720,
        "frames": 1,
        "controls": controls_of(BASE),
        "measured_available": False,
        "light_angles": list(light_angles(BASE["lights"][0])),
    }
    srv = PreviewServer(engine, 0, info)
    t = threading.Thread(target=srv.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    t.start()
    yield srv
    srv.shutdown()
    srv.server_close()
    engine.close()


def _css_point(page, uv):
    """Where on the page the centre of photo pixel ``uv`` is (pixel-centre convention)."""
    box = page.evaluate(
        "() => { const i = document.getElementById('photo'); const b = i.getBoundingClientRect();"
        " return [b.left, b.top, b.width / i.naturalWidth, b.height / i.naturalHeight]; }"
    )
    return box[0] + (uv[0] + 0.5) * box[2], box[1] + (uv[1] + 0.5) * box[3]


def _shown_image(page, element="photo") -> np.ndarray:
    """The bytes the page's image element loaded (its address, fetched again: the server keeps them)."""
    src = page.evaluate(f"() => document.getElementById('{element}').src")
    with urllib.request.urlopen(src, timeout=60) as r:
        data = r.read()
    assert data[:2] == b"BM", data[:8]  # lossless (BMP)
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)


def _ground_under(pixel, rvec, tvec) -> np.ndarray:
    """The marker plane's point under ``pixel``: OpenCV's undistortPoints and a ray / plane intersection,
    at the pose the page rendered with (independent of arshadow's camera model)."""
    fs = cv2.FileStorage(str(CALIB), cv2.FILE_STORAGE_READ)
    K, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    fs.release()
    xy = cv2.undistortPoints(np.array([[pixel]], np.float64), K, dist).reshape(2)
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    c = -R.T @ np.asarray(tvec, np.float64).reshape(3)
    d = R.T @ np.array([xy[0], xy[1], 1.0])
    return c + d * (-c[2] / d[2])


def test_drag_save_and_render_reproduce_the_page(browser, server, tmp_path, tol):
    page = browser.new_page(viewport={"width": 1600, "height": 900})
    errors: list = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    requests: list = []
    page.on("request", lambda r: requests.append(r.url))
    page.goto(server.url)
    page.wait_for_function("() => window.previewIdle && window.previewIdle()", timeout=120_000)
    # drag: press at one pixel, move in steps, release over the target
    page.mouse.move(*_css_point(page, START_PX))
    page.mouse.down()
    x, y = _css_point(page, TARGET_PX)
    page.mouse.move(x - 40, y - 10, steps=4)
    page.mouse.move(x, y, steps=3)
    page.mouse.up()
    page.wait_for_timeout(200)
    page.wait_for_function("() => window.previewIdle()", timeout=120_000)
    # then the turn slider (drafts while it moves, exact when let go): the dragged place stays
    page.fill("#rz", "40")
    page.dispatch_event("#rz", "input")
    page.dispatch_event("#rz", "change")
    page.wait_for_timeout(200)
    page.wait_for_function("() => window.previewIdle()", timeout=120_000)
    shown = _shown_image(page)
    report = page.evaluate("() => JSON.parse(document.getElementById('report').textContent)")
    page.click("#save")
    page.wait_for_function("() => document.body.dataset.saved", timeout=60_000)
    saved_text = page.inner_text("#saved")
    shot = tmp_path / "preview.png"
    page.screenshot(path=str(shot))
    keep = os.environ.get("ARSHADOW_PREVIEW_SCREENSHOT")
    if keep:  # the README's picture, made by this browser
        img = cv2.imread(str(shot))
        small = cv2.resize(img, (img.shape[1] * 5 // 8, img.shape[0] * 5 // 8), interpolation=cv2.INTER_AREA)
        cv2.imwrite(keep, small, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    # the shadow-mask toggle: the mask of the same frame over the image
    page.check("#show_mask")
    page.wait_for_function("() => window.previewIdle() && !document.getElementById('mask').hidden", timeout=120_000)
    mask = _shown_image(page, "mask")
    page.close()
    assert not errors, errors
    assert all(u.startswith(f"http://127.0.0.1:{server.port}/") for u in requests), requests

    assert mask.shape == shown.shape[:2] and (mask > 0).sum() > 10000

    # the saved place is the ground point under the target pixel
    scene_path = Path(server.engine.scene_out)
    scene = yaml.safe_load(scene_path.read_text())
    want = _ground_under(TARGET_PX, report["report"]["rvec"], report["report"]["tvec"])
    err_mm = 1e3 * float(np.hypot(scene["place"][0] - want[0], scene["place"][1] - want[1]))
    assert err_mm <= tol.preview_place_mm, (scene["place"], want.tolist(), err_mm)
    assert scene["place"][2] == 0.0 and scene["rotate"] == [0.0, 0.0, 40.0]

    # arshadow render with the command line the page showed, and batch with the saved file: the page's pixels
    cmd = next(line for line in saved_text.splitlines() if line.startswith("arshadow render "))
    argv = shlex.split(cmd)
    argv[argv.index("-o") + 1] = str(tmp_path / "render")
    p = subprocess.run([sys.executable, "-m", "arshadow", *argv[1:]], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert np.array_equal(cv2.imread(str(tmp_path / "render" / "knot_point.png")), shown)
    # batch --config with the saved file (its paths relative to its own folder)
    p = subprocess.run(
        [sys.executable, "-m", "arshadow", "batch", str(PHOTO), "--config", str(scene_path), "-o", str(tmp_path / "b")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    assert np.array_equal(cv2.imread(str(tmp_path / "b" / "knot_point.png")), shown)
