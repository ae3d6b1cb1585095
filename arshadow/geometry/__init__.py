"""Pure geometry (numpy only, no GL): testable without a context.

- :mod:`arshadow.geometry.mesh`: ``load_occluder`` and ``ShadowCaster`` (cached adjacency and normals,
  computed once per mesh).
- :mod:`arshadow.geometry.silhouette`: the silhouette detectors (adjacency, triangular, VnV, HSD, Delta+).
- :mod:`arshadow.geometry.silhouette_reference`: paper-faithful, operation-counting versions (benchmarks).
- :mod:`arshadow.geometry.volume`: shadow volumes (caps, truncation, stencil layer bounds).
- :mod:`arshadow.geometry.projection`: planar projection shadows ([Kolivand-Stencil] and [Kolivand-Sun]).
- :mod:`arshadow.geometry.exact`: the exact projected shadow (the tests' and benchmarks' reference).
- :mod:`arshadow.geometry.ground`: a ground plane that is not the marker plane (``--ground``, ``marker_from_ground``).
"""
