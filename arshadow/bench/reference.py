"""The path-traced reference cases: make them (Mitsuba), store them small, run arshadow on them, score.

A case is one :class:`arshadow.bench.reference_scene.ReferenceScene` and its renders, committed under
``tests/data/reference/<set>/``: ``<name>.jpg`` the plate as a user gives it (8-bit sRGB), ``<name>.npz`` the
truth's change of the plate (smoothed, camera-linear, int16 steps) and the masks, cropped to the part of the image the
insert changes, and ``cases.json`` the scenes (camera, light, object, seeds, spp), the noise floor and the
render times. Scoring those needs no Mitsuba (:func:`run_case`); making them does (:func:`make_case`,
``tests/reference/make_reference.py``).

Pipeline per case, as on the command line (docs/reference.md)::

    arshadow light PLATE --calib CAM.yml --marker-length L --probe box:.. --probe-place X,Y,0 [--kind point] -o light.json
    arshadow render PLATE --calib CAM.yml --marker-length L --model MODEL --place .. --color R,G,B \\
        --light-from light.json -o out/                       # "measured"
    arshadow render PLATE ... --light directional:X,Y,Z        # "true": the light given, default options
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from ..compose.composite import linear_to_srgb
from ..errors import ImageError
from ..io import write_bytes
from .reference_scene import PAPER_CODE, ReferenceScene, intrinsics_of, light_spec, pose_of

if TYPE_CHECKING:
    from ..estimate.record import LightEstimate
from .reference_score import change_map, change_threshold, decode8, residuals, residuals_smoothed, smooth_regions

__all__ = [
    "Case",
    "case_residuals",
    "load_cases",
    "make_case",
    "measure_light",
    "object_color",
    "plate_alignment",
    "run_arshadow",
    "run_case",
    "save_case",
    "to_plate8",
]

#: pixels of margin round the changed region in the stored crop
CROP_MARGIN_PX = 16
#: the committed plates' JPEG quality
JPEG_QUALITY = 95
#: the stored smoothed truth's quantisation step, camera-linear (its smoothed noise is ~0.002)
STORE_STEP = 1.0 / 8192


@dataclass
class Case:
    """A stored reference case.

    Attributes
    ----------
    scene : ReferenceScene
    plate8 : (H, W, 3) uint8
        The plate, BGR (as read from the committed JPEG).
    smoothed_truth : (h, w, 3) float64
        S(truth - plate) in the crop (:func:`arshadow.bench.reference_score.smooth_regions`, camera-linear
        RGB, stored in steps of :data:`STORE_STEP`, 0 beyond 8 px of where the truth changes).
    masks : dict of (h, w) bool
        ``ground``, ``object``, ``contact`` in the crop.
    crop : (4,) int
        ``(y0, y1, x0, x1)`` of the crop in the image.
    threshold : float
        The noise part of the changed-pixel threshold (:func:`arshadow.bench.reference_score.change_threshold`;
        :func:`arshadow.bench.reference_score.change_map` adds the plate's share).
    info : dict
        The case's JSON entry (noise floor, render seconds).
    plate_jpeg : bytes
        The plate's JPEG file (a case just made; what :func:`save_case` writes).
    """

    scene: ReferenceScene
    plate8: np.ndarray
    smoothed_truth: np.ndarray
    masks: dict
    crop: tuple
    threshold: float
    info: dict
    plate_jpeg: bytes = b""


def object_color(sc: ReferenceScene) -> str:
    """The object's ``--color``: its reflectance relative to the paper's (arshadow exposes the object like the
    marker's paper, taken as white), as 8-bit sRGB codes ``"R,G,B"``."""
    from ..compose.composite import SRGB_TO_LINEAR

    rel = np.clip(np.asarray(sc.color, np.float64) / float(SRGB_TO_LINEAR[PAPER_CODE]), 0.0, 1.0)
    return ",".join(str(int(round(255.0 * float(v)))) for v in linear_to_srgb(rel))


def to_plate8(linear: np.ndarray) -> np.ndarray:
    """Camera-linear RGB (H, W, 3) -> the 8-bit sRGB BGR photo (clipped, rounded)."""
    codes = linear_to_srgb(np.clip(linear, 0.0, 1.0)) * 255.0 + 0.5
    return np.clip(codes, 0, 255).astype(np.uint8)[:, :, ::-1].copy()


def run_arshadow(
    plate8: np.ndarray,
    sc: ReferenceScene,
    light: str = "measured",
    options: dict | None = None,
    pose: str = "tracked",
    est: Any = None,
) -> tuple[np.ndarray, Any]:
    """arshadow on the plate: ``(composite (H, W, 3) uint8 BGR, estimate or None)``.

    ``light``: ``"measured"`` (``arshadow light`` with the probe, then ``--light-from``) or ``"true"`` (the
    scene's light given with ``--light``, default options). ``options``: more scene keys (``aa``,
    ``soft_samples``, ``opacity``, ``shadow_color``, ``no_exposure``...). ``pose``: ``"tracked"`` (the marker
    tracked in the plate, as ``arshadow render`` does) or ``"true"`` (the scene's camera: no tracking error,
    the rendering model alone; the light estimate still tracks). ``est``: a light estimate of this plate
    already made (measured light; made here when None).
    """
    from ..frame.session import Session
    from ..scene.spec import scene_from_dict

    K = intrinsics_of(sc)
    d: dict[str, Any] = {
        "calib": K,
        "marker_length": sc.marker_length,
        "model": sc.model,
        "place": list(sc.place),
        "rotate": list(sc.rotate),
        "color": object_color(sc),
    }
    if light == "measured":
        est = measure_light(plate8, sc) if est is None else est
        d["light_from"] = est
    elif light == "true":
        d["lights"] = [light_spec(sc)]
        est = None
    else:
        raise ValueError(f"light must be 'measured' or 'true', got {light!r}")
    d.update(options or {})
    with Session(scene_from_dict(d)) as s:
        if pose == "true":
            res = s.render(plate8, pose_of(sc), want_mask=False)
        else:
            res = s.process(plate8, want_mask=False)
    return res.composite, est


def measure_light(plate8: np.ndarray, sc: ReferenceScene) -> LightEstimate:
    """``arshadow light`` on the plate with the scene's probe (``--kind point`` for a point light):
    :class:`arshadow.estimate.LightEstimate`."""
    from ..estimate import estimate_light

    kind = "point" if sc.light == "point" else "directional"
    return estimate_light(
        plate8,
        calib=intrinsics_of(sc),
        marker_length=sc.marker_length,
        probe=sc.probe,
        probe_place=sc.probe_place,
        kind=kind,
    )


def case_residuals(case: Case, composite8: np.ndarray) -> dict:
    """The residuals (:func:`arshadow.bench.reference_score.residuals`) of a composite of the case's plate."""
    y0, y1, x0, x1 = case.crop
    dc = decode8(composite8[y0:y1, x0:x1]) - decode8(case.plate8[y0:y1, x0:x1])
    thr = change_map(case.threshold, decode8(case.plate8[y0:y1, x0:x1]))
    return residuals_smoothed(smooth_regions(dc, case.masks), case.smoothed_truth, case.masks, thr)


def run_case(
    case: Case, light: str = "measured", options: dict | None = None, pose: str = "tracked", est: Any = None
) -> dict:
    """arshadow on the case's plate (:func:`run_arshadow`), scored: the residuals plus ``light_error_deg``
    (directional) or ``light_error_pct`` (point, of the distance) of the estimate when measured."""
    comp, est = run_arshadow(case.plate8, case.scene, light, options, pose, est)
    out = case_residuals(case, comp)
    if est is not None:
        out.update(light_error(case.scene, est))
    return out


def light_error(sc: ReferenceScene, est: Any) -> dict:
    """How far the estimate's light is from the scene's."""
    v = np.asarray(sc.light_vec, np.float64)
    if sc.light == "point":
        p = np.asarray(est.position, np.float64)
        return {"light_error_pct": float(100.0 * np.linalg.norm(p - v) / np.linalg.norm(v))}
    d = np.asarray(est.direction, np.float64)
    c = float(np.dot(d, v) / (np.linalg.norm(d) * np.linalg.norm(v)))
    return {"light_error_deg": math.degrees(math.acos(min(1.0, max(-1.0, c))))}


# ---------------------------------------------------------------------------------------------------
# making and storing (make_case needs Mitsuba)
# ---------------------------------------------------------------------------------------------------
def make_case(sc: ReferenceScene) -> tuple[Case, dict]:
    """Render a scene (plate, truth, second truth, masks) with Mitsuba: ``(case, full)`` where ``full`` has
    the full-frame camera-linear renders (``plate``, ``truth``, ``truth2``) and ``seconds``."""
    from .reference_scene import render_scene, scene_masks

    r = render_scene(sc)
    masks = scene_masks(sc)
    plate8 = to_plate8(r["plate"])
    ok, buf = cv2.imencode(".jpg", plate8, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    assert decoded is not None  # decoding what imencode just wrote
    plate8 = decoded
    truth, truth2, plate = (np.clip(r[k], 0.0, 1.0) for k in ("truth", "truth2", "plate"))
    thr = change_threshold(truth2 - truth, masks)
    thr_map = change_map(thr, decode8(plate8))
    full = residuals(truth2 - plate, truth - plate, masks, thr_map, comp_changes=False)  # the noise floor
    st = smooth_regions(truth - plate, masks)
    changed = np.abs(st).sum(axis=2) > thr_map
    changed |= masks["object"] | masks["contact"]
    keep = cv2.dilate(changed.astype(np.uint8), np.ones((17, 17), np.uint8)) > 0
    st[~keep] = 0.0
    st = np.rint(st / STORE_STEP) * STORE_STEP
    ys, xs = np.nonzero(keep)
    H, W = plate.shape[:2]
    crop = (
        max(int(ys.min()) - CROP_MARGIN_PX, 0),
        min(int(ys.max()) + CROP_MARGIN_PX + 1, H),
        max(int(xs.min()) - CROP_MARGIN_PX, 0),
        min(int(xs.max()) + CROP_MARGIN_PX + 1, W),
    )
    y0, y1, x0, x1 = crop
    cm = {k: v[y0:y1, x0:x1].copy() for k, v in masks.items()}
    info = {
        "scene": sc.to_json(),
        "crop": list(crop),
        "threshold": thr,
        "noise_floor": {k: full[k] for k in ("ground", "contact", "object")},
        "render_seconds": r["seconds"],
    }
    case = Case(sc, plate8, st[y0:y1, x0:x1], cm, crop, thr, info, buf.tobytes())
    noise_crop = residuals_smoothed(
        smooth_regions((truth2 - plate)[y0:y1, x0:x1], cm),
        case.smoothed_truth,
        cm,
        thr_map[y0:y1, x0:x1],
        comp_changes=False,
    )
    info["noise_floor_crop"] = {k: noise_crop[k] for k in ("ground", "contact", "object")}
    return case, {"plate": r["plate"], "truth": r["truth"], "truth2": r["truth2"], "seconds": r["seconds"]}


def save_case(folder: str | os.PathLike[str], case: Case) -> None:
    """Write ``<name>.jpg`` and ``<name>.npz`` (atomically) and the case's entry of ``cases.json``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    name = case.scene.name
    write_bytes(folder / f"{name}.jpg", case.plate_jpeg)
    tmp = folder / f".{name}.tmp.npz"
    arrays: dict[str, np.ndarray] = {
        "smoothed_truth": np.rint(case.smoothed_truth / STORE_STEP).astype(np.int16),
        **{f"mask_{k}": np.packbits(v) for k, v in case.masks.items()},
        "shape": np.array(case.smoothed_truth.shape[:2]),
    }
    np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]  # numpy's stub reads ** as its bool options
    os.replace(tmp, folder / f"{name}.npz")
    index = folder / "cases.json"
    cases = json.loads(index.read_text()) if index.exists() else {}
    cases[name] = case.info
    tmpj = folder / ".cases.json.tmp"
    tmpj.write_text(json.dumps(cases, indent=1, sort_keys=True) + "\n")
    os.replace(tmpj, index)


def load_cases(folder: str | os.PathLike[str]) -> list[Case]:
    """The committed cases of a folder (``cases.json`` order: by name)."""
    folder = Path(folder)
    cases = json.loads((folder / "cases.json").read_text())
    out = []
    for name in sorted(cases):
        info = cases[name]
        z = np.load(folder / f"{name}.npz")
        h, w = (int(v) for v in z["shape"])
        masks = {
            k: np.unpackbits(z[f"mask_{k}"])[: h * w].reshape(h, w).astype(bool)
            for k in ("ground", "object", "contact")
        }
        plate8 = cv2.imread(str(folder / f"{name}.jpg"), cv2.IMREAD_COLOR)
        if plate8 is None:  # a case half-committed: name it here, not as a None plate deep in the scoring
            raise ImageError(f"{folder / f'{name}.jpg'}: the plate of reference case {name!r} is missing or unreadable")
        out.append(
            Case(
                ReferenceScene.from_json(info["scene"]),
                plate8,
                z["smoothed_truth"].astype(np.float64) * STORE_STEP,
                masks,
                tuple(info["crop"]),
                float(info["threshold"]),
                info,
            )
        )
    return out


# ---------------------------------------------------------------------------------------------------
# the camera check: does the path tracer's camera image the world where arshadow's pinhole does?
# ---------------------------------------------------------------------------------------------------
def print_linear(sc: ReferenceScene, box: tuple[int, int, int, int], sub: int = 16) -> np.ndarray:
    """arshadow's exact render of the scene's print (:func:`arshadow.synth.render_print_scene`), green, in
    linear light over the pixel box ``(r0, r1, c0, c1)``: each pixel the mean of its ``sub x sub`` sub-pixels,
    each decoded from sRGB first (a sensor integrates light; averaging code values and then decoding, as the
    renderer's own supersampling does, darkens the pixels an edge crosses: it biased the camera check's
    scale by -0.25 % on the committed plates)."""
    from ..camera import Intrinsics
    from ..compose.composite import srgb_to_linear
    from ..synth.markers import render_print_scene

    K, (r0, r1, c0, c1) = intrinsics_of(sc), box
    # the box at sub x the resolution: pixel (c, r)'s centre is sub-pixel ((c - c0 + 0.5) sub - 0.5, ...)
    fine = Intrinsics(
        K.fx * sub,
        K.fy * sub,
        (K.cx - c0 + 0.5) * sub - 0.5,
        (K.cy - r0 + 0.5) * sub - 0.5,
        (c1 - c0) * sub,
        (r1 - r0) * sub,
    )
    code = render_print_scene(fine, pose_of(sc), marker_length=sc.marker_length, supersample=1)["image"][:, :, 1]
    lin = srgb_to_linear(np.clip(code, 0.0, 255.0) / 255.0)
    out: np.ndarray = lin.reshape(r1 - r0, sub, c1 - c0, sub).mean(axis=(1, 3))
    return out


def plate_alignment(plate8: np.ndarray, sc: ReferenceScene) -> tuple[float, float, float]:
    """How the plate's printed paper sits against arshadow's own exact rendering of the print at the scene's
    camera, area-averaged in linear light (:func:`print_linear`): ``(dx, dy, scale)``, the shift in pixels
    and the relative scale about the principal point (Lucas-Kanade over the paper eroded by 2 px, with a
    brightness gain and gradient: the paper's lighting need not be uniform).

    Independent of the marker detector, whose own corner bias on an exact render is a few tenths of a pixel
    (``Tolerances.synth_corner_px``): a camera mismatch of a tenth of a pixel or 0.1 % of focal length shows.
    (Before 2026-11-28 the reference was averaged in code values, which biased the scale by -0.25 %.)
    """
    from ..synth.markers import render_print_scene

    K, pose = intrinsics_of(sc), pose_of(sc)
    paper = render_print_scene(K, pose, marker_length=sc.marker_length, supersample=1)["paper_world"]
    img = decode8(plate8)[:, :, 1]
    uv = K.project(paper, pose)
    mask = np.zeros(img.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(uv * 16).astype(np.int32), 1, shift=4)
    m = cv2.erode(mask, np.ones((5, 5), np.uint8)) > 0
    ys, xs = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
    r0, r1 = max(ys[0] - 2, 0), min(ys[-1] + 3, img.shape[0])
    c0, c1 = max(xs[0] - 2, 0), min(xs[-1] + 3, img.shape[1])
    ref = print_linear(sc, (r0, r1, c0, c1))
    img, m = img[r0:r1, c0:c1], m[r0:r1, c0:c1]
    gy, gx = np.gradient(ref)
    vv, uu = np.mgrid[r0:r1, c0:c1]
    X, Y = uu - K.cx, vv - K.cy
    # img ~ (a + bx X + by Y) ref(x - d - (s - 1) x): linear in (a, bx, by, a dx, a dy, a (s - 1)), ignoring b d
    cols = [ref, ref * X, ref * Y, -gx, -gy, -(gx * X + gy * Y)]
    A = np.column_stack([c[m] for c in cols])
    sol = np.linalg.lstsq(A, img[m], rcond=None)[0]
    a = sol[0]
    return float(sol[3] / a), float(sol[4] / a), float(sol[5] / a)
