"""The README's first command: ``arshadow demo`` renders every bundled sample and a contact sheet."""

import json

import cv2
import pytest

from arshadow.cli import main

pytestmark = pytest.mark.gl


def test_demo_renders_every_sample(gl_ctx, tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    items = report["images"]
    assert len(items) >= 5
    assert all(i["status"] == "ok" for i in items), [(i["input"], i["error"]) for i in items]
    for i in items:
        photo = cv2.imread(i["output"])
        mask = cv2.imread(i["mask"], cv2.IMREAD_UNCHANGED)
        assert photo is not None and mask is not None and mask.shape == photo.shape[:2]
        assert (mask > 0).sum() > 2000, f"{i['input']}: no shadow in the mask"
    assert cv2.imread(str(out / "contact_sheet.png")) is not None
    assert not [p for p in out.iterdir() if ".tmp" in p.name]  # nothing half-written left behind


def test_demo_relative_output_outside_the_samples(gl_ctx, tmp_path, monkeypatch, capsys):
    """The README's ``arshadow demo -o demo_out`` from any working directory: the measured-look item reads its
    estimate back from the relative output folder (it was resolved against the samples' folder: exit 1)."""
    monkeypatch.chdir(tmp_path)
    assert main(["demo", "--quiet", "-o", "demo_out"]) == 0, capsys.readouterr().err
    assert (tmp_path / "demo_out" / "probe_shadow.light.json").is_file()
    assert (tmp_path / "demo_out" / "probe_shadow.png").is_file()
