"""Learn a rigid map of loose markers from the frames that see them (the marker-map work).

The method (after MarkerMapper, Muñoz-Salinas et al., Pattern Recognition 2018):

1. each detected marker's pose in each frame (IPPE, both solutions kept);
2. for every pair of markers seen in one frame, the pair's transform; per pair, a robust average (the
   candidate that most others agree with, then the mean of those that agree);
3. a spanning tree of the pose graph from the reference marker through the most reliable pairs (the pairs
   seen together in the most agreeing frames: Prim's algorithm on those counts) places every marker;
4. each frame's camera from its markers (the candidate that reprojects all of them best); observations
   that disagree with it (a false id, a flipped pose) are dropped;
5. bundle adjustment of all marker and camera poses on the corners (:mod:`arshadow.tracking.bundle`), then
   observations that still disagree are dropped and the fit repeated once.

Rejected, with the reason in :attr:`MarkerMap.rejected`: a marker seen in one frame only, a marker not
connected to the reference by pairs seen together in two frames or more, an id seen twice in one frame,
an observation far from the map, and (reported) a pair whose average disagrees with the graph.

Frames: the map's frame is the reference marker's (the lowest id kept, or the one asked for): the same
world frame as a single-marker run with that marker, so ``--place`` keeps its meaning.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from ..camera.model import Intrinsics
from ..errors import MarkerNotFoundError, UsageError
from ..transforms import invert_rigid, matrix_from_rvec_tvec, rvec_tvec_from_matrix
from .board import Board
from .bundle import bundle_adjust
from .dictionary import marker_object_points

__all__ = ["MarkerMap", "Observations", "learn_map", "marker_lengths_for", "reprojection_px"]

#: a pair's candidates agree within this rotation (degrees) and translation (fraction of the distance)
PAIR_AGREE_DEG = 3.0
PAIR_AGREE_REL = 0.05
#: a pair average farther than this from the graph (deg / fraction of the distance) is reported
GRAPH_DISAGREE_DEG = 5.0
GRAPH_DISAGREE_REL = 0.1
#: an observation with a corner RMS above this (pixels) after the camera's initial pose is dropped
INIT_OUTLIER_PX = 10.0
#: after the bundle adjustment: dropped above max(this, 5 x the median RMS)
FINAL_OUTLIER_PX = 3.0
#: the bundle adjustment uses at most this many frames (the others only count as "frames seen")
MAX_BA_FRAMES = 150


@dataclass
class Observations:
    """The detections of all frames, one row per (frame, marker).

    Attributes
    ----------
    frame : (n,) int
        Frame index (0-based, in the order given).
    ids : (n,) int
        Marker id.
    corners : (n, 4, 2) float64
        Detected corners TL, TR, BR, BL, pixels of the (distorted) image.
    n_frames : int
        Frames looked at (with or without a marker).
    image_size : (width, height) or None
        The frames' size (None: the calibration's).
    """

    frame: np.ndarray
    ids: np.ndarray
    corners: np.ndarray
    n_frames: int
    image_size: tuple | None = None

    @classmethod
    def from_detections(cls, detections: Iterable[Any], image_size: tuple | None = None) -> Observations:
        """From a sequence of :class:`~arshadow.tracking.detect.Detection` (or ``(ids, corners)``), one per frame."""
        fr, ids, cs = [], [], []
        n = 0
        for k, d in enumerate(detections):
            n = k + 1
            i, c = (d.ids, d.corners) if hasattr(d, "ids") else d
            i = np.asarray(i, int).ravel()
            fr.append(np.full(i.size, k, int))
            ids.append(i)
            cs.append(np.asarray(c, np.float64).reshape(-1, 4, 2))
        if not fr:
            return cls(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 4, 2)), 0, image_size)
        return cls(np.concatenate(fr), np.concatenate(ids), np.concatenate(cs), n, image_size)


@dataclass
class MarkerMap:
    """A learned map: each kept marker's corners in the reference marker's frame, and the fit's residuals.

    Attributes
    ----------
    reference_id : int
    dictionary : str
    corners : dict
        id -> (4, 3) float64 corners TL, TR, BR, BL in the map frame (metres).
    ref_from_marker : dict
        id -> (4, 4) float64 marker pose in the map frame.
    rms_px : dict
        id -> RMS corner reprojection error of the marker's kept observations after the fit (pixels).
    frames_seen : dict
        id -> frames in which the marker was detected (all frames, not only the fitted ones).
    frames_used : int
        Frames in the bundle adjustment.
    n_frames : int
        Frames looked at.
    rms_total_px : float
        RMS over all kept observations.
    rejected : list of str
        What was rejected and why.
    cam_from_ref : dict
        Fitted frame index -> (4, 4) camera pose in the map frame.
    """

    reference_id: int
    dictionary: str
    corners: dict
    ref_from_marker: dict
    rms_px: dict
    frames_seen: dict
    frames_used: int
    n_frames: int
    rms_total_px: float
    rejected: list = field(default_factory=list)
    cam_from_ref: dict = field(default_factory=dict)

    def board(self, source: str = "") -> Board:
        """The map as a generic board (``type: markers``): what ``--board`` reads."""
        return Board(
            kind="markers",
            size=(len(self.corners), 1),
            marker_length=1.0,
            dictionary=self.dictionary,
            markers={int(i): np.asarray(c, np.float64) for i, c in sorted(self.corners.items())},
            source=source,
        )

    def summary(self) -> str:
        """One line: markers, reference, frames, residual."""
        return (
            f"map of {len(self.corners)} markers (reference {self.reference_id}) from {self.frames_used} of "
            f"{self.n_frames} frames; corner RMS {self.rms_total_px:.2f} px"
        )


def marker_lengths_for(spec: dict | float, ids: Iterable[int]) -> dict:
    """id -> marker side (metres) from ``spec``: a number (all ids), or a dict id -> length with an optional
    ``None`` key for the others.

    >>> marker_lengths_for({None: 0.05, 3: 0.1}, [1, 3])
    {1: 0.05, 3: 0.1}

    Raises
    ------
    UsageError
        An id without a length.
    """
    if not isinstance(spec, dict):
        spec = {None: float(spec)}
    out: dict[int, float] = {}
    for i in ids:
        v = spec.get(int(i), spec.get(None))
        if v is None:
            raise UsageError(f"no marker length for id {int(i)} (give --marker-length L or {int(i)}=L)")
        out[int(i)] = float(v)
    return out


def _single_poses(obs_norm: np.ndarray, lengths: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Both IPPE solutions of each observation: (n, 2, 4, 4) float64 ``cam_from_marker`` (NaN where IPPE
    gave no solution) and (n, 2) errors (normalised units; inf where no solution)."""
    n = len(obs_norm)
    T = np.full((n, 2, 4, 4), np.nan)
    err = np.full((n, 2), np.inf)
    for k in range(n):
        obj = marker_object_points(lengths[k])
        try:
            _, rs, ts, es = cv2.solvePnPGeneric(
                obj, obs_norm[k].reshape(4, 1, 2), np.eye(3), None, flags=cv2.SOLVEPNP_IPPE_SQUARE
            )
        except cv2.error:
            continue
        for j in range(min(2, len(rs))):
            T[k, j] = matrix_from_rvec_tvec(rs[j], ts[j])
            err[k, j] = float(np.ravel(es)[j]) if es is not None else 0.0
    return T, err


def _rot_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angles (degrees) between rotation stacks ``Ra (..., 3, 3)`` and ``Rb (..., 3, 3)``."""
    c = (np.einsum("...ij,...ij->...", Ra, Rb) - 1.0) / 2.0
    out: np.ndarray = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
    return out


def _robust_average(Ts: np.ndarray) -> tuple[np.ndarray, int]:
    """The robust mean of rigid transforms ``Ts (k, 4, 4)``: the candidate most others agree with, then the
    mean of those that agree (rotation projected back onto SO(3)). Returns ((4, 4), agreeing count)."""
    if len(Ts) > 200:
        Ts = Ts[np.linspace(0, len(Ts) - 1, 200).round().astype(int)]
    R, t = Ts[:, :3, :3], Ts[:, :3, 3]
    dr = _rot_deg(R[:, None], R[None, :])
    scale = np.maximum(np.linalg.norm(t, axis=1), 1e-3)
    dt = np.linalg.norm(t[:, None] - t[None, :], axis=2) / scale[:, None]
    agree = (dr < PAIR_AGREE_DEG) & (dt < PAIR_AGREE_REL)
    best = int(np.argmax(agree.sum(axis=1)))
    inl = agree[best]
    u, _, vt = np.linalg.svd(R[inl].mean(axis=0))
    out = np.eye(4)
    out[:3, :3] = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    out[:3, 3] = t[inl].mean(axis=0)
    return out, int(inl.sum())


def _pair_edges(frame: np.ndarray, ids: np.ndarray, T: np.ndarray) -> dict[tuple[int, int], tuple[np.ndarray, int]]:
    """Per co-visible pair (a < b): the robust ``a_from_b`` and how many frames agree with it."""
    cands: dict = {}
    order = np.argsort(frame, kind="stable")
    bounds = np.flatnonzero(np.diff(frame[order])) + 1
    for grp in np.split(order, bounds):
        if len(grp) < 2:
            continue
        for x in range(len(grp)):
            for y in range(len(grp)):
                a, b = grp[x], grp[y]
                if ids[a] < ids[b] and np.isfinite(T[a, 0, 0]) and np.isfinite(T[b, 0, 0]):
                    cands.setdefault((int(ids[a]), int(ids[b])), []).append(invert_rigid(T[a]) @ T[b])
    return {k: _robust_average(np.asarray(v)) for k, v in cands.items()}


def _spanning_tree(edges: dict[tuple[int, int], tuple[np.ndarray, int]], ref: int) -> dict[int, np.ndarray]:
    """Prim's maximum spanning tree on the agreeing counts (>= 2) from ``ref``: id -> ``ref_from_id``."""
    adj: dict = {}
    for (a, b), (T, w) in edges.items():
        if w >= 2:
            adj.setdefault(a, []).append((b, T, w))
            adj.setdefault(b, []).append((a, invert_rigid(T), w))
    placed = {ref: np.eye(4)}
    while True:
        best = None
        for a in placed:
            for b, T, w in adj.get(a, []):
                if b not in placed and (best is None or w > best[0]):
                    best = (w, a, b, T)
        if best is None:
            return placed
        _, a, b, T = best
        placed[b] = placed[a] @ T


def _graph_disagreements(edges: dict[tuple[int, int], tuple[np.ndarray, int]], placed: dict[int, np.ndarray]) -> list:
    """Pairs (both placed) whose average is far from the tree's: descriptions for :attr:`MarkerMap.rejected`."""
    out = []
    for (a, b), (T, _w) in sorted(edges.items()):
        if a in placed and b in placed:
            G = invert_rigid(placed[a]) @ placed[b]
            ang = float(_rot_deg(G[:3, :3], T[:3, :3]))
            d = float(np.linalg.norm(G[:3, 3] - T[:3, 3]) / max(float(np.linalg.norm(G[:3, 3])), 1e-3))
            if ang > GRAPH_DISAGREE_DEG or d > GRAPH_DISAGREE_REL:
                out.append(f"pair {a}-{b} disagrees with the graph ({ang:.1f} deg, {100 * d:.0f} % of the distance)")
    return out


def _init_cameras(
    frame: np.ndarray,
    midx: np.ndarray,
    T: np.ndarray,
    marker_T: np.ndarray,
    local: np.ndarray,
    obs_norm: np.ndarray,
    focal: np.ndarray,
) -> tuple[dict[int, np.ndarray], np.ndarray]:
    """Each frame's ``cam_from_ref``: of every observation's two IPPE solutions composed with its marker's
    map pose, the one that reprojects the frame's markers best. Returns ({frame: (4, 4)}, (n,) RMS px)."""
    rms = np.full(len(frame), np.inf)
    cams = {}
    for f in np.unique(frame):
        rows = np.flatnonzero(frame == f)
        pts = np.einsum("mij,mkj->mki", marker_T[midx[rows], :3, :3], local[midx[rows]])
        pts = pts + marker_T[midx[rows], None, :3, 3]  # (r, 4, 3) map corners
        best = None
        for r in rows:
            for j in range(2):
                if not np.isfinite(T[r, j, 0, 0]):
                    continue
                C = T[r, j] @ invert_rigid(marker_T[midx[r]])
                p = np.einsum("ij,mkj->mki", C[:3, :3], pts) + C[:3, 3]
                if np.any(p[..., 2] <= 1e-6):
                    continue
                e = np.sqrt(np.mean((((p[..., :2] / p[..., 2:]) - obs_norm[rows]) * focal) ** 2, axis=(1, 2)))
                score = float(np.median(e))
                if best is None or score < best[0]:
                    best = (score, C, e)
        if best is not None:
            cams[int(f)] = best[1]
            rms[rows] = best[2]
    return cams, rms


def _select_frames(frame: np.ndarray, midx: np.ndarray, max_frames: int) -> set[int]:
    """Frames for the bundle adjustment: those with >= 2 markers, evenly thinned to ``max_frames``, then
    frames added back for a marker left in fewer than 3."""
    fs, counts = np.unique(frame, return_counts=True)
    multi = fs[counts >= 2]
    if len(multi) <= max_frames:
        return set(int(f) for f in multi)
    keep = set(int(f) for f in multi[np.linspace(0, len(multi) - 1, max_frames).round().astype(int)])
    for m in np.unique(midx):
        have = [f for f in np.unique(frame[midx == m]) if int(f) in keep]
        if len(have) < 3:
            extra = [int(f) for f in np.unique(frame[midx == m]) if int(f) in set(multi.tolist())]
            keep.update(extra[:: max(1, len(extra) // 3)][:3])
    return keep


def learn_map(
    obs: Observations,
    intrinsics: Intrinsics,
    marker_length: dict | float,
    *,
    dictionary: str = "DICT_6X6_250",
    reference_id: int | None = None,
    max_ba_frames: int = MAX_BA_FRAMES,
) -> MarkerMap:
    """Learn the rigid map of the markers in ``obs`` (module docstring: the method).

    Parameters
    ----------
    obs : Observations
        Detections in images of the size of ``intrinsics`` (or the same aspect ratio: scaled).
    intrinsics : Intrinsics
    marker_length : float or dict
        Marker side in metres, one for all or per id (:func:`marker_lengths_for`): the map's scale.
    dictionary : str
        Written into the map (its markers' dictionary).
    reference_id : int, optional
        The map's frame; default the lowest id kept.

    Raises
    ------
    MarkerNotFoundError
        No marker seen in two frames; the asked reference marker not kept.
    """
    rejected: list = []
    frame, ids, corners = obs.frame, obs.ids, obs.corners
    # an id twice in one frame: a false id (or a second print): neither detection is trusted
    key = frame.astype(np.int64) * 1_000_000 + ids
    uk, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    dup = cnt[inv] > 1
    for k in uk[cnt > 1]:
        rejected.append(f"marker {int(k % 1_000_000)} seen twice in frame {int(k // 1_000_000)}")
    frames_seen = {int(i): int(np.unique(frame[(ids == i) & ~dup]).size) for i in np.unique(ids)}
    once = {i for i, c in frames_seen.items() if c < 2}
    rejected += [f"marker {i} seen in one frame only" for i in sorted(once)]
    keep = ~dup & ~np.isin(ids, list(once))
    frame, ids, corners = frame[keep], ids[keep], corners[keep]
    if len(ids) == 0:
        raise MarkerNotFoundError("no marker seen in two frames or more: nothing to map")
    w, h = obs.image_size or (intrinsics.width, intrinsics.height)
    intr = intrinsics.for_image(w, h)[0]
    lengths_of = marker_lengths_for(marker_length, np.unique(ids))
    pin = intr.undistort_pixels(corners.reshape(-1, 2)).reshape(-1, 4, 2)
    focal = np.array([intr.fx, intr.fy])
    obs_norm = (pin - [intr.cx, intr.cy]) / focal
    good = np.all(np.isfinite(obs_norm), axis=(1, 2))
    frame, ids, corners, obs_norm = frame[good], ids[good], corners[good], obs_norm[good]
    T, _ = _single_poses(obs_norm, [lengths_of[int(i)] for i in ids])

    edges = _pair_edges(frame, ids, T[:, 0])
    kept_ids = sorted(set(ids.tolist()))
    ref = kept_ids[0] if reference_id is None else int(reference_id)
    if ref not in kept_ids:
        raise MarkerNotFoundError(
            f"reference marker {ref} not seen in two frames (seen: {', '.join(map(str, kept_ids))})"
        )
    placed = _spanning_tree(edges, ref)
    if len(placed) < len(kept_ids) and reference_id is None:
        # the lowest id may sit on a small island: start from the marker that connects the most
        best = max(kept_ids, key=lambda i: (len(_spanning_tree(edges, i)), -i))
        comp = _spanning_tree(edges, best)
        ref = min(comp)
        placed = _spanning_tree(edges, ref)
    for i in kept_ids:
        if i not in placed:
            rejected.append(f"marker {i} not connected to the map (seen with its markers in fewer than 2 frames)")
    rejected += _graph_disagreements(edges, placed)
    order = sorted(placed)
    index = {i: k for k, i in enumerate(order)}
    sel = np.isin(ids, order)
    frame, ids, obs_norm, T = frame[sel], ids[sel], obs_norm[sel], T[sel]
    midx = np.array([index[int(i)] for i in ids], int)
    local = np.stack([marker_object_points(lengths_of[i]) for i in order])
    marker_T = np.stack([placed[i] for i in order])

    cams, rms = _init_cameras(frame, midx, T, marker_T, local, obs_norm, focal)
    d = {"frame": frame, "midx": midx, "obs_norm": obs_norm, "rms": rms, "local": local}
    fit = (cams, marker_T, order, ref, focal, max_ba_frames)
    return _fit(d, fit, rejected, frames_seen, obs.n_frames, str(dictionary))


def _fit(d: dict, fit: tuple, rejected: list, frames_seen: dict, n_frames: int, dictionary: str) -> MarkerMap:
    """Bundle adjustment with two outlier passes; the :class:`MarkerMap`."""
    cams, marker_T, order, ref, focal, max_ba_frames = fit
    frame, midx, obs_norm, local = d["frame"], d["midx"], d["obs_norm"], d["local"]
    ok = np.isfinite(d["rms"]) & (d["rms"] < INIT_OUTLIER_PX)
    for r in np.flatnonzero(~ok & np.isfinite(d["rms"])):
        rejected.append(
            f"marker {order[midx[r]]} in frame {int(frame[r])}: {d['rms'][r]:.1f} px from the map (false id?)"
        )
    use = _select_frames(frame[ok], midx[ok], max_ba_frames)
    rows = np.flatnonzero(ok & np.isin(frame, list(use)))
    ref_index = order.index(ref)
    mrt = np.array([np.concatenate(rvec_tvec_from_matrix(Tm)) for Tm in marker_T])
    if len(order) == 1 or rows.size == 0:  # one marker: nothing to adjust (a map of it alone)
        rejected.append("only one marker in the map: no bundle adjustment")
        e = d["rms"][ok]
        return MarkerMap(
            reference_id=int(ref),
            dictionary=dictionary,
            corners={ref: local[ref_index].copy()},
            ref_from_marker={ref: np.eye(4)},
            rms_px={ref: float(np.sqrt(np.mean(e**2))) if e.size else math.nan},
            frames_seen={ref: frames_seen[ref]},
            frames_used=0,
            n_frames=int(n_frames),
            rms_total_px=float(np.sqrt(np.mean(e**2))) if e.size else math.nan,
            rejected=rejected,
        )
    for _ in range(2):
        fl = sorted(set(frame[rows].tolist()))
        fpos = {f: k for k, f in enumerate(fl)}
        crt = np.array([np.concatenate(rvec_tvec_from_matrix(cams[f])) for f in fl])
        res = bundle_adjust(
            mrt, crt, local, midx[rows], np.array([fpos[f] for f in frame[rows]]), obs_norm[rows], focal, ref_index
        )
        mrt = res.marker_rt
        cams.update({f: matrix_from_rvec_tvec(res.cam_rt[k, :3], res.cam_rt[k, 3:]) for f, k in fpos.items()})
        limit = max(FINAL_OUTLIER_PX, 5.0 * float(np.median(res.residual_px)))
        bad = res.residual_px > limit
        if not bad.any():
            break
        for r, e in zip(rows[bad], res.residual_px[bad], strict=True):
            rejected.append(f"marker {order[midx[r]]} in frame {int(frame[r])}: {e:.1f} px after the fit")
        rows = rows[~bad]
    resid = res.residual_px[~bad] if bad.any() else res.residual_px
    final_rows = rows
    rms_px = {}
    for k, i in enumerate(order):
        e = resid[midx[final_rows] == k]
        rms_px[i] = float(np.sqrt(np.mean(e**2))) if e.size else math.nan
    ref_from = {i: matrix_from_rvec_tvec(mrt[k, :3], mrt[k, 3:]) for k, i in enumerate(order)}
    corners = {i: (ref_from[i][:3, :3] @ local[k].T).T + ref_from[i][:3, 3] for k, i in enumerate(order)}
    fitted = set(frame[final_rows].tolist())
    return MarkerMap(
        reference_id=int(ref),
        dictionary=dictionary,
        corners=corners,
        ref_from_marker=ref_from,
        rms_px=rms_px,
        frames_seen={i: frames_seen[i] for i in order},
        frames_used=len(fitted),
        n_frames=int(n_frames),
        rms_total_px=float(np.sqrt(np.mean(resid**2))) if resid.size else math.nan,
        rejected=rejected,
        cam_from_ref={f: cams[f] for f in sorted(fitted)},
    )


def reprojection_px(mmap: MarkerMap, intrinsics: Intrinsics, obs: Observations) -> np.ndarray:
    """RMS corner error (pixels) of each fitted observation of ``obs`` against the map and its cameras:
    (n,) float64, NaN for observations of unmapped markers or unfitted frames."""
    out = np.full(len(obs.ids), np.nan)
    for r in range(len(obs.ids)):
        f, i = int(obs.frame[r]), int(obs.ids[r])
        if f in mmap.cam_from_ref and i in mmap.corners:
            uv = intrinsics.project(mmap.corners[i], mmap.cam_from_ref[f])
            out[r] = float(np.sqrt(np.mean(np.sum((uv - obs.corners[r]) ** 2, axis=1))))
    return out
