"""Stage modules: each declares one :class:`~faceforge.pipeline.Stage` and its command.

Every module here is imported by :func:`faceforge.pipeline.discover` (sorted by
name), so adding a stage means adding one file; see ``faceforge/pipeline/__init__.py``
for the pattern. Keep module imports light: heavy imports go inside ``run``.
"""
