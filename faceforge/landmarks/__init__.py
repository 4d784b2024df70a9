"""Automatic MPEG-4 FDP landmarks on a head mesh (issue 26).

``raster`` (headless z-buffer renders), ``detector`` (MediaPipe Face Landmarker), ``views``
(the face search over 24 axis frames, consensus cameras), ``lift`` (back-projection, holes
to their rim), ``rules`` (chin, cheeks, eye openings from the mesh), ``symmetry`` (mirror
plane), ``detect`` (:func:`detect.detect_landmarks`, the whole chain), ``find`` (the user's
file completed by detection), ``output`` (landmark file, report, picture). Heavy imports
stay inside the modules, so importing this package costs nothing.
"""
