"""Atomic outputs and image reading (arshadow/io.py)."""

import os
import stat

import cv2
import numpy as np
import pytest

from arshadow.errors import ImageError
from arshadow.io import atomic_path, read_image, write_image, write_json


def test_atomic_write_leaves_old_file_on_failure(tmp_path):
    target = tmp_path / "out.json"
    write_json(target, {"a": 1})
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert target.read_text().strip().startswith("{")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]  # no temporary left behind


def test_outputs_get_umask_mode(tmp_path):
    old = os.umask(0o022)
    try:
        p = write_image(tmp_path / "x.png", np.zeros((4, 4, 3), np.uint8))
    finally:
        os.umask(old)
    assert stat.S_IMODE(p.stat().st_mode) == 0o644


def test_json_refuses_nan(tmp_path):
    with pytest.raises(ValueError):
        write_json(tmp_path / "r.json", {"x": float("nan")})
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize(
    "img",
    [
        np.full((5, 6), 200, np.uint8),
        np.full((5, 6), 65535, np.uint16),
        np.dstack([np.full((5, 6), 10, np.uint8)] * 4),
    ],
    ids=["gray", "16bit", "bgra"],
)
def test_read_image_converts_to_bgr8(tmp_path, img):
    p = tmp_path / "in.png"
    cv2.imwrite(str(p), img)
    out = read_image(p)
    assert out.shape == (5, 6, 3) and out.dtype == np.uint8


def test_read_image_errors_name_the_file(tmp_path):
    with pytest.raises(ImageError, match="no such image"):
        read_image(tmp_path / "missing.png")
    bad = tmp_path / "corrupt.jpg"
    bad.write_bytes(b"\xff\xd8 not a jpeg")
    with pytest.raises(ImageError, match="corrupt.jpg"):
        read_image(bad)
