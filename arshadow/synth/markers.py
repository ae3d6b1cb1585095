"""Synthetic photos of a printed marker or board with known truth.

The ground truth of every photo is the pose it is generated from (never a detector's output).

Scene: a textured floor fills the plane z = 0 (world frame = marker frame, CONVENTIONS.md); the marker or
board is printed on white paper (with a margin) lying on it. Rendering is exact per pixel:

1. For every output (distorted) pixel the pinhole pixel it sees comes from
   :meth:`Intrinsics.undistort_pixels` (exact inverse of the lens distortion; cached per camera).
2. The inverse plane homography ``(K [r1 r2 t])^-1`` takes that pinhole pixel to the floor point (x, y).
3. The floor is sampled from a periodic procedural texture; the paper is rendered only in its region of
   interest, supersampled S x S per pixel (box filter = a real sensor's pixel integration), from a
   pre-made, high-resolution texture of the print (cached per marker / board).

Then exposure, optical blur (Gaussian), sensor noise (Gaussian, 8-bit units), and JPEG compression.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import ArrayLike

from .._check import check_finite, check_shape
from ..camera.model import Intrinsics
from ..compose.composite import linear_to_srgb, srgb_to_linear
from ..errors import UsageError
from ..tracking.board import Board
from ..tracking.dictionary import get_dictionary, marker_bits, marker_object_points
from ..transforms import transform_points
from .poses import camera_path, look_at_pose, pan_path, random_pose

__all__ = [
    "SynthPhoto",
    "board_markers",
    "camera_effects",
    "camera_path",
    "look_at_pose",
    "pan_path",
    "random_pose",
    "render_marker_photo",
    "render_print_scene",
]

PAPER_WHITE = 235.0
INK_BLACK = 22.0
#: floor texture: texels per metre and size (periodic)
FLOOR_PPM = 1000.0
FLOOR_SIZE = 1024
#: paper texture resolution: texels per marker side (single marker); boards cap the long side
MARKER_TEXELS = 1024
BOARD_MAX_TEXELS = 4096


@dataclass
class SynthPhoto:
    """A synthetic photo and its truth.

    Attributes
    ----------
    image : (H, W, 3) uint8
        BGR photo.
    cam_from_world : (4, 4) float64
        The true pose (world -> OpenCV camera) it was rendered from.
    intrinsics : Intrinsics
        The camera (with its distortion) it was rendered with.
    corners_px : dict[int, (4, 2) float64]
        True (distorted) pixel positions of each marker's corners TL, TR, BR, BL.
    charuco_corners_px : (n, 2) float64 or None
        ChArUco boards: true pixel positions of the inner chessboard corners, OpenCV's id order.
    """

    image: np.ndarray
    cam_from_world: np.ndarray
    intrinsics: Intrinsics
    dictionary: str = "DICT_6X6_250"
    marker_id: int | None = None
    marker_length: float | None = None
    board: Board | None = None
    corners_px: dict = field(default_factory=dict)
    charuco_corners_px: np.ndarray | None = None
    paper_world: np.ndarray | None = None
    params: dict = field(default_factory=dict)

    @property
    def distance(self) -> float:
        """Distance from the camera centre to the world origin, metres."""
        return float(np.linalg.norm(self.cam_from_world[:3, 3]))


# ---------------------------------------------------------------------------------------------------
# textures (cached)
# ---------------------------------------------------------------------------------------------------
@lru_cache(maxsize=2)
def _floor_texture(seed: int = 7) -> np.ndarray:
    """(FLOOR_SIZE, FLOOR_SIZE, 3) float32 BGR periodic floor texture (procedural stone/wood-ish)."""
    rng = np.random.default_rng(seed)
    n = FLOOR_SIZE
    f = np.fft.fftfreq(n)
    fr = np.sqrt(f[:, None] ** 2 + f[None, :] ** 2)
    fr[0, 0] = 1.0
    out = np.empty((n, n, 3), np.float32)
    base = np.array([95.0, 125.0, 150.0])  # BGR: warm grey-brown
    spectrum = 1.0 / fr**1.3  # pink-ish noise: structure at every scale, no sharp edges
    spectrum[fr > 0.25] = 0.0
    common = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * spectrum))
    common = (common - common.mean()) / common.std()
    for c in range(3):
        own = np.real(np.fft.ifft2(np.fft.fft2(rng.normal(size=(n, n))) * spectrum))
        own = (own - own.mean()) / own.std()
        out[:, :, c] = base[c] + 28.0 * common + 6.0 * own
    np.clip(out, 0, 255, out=out)
    out.setflags(write=False)
    return out


def _layout_texture(markers: list, black_squares: np.ndarray, paper: tuple, ppm: float) -> tuple[np.ndarray, tuple]:
    """Rasterise a print (paper rectangle with black squares and markers), 2x2 supersampled.

    markers: list of ((x_left, y_top), side, bits (c, c) bool); black_squares (k, 2, 2); paper
    (xmin, ymin, xmax, ymax); ppm: texels per metre. Returns (h, w, 2) float32 premultiplied
    (value, alpha=1) and the world -> texel mapping (x0, y1, ppm).
    """
    xmin, ymin, xmax, ymax = paper
    w = int(math.ceil((xmax - xmin) * ppm))
    h = int(math.ceil((ymax - ymin) * ppm))
    ss = 2
    W, H = w * ss, h * ss
    xs = xmin + (np.arange(W) + 0.5) / (ppm * ss)
    ys = ymax - (np.arange(H) + 0.5) / (ppm * ss)
    img = np.full((H, W), PAPER_WHITE, np.float32)
    for (x0, x1), (y0, y1) in ((sq[:, 0], sq[:, 1]) for sq in black_squares):
        ci = slice(np.searchsorted(xs, x0), np.searchsorted(xs, x1))
        ri = slice(np.searchsorted(-ys, -y1), np.searchsorted(-ys, -y0))
        img[ri, ci] = INK_BLACK
    for (xl, yt), side, bits in markers:
        c = bits.shape[0]
        i0, i1 = np.searchsorted(xs, xl), np.searchsorted(xs, xl + side)
        j0, j1 = np.searchsorted(-ys, -yt), np.searchsorted(-ys, -(yt - side))
        col = np.clip(((xs[i0:i1] - xl) / side * c).astype(int), 0, c - 1)
        row = np.clip(((yt - ys[j0:j1]) / side * c).astype(int), 0, c - 1)
        img[j0:j1, i0:i1] = np.where(bits[row[:, None], col[None, :]], PAPER_WHITE, INK_BLACK)
    img = np.asarray(cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA), dtype=np.float32)
    tex = np.dstack([img, np.ones_like(img)]).astype(np.float32)
    # texel (i, j) centre is world (xmin + (i + 0.5)/ppm, ymax - (j + 0.5)/ppm)
    return tex, (xmin, ymax, ppm)


@lru_cache(maxsize=16)
def _marker_texture(dictionary: str, marker_id: int, margin_rel: float) -> tuple[np.ndarray, tuple]:
    """Texture of a single marker of side 1 (world units = marker lengths), centred on the origin."""
    bits = marker_bits(get_dictionary(dictionary), marker_id)
    h = 0.5 + margin_rel
    tex, mapping = _layout_texture(
        [((-0.5, 0.5), 1.0, bits)], np.zeros((0, 2, 2)), (-h, -h, h, h), float(MARKER_TEXELS)
    )
    tex.setflags(write=False)
    return tex, mapping


def board_markers(board: Board) -> list:
    """The board's markers as a print lays them out: ``[((x_left, y_top), side, bits)]``, the top-left corner
    in the board's world frame (metres), the side (metres) and the marker's cells ``bits (c, c) bool`` (True
    white, with the black border) from :func:`arshadow.tracking.dictionary.marker_bits`."""
    d = board.cv_dictionary
    return [
        ((c[0, 0], c[0, 1]), board.marker_length, marker_bits(d, mid)) for mid, c in board.marker_corners_world.items()
    ]


def board_print(board: Board, margin: float, ppm: float) -> tuple[np.ndarray, tuple, tuple]:
    """The printed board with a white ``margin`` (metres) at ``ppm`` texels per metre.

    Returns ``(tex, mapping, paper)``: ``tex`` (h, w, 2) float32 (value, alpha) from :func:`_layout_texture`
    (paper white = :data:`PAPER_WHITE`, ink = :data:`INK_BLACK`), ``mapping`` ``(x0, y1, ppm)`` and the
    paper rectangle ``(xmin, ymin, xmax, ymax)`` in the board's world frame.
    """
    paper = _board_paper(board, margin)
    tex, mapping = _layout_texture(board_markers(board), board.black_squares_world, paper, ppm)
    return tex, mapping, paper


def _board_paper(board: Board, margin: float) -> tuple:
    bw, bh = board.extent
    return (-margin, -bh - margin, bw + margin, margin)


@lru_cache(maxsize=8)
def _board_texture(board: Board, margin: float) -> tuple[np.ndarray, tuple, tuple]:
    paper = _board_paper(board, margin)
    ppm = min(BOARD_MAX_TEXELS / max(paper[2] - paper[0], paper[3] - paper[1]), MARKER_TEXELS / board.marker_length)
    tex, mapping, _ = board_print(board, margin, ppm)
    tex.setflags(write=False)
    return tex, mapping, paper


@lru_cache(maxsize=4)
def _pinhole_maps(intr: Intrinsics) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """Per-camera maps: the pinhole pixel that each output (distorted) pixel centre sees.

    Returns ``(mx, my)`` (H, W) float64 (exact, for the paper), ``pts32`` (H*W, 1, 2) float32 (for the
    floor) and ``(cx8, cy8)`` every 8th row / column (to find the paper's region quickly).
    """
    grid = intr.pixel_grid()
    pin = intr.undistort_pixels(grid) if intr.has_distortion else grid
    if not np.all(np.isfinite(pin)):
        raise UsageError("the camera's distortion cannot be inverted over the whole image")
    mx = pin[:, 0].reshape(intr.height, intr.width)
    my = pin[:, 1].reshape(intr.height, intr.width)
    pts32 = pin.astype(np.float32).reshape(-1, 1, 2)
    coarse = (np.ascontiguousarray(mx[::8, ::8]), np.ascontiguousarray(my[::8, ::8]))
    for a in (mx, my, pts32, *coarse):
        a.setflags(write=False)
    return mx, my, pts32, coarse


# ---------------------------------------------------------------------------------------------------
# rendering
# ---------------------------------------------------------------------------------------------------
def _plane_coords(hinv: np.ndarray, mx: np.ndarray, my: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World (x, y) on z = 0 seen at pinhole pixels (mx, my); valid where the plane is in front."""
    X = hinv[0, 0] * mx + hinv[0, 1] * my + hinv[0, 2]
    Y = hinv[1, 0] * mx + hinv[1, 1] * my + hinv[1, 2]
    Wh = hinv[2, 0] * mx + hinv[2, 1] * my + hinv[2, 2]
    valid = Wh > 1e-12
    Wh = np.where(valid, Wh, 1.0)
    return X / Wh, Y / Wh, valid


def render_print_scene(
    intrinsics: Intrinsics,
    cam_from_world: ArrayLike,
    *,
    dictionary: str = "DICT_6X6_250",
    marker_id: int = 0,
    marker_length: float | None = None,
    board: Board | None = None,
    floor: str | Callable[[np.ndarray, np.ndarray], np.ndarray] = "texture",
    paper_margin: float | None = None,
    supersample: int | None = None,
) -> dict:
    """The floor and the print seen from ``cam_from_world``, before any camera effect.

    The same scene as :func:`render_marker_photo` (parameters alike; ``floor`` may also be a function of the
    ground point, ``codes = floor(x, y)``, ``(H, W) float64`` metres in, grey 8-bit sRGB codes out, one
    sample per pixel), as reflectance: the returned
    ``"image"`` is (H, W, 3) float32 BGR in 8-bit sRGB code units (paper white = :data:`PAPER_WHITE`, ink =
    :data:`INK_BLACK`, the floor's texture), not clipped nor rounded. Also returned: ``"cam_from_world"``
    (4, 4), ``"corners_world"`` {id: (4, 3)}, ``"paper_world"`` (4, 3), ``"dictionary"`` and
    ``"supersample"`` (samples per pixel side used in the paper's region).
    """
    if not isinstance(intrinsics, Intrinsics):
        raise UsageError("intrinsics must be an arshadow.camera.Intrinsics")
    pose = check_finite(
        check_shape(np.asarray(cam_from_world, dtype=np.float64), "4,4", "cam_from_world"), "cam_from_world"
    ).copy()
    if (board is None) == (marker_length is None):
        raise UsageError("give exactly one of marker_length and board")
    W, H = intrinsics.width, intrinsics.height
    mx, my, pts32, (mx8, my8) = _pinhole_maps(intrinsics)
    K = intrinsics.K
    hw = K @ np.column_stack([pose[:3, 0], pose[:3, 1], pose[:3, 3]])
    hinv = np.linalg.inv(hw)

    # -- the print and its texture --
    if board is None:
        assert marker_length is not None  # exactly one of marker_length and board (checked above)
        L = float(marker_length)
        if not (L > 0 and math.isfinite(L)):
            raise UsageError(f"marker_length must be a positive length, got {marker_length}")
        margin = 0.3 * L if paper_margin is None else float(paper_margin)
        tex, (tx0, ty1, tppm) = _marker_texture(str(dictionary), int(marker_id), margin / L)
        tppm = tppm / L  # texture world unit = marker length
        tx0, ty1 = tx0 * L, ty1 * L
        h = L / 2 + margin
        paper = (-h, -h, h, h)
        corners_world = {int(marker_id): marker_object_points(L)}
        dict_name = str(dictionary)
    else:
        margin = 0.5 * max(board.marker_length, board.square_length) if paper_margin is None else float(paper_margin)
        tex, (tx0, ty1, tppm), paper = _board_texture(board, margin)
        corners_world = board.marker_corners_world
        dict_name = str(board.dictionary)
    paper_world = np.array(
        [[paper[0], paper[3], 0], [paper[2], paper[3], 0], [paper[2], paper[1], 0], [paper[0], paper[1], 0]],
        dtype=np.float64,
    )

    # -- floor over the whole image (float32 is plenty for the floor) --
    if not callable(floor) and floor not in ("texture", "plain"):
        raise UsageError(f"floor must be 'texture', 'plain' or a function of (x, y), got '{floor}'")
    wrow = hinv[2].astype(np.float32)
    wh = (pts32[:, 0, 0] * wrow[0] + pts32[:, 0, 1] * wrow[1] + wrow[2]).reshape(H, W)
    valid = wh > 1e-9
    if floor == "texture":
        ftex = _floor_texture()
        to_tex = np.array([[FLOOR_PPM, 0, 0], [0, -FLOOR_PPM, 0], [0, 0, 1.0]]) @ hinv
        ft = cv2.perspectiveTransform(pts32, to_tex).reshape(H, W, 2)
        # (BORDER_WRAP folds any coordinate into the periodic texture: no np.mod needed)
        # (OpenCV's stubs do not allow map2=None, which cv2.remap takes with a 2-channel map1)
        img = cv2.remap(ftex, ft, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)  # type: ignore[call-overload]
    elif callable(floor):  # grey codes from the ground point (x, y)
        xy = cv2.perspectiveTransform(pts32, hinv).reshape(H, W, 2).astype(np.float64)
        img = np.repeat(np.asarray(floor(xy[:, :, 0], xy[:, :, 1]), np.float32)[:, :, None], 3, axis=2)
    else:
        img = np.full((H, W, 3), 128.0, np.float32)
    img[~valid] = (200.0, 196.0, 190.0)  # wall / sky beyond the horizon

    # -- the paper, supersampled in its region of interest --
    cam_paper = transform_points(pose, paper_world)
    if np.all(cam_paper[:, 2] > 1e-6):
        pin = intrinsics.project(cam_paper, distort=False)
        # coarse search on every 8th pixel, then 9 px of slack (the map moves < 8 px per 8 px)
        lo, hi = pin.min(axis=0) - 2.0, pin.max(axis=0) + 2.0
        inside = (mx8 >= lo[0] - 9) & (mx8 <= hi[0] + 9) & (my8 >= lo[1] - 9) & (my8 <= hi[1] + 9)
        rows = np.flatnonzero(inside.any(axis=1))
        cols = np.flatnonzero(inside.any(axis=0))
        if rows.size == 0:
            roi = None
        else:
            r0, r1 = max(rows[0] * 8 - 8, 0), min(rows[-1] * 8 + 9, H)
            c0, c1 = max(cols[0] * 8 - 8, 0), min(cols[-1] * 8 + 9, W)
            sub_in = (
                (mx[r0:r1, c0:c1] >= lo[0])
                & (mx[r0:r1, c0:c1] <= hi[0])
                & (my[r0:r1, c0:c1] >= lo[1])
                & (my[r0:r1, c0:c1] <= hi[1])
            )
            rr, cc = np.flatnonzero(sub_in.any(axis=1)), np.flatnonzero(sub_in.any(axis=0))
            roi = None if rr.size == 0 else (r0 + rr[0], r0 + rr[-1] + 1, c0 + cc[0], c0 + cc[-1] + 1)
    else:
        roi = (0, H, 0, W)
    if roi is not None:
        r0, r1, c0, c1 = roi
        npx = (r1 - r0) * (c1 - c0)
        S = int(supersample) if supersample else int(np.clip(math.floor(math.sqrt(3.0e6 / max(npx, 1))), 2, 4))
        # sub-sample pinhole coordinates: bilinear in the exact per-pixel map (smooth; error << 1e-3 px)
        sub = []
        for m in (mx, my):
            block = np.pad(m[r0:r1, c0:c1], 1, mode="reflect", reflect_type="odd")
            up = cv2.resize(block, (block.shape[1] * S, block.shape[0] * S), interpolation=cv2.INTER_LINEAR)
            sub.append(up[S:-S, S:-S])
        sx, sy, svalid = _plane_coords(hinv, sub[0], sub[1])
        tu = ((sx - tx0) * tppm - 0.5).astype(np.float32)
        tv = ((ty1 - sy) * tppm - 0.5).astype(np.float32)
        tu[~svalid] = -10.0
        samp = cv2.remap(tex, tu, tv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        samp = cv2.resize(samp, (c1 - c0, r1 - r0), interpolation=cv2.INTER_AREA)
        val, alpha = samp[:, :, 0], samp[:, :, 1]
        paper_bgr = val[:, :, None] * np.array([1.0, 1.0, 1.0], np.float32)
        img[r0:r1, c0:c1] = paper_bgr + (1.0 - alpha[:, :, None]) * img[r0:r1, c0:c1]
    else:
        S = 0

    return {
        "image": img,
        "cam_from_world": pose,
        "corners_world": corners_world,
        "paper_world": paper_world,
        "dictionary": dict_name,
        "supersample": S,
    }


def camera_effects(
    img: np.ndarray,
    *,
    exposure: float = 1.0,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    seed: int | None = None,
    jpeg_quality: int | None = None,
    blur_linear: bool = False,
) -> np.ndarray:
    """Exposure, Gaussian blur, Gaussian noise (8-bit units), rounding and JPEG on a float32 image in 8-bit
    code units: (H, W, 3) float32 (modified in place) -> (H, W, 3) uint8. The blur acts on the code values,
    or with ``blur_linear`` on linear light (decoded, blurred, encoded: as optics blur, before the tone
    curve)."""
    if exposure != 1.0:
        img *= np.float32(exposure)
    if blur_sigma and blur_sigma > 0 and blur_linear:
        lin = cv2.GaussianBlur(
            srgb_to_linear(np.clip(img, 0, 255) / 255.0).astype(np.float32), (0, 0), float(blur_sigma)
        )
        img = (linear_to_srgb(lin) * 255.0).astype(np.float32)
    elif blur_sigma and blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), float(blur_sigma))
    if noise_sigma and noise_sigma > 0:
        # OpenCV's RNG is 3x faster than numpy's here; seeded per call, so photos are reproducible
        cv2.setRNGSeed(int(np.random.default_rng(seed).integers(2**31 - 1)))
        noise = np.empty((img.shape[0], img.shape[1] * img.shape[2]), np.float32)  # 1 channel: every
        # value gets noise (a scalar sigma on 3 channels would not); OpenCV's stubs lack scalar mean / sigma
        cv2.randn(noise, 0.0, float(noise_sigma))  # type: ignore[call-overload]
        img += noise.reshape(img.shape)
    img += np.float32(0.5)
    np.clip(img, 0, 255, out=img)
    out = img.astype(np.uint8)
    if jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        out = np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR), dtype=np.uint8)
    return out


def render_marker_photo(
    intrinsics: Intrinsics,
    cam_from_world: ArrayLike,
    *,
    dictionary: str = "DICT_6X6_250",
    marker_id: int = 0,
    marker_length: float | None = None,
    board: Board | None = None,
    noise_sigma: float = 0.0,
    blur_sigma: float = 0.0,
    jpeg_quality: int | None = None,
    exposure: float = 1.0,
    seed: int | None = None,
    floor: str | Callable[[np.ndarray, np.ndarray], np.ndarray] = "texture",
    paper_margin: float | None = None,
    supersample: int | None = None,
) -> SynthPhoto:
    """Render a photo of a printed marker (or board) lying on a floor, seen from ``cam_from_world``.

    Parameters
    ----------
    intrinsics : Intrinsics
        The camera, including its lens distortion (applied exactly).
    cam_from_world : (4, 4) float64
        True pose, world (marker / board frame) -> OpenCV camera.
    dictionary : str
        Dictionary name or file (single marker; a board brings its own).
    marker_id : int
        The marker's id (single marker).
    marker_length : float
        Marker side in metres (single marker). Give this *or* ``board``.
    board : Board, optional
        A grid or ChArUco board (its world frame: see :mod:`arshadow.tracking.board`).
    noise_sigma : float
        Gaussian sensor noise, standard deviation in 8-bit units.
    blur_sigma : float
        Gaussian optical blur, pixels.
    jpeg_quality : int, optional
        JPEG-compress the photo at this quality (1..100).
    exposure : float
        Brightness factor (1 = nominal; paper white = 235).
    seed : int, optional
        Seed of the noise.
    floor : str or callable
        ``"texture"`` (procedural, default), ``"plain"`` (uniform grey) or a function of the ground point,
        ``codes = floor(x, y)`` (metres in, grey 8-bit sRGB codes out: :func:`render_print_scene`).
    paper_margin : float, optional
        White paper around the print, metres (default 0.3 x marker length, boards 0.5 x the larger of
        square and marker length).
    supersample : int, optional
        Samples per pixel side in the paper's region (default: 4, fewer for very large prints).

    Returns
    -------
    SynthPhoto
    """
    if jpeg_quality is not None and not 1 <= int(jpeg_quality) <= 100:
        raise UsageError(f"jpeg_quality must be 1..100, got {jpeg_quality}")
    if not (exposure > 0 and math.isfinite(exposure)):
        raise UsageError(f"exposure must be positive, got {exposure}")
    scene = render_print_scene(
        intrinsics,
        cam_from_world,
        dictionary=dictionary,
        marker_id=marker_id,
        marker_length=marker_length,
        board=board,
        floor=floor,
        paper_margin=paper_margin,
        supersample=supersample,
    )
    pose, img, S = scene["cam_from_world"], scene["image"], scene["supersample"]
    corners_world, dict_name, paper_world = scene["corners_world"], scene["dictionary"], scene["paper_world"]
    out = camera_effects(
        img, exposure=exposure, blur_sigma=blur_sigma, noise_sigma=noise_sigma, seed=seed, jpeg_quality=jpeg_quality
    )

    corners_px = {mid: intrinsics.project(c, pose) for mid, c in corners_world.items()}
    ch = None
    if board is not None and board.kind == "charuco":
        ch = intrinsics.project(board.charuco_corners_world, pose)
    return SynthPhoto(
        image=out,
        cam_from_world=pose,
        intrinsics=intrinsics,
        dictionary=dict_name,
        marker_id=None if board is not None else int(marker_id),
        marker_length=None if marker_length is None else float(marker_length),
        board=board,
        corners_px=corners_px,
        charuco_corners_px=ch,
        paper_world=paper_world,
        params=dict(
            noise_sigma=noise_sigma,
            blur_sigma=blur_sigma,
            jpeg_quality=jpeg_quality,
            exposure=exposure,
            seed=seed,
            floor=floor,
            supersample=S,
        ),
    )
