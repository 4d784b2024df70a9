"""The face landmarker is made without MediaPipe's package imports (matplotlib, cv2, audio)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

CODE = """
import sys
sys.path.insert(0, %r)
import numpy as np
from faceforge.landmarks.detector import Detector
with Detector() as d:
    assert d.detect(np.full((128, 128, 3), 128, np.uint8)) is None
heavy = sorted(m for m in ("matplotlib", "cv2", "sounddevice") if m in sys.modules)
left = sorted(m for m in sys.modules if m == "mediapipe" or m.startswith("mediapipe."))
import mediapipe                              # the ordinary import still works afterwards
print(heavy, left[:3], mediapipe.tasks.vision.FaceLandmarker.__name__)
"""


def test_detector_skips_mediapipes_heavy_imports_and_leaves_the_ordinary_import_working():
    out = subprocess.run([sys.executable, "-c", CODE % str(ROOT)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[] [] FaceLandmarker"
