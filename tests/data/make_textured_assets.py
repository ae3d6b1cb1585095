"""Write the textured test meshes in tests/data/textured/ (run from the repository root; deterministic).

A 10 x 10 cm square (two triangles) with a 64 x 64 RGB texture of four coloured quadrants, a white disc
in the (u, v) = (0.25, 0.75) quadrant (so any flip or transpose of the UVs shows), written by hand, without
trimesh, so that the loader is checked against the formats' own specifications:

- ``quad.glb``: glTF 2.0 binary, Y-up (the square lies in the file's XZ plane, normal +Y), the texture as
  an embedded PNG, ``baseColorFactor`` (1, 1, 1, 1), ``metallicFactor`` 0, ``roughnessFactor`` 0.8;
  glTF texture coordinates have their origin at the image's top-left (spec 3.9.2).
- ``quad.obj`` + ``quad.mtl`` + ``quad.png``: Z-up (the square in the XY plane), ``map_Kd``; OBJ texture
  coordinates have their origin at the image's bottom-left.

Corners (x, y) in metres and the texture point at each, as (column, row) fractions of the image from its
top-left: (-0.05, -0.05) -> (0, 1), (0.05, -0.05) -> (1, 1), (0.05, 0.05) -> (1, 0), (-0.05, 0.05) -> (0, 0);
i.e. the image lies on the square as seen from above with its top row at +y.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import cv2
import numpy as np

OUT = Path(__file__).with_name("textured")
SIZE = 64
#: quadrant colours (sRGB 0..255, RGB) by (row half, column half) of the image
QUADRANTS = {(0, 0): (200, 30, 30), (0, 1): (30, 200, 30), (1, 0): (30, 30, 200), (1, 1): (220, 200, 40)}
#: the square's corners (x, y), and the (column, row) image fractions at each (see module doc)
CORNERS = np.array([[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05]])
IMAGE_AT_CORNER = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])


def texture_rgb() -> np.ndarray:
    """(64, 64, 3) uint8 RGB, row 0 = the image's top."""
    img = np.zeros((SIZE, SIZE, 3), np.uint8)
    h = SIZE // 2
    for (r, c), col in QUADRANTS.items():
        img[r * h : (r + 1) * h, c * h : (c + 1) * h] = col
    cv2.circle(img, (h // 2, h // 2), h // 4, (255, 255, 255), -1)  # in the top-left quadrant
    return img


def _png(img_rgb: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", cv2.cvtColor(img_rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return buf.tobytes()


def write_glb(path: Path) -> None:
    # Y-up file: world (x, y, 0) -> file (x, 0, -y) (arshadow turns file +y to world +z, file +z to world -y)
    pos = np.array([[x, 0.0, -y] for x, y in CORNERS], np.float32)
    uv = IMAGE_AT_CORNER.astype(np.float32)  # glTF: (s, t) from the image's top-left
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    png = _png(texture_rgb())
    parts = [pos.tobytes(), uv.tobytes(), idx.tobytes() + b"\0\0", png]
    offsets = np.cumsum([0] + [len(p) for p in parts])
    pad = (-len(b"".join(parts))) % 4
    binary = b"".join(parts) + b"\0" * pad
    gltf = {
        "asset": {"version": "2.0", "generator": "arshadow tests/data/make_textured_assets.py"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "materials": [
            {
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": 0},
                    "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.8,
                }
            }
        ],
        "textures": [{"source": 0}],
        "images": [{"bufferView": 3, "mimeType": "image/png"}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": int(offsets[0]), "byteLength": len(parts[0]), "target": 34962},
            {"buffer": 0, "byteOffset": int(offsets[1]), "byteLength": len(parts[1]), "target": 34962},
            {"buffer": 0, "byteOffset": int(offsets[2]), "byteLength": 12, "target": 34963},
            {"buffer": 0, "byteOffset": int(offsets[3]), "byteLength": len(parts[3])},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": 4,
                "type": "VEC3",
                "min": pos.min(0).tolist(),
                "max": pos.max(0).tolist(),
            },
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"},
        ],
    }
    js = json.dumps(gltf, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(binary), 0x004E4942) + binary
    path.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)


def write_obj(path: Path) -> None:
    path.with_suffix(".png").write_bytes(_png(texture_rgb()))
    path.with_suffix(".mtl").write_text("newmtl quad\nKd 1.0 1.0 1.0\nmap_Kd quad.png\n")
    lines = ["mtllib quad.mtl", "usemtl quad"]
    lines += [f"v {x:.6f} {y:.6f} 0.000000" for x, y in CORNERS]
    lines += [f"vt {c:.6f} {1.0 - r:.6f}" for c, r in IMAGE_AT_CORNER]  # OBJ: v from the image's bottom
    lines += ["f 1/1 2/2 3/3", "f 1/1 3/3 4/4"]
    path.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    OUT.mkdir(exist_ok=True)
    write_glb(OUT / "quad.glb")
    write_obj(OUT / "quad.obj")
    print("wrote", sorted(p.name for p in OUT.iterdir()))
