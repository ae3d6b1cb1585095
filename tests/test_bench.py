"""`arshadow bench --quick` end to end: the outputs exist and are well-formed (one run, quick settings).

Checks structure and internal consistency only (speed figures are benchmarks, not tests): every CSV
parses with its expected columns, times are positive with q25 <= median <= q75, errors are in range, the
reference detectors agree with the fast ones, the summary answers every section and embeds the plots.
"""

from __future__ import annotations

import csv
import json

import pytest

pytestmark = pytest.mark.gl


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


#: the sections the default suite's quick bench runs: the realism section (the path-traced reference's
#: scoring, 30-80 s of the run's 70-200 s) has its own default test (test_reference.py::test_realism_bench_rows);
#: the whole quick bench is the `slow` test below
DEFAULT_SECTIONS = ("silhouettes", "render", "tracking", "pipeline")


def test_bench_quick(tmp_path, gl_ctx):
    _bench_quick(tmp_path, DEFAULT_SECTIONS)


@pytest.mark.slow
def test_bench_quick_every_section(tmp_path, gl_ctx):
    from arshadow.bench import SECTIONS

    out = _bench_quick(tmp_path, SECTIONS)
    assert (out / "realism.csv").is_file() and "realism" in (out / "summary.md").read_text().lower()


def _bench_quick(tmp_path, sections):
    from arshadow.bench import QUICK
    from arshadow.bench.plots import available
    from arshadow.cli import main

    out = tmp_path / "bench"
    assert main(["bench", "--quick", "--sections", ",".join(sections), "-o", str(out)]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["meta"]["settings"] == "quick" and res["meta"]["GL_RENDERER"]
    assert set(res["meta"]["section_seconds"]) == set(sections)

    det = _rows(out / "silhouette_detectors.csv")
    assert {int(r["faces"]) for r in det} == {12, *QUICK["sizes"]}
    assert {r["method"] for r in det} == {"adjacency", "triangular", "vnv", "hsd", "delta_plus"}
    for r in det:
        assert 0 < float(r["time_q25"]) <= float(r["time_ms"]) <= float(r["time_q75"])
        if r["method"] != "delta_plus":  # exact detectors
            assert float(r["missed_edges_frac"]) == 0 and float(r["extra_edges_frac"]) == 0
    ref = _rows(out / "silhouette_reference.csv")
    assert ref and all(r["same_edges"] == "True" for r in ref)
    assert len(_rows(out / "silhouette_paper_formulas.csv")) == 11

    rnd = _rows(out / "render.csv")
    fams = {r["family"] for r in rnd}
    assert {"stencil", "planar", "stencil AA", "stencil scaled", "shadow map"} <= fams
    for r in rnd:
        assert 0 < float(r["time_ms"]) and 0.0 <= float(r["iou"]) <= 1.0 and int(r["xor_px"]) >= 0
    assert any(r["config"].startswith("shadow map 8192") for r in rnd)
    for r in rnd:
        assert float(r["area_ratio"]) >= 0.0
    # the thin card (the benchmarks' brief: pyrender loses its shadow-map shadow at >= 4096 texels): stencil and shadow-map
    # rows against its exact shadow, the map's texel recorded, the summary's verdict present
    card = [r for r in rnd if r["scene"].startswith("thin card")]
    assert {r["family"] for r in card} == {"stencil", "planar", "shadow map", "shadow map, bias off"}
    assert not any(r["family"] == "shadow map, bias off" for r in rnd if not r["scene"].startswith("thin card"))
    assert any(r["config"].startswith("shadow map 8192") for r in card)
    assert all(float(r["map_texel_um"]) > 0 for r in card if r["family"] == "shadow map")

    trk = _rows(out / "tracking.csv")
    assert any("ROI" in r["config"] for r in trk) and any("board" in r["config"] for r in trk)
    assert any("fast_detect off" in r["config"] for r in trk)
    assert all(int(r["detected"]) > 0 for r in trk)

    st = _rows(out / "pipeline_stages.csv")
    assert {r["resolution"] for r in st} == {"640x480", "1280x720", "1920x1080"}
    assert {int(r["lights"]) for r in _rows(out / "pipeline_lights.csv")} == set(QUICK["light_counts"])
    assert len(_rows(out / "pipeline_paper003.csv")) == 3

    md = (out / "summary.md").read_text()
    for heading in (
        "## 1. Silhouette detectors",
        "## 2. Render quality vs time",
        "## 3. Tracking vs time",
        "## 4. Pipeline",
        "74.35",
        "61 438",
        "**Thin card**",
        "Verdict:",
        "llvmpipe" if "llvmpipe" in res["meta"]["GL_RENDERER"] else "GL",
    ):
        assert heading in md
    if available():
        pngs = sorted(p.name for p in out.glob("*.png"))
        assert len(pngs) >= 6
        for p in pngs:
            assert (out / p).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            assert f"]({p})" in md  # embedded in the summary
    else:
        assert "pip install arshadow[bench]" in md
    return out
