"""The GLBs faceforge writes, through the Khronos glTF validator (npm ``gltf-validator``): no error,
no warning. Needs ``GLTF_VALIDATOR_DIR``, a folder where ``npm install gltf-validator`` ran, and
``node`` on PATH; skipped otherwise (benchmarks/bench_bake.py runs it on the real bakes).

The shapes are synthetic (each sample head's vertices moved by a vertex-dependent wave), the
layouts the real ones: the bake's (52 named targets, no animation), ``animate --curves -o x.glb``'s
(the 52 targets plus a weights animation) and ``animate -o x.glb``'s (one target per frame).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from faceforge.blendshapes.arkit import ARKIT_NAMES
from faceforge.io.export_common import polygons_from_fan
from faceforge.io.export_gltf import write_glb
from faceforge.io.export_shapes import read_obj_uvs, write_shapes_glb
from faceforge.io.mesh import load_mesh

ROOT = Path(__file__).resolve().parents[2]
VALIDATOR = os.environ.get("GLTF_VALIDATOR_DIR")
pytestmark = pytest.mark.skipif(
    not (VALIDATOR and (Path(VALIDATOR) / "node_modules" / "gltf-validator").is_dir() and shutil.which("node")),
    reason="no glTF validator: set GLTF_VALIDATOR_DIR to a folder where `npm install gltf-validator` ran")
HEADS = {"makehuman": "makehuman/mh_head_default.obj", "ict": "ict/ict_face_headneck_neutral.obj",
         "mediapipe": "mediapipe/face_model_with_iris.obj"}
JS = ("const fs=require('fs'),v=require('gltf-validator');v.validateBytes(new Uint8Array(fs.readFileSync("
      "process.argv[1]))).then(r=>console.log(JSON.stringify({errors:r.issues.numErrors,warnings:"
      "r.issues.numWarnings,messages:r.issues.messages.filter(m=>m.severity<2)})))")


def validate(glb: Path) -> dict:
    done = subprocess.run(["node", "-e", JS, str(glb)], capture_output=True, text=True, cwd=VALIDATOR, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)


def _moved(vertices: np.ndarray, k: int) -> np.ndarray:
    """(k, n, 3) float32: k different smooth motions of 2 % of the head's size."""
    size = float(np.ptp(vertices, axis=0).max())
    phase = vertices @ np.array([3.0, 5.0, 7.0]) / size
    t = np.arange(1, k + 1)[:, None] / k
    return (vertices[None] + 0.02 * size * np.sin(2 * np.pi * (t + phase[None]))[..., None]).astype(np.float32)


@pytest.mark.parametrize("head", sorted(HEADS))
def test_the_shapes_and_weights_glbs_validate_clean(tmp_path, head):
    mesh = ROOT / "samples" / HEADS[head]
    vertices, triangles, info = load_mesh(mesh)
    polygons = polygons_from_fan(triangles, info.face_source)
    shapes = _moved(vertices, len(ARKIT_NAMES))
    uvs = read_obj_uvs(mesh, len(vertices))
    weights = np.random.default_rng(27).uniform(0, 1, (12, len(ARKIT_NAMES)))
    files = [write_shapes_glb(tmp_path / "bake.glb", vertices, shapes, list(ARKIT_NAMES), polygons, uvs=uvs),
             write_shapes_glb(tmp_path / "curves.glb", vertices, shapes, list(ARKIT_NAMES), polygons, uvs=uvs,
                              weights=weights, fps=25.0),
             write_glb(tmp_path / "frames.glb", _moved(vertices, 5), polygons, 25.0)]
    for glb in files:
        report = validate(glb)
        assert report["errors"] == 0 and report["warnings"] == 0, (glb.name, report["messages"][:5])
