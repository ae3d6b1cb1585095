"""Shared fixtures and the one table of tolerances every test uses.

Tolerances are thresholds from the issues' acceptance criteria; a test that fails is fixed in the code or
the test data, never by loosening a number here.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

#: scripts that regenerate test data (they need pvlib/pandas), not tests: not imported by --doctest-modules
collect_ignore = ["data"]

#: the fixtures that give a test an OpenGL context
GL_FIXTURES = {"ctx", "gl_ctx"}
#: test modules whose tests render through Session / render_photo / the CLI (they create their own context)
GL_MODULES: set[str] = set()
#: test modules that encode or decode video files (besides every module with "video" in its name)
VIDEO_MODULES: set[str] = set()


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Mark GL and video tests (``pytest -m "not gl and not video"`` is the fast unit loop, CONTRIBUTING.md):
    ``gl`` for a test that uses :func:`ctx` / :func:`gl_ctx` or lives in :data:`GL_MODULES`, ``video`` for one
    in a module named ``*video*`` or listed in :data:`VIDEO_MODULES`. An unmarked test that creates an OpenGL
    context fails (:func:`_gl_guard`).

    ``slow`` tests are deselected unless the ``-m`` expression names ``slow`` (so that ``-m "not gl"`` does
    not bring them back, as an ``-m`` given on the command line replaces the one in ``addopts`` would)."""
    if "slow" not in (config.getoption("markexpr") or ""):
        slow = [it for it in items if it.get_closest_marker("slow") is not None]
        if slow:
            config.hook.pytest_deselected(items=slow)
            items[:] = [it for it in items if it.get_closest_marker("slow") is None]
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1] if getattr(item, "module", None) else ""
        if GL_FIXTURES & set(getattr(item, "fixturenames", ())) or module in GL_MODULES:
            item.add_marker(pytest.mark.gl)
        if "video" in module or module in VIDEO_MODULES:
            item.add_marker(pytest.mark.video)


@pytest.fixture(autouse=True)
def _gl_guard(request, monkeypatch):
    """A test not marked ``gl`` must not create an OpenGL context (it would slow the fast loop down and run
    where no GL is): creating one fails the test, naming the marker to add."""
    if request.node.get_closest_marker("gl") is not None:
        yield
        return
    import moderngl

    def refuse(*args, **kwargs):
        pytest.fail(
            f"{request.node.nodeid} creates an OpenGL context but is not marked gl: use the ctx fixture, "
            "@pytest.mark.gl, or add its module to GL_MODULES in tests/conftest.py",
            pytrace=False,
        )

    monkeypatch.setattr(moderngl, "create_context", refuse)
    yield


@dataclass(frozen=True)
class Tolerances:
    # tracking (the tracking acceptance tests)
    corner_px: float = 1.0  # OpenCV's own test tolerance on realdata corners
    calib_focal_rel: float = 0.005  # fx, fy within 0.5 %
    calib_center_px: float = 2.0  # cx, cy within 2 px
    calib_rms_px: float = 0.45
    synth_rot_median_deg: float = 0.25
    synth_trans_median_rel: float = 0.005
    synth_rot_p95_deg: float = 1.5
    synth_rot_flag_deg: float = 5.0
    charuco_rot_median_deg: float = 0.1
    unrefined_corner_px: float = 2.5  # no corner refinement vs OpenCV's expected (integer contour) corners
    synth_calib_rms_px: float = 0.3  # calibration from 10 synthetic ChArUco views (noise 1, blur 0.5)
    synth_calib_focal_rel: float = 0.01
    synth_calib_center_px: float = 5.0
    cli_pose_rot_deg: float = 1.0  # `arshadow pose` on one synthetic photo vs its generating pose
    cli_pose_trans_m: float = 0.005
    opencv_board_rot_deg: float = 0.5  # reported OpenCV board pose vs OpenCV's own ChArUco solvePnP
    opencv_board_trans_rel: float = 0.005
    exposure_ratio_abs: float = 0.02  # mean brightness ratio of a half-exposure synthetic photo vs 0.5
    undistort_px: float = 1e-6  # exact inverse of the distortion (round trip)
    project_vs_opencv_px: float = 1e-7  # Intrinsics.project against cv2.projectPoints
    gl_projection_px: float = 1e-8  # GL clip matrix -> pixel centre against project(distort=False)
    synth_corner_px: float = 0.35  # generator's true corners vs OpenCV's sub-pixel detection (no noise)
    # ECC corners (refine="ecc") vs the generating pose's projected corners, worst corner of 12 photos (blur 0.8
    # in code values or 1.0 in linear light, noise 2, JPEG 90, 52-94 px markers): measured 0.088 / 0.174 px
    # (the edge corners: 0.105 / 0.97 px before 2026-11-28, biased inwards by the blur in linear light;
    # 0.105 / 0.33 px since); a half-pixel error fails
    ecc_corner_px: float = 0.2
    ecc_corner_centroid_px: float = 0.1  # their mean offset per photo (measured <= 0.053): half a pixel fails
    # the same behind a strong lens (k1 -0.3, 50-57 px markers near the top edge): 0.051 px measured; the
    # alignment made in distorted pixels (the lens ignored) errs 0.24-0.33 px there
    ecc_distorted_corner_px: float = 0.1
    # edge corners (refine="edge") on photos whose pixel area and blur act in linear light (tests/test_edge_refine.py:
    # 26-50 px markers, blur 0 / 0.8 px, noise 1, JPEG 90, with and without a strong lens): worst corner measured
    # 0.17 px, the marker's scale (mean radial offset) within 0.065 px; the code-value crossings alone put the
    # corners 0.21-0.82 px inwards (scale) there, 0.26-1.08 px worst
    edge_linear_corner_px: float = 0.2
    edge_linear_scale_px: float = 0.1
    synth_charuco_corner_px: float = 0.25  # same for ChArUco chessboard corners
    synth_detect_rate: float = 0.95  # markers found among the 200 acceptance photos
    board_vs_marker_rot_ratio: float = 0.5  # board median rotation error < this x single marker's
    calib_extrinsic_rot_deg: float = 0.1  # per-view board pose vs OpenCV's reference calibration
    calib_extrinsic_mm: float = 0.5
    # geometry (the geometry core)
    footprint_iou: float = 0.9999
    # faces whose facing may flip between a light at 1e6 m and the same direction at infinity: |cos| of the
    # angle between face normal and light below mesh size / 1e6 (~1e-7), bounded here with margin
    grazing_far_light_cos: float = 1e-6
    # faces whose facing may flip when the mesh is scaled by 1e-3/1e3 or moved 1 km: rounding-level grazing
    grazing_rescaled_cos: float = 1e-9
    # compositor (the compositor)
    shadow_iou_median: float = 0.99
    shadow_iou_worst: float = 0.97
    shadow_boundary_px: float = 0.25
    shadow_min_pixels: int = 2000
    end_to_end_iou_median: float = 0.95
    coverage_mismatch_frac: float = 2e-4  # occluder alpha / ground-visible masks vs the oracle, per pixel
    phong_shadow_atol: float = 2e-3  # linear colour of a self-shadowed face vs ambient only
    phong_lit_atol: float = 5e-3  # linear colour of a lit face vs ambient + diffuse
    roi_vs_full_px: int = 10  # mismatched pixels between a sub-canvas render and the full render
    # shadow-map baseline (the benchmarks' brief) at 4096 texels, PCF 3x3: measured IoU 0.99984 (box, point light) and
    # 0.99983 (wall, low sun, camera in its shadow) on llvmpipe; the stencil path is exact (IoU 1)
    shadowmap_iou_4096: float = 0.999
    aa_error_ratio: float = 0.6  # anti-aliased mask's coverage error must be below this share of no-AA's
    lens_map_px: float = 2e-3  # cached undistortion map round trip (float32 map storage)
    remap_step_px: float = 1 / 32  # cv2.remap's sub-pixel coordinate quantisation
    lens_roi_slack_px: int = 40  # distorted ROI may exceed the content's box by two 8-px tiles and slack
    lens_warp_disk_iou: float = 0.995  # warped pinhole disk vs the analytically distorted disk
    gpu_compose_levels: int = 1  # shader compose vs numpy compose, per channel / mask value (the planner)
    # window search vs full-frame search of the same photo: corner refinement sees a cropped image (measured
    # 2e-7 in the pose matrix entries)
    tracking_window_pose_atol: float = 1e-5
    plan_mask_iou: float = 0.999  # planner's auto plan vs the general (reference) plan (the planner)
    fast_detector_distance_rel: float = 0.01  # fast detection pass: camera position error / distance
    fallback_detector_distance_rel: float = 0.02  # full-search fallback: distance error / distance
    # lights (the lights work)
    sun_median_deg: float = 0.01
    sun_max_deg: float = 0.05
    penumbra_rel: float = 0.15
    sun_paper_median_deg: tuple = (0.15, 0.25)  # paper-004 model (corrected): measured 0.20-0.21 deg
    sun_paper_max_deg: tuple = (0.8, 1.2)  # measured 1.05-1.07 deg
    area_light_segment: float = 0.025  # stratified 256-sample disc vs exact segment area (iid: sd 0.031)
    penumbra_profile_64: float = 0.1  # rendered profile vs exact disc profile, 64 samples (measured 0.04)
    penumbra_1090_rel: float = 0.05  # 10-90 % penumbra width of the sampled disc vs exact (256 samples)
    penumbra_centre_rel: float = 0.02  # 50 % crossing of a sampled sun cone vs the centre direction's shadow
    # stress suite (the stress suite)
    stress_stack_iou: float = 0.99  # stacked plates (10..300 layers) vs the oracle at 200x150
    stress_f32_pixels: int = 3  # boundary pixels that may flip between float32-exact and float64 vertices
    stress_far_iou: float = 0.99  # box 1 km away, infinite far plane, vs the oracle
    stress_geometry_iou: float = 0.99  # random configurations: rendered ground mask vs exact union
    # a sub-pixel shadow sliver: a mismatched pixel centre off the raster band must lie this close to the
    # exact edge (rounding; the one case found: 0.0001 px)
    stress_sliver_edge_px: float = 0.01
    stress_track_rot_deg: float = 2.0  # tracking stress: a confident (unflagged) pose must be this close
    contact_seam_mean: float = 0.03  # mean signed error (share of the photo's light) over contact pixels
    # video chunks (the long-video work): a chunk's exposure smoothing (a one-pole filter, 0.82 per frame) starts from
    # its 50-frame primer, not from the whole history: 5e-5 of the first difference is left (measured 1.4e-6)
    chunk_exposure_gain_rel: float = 1e-5
    # browser preview (the preview work): the dragged object's saved place vs the ground point under the target pixel
    # (back-projected in the test with OpenCV's undistortPoints); the bound
    preview_place_mm: float = 1.0
    # its draft frames (an equivalent camera and lights, arshadow/preview/draft.py) vs the exact render of the
    # same drag or turn: shadow-mask pixels that differ (rounding at edges; measured 0-6) and, under a
    # directional light, composite levels (measured 0 for a drag, 2 for a turn)
    preview_draft_mask_px: int = 10
    preview_draft_levels: int = 2
    # shading (the realism work): corner normals, sky visibility, materials, camera effects
    normal_flat_deg: float = 1e-6  # a flat face's corner normals vs its face normal (exact up to rounding)
    normal_sphere_deg: float = 0.5  # icosphere (1280 faces) corner normals vs the radial direction (0.30 measured)
    sky_ground_abs: float = 0.015  # ground sky visibility (256 directions, 256^2 texels) vs Lambert (0.010 measured)
    falloff_rel: float = (
        0.01  # a point light's shaded term vs albedo cos |L|^2 / d^2 (float32 shading, per-vertex normals)
    )
    ratio_falloff_abs: float = 0.004  # mask scaled by a point light's fall-off vs the closed form (RG16F target)
    ratio_falloff_rel: float = 0.012  # composite's shadow share vs the lamp's and sky's physics (8-bit output)
    mean_albedo_rel: float = 0.01  # a textured mesh's sampled mean colour vs its texture's mean (0.6 % measured)
    object_shade_rel: float = 0.012  # measured light, box face vs the physics (8-bit: ~0.5 %/level)
    sky_raster_mean: float = 0.004  # GL vs numpy ground map, mean |difference| (tori: 0.0009, 0.0022 measured)
    sky_raster_p99: float = 0.03  # GL vs numpy ground map, 99th percentile |difference| (0.012, 0.027 measured)
    sky_object_abs: float = 2e-3  # convex object, 4096 directions vs the tilted-plane horizon closed form
    sky_object_rays_abs: float = 0.01  # ray-cast self-occlusion (1024 directions) vs Lambert's form factor
    sky_object_raster_mean: float = (
        0.02  # item-buffer self-occlusion (64 dirs) vs BVH rays (256), torus (0.009 measured)
    )
    psf_sigma_px: float = 0.15  # marker-edge blur vs the synthetic photo's linear-light Gaussian (0..3 px)
    noise_sigma_rel: float = 0.1  # measured noise sigma vs the added one (with quantisation), relative
    # the compose paths' sensor noise vs the measured table, per 16-level bin of ~5000 samples (standard error
    # of the sigma 1 %): sigma (with the rounding's 1/12 level^2) within 5 % (numpy's add_noise measured
    # <= 3.0 %, the shader <= 2.5 %), the mean within 4 standard errors of the bin's (sd / sqrt(n)), and the
    # correlation of neighbouring pixels and of two channels (standard error 0.003) within 0.02
    noise_table_sigma_rel: float = 0.05
    noise_table_mean_se: float = 4.0
    noise_corr_abs: float = 0.02
    sky_projection_abs: float = 0.02  # rendered sky-occlusion channel vs the map sampled at the pixel's ground point
    texture_median_abs: float = 0.01  # rendered textured quad vs cv2.warpPerspective of its texture (linear)
    texture_p99_abs: float = 0.05
    # the render seam (the layout work): a colour written into the RGBA16F colour attachment (11-bit mantissa)
    half_float_rel: float = 2.0**-10
    # path-traced reference (the realism work, tests/test_reference.py, docs/reference.md). Camera: the Mitsuba
    # plate's paper against arshadow's exact render of the print averaged in linear light (measured on the
    # plates re-rendered 2026-11-28: shift <= 0.022 px own, <= 0.037 px held-out; scale -0.0006..-0.0000;
    # the plates before, over W - 1: +0.0025..+0.0033).
    # Detected corners (a detector's view, biased by the image's lighting and noise): on the plate against
    # those detected on the exact render at the same camera, measured <= 0.51 px per corner (point light:
    # a brightness gradient over the paper), centroid <= 0.16 px; the plate's centroid against the
    # projected corners <= 0.14 px.
    ref_camera_shift_px: float = 0.15
    ref_camera_scale: float = 0.0015  # relative, about the principal point (see above; a 0.25 % error is seen)
    ref_corner_px: float = 0.6
    ref_corner_centroid_px: float = 0.2
    # Baseline of today's renderer (2026-11-26, median over each set's six scenes; arshadow light on the
    # plate, render --light-from with the tracked pose): own ground 0.402, contact 0.446, object 0.130; with
    # the true light given (default options) ground 0.361. Limits = those + 0.01 (rounding up). The issue's
    # targets (on the held-out set) are ground <= 0.10, contact <= 0.12, object <= 0.05: tighten these when
    # the realism work lands, never loosen them.
    # Re-measured 2026-11-26 after the ground's light reflected by the object and the estimate's allowance
    # for the probe's sky occlusion (tests/benchmarks/score_realism.py, config "sky"). Over the own set's six
    # scenes (the two point-light plates were refused for a while by a non-positive-definite Laplace
    # covariance, +/- inf degrees, fixed in estimate/light.py; over the four sun scenes alone: 0.252 / 0.275
    # / 0.118): own ground 0.252, contact 0.310, object 0.128; limits + 0.01. ref_own_true_ground (true
    # light, no sky occlusion) is unchanged.
    # Re-measured 2026-11-26 after the corner refinement's default became ``edge`` (the tracked pose's error
    # shrank; docs/tracking.md): own ground 0.221, contact 0.248, object 0.107, true light 0.348; held-out
    # 0.204 / 0.217 / 0.142. Limits + 0.01. Then the point lamps' fall-off on the object and the shadow ratio
    # at the object (docs/reference.md): held-out object 0.142 -> 0.134, the rest unchanged.
    # Re-measured 2026-11-26 after the ground bounce's units (times the paper's albedo) and the object's own
    # sky visibility on by default, with the sky's and the light's colours on it: own 0.214 / 0.237 / 0.065,
    # held-out 0.199 / 0.202 / 0.096; limits + 0.01. Then colour bleeding (a coloured object's reflected light
    # per colour channel): held-out 0.191 / 0.174 / 0.096, own unchanged. Then the ground's light on the
    # object's faces weighted by the irradiance of the ground each face sees: own 0.185 / 0.235 / 0.065,
    # held-out 0.191 / 0.175 / 0.096 (the held-out limits stay: never loosened).
    # Re-measured 2026-11-28 on this session's machine (its llvmpipe gives own 0.183 / 0.231 / 0.065, held-out
    # 0.192 / 0.177 / 0.096 for the same code), then a measured point lamp's shadow ratio across the floor:
    # held-out ground 0.183, the rest unchanged. Limits + 0.01 where that is tighter. Then the photos'
    # corner refinement ``ecc`` (docs/tracking.md): own 0.174 / 0.198 / 0.053, true light 0.342; held-out
    # 0.154 / 0.176 / 0.082.
    # Re-rendered 2026-11-28 with the scenes' own camera (mitsuba_fov over W, not W - 1; docs/reference.md):
    # own 0.177 / 0.186 / 0.053, true light 0.350; held-out 0.148 / 0.166 / 0.075 (five cases,
    # ho_box_rotated_tiles refused by the probe-outline check). Limits + 0.01 where that is tighter.
    # Re-measured 2026-11-29 after the object's faces see the ground's light as the photo shows it (the
    # marker's paper beside the object) in the map's units, and a point lamp's light per face at its own
    # distance (docs/reference.md): own 0.176 / 0.191 / 0.053; held-out 0.147 / 0.121 / 0.075. Limits +
    # 0.01 where that is tighter (held-out ground and contact).
    # Re-measured 2026-11-29 after the object's outline got its pixels' coverage without MSAA (the planner's
    # outline_aa, on with --aa 0; docs/compositing.md): own 0.152 / 0.178 / 0.051, true light 0.330;
    # held-out 0.142 / 0.101 / 0.071. Limits + 0.01.
    # Re-measured 2026-11-29 after the object's light on itself (a torus's inside; docs/reference.md, "the
    # object's residual"): own object 0.047, held-out unchanged (0.142 / 0.101 / 0.071); then the ground's
    # light as each face sees it (arshadow.shading.objground): own 0.153 / 0.180 / 0.053, held-out 0.142 /
    # 0.100 / 0.068. Limits + 0.01 where that is tighter (held-out object).
    # Re-measured 2026-11-29 (later) after the light estimate's shadow edges (docs/light.md, "the shadow's edges"):
    # own 0.149 / 0.172 / 0.048; held-out 0.128 / 0.111 (0.1110) / 0.050. Limits + 0.01 where that is tighter
    # (the held-out contact limit stays: never loosened).
    # Re-measured 2026-11-29 (fifth session) after the shadow ratio carries the lit floor's change across the
    # probe shadow's edge, per side (arshadow.estimate.ratio._lit_change): own 0.144 / 0.170 / 0.041; held-out
    # 0.111 / 0.107 / 0.037, five cases 0.101 / 0.087 / 0.040. Limits + 0.01 where that is tighter.
    # Re-measured 2026-11-29 (sixth session) after the marker's paper class ends at the sheet's edge (a neutral
    # floor is not paper: arshadow.estimate.paper.paper_cells) and the shadow ratio allows for the light the
    # probe reflects (arshadow.estimate.ratio.probe_ground): own 0.146 / 0.167 / 0.041; held-out 0.0997 / 0.1091 /
    # 0.037, five cases 0.098 / 0.090 / 0.040. Limits + 0.01 where that is tighter.
    ref_own_ground: float = 0.154
    ref_own_contact: float = 0.177
    ref_own_object: float = 0.051
    ref_own_true_ground: float = 0.340
    # Re-measured 2026-11-29 (third session) after the probe check skipped the probe's own creases
    # (arshadow.estimate.outline): ho_box_rotated_tiles is no longer refused (its outline agreement 0.39 ->
    # 0.56), so the held-out medians are over six cases: 0.128 / 0.1295 / 0.043, limits + 0.01 (a set one
    # case larger: its first limits). The five-case limits above stay, over the same five cases (heldout5).
    # Re-measured 2026-11-29 (fourth session) after the sky map's taper kept the object's reflected light
    # (arshadow.shading.sky.ACTIVE_OCCLUSION): own 0.148 / 0.172 / 0.048; held-out 0.122 / 0.1295 / 0.043,
    # five cases 0.123 / 0.111 / 0.050. Limits + 0.01 where that is tighter (the held-out grounds). Then the
    # fifth session's lit floor's change (the own limits' note above): all six limits + 0.01.
    ref_heldout_ground: float = 0.110
    ref_heldout_contact: float = 0.117
    ref_heldout_object: float = 0.047
    ref_heldout5_ground: float = 0.108
    ref_heldout5_contact: float = 0.097
    ref_heldout5_object: float = 0.050
    # a material as reflective as the paper, under the measured light, against the paper's measured colour
    # (8-bit codes; the 8-bit encode and the top face's samples)
    paper_match_codes: float = 2.0
    # the light estimate's probe check on the own path-traced plates at their own camera (test_reference.py):
    # 0.93-0.99 in place (0.73-0.86 before its own creases were skipped), 0.20-0.32 given 4 cm off along -y
    # the shadow ratio's texture check (arshadow.estimate.ratio.texture_uncertainty) covers the ratio's real error
    # within this many of its sigmas (measured 2026-11-29 on the twelve path-traced plates: at most 2.25 for the
    # pairs as they read, 2.10 with the lit floor's change carried across the edge, the default)
    ratio_texture_cover: float = 2.5
    # the light estimate on the plain-floor path-traced plates (test_reference.py; measured 2026-11-29: suns
    # 0.10 / 0.16 deg, lamps 0.3 / 2.0 %; the ratio +0.007 / +0.009 (suns), +0.042 / +0.046 (lamps) of the
    # scene's own sky share; the probe's and the floor's reflectances within 0.03 of the truth)
    plain_sun_deg: float = 0.5
    plain_lamp_rel: float = 0.04
    plain_ratio_sun: float = 0.03
    plain_ratio_lamp: float = 0.06
    plain_albedo: float = 0.04
    # the probe's reflectance off its top face on arshadow.synth.lit photos (test_light_ratio.py), relative
    # (measured 2026-11-29: 0.2-0.9 % off at reflectances 0.3, 0.5 and 1.2)
    probe_albedo_rel: float = 0.03
    outline_in_place: float = 0.9
    outline_away: float = 0.4
    # the object's outline anti-aliased without MSAA (arshadow.compose.outline; tests/test_outline_aa.py)
    outline_exact: float = 1e-6  # a pixel one straight edge crosses: its coverage against the clipped square's area
    outline_area_px2: float = 1.0  # the AA'd alpha's sum against the silhouette polygon's area (a box: 0.4 measured)
    outline_edge_mean: float = 0.01  # mean |coverage error| over the outline's pixels (0.0025 measured; aa 0: 0.24)
    # marker maps (the marker-map work): learned marker poses against the generating poses (the figures)
    map_marker_median_mm: float = 1.0
    map_marker_median_deg: float = 0.2
    map_vs_single_rot_ratio: float = 0.5  # camera rotation error with the map <= half the single marker's
    map_real_rigid_mm: float = 1.0  # real sheet: inter-marker distances of maps from disjoint halves agree
    map_layout_median_mm: float = 0.5  # chessboard clip: centre distances vs the printed layout (0.23)
    map_layout_max_mm: float = 1.5  # (measured 0.81)
    # light estimate, never confidently wrong (the trust fixes items 2-4)
    light_confident_deg: float = 3.0  # a confident light must be this close (the bar)
    # the estimate's shadow model (test_shadow_model.py): a blurred edge's coverage against erfc (float32),
    # a polygon's summed coverage against its area (the blur's corners round it off by ~sigma^2 per corner)
    shadow_model_coverage: float = 1e-5
    shadow_model_area: float = 2e-3
    light_hidden_deg: float = 1.0  # a partly hidden shadow's direction (the median bar, one case)
    light_point_distance_rel: float = 0.05  # a point light's position error / distance: the median bar
    # the probe's face shading at the generating light: log residual (measured 0.0006..0.005 on 5 cases)
    light_face_shading_true: float = 0.05
    # motion blur (camera effects in a video, tests/test_motion_blur.py): the frame's image motion against the
    # box corners projected by hand / by cv2.projectPoints (float64 both; the video's poses round-trip through
    # the JSON record's rvec / tvec); the box kernel's second moments against a segment's L^2 / 12 (the
    # bilinear splat adds u (1 - u) per axis, 1/6 px^2 on average, at most 1/4); an edge's 10-90 % rise
    # against 0.8 L; the blurred layers against the static ones blurred by an independent kernel (float32)
    motion_project_px: float = 1e-9
    motion_record_px: float = 1e-3
    motion_moment_px2: float = 0.25
    motion_ramp_px: float = 0.1
    motion_layer_abs: float = 1e-5


TOL = Tolerances()


@pytest.fixture(scope="session")
def tol() -> Tolerances:
    return TOL


@pytest.fixture
def rng():
    """A seeded generator: every random test is reproducible."""
    return np.random.default_rng(20261121)


@pytest.fixture(scope="session")
def realdata() -> Path:
    """``../shared/realdata`` (or ``$ARSHADOW_REALDATA``); skips, saying why, when it is absent."""
    p = Path(os.environ.get("ARSHADOW_REALDATA", ROOT.parent / "shared" / "realdata"))
    if not (p / "expected.json").is_file():
        pytest.skip(f"real photos not found at {p} (set ARSHADOW_REALDATA)")
    return p


@pytest.fixture(scope="session")
def gl_ctx():
    """One moderngl context for the session; skips only when no GL context can be created at all."""
    from arshadow.errors import GLContextError
    from arshadow.gl.context import create_context

    try:
        ctx = create_context()
    except GLContextError as exc:
        pytest.skip(f"no OpenGL context can be created here: {exc}")
    yield ctx
    ctx.release()


@pytest.fixture
def ctx(gl_ctx):
    """Per-test view of the session context: GL must be error-free before and after the test."""
    assert gl_ctx.error == "GL_NO_ERROR", f"GL error before test: {gl_ctx.error}"
    yield gl_ctx
    err = gl_ctx.error
    assert err == "GL_NO_ERROR", f"GL error left by test: {err}"
