"""Pure functions on ``(vertices (n, 3) float64, faces (m, 3) int64)`` meshes.

Submodules: :mod:`.triangles` (normals, areas, barycentric coordinates),
:mod:`.surface_points` (§5.1.1 surface points, projection), :mod:`.rbf`
(§4 Hardy multiquadric morph), :mod:`.rays` (ray casting), :mod:`.geodesic`
(heat-method geodesic distance). Imports nothing of faceforge except
``constants`` and ``exceptions``.
"""
