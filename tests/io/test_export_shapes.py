"""Named blendshapes written as glTF and USD and read back."""

from __future__ import annotations

import numpy as np
import pytest

from faceforge.io.export_shapes import read_obj_uvs, read_shapes_glb, write_shapes_glb, write_shapes_usda

QUADS = [(0, 1, 2, 3), (1, 4, 5, 2)]


def _mesh():
    base = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0.2], [2, 1, 0.2]], dtype=float)
    rng = np.random.default_rng(0)
    shapes = base + rng.normal(scale=0.1, size=(3, 6, 3))
    shapes[2] = base                                       # a placeholder (not made)
    return base, shapes, ["jawOpen", "eyeBlinkLeft", "tongueOut"]


def test_glb_round_trip_names_normals_uvs_weights(tmp_path):
    base, shapes, names = _mesh()
    uvs = np.linspace(0, 1, 12).reshape(6, 2)
    w = np.array([[0, 0, 0], [0.5, 1, 0], [1, 0.25, 0]])
    p = write_shapes_glb(tmp_path / "s.glb", base, shapes, names, QUADS, uvs=uvs, weights=w, fps=30,
                         not_made=["tongueOut"])
    g = read_shapes_glb(p)
    assert g["names"] == names
    # neutral + delta is each shape exactly in float32
    assert np.array_equal(g["base"] + g["targets"], shapes.astype(np.float32))
    assert np.allclose(np.linalg.norm(g["normals"], axis=1), 1.0, atol=1e-6)
    assert np.allclose(g["normals"][[0, 3]], [0, 0, 1], atol=1e-6)   # only on the flat quad: +Z
    assert np.allclose(g["uvs"][:, 0], uvs[:, 0]) and np.allclose(g["uvs"][:, 1], 1 - uvs[:, 1])
    assert np.allclose(g["times"], np.arange(3) / 30) and np.allclose(g["weights"], w)
    assert len(g["triangles"]) == 4
    from faceforge.io.export_gltf import parse_glb

    gltf, _ = parse_glb(p)
    assert gltf["meshes"][0]["extras"]["notMade"] == ["tongueOut"]


def test_glb_rejects_bad_input(tmp_path):
    base, shapes, names = _mesh()
    with pytest.raises(ValueError, match="unique"):
        write_shapes_glb(tmp_path / "s.glb", base, shapes, ["a", "a", "b"], QUADS)
    with pytest.raises(ValueError, match="weights"):
        write_shapes_glb(tmp_path / "s.glb", base, shapes, names, QUADS, weights=np.zeros((2, 2)))


def test_usd_blend_shapes_read_back_with_pxr(tmp_path):
    pxr = pytest.importorskip("pxr")
    from pxr import Usd, UsdSkel

    base, shapes, names = _mesh()
    w = np.array([[0, 0, 0], [0.5, 1, 0]])
    p = write_shapes_usda(tmp_path / "s.usda", base, shapes, names, QUADS, weights=w, fps=24)
    stage = Usd.Stage.Open(str(p))
    mesh = stage.GetPrimAtPath("/Head/face")
    binding = UsdSkel.BindingAPI(mesh)
    assert list(binding.GetBlendShapesAttr().Get()) == names
    for name, shape in zip(names, shapes):
        bs = UsdSkel.BlendShape(stage.GetPrimAtPath(f"/Head/face/{name}"))
        offsets = np.array(bs.GetOffsetsAttr().Get(), dtype=float).reshape(-1, 3)
        idx = np.array(bs.GetPointIndicesAttr().Get(), dtype=int)
        full = np.zeros_like(base)
        full[idx] = offsets
        assert np.allclose(full, shape - base, atol=1e-6)
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Head/skel/anim"))
    assert list(anim.GetBlendShapesAttr().Get()) == names
    assert np.allclose(anim.GetBlendShapeWeightsAttr().Get(1), w[1])


def test_obj_uvs_per_vertex_or_none(tmp_path):
    p = tmp_path / "m.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.1 0.2\nvt 0.3 0.4\nvt 0.5 0.6\nf 1/1 2/2 3/3\n")
    assert np.allclose(read_obj_uvs(p, 3), [[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]])
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nf 1/1 2/2 3/1\nf 2/1 4/2 3/1\n")
    assert read_obj_uvs(p, 4) is None          # vertex 2 has two UVs: a seam
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert read_obj_uvs(p, 3) is None
