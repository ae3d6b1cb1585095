"""Putting the render into the photo on the CPU (numpy, no GL).

- :mod:`arshadow.compose.lens`: the lens warp of a pinhole render into the distorted photo.
- :mod:`arshadow.compose.composite`: linear-light compositing of the object and its shadow.

The shader path that does the same on the GPU is :mod:`arshadow.gl.gpu_compose`.
"""
