"""Independent per-pixel oracle for the renderer's shadow mask (no GL, no arshadow geometry code).

For a pinhole camera ``K``, ``cam_from_world`` and an occluder given as raw ``vertices (n, 3)`` /
``faces (m, 3)``:

- ground point of a pixel centre ``(u, v)``: back-project the ray ``R^T K^-1 (u, v, 1)`` from the camera
  centre and intersect it with z = 0 (only rays going down reach the ground);
- occluder coverage: the ray hits an occluder triangle above the ground (z >= 0) before reaching it;
  computed by testing the pixel centre against every triangle's image (projected vertices, all in front
  of the camera) and checking the hit point's height;
- shadow: the ground point lies inside the union of the occluder's triangles projected from the light
  onto z = 0 (:func:`oracle.ground_shadow_triangles`, the tests' one analytic ground shadow); tested in
  ground coordinates, so shadow triangles reaching behind the camera need no clipping.

Everything is vectorised numpy with a per-triangle loop over bounding-box candidates. Points are arbitrary
(sub-pixel) image positions, so the same code gives the pixel-centre oracle and the fine-resolution
boundary-distance measurement (:func:`boundary_distance`).
"""

from __future__ import annotations

import numpy as np

from arshadow.geometry.exact import ShadowOracle, ground_points, in_ground_square, iou, occluder_coverage  # noqa: F401 (re-exported for the tests)

__all__ = ["ShadowOracle", "boundary_distance", "ground_points", "iou", "occluder_coverage"]


def boundary_distance(oracle: ShadowOracle, pixels_uv, threshold, radius=1.0, step=1.0 / 32, far_radius=4.0):
    """Distance (px) from each given pixel centre to the boundary of the oracle's thresholded mask
    ``mask >= threshold``, measured on a fine grid (``step`` px) within ``radius``; pixels with no
    opposite-class sample within ``radius`` are re-measured with a coarser grid up to ``far_radius``
    (and get ``far_radius`` if still none is found: a gross error).

    Returns (n,) float64.
    """
    pixels_uv = np.asarray(pixels_uv, np.float64).reshape(-1, 2)
    out = np.full(len(pixels_uv), np.nan)
    for r, st in ((radius, step), (far_radius, 0.25)):
        todo = np.flatnonzero(np.isnan(out))
        if todo.size == 0:
            break
        offs = np.arange(-r, r + st / 2, st)
        du, dv = np.meshgrid(offs, offs)
        du, dv = du.ravel(), dv.ravel()
        dist = np.hypot(du, dv)
        keep = dist <= r
        du, dv, dist = du[keep], dv[keep], dist[keep]
        for i in todo:
            u, v = pixels_uv[i]
            c0 = oracle.classify(np.array([u]), np.array([v]))[0][0] >= threshold
            m = oracle.classify(u + du, v + dv)[0] >= threshold
            opp = m != c0
            if np.any(opp):
                out[i] = float(dist[opp].min())
    out[np.isnan(out)] = far_radius
    return out
