"""Notebook friendliness (the compositing-layers work): results show themselves as images; a sheet of results."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from arshadow.frame.report import ReportItem
from arshadow.frame.session import FrameResult
from arshadow.notebook import results_sheet


def _result(k, shape=(90, 160)):
    rng = np.random.default_rng(k)
    img = rng.integers(0, 256, shape + (3,), dtype=np.uint8)
    item = ReportItem(input=f"shots/p{k}.jpg", mode="zpass", timings_ms={"total": 12.0})
    return FrameResult(img, None, None, np.eye(4), item)


def test_frame_result_and_sheet_show_as_png():
    r = _result(0)
    png = r._repr_png_()
    assert np.array_equal(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR), r.composite)
    sheet = results_sheet([r, _result(1)], captions=False, width=80)
    back = cv2.imdecode(np.frombuffer(sheet._repr_png_(), np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(back, sheet.image)


def test_sheet_layout_and_tiles():
    results = [_result(k) for k in range(5)]
    sheet = results_sheet(results, columns=2, width=80, captions=False).image
    # 80 x 45 tiles (the 16:9 aspect kept), 2 columns, 3 rows, 4 px gaps around and between
    assert sheet.shape == (3 * 45 + 4 * 4, 2 * 80 + 3 * 4, 3)
    tile = sheet[4 + 45 + 4 : 4 + 45 + 4 + 45, 4 + 80 + 4 : 4 + 80 + 4 + 80]  # row 1, column 1: result 3
    assert np.array_equal(tile, cv2.resize(results[3].composite, (80, 45), interpolation=cv2.INTER_AREA))
    captioned = results_sheet(results[:3], width=80).image
    assert captioned.shape == (45 + 30 + 8, 3 * 80 + 4 * 4, 3)  # one row of three, a 30 px caption bar
    with pytest.raises(ValueError):
        results_sheet([])
