"""Generate the sample meshes in samples/meshes/ (deterministic; run from anywhere).

    python samples/make_meshes.py

- ``knot.ply``: a (2, 3) torus-knot tube, 194 x 22 quads = 8 536 triangles (the size of [Kolivand-DeltaPlus]'s AR
  scene), closed, non-convex, with a colour gradient along the tube; about 0.12 m across, resting on
  the ground.
- ``house.obj``: a low-poly house (walls + gable roof as one closed pentagonal prism, plus a closed box
  chimney poking out of the roof) - flat faces, good for the Hybrid Silhouette Detector.
- ``umbrella.ply``: an open mesh: a single-sided scalloped canopy (8 panels) on an open tube pole; its
  shadow needs the two-sided rule for open meshes.

The functions are importable (tests and benchmarks use :func:`torus_knot` for bigger meshes).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def torus_knot(
    n_seg: int = 194, n_side: int = 22, p: int = 2, q: int = 3, R: float = 0.04, r: float = 0.016, tube: float = 0.011
):
    """A closed (p, q) torus-knot tube: ``n_seg * n_side * 2`` triangles, outward wound.

    Returns ``vertices (n_seg*n_side, 3)``, ``faces (2*n_seg*n_side, 3)`` and per-vertex colours
    ``(n, 4) uint8``. The knot rests on z = 0.
    """
    t = np.linspace(0.0, 2.0 * np.pi, n_seg, endpoint=False)

    def curve(t):
        rr = R + r * np.cos(q * t)
        return np.stack([rr * np.cos(p * t), rr * np.sin(p * t), r * np.sin(q * t)], axis=-1)

    c = curve(t)
    # analytic-ish derivatives by central differences on the closed curve (Frenet frame is smooth here)
    dt = 1e-4
    d1 = (curve(t + dt) - curve(t - dt)) / (2 * dt)
    d2 = (curve(t + dt) - 2 * c + curve(t - dt)) / dt**2
    T = d1 / np.linalg.norm(d1, axis=1)[:, None]
    B = np.cross(d1, d2)
    B /= np.linalg.norm(B, axis=1)[:, None]
    N = np.cross(B, T)
    a = np.linspace(0.0, 2.0 * np.pi, n_side, endpoint=False)
    v = c[:, None, :] + tube * (np.cos(a)[None, :, None] * N[:, None, :] + np.sin(a)[None, :, None] * B[:, None, :])
    v = v.reshape(-1, 3)
    i = np.arange(n_seg)[:, None]
    j = np.arange(n_side)[None, :]
    v00 = i * n_side + j
    v10 = ((i + 1) % n_seg) * n_side + j
    v01 = i * n_side + (j + 1) % n_side
    v11 = ((i + 1) % n_seg) * n_side + (j + 1) % n_side
    f = np.concatenate([np.stack([v00, v10, v11], -1).reshape(-1, 3), np.stack([v00, v11, v01], -1).reshape(-1, 3)])
    # outward winding check: enclosed volume must be positive
    tri = v[f]
    if np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() < 0:
        f = f[:, ::-1]
    v[:, 2] -= v[:, 2].min()
    hue = np.repeat(t / (2 * np.pi), n_side)
    col = np.stack([0.5 + 0.5 * np.cos(2 * np.pi * (hue + k / 3)) for k in range(3)], axis=1)
    col = (255 * (0.25 + 0.7 * col)).astype(np.uint8)
    col = np.concatenate([col, np.full((len(v), 1), 255, np.uint8)], axis=1)
    return v, f, col


def house():
    """A low-poly house: a closed pentagonal prism (walls + gable roof) and a closed box chimney."""
    w, d, h, ridge = 0.06, 0.08, 0.04, 0.065  # width (x), depth (y), wall height, ridge height
    pent = np.array([[-w / 2, 0, 0], [w / 2, 0, 0], [w / 2, 0, h], [0, 0, ridge], [-w / 2, 0, h]])
    front = pent + [0, -d / 2, 0]
    back = pent + [0, d / 2, 0]
    v = np.concatenate([front, back])
    f = []
    # front (y = -d/2, normal -y) and back pentagons as fans
    for k in range(1, 4):
        f.append([0, k, k + 1])
        f.append([5, 5 + k + 1, 5 + k])
    # sides: quads between consecutive pentagon corners
    for k in range(5):
        a, b = k, (k + 1) % 5
        f.append([a, 5 + a, 5 + b])
        f.append([a, 5 + b, b])
    f = np.array(f)
    tri = v[f]
    if np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() < 0:
        f = f[:, ::-1]
    # chimney: a box from z = 0.035 to 0.08 at x = 0.015, y = 0.015
    import trimesh

    ch = trimesh.creation.box(extents=[0.012, 0.012, 0.045])
    cv = np.asarray(ch.vertices) + [0.015, 0.015, 0.035 + 0.0225]
    cf = np.asarray(ch.faces) + len(v)
    verts = np.concatenate([v, cv])
    faces = np.concatenate([f, cf])
    fc = np.concatenate(
        [
            np.tile([200, 120, 90, 255], (6, 1)),
            np.tile([230, 220, 200, 255], (len(f) - 6, 1)),
            np.tile([120, 60, 50, 255], (len(cf), 1)),
        ]
    )
    return verts, faces, fc.astype(np.uint8)


def umbrella(
    n_panels: int = 8,
    n_rings: int = 10,
    n_per_panel: int = 8,
    radius: float = 0.06,
    top: float = 0.09,
    depth: float = 0.03,
    pole_r: float = 0.0025,
):
    """An open umbrella: a single-sided canopy (faces wound to face up) and an open tube as the pole."""
    n_ang = n_panels * n_per_panel
    ang = np.linspace(0.0, 2 * np.pi, n_ang, endpoint=False)
    rad = np.linspace(0.0, 1.0, n_rings + 1)[1:]
    # scalloped rim: panels sag between the ribs
    scallop = 1.0 - 0.12 * np.sin(np.pi * (np.arange(n_ang) % n_per_panel) / n_per_panel)
    rr = radius * rad[:, None] * scallop[None, :]
    z = top - depth * (rad[:, None] ** 1.5) * (0.85 + 0.15 * scallop[None, :])
    ring = np.stack([rr * np.cos(ang)[None, :], rr * np.sin(ang)[None, :], z], axis=-1).reshape(-1, 3)
    v = np.concatenate([[[0.0, 0.0, top]], ring])
    f = []
    for j in range(n_ang):
        f.append([0, 1 + j, 1 + (j + 1) % n_ang])
    for i in range(n_rings - 1):
        for j in range(n_ang):
            a = 1 + i * n_ang + j
            b = 1 + i * n_ang + (j + 1) % n_ang
            c = a + n_ang
            d = b + n_ang
            f += [[a, c, d], [a, d, b]]
    f = np.array(f)
    nrm = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    f[nrm[:, 2] < 0] = f[nrm[:, 2] < 0][:, ::-1]
    # pole: an open tube (no caps) from the ground to the canopy's top
    k = 12
    a = np.linspace(0, 2 * np.pi, k, endpoint=False)
    bot = np.stack([pole_r * np.cos(a), pole_r * np.sin(a), np.zeros(k)], 1)
    tp = bot + [0, 0, top - 0.002]
    base = len(v)
    v = np.concatenate([v, bot, tp])
    pf = []
    for j in range(k):
        a0, a1 = base + j, base + (j + 1) % k
        b0, b1 = a0 + k, a1 + k
        pf += [[a0, a1, b1], [a0, b1, b0]]
    faces = np.concatenate([f, np.array(pf)])
    col = np.tile([40, 90, 200, 255], (len(v), 1))
    col[base:] = [60, 60, 60, 255]
    return v, faces, col.astype(np.uint8)


def main() -> None:
    import trimesh

    out = HERE / "meshes"
    out.mkdir(parents=True, exist_ok=True)
    v, f, c = torus_knot()
    trimesh.Trimesh(v, f, vertex_colors=c, process=False).export(out / "knot.ply")
    v, f, fc = house()
    trimesh.Trimesh(v, f, face_colors=fc, process=False).export(out / "house.obj")
    v, f, c = umbrella()
    trimesh.Trimesh(v, f, vertex_colors=c, process=False).export(out / "umbrella.ply")
    for p in sorted(out.iterdir()):
        print(p.relative_to(HERE.parent), p.stat().st_size, "bytes")


if __name__ == "__main__":
    main()
