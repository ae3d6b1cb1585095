"""Shading inputs computed without a GL context: corner normals, sky visibility, materials, camera effects.

- :mod:`arshadow.geometry.normals`: per-corner normals that keep flat faces flat (crease angle per face);
- :mod:`arshadow.shading.sky`: the object's occlusion of the sky, on the ground and on the object;
- :mod:`arshadow.geometry.material`: base colour, texture and UVs read from the mesh file.
"""
