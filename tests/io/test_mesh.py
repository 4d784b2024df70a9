"""Mesh reading/writing: user's vertex order kept, polygons triangulated with a map back,
and every kind of broken file rejected with a one-line MeshError naming it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from faceforge.exceptions import MeshError
from faceforge.io.mesh import load_mesh, read_obj_polygons, save_mesh, supported_formats, triangulate_polygons

DATA = Path(__file__).resolve().parents[1] / "data"


def tetra():
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) * 0.1 + 1 / 3
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int64)
    return v, f


def test_obj_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    v = rng.normal(size=(50, 3)) * 1e3
    f = rng.integers(0, 50, size=(80, 3))
    path = save_mesh(tmp_path / "m.obj", v, f)
    v2, f2, info = load_mesh(path)
    assert np.array_equal(v2, v) and np.array_equal(f2, f)
    assert v2.dtype == np.float64 and f2.dtype == np.int64
    assert info.format == "obj" and not info.triangulated and np.array_equal(info.face_source, np.arange(80))


@pytest.mark.parametrize("ext, atol", [(".ply", 0.0), (".off", 0.0), (".glb", 1e-6)])
def test_round_trip_other_formats_keeps_order(tmp_path, ext, atol):
    v, f = tetra()
    v2, f2, _ = load_mesh(save_mesh(tmp_path / f"m{ext}", v, f))
    assert np.allclose(v2, v, atol=atol, rtol=0) and np.array_equal(f2, f)


def test_stl_round_trip_merges_the_soup_into_the_same_triangles(tmp_path):
    v, f = tetra()
    v2, f2, _ = load_mesh(save_mesh(tmp_path / "m.stl", v, f))
    assert len(v2) == 4  # shared corners merged back
    def triangles(vv, ff):
        return sorted(tuple(np.round(vv[t], 6).ravel()) for t in ff)
    assert triangles(v2, f2) == triangles(v, f)


def test_obj_with_quads_texture_indices_and_negative_indices(tmp_path):
    text = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nvt 0 0\nvt 1 1\nvn 0 0 1\n"
            "f 1/1/1 2/2/1 3/1/1 4/2/1\n"   # quad with v/vt/vn
            "f -4 5 -3\n")                  # triangle with relative indices (2 5 3)
    path = tmp_path / "q.obj"
    path.write_text(text)
    v, f, info = load_mesh(path)
    assert v.shape == (5, 3) and np.array_equal(v[4], [2, 0, 0])   # order as written
    assert f.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 2]]
    assert info.face_source.tolist() == [0, 0, 1] and info.n_polygons == 2 and info.triangulated


def test_obj_polygons_are_read_as_in_the_file(tmp_path):
    path = tmp_path / "q.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nf 1/1/1 2/2/1 3/1/1 4/2/1\nf -4 5 -3\n")
    v, polygons = read_obj_polygons(path)
    assert v.shape == (5, 3) and polygons == [[0, 1, 2, 3], [1, 4, 2]]      # the quad stays a quad
    with pytest.raises(MeshError) as exc:
        read_obj_polygons(DATA / "malformed.obj")
    assert exc.value.line == 3
    with pytest.raises(MeshError, match="not found"):
        read_obj_polygons(tmp_path / "none.obj")


def test_fan_triangulation_invariants():
    rng = np.random.default_rng(1)
    polygons = [list(rng.permutation(20)[: rng.integers(3, 8)]) for _ in range(30)]
    faces, source = triangulate_polygons(polygons)
    assert len(faces) == sum(len(p) - 2 for p in polygons)
    for tri, s in zip(faces, source):
        assert set(tri) <= set(polygons[s]) and tri[0] == polygons[s][0]
    # a planar convex polygon keeps its area
    k = 7
    angles = np.linspace(0, 2 * np.pi, k, endpoint=False)
    pts = np.stack([np.cos(angles), np.sin(angles), np.zeros(k)], axis=1)
    tri, _ = triangulate_polygons([list(range(k))])
    area = 0.5 * np.linalg.norm(np.cross(pts[tri[:, 1]] - pts[tri[:, 0]], pts[tri[:, 2]] - pts[tri[:, 0]]), axis=1).sum()
    assert np.isclose(area, 0.5 * k * np.sin(2 * np.pi / k))


def test_ply_mixed_polygons_keep_file_order(tmp_path):
    path = tmp_path / "mixed.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
                    "property float z\nelement face 3\nproperty list uchar int vertex_indices\nend_header\n"
                    "0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 0\n2 1 0\n3 1 4 5\n4 0 1 2 3\n3 1 5 2\n")
    _, f, info = load_mesh(path)
    assert f.tolist() == [[1, 4, 5], [0, 1, 2], [0, 2, 3], [1, 5, 2]]
    assert info.face_source.tolist() == [0, 1, 1, 2]


def test_sample_head_loads_with_its_quads(repo_root):
    path = repo_root / "samples" / "makehuman" / "mh_head_default.obj"
    if not path.exists():
        pytest.skip("sample head not in this checkout")
    v, f, info = load_mesh(path)
    n_v = sum(1 for line in path.read_text().splitlines() if line.startswith("v "))
    first = next(line for line in path.read_text().splitlines() if line.startswith("v "))
    assert len(v) == n_v and np.allclose(v[0], [float(x) for x in first.split()[1:4]])
    assert len(f) == 2 * info.n_polygons  # an all-quad mesh


@pytest.mark.parametrize("name, cause", [
    ("nan_vertex.obj", "1 vertices have NaN or infinite coordinates (first: vertex 2)"),
    ("inf_vertex.stl", "NaN or infinite coordinates"),
    ("no_faces.obj", "mesh has no faces"),
    ("bad_index.obj", "face 0 refers to vertex [0, 1, 6] but the mesh has 3 vertices"),
    ("garbage.ply", "cannot read PLY"),
    ("truncated.off", "malformed OFF: header announces 4 vertices and 2 faces; file ends early"),
])
def test_broken_files_are_rejected_naming_the_file(name, cause):
    with pytest.raises(MeshError) as exc:
        load_mesh(DATA / name)
    text = str(exc.value)
    assert text.startswith(str(DATA / name)) and cause in text and "\n" not in text


def test_malformed_obj_names_the_line():
    with pytest.raises(MeshError) as exc:
        load_mesh(DATA / "malformed.obj")
    assert exc.value.line == 3 and str(exc.value).startswith(f"{DATA / 'malformed.obj'}:3: malformed OBJ line")


def test_missing_folder_empty_and_unsupported(tmp_path):
    with pytest.raises(MeshError, match=r"nope.obj: mesh file not found$"):
        load_mesh(tmp_path / "nope.obj")
    with pytest.raises(MeshError, match=r"is a folder"):
        load_mesh(tmp_path)
    (tmp_path / "empty.obj").write_text("")
    with pytest.raises(MeshError, match=r"empty.obj: mesh has no vertices$"):
        load_mesh(tmp_path / "empty.obj")
    (tmp_path / "head.fbx").write_text("x")
    with pytest.raises(MeshError) as exc:
        load_mesh(tmp_path / "head.fbx")
    assert str(exc.value) == f"{tmp_path / 'head.fbx'}: unsupported mesh format '.fbx' (supported: {', '.join(supported_formats())})"
    for ext in (".obj", ".ply", ".stl", ".off", ".glb"):
        assert ext in supported_formats()


def test_save_mesh_rejects_bad_shapes_and_formats(tmp_path):
    v, f = tetra()
    with pytest.raises(ValueError, match=r"\(4, 2\)"):
        save_mesh(tmp_path / "x.obj", v[:, :2], f)
    with pytest.raises(MeshError, match="cannot write format '.fbx'"):
        save_mesh(tmp_path / "x.fbx", v, f)
